"""One model's work on the frames a source hands over, in two lanes.

:class:`Streamer` computes and sends (the robot lane) and hands every frame to the data
lane; :func:`fingerfit.live.stream.run` is the loop that feeds it (the lanes, the status
line, Ctrl-C and the watchdog are described there).
"""

from __future__ import annotations

import collections
import math
import time
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..kinematics import KinematicsPlan
from ..model import HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..track.live import LiveTracker
from ..transforms import FloatArray
from .datalane import DataLane
from .markers import is_marker_model, kinematics_of, marker_solver, with_hand
from .outputs import BagOutput, LslOutput, RecordOutput, Ros2Output
from .sources import Block
from .values import (
    Channels,
    FrameValues,
    Summary,
    channels_of,
    empty_recording,
    model_sensors,
    sensor_presence,
    source_codes,
)

#: Default ``--max-age`` (ms): the robot lane sends no frame older than this.
DEFAULT_MAX_AGE_MS = 20.0
#: ``--on-silence`` policies: the robot keeps its pose, or goes to its rest pose.
SILENCE_POLICIES = ("hold", "release")


class Streamer:
    """Kinematics and outputs for one model, in two lanes.

    * The **robot lane** (live outputs: LSL, DDS; the robot's joints with
      ``retargeter``) is latest-wins: of the frames that arrived together it computes and
      sends only the newest, counts the others as skipped, and never sends a frame older
      than ``max_age`` (counted as stale).
    * The **data lane** (:class:`DataLane`: ``record``, ``bag``, ``view``) writes every
      frame, on its own thread, behind the robot lane.

    Parameters
    ----------
    model : HandModel
    lsl : LslOutput, optional
    ros2 : Ros2Output, optional
    bag : BagOutput, optional
    record : RecordOutput, optional
    record_units : str
        Units of the fingertips in the angles CSV (as ``fingerfit angles``).
    tips_frame : {"tracker", "hand"}
        Frame of the LSL fingertips.
    channels : Channels, optional
        The streamed names (default: from the model); the LSL outlets must use the same.
    retargeter : fingerfit.retarget.Retargeter, optional
        Drives a robot hand: every sent frame's kinematics go through its ``step``; the
        ROS 2 outputs then carry the robot's joints (``robot.joint_names``, rad) and the
        LSL output its ``-robot`` outlet (built with ``robot_labels``).
    bag_retargeter : fingerfit.retarget.Retargeter, optional
        The bag's robot joints when there is also a live output (a second instance on a
        robot of its own: the data lane steps through every frame on another thread).
        Without a live output the bag uses ``retargeter``.
    max_age : float
        Seconds: a frame older than this when the robot lane would send it is not sent.
    on_silence : {"hold", "release"}
        What the robot outlet sends when the watchdog fires (:meth:`silence`).
    view : fingerfit.view.LiveView, optional
        The live view, fed by the data lane. Its robot follows the data lane's
        retargeter when that lane has one (no live output, or a bag); else, with a live
        output and a ``retargeter``, the joints the robot lane sent (each sent frame's
        copied to ``view.sent``, nothing else added to the robot lane).
    """

    def __init__(
        self,
        model: HandModel,
        *,
        lsl: LslOutput | None = None,
        ros2: Ros2Output | None = None,
        bag: BagOutput | None = None,
        record: RecordOutput | None = None,
        record_units: str = "mm",
        tips_frame: str = "tracker",
        channels: Channels | None = None,
        retargeter: Any = None,
        bag_retargeter: Any = None,
        max_age: float = DEFAULT_MAX_AGE_MS / 1e3,
        on_silence: str = "hold",
        view: Any = None,
    ) -> None:
        if tips_frame not in ("tracker", "hand"):
            raise FingerfitError("must be tracker or hand", field="--tips-frame")
        markers = is_marker_model(model)
        if markers and retargeter is not None and retargeter.variant != "user_axis":
            raise FingerfitError(
                "a model fitted from markers has its fitted axes only", field="--orthogonal"
            )
        check_max_age(1e3 * max_age)
        if on_silence not in SILENCE_POLICIES:
            raise FingerfitError(
                f"must be one of {', '.join(SILENCE_POLICIES)}", field="--on-silence"
            )
        self.model = model
        self.lsl, self.ros2, self.bag, self.record = lsl, ros2, bag, record
        self.record_units = record_units
        self.tips_frame = tips_frame
        self.max_age = max_age
        self.on_silence = on_silence
        self.sensors = model_sensors(model)
        self.markers = markers
        if markers:
            marker_solver()  # imported now, not on the first frames
        self.live = lsl is not None or ros2 is not None
        variants = ["user_axis"]
        if retargeter is not None and retargeter.variant not in variants:
            variants.append(retargeter.variant)  # --orthogonal: computed with the others
        self.variants = tuple(variants)
        self.retargeter = retargeter
        # Names from a probe of no frames; values are then taken by name from every
        # block, so the channel order is fixed for the whole stream.
        self.channels = channels or channels_of(
            model, kinematics_of(model, empty_recording(self.sensors, markers), ("user_axis",))[0]
        )
        # The model's constants are prepared once (swing-twist models; the paper's
        # projection angles go through compute_kinematics on every block).
        self.plan = (
            KinematicsPlan(model, self.variants)
            if model.angle_method == "swing_twist" and self.live and not markers
            else None
        )
        # Frames with a missing sensor: solved by the model, one at a time (a model without
        # calibration statistics cannot: those frames are held).
        # (a model fitted from markers solves such frames in its own kinematics)
        self.tracker = (
            LiveTracker(model, self.variants)
            if model.tracking is not None and self.live and not markers
            else None
        )
        self._nan: dict[int, PoseSeries] = {}
        if self.tracker is not None:  # what _all_solved reads
            self._hand_index = self.sensors.index(HAND_SENSOR)
            self._digit_sensors = [
                np.array([self.sensors.index(jm.child) for jm in fm.joints.values()])
                for fm in model.fingers.values()
            ]
        self.wall_offset = time.time() - time.monotonic()
        self.summary = Summary()
        # The robot lane's per-frame buffers, allocated once: the values of the frame
        # sent, its valid flag and arrival, and the last values sent (the hold).
        self._frame = FrameValues(self.channels, self.tips_frame)
        self._valid = np.zeros(1)
        self._arrival = np.zeros(1)
        self._last: dict[str, FloatArray] = {}
        self.data: DataLane | None = None
        if bag is not None and retargeter is not None and self.live and bag_retargeter is None:
            raise ValueError("a bag of the robot's joints beside live outputs needs bag_retargeter")
        self._view_sent = None
        if record is not None or bag is not None or view is not None:
            data_retargeter = bag_retargeter if self.live else retargeter
            if view is not None and retargeter is not None and data_retargeter is None:
                view.sent = self._view_sent = collections.deque()
            self.data = DataLane(
                model,
                self.summary,
                record=record,
                bag=bag,
                record_units=record_units,
                channels=self.channels,
                sensors=self.sensors,
                retargeter=data_retargeter,
                wall_offset=self.wall_offset,
                view=view,
            )

    def outputs(self) -> list:
        return [o for o in (self.lsl, self.ros2, self.bag, self.record) if o is not None]

    def has_consumers(self) -> bool:
        """Whether every network output (LSL, DDS) has a consumer."""
        return all(o.has_consumers() for o in (self.lsl, self.ros2) if o is not None)

    def process(self, block: Block) -> None:
        """Hand one block to both lanes and update the summary: the robot lane sends its
        newest frame (or none, all stale), the data lane queues every frame."""
        n = block.recording.n_frames
        if n == 0:
            return
        s = self.summary
        have = block.recording.markers if self.markers else block.recording.poses
        if any(x not in have for x in self.sensors):
            block = Block(self._complete(block.recording), block.arrival, block.lost)
        presence = sensor_presence(block.recording, self.sensors)
        valid = presence.all(axis=1)
        if self.live:
            self._send(block, bool(valid[-1]), presence[-1])
        s.received += n
        s.lost += block.lost
        bad = int(n - np.count_nonzero(valid))
        s.invalid += bad
        if bad:
            codes = source_codes(
                presence, self.sensors, self.model, self.channels.digits, self.solves
            )
            s.held += int(np.count_nonzero((codes == 2).any(axis=1)))
        if self.data is not None:
            if self.data.error is not None:
                raise self.data.error
            self.data.put(block)

    @property
    def solves(self) -> bool:
        """Whether frames with a missing sensor are solved by the model (its calibration
        statistics; else they are held)."""
        return self.model.tracking is not None

    def _all_solved(self, present: np.ndarray) -> bool:
        """Whether the model solves every digit of a frame (``present``: each of
        :attr:`sensors`): the hand sensor there, and every digit missing one of its own and
        having another."""
        return bool(present[self._hand_index]) and all(
            present[idx].any() and not present[idx].all() for idx in self._digit_sensors
        )

    def _complete(self, rec: Recording) -> Recording:
        """``rec`` with a pose series of NaN for each model sensor it lacks (a source that
        never delivers one: the layout was checked before the stream started); of a
        marker model, NaN positions for each marker it lacks."""
        n = rec.n_frames
        if self.markers:
            markers = dict(rec.markers)
            for x in self.sensors:
                markers.setdefault(x, np.full((n, 3), np.nan))
            return Recording(rec.name, rec.time, rec.poses, rec.notes, markers)
        nan = self._nan.get(n)
        if nan is None:
            nan = self._nan[n] = PoseSeries(np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan))
        poses = dict(rec.poses)
        for x in self.sensors:
            poses.setdefault(x, nan)
        return Recording(rec.name, rec.time, poses, rec.notes)

    def _send(self, block: Block, valid: bool, present: np.ndarray) -> None:
        """The robot lane: the newest frame of ``block`` (``valid``: every sensor present
        in it; ``present``: each of :attr:`sensors`) if it is fresh enough."""
        s = self.summary
        n = block.recording.n_frames
        arrived = float(block.arrival[-1])
        if n > 1:
            age = time.monotonic() - block.arrival[:-1]
            old = int(np.count_nonzero(age > self.max_age))
            s.stale += old
            s.skipped += n - 1 - old
        if time.monotonic() - arrived > self.max_age:
            s.stale += 1
            return
        rec = block.recording if n == 1 else block.recording.slice(slice(n - 1, n))
        t = time.perf_counter()
        unconverged = 0
        if self.tracker is not None and not valid and self._all_solved(present):
            kin = self.tracker.blank(rec)  # no digit to compute directly: all solved
        elif self.plan is not None:
            kin = self.plan.run(rec)
        else:
            kin, unconverged = kinematics_of(self.model, rec, self.variants)
        source = None
        if self.markers and not valid:  # the marker IK solves with the markers seen
            codes = source_codes(
                present[None], self.sensors, self.model, self.channels.digits, True
            )
            source = dict(zip(self.channels.digits, codes[0].tolist(), strict=True))
        if self.tracker is not None:
            if valid:
                self.tracker.remember(kin, float(rec.time[0]))
            else:
                source = self.tracker.step(rec, kin)
        if self.markers and (self.retargeter is not None or self.tips_frame == "hand"):
            rec, kin = with_hand(self.model, rec, kin)  # the hand's pose, as a sensor's
        robot = self.retargeter.step(rec, kin)[0] if self.retargeter is not None else None
        compute = time.perf_counter() - t
        held = self._frame.values(kin, rec, robot, source)
        for key, row in held.items():
            self._fill(key, row)
        sent_age = time.monotonic() - arrived
        if sent_age > self.max_age:  # the compute made it too old: not sent, so not held
            s.stale += 1
            return
        self._keep(held)
        self._valid[0] = 1.0 if valid else 0.0
        self._arrival[0] = arrived
        self._push(held, self._valid, self._arrival, robot is not None)
        done = time.monotonic()
        s.sent += 1
        s.unconverged += unconverged
        s.add(done - arrived, compute, 1, sent_age)
        if self._view_sent is not None:  # the view's robot: this frame's sent joints
            self._view_sent.append((s.received + n - 1, held["robot"][0].copy()))

    def _fill(self, key: str, row: FloatArray) -> None:
        """In place: NaN in ``row`` (shape (1, k)) -> the column's last value sent (NaN
        until a value was sent)."""
        last = self._last.get(key)
        r = row[0]
        if last is not None and not np.isfinite(r).all():
            np.copyto(r, last, where=~np.isfinite(r))

    def _keep(self, held: dict) -> None:
        """The frame about to be sent: its (filled) values become the last values sent,
        kept in arrays of their own. A frame that went stale in its compute is not kept:
        the hold is the last frame a consumer got."""
        for key, row in held.items():
            last = self._last.get(key)
            if last is None:
                self._last[key] = row[0].copy()
            else:
                np.copyto(last, row[0])

    def _push(self, held: dict, valid: FloatArray, arrival: FloatArray, robot: bool) -> None:
        if self.lsl is not None:
            self.lsl.push(
                held["angles"], held["tips"], valid, arrival, held.get("robot"), held["source"]
            )
        if self.ros2 is not None:
            self.ros2.push_source(held["source"][0], float(arrival[0]) + self.wall_offset)
        if self.ros2 is not None:
            self.ros2.push(held["robot"] if robot else held["joints"], arrival + self.wall_offset)

    def silence(self, now: float) -> None:
        """The watchdog: the source fell silent. One sample with ``valid`` 0 on every LSL
        outlet at ``now`` (``time.monotonic()`` s): the held values, and on the robot
        outlet the robot's last pose (``hold``) or its rest pose (``release``:
        ``retargeter.setup.hold``, which DDS then also gets; under ``hold`` DDS, whose
        ``JointState`` has no validity field, gets nothing)."""
        self.summary.silences += 1
        self.invalidate(now)

    def invalidate(self, now: float) -> None:
        """What :meth:`silence` sends (``valid`` 0, the robot's policy), without counting
        a silence: also sent when the source ends with an error before the watchdog
        fired, so the robot's last command says the data stopped."""
        if not self.live or not self._last:
            return
        held = {k: v[None, :] for k, v in self._last.items()}
        release = self.on_silence == "release" and self.retargeter is not None
        if release:
            rest = np.asarray(self.retargeter.setup.hold, dtype=float)
            held["robot"] = rest[None, :]
            self._last["robot"] = rest.copy()
        arrival = np.array([now])
        if self.lsl is not None:
            self.lsl.push(
                held["angles"],
                held["tips"],
                np.zeros(1),
                arrival,
                held.get("robot"),
                held.get("source"),
            )
        if self.ros2 is not None and release:
            self.ros2.push(held["robot"], arrival + self.wall_offset)

    def close(self, ok: bool = True) -> None:
        """Write the data lane's backlog and close its files (kept when ``ok``), then
        close the live outputs."""
        errors: list[BaseException] = []
        if self.data is not None:
            try:
                self.data.finish(ok)
            except BaseException as exc:
                errors.append(exc)
        for o in (self.lsl, self.ros2):
            if o is not None:
                try:
                    o.close()
                except FingerfitError as exc:
                    errors.append(exc)
        if errors:
            raise errors[0]


def positive_ms(ms: float, field: str) -> float:
    """A duration option in ms -> s; a clear error naming ``field`` unless a positive
    number."""
    if not (math.isfinite(ms) and ms > 0):
        raise FingerfitError(f"must be a positive number of ms, not {ms:g}", field=field)
    return ms / 1e3


def check_max_age(ms: float) -> float:
    """``--max-age`` in ms -> s; a clear error unless a positive number."""
    return positive_ms(ms, "--max-age")
