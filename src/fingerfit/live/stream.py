"""The streaming loop: source -> kinematics -> outputs, in two lanes.

Frames go through :func:`fingerfit.kinematics.compute_kinematics` -- the function
``fingerfit angles`` uses, so the streamed numbers are the same -- in two lanes:

* the **robot lane** (LSL, DDS: what a robot or a teleoperation consumer acts on) is
  latest-wins: of the frames that arrived together only the newest is computed and sent,
  the others are counted as skipped, and a frame older than ``max_age`` is never sent
  (counted as stale);
* the **data lane** (``--record``, ``--ros2-bag``) writes every frame, on its own thread
  and in vectorised blocks, so a recording is complete whatever the robot lane skipped.

Per output column, a frame whose value could not be computed (a sensor missing) holds the
column's last value; the ``valid`` channel says whether every sensor the model uses was
present in the frame. The angles CSV (``--record``) gets the frames as ``fingerfit
angles`` writes them (empty fields where a sensor is missing), not the held values.

With a :class:`fingerfit.retarget.Retargeter` (``--retarget ROBOT``), the sent frames'
kinematics then go through :meth:`~fingerfit.retarget.Retargeter.step`, which keeps the
solver's warm start from frame to frame; the ROS 2 outputs carry the robot's joints and
LSL gets a third outlet ``PREFIX-robot``. The bag's robot joints come from a second
retargeter that steps through every frame (the offline ``fingerfit retarget`` joints).

A watchdog marks a source that falls silent (``valid`` 0 on the live outputs and the
robot's ``hold`` or ``release`` policy, :meth:`Streamer.silence`).
"""

from __future__ import annotations

import collections
import contextlib
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..kinematics import Kinematics, KinematicsPlan, compute_kinematics, kinematics_table
from ..model import HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..transforms import FloatArray
from .outputs import BagOutput, LslOutput, RecordOutput, Ros2Output
from .sources import MAX_BLOCK, Block

#: Seconds between status-line updates.
STATUS_PERIOD = 0.5
#: Default ``--max-age`` (ms): the robot lane sends no frame older than this.
DEFAULT_MAX_AGE_MS = 20.0
#: Default ``--silence-ms`` (ms): the watchdog fires after this long without a frame.
DEFAULT_SILENCE_MS = 50.0
#: ``--on-silence`` policies: the robot keeps its pose, or goes to its rest pose.
SILENCE_POLICIES = ("hold", "release")
#: Seconds between the data lane's passes over what is queued.
DATA_PERIOD = 0.05
#: Python's thread switch interval (s) while a data lane runs beside the robot lane.
SWITCH_INTERVAL = 0.0005


def model_sensors(model: HandModel) -> list[str]:
    """Sensors the model's kinematics read: the hand sensor, then each digit's in joint order."""
    out = [HAND_SENSOR]
    for fm in model.fingers.values():
        for jm in fm.joints.values():
            for s in (jm.parent, jm.child):
                if s not in out:
                    out.append(s)
    return out


def robot_joint_units(robot: Any) -> list[str]:
    """Unit of each robot joint's value: ``radians`` (hinge/revolute) or ``meters``
    (slide/prismatic).

    Parameters
    ----------
    robot : fingerfit.retarget.robots.Robot

    Returns
    -------
    list of str
        One per ``robot.joint_names``.
    """
    return ["meters" if slide else "radians" for slide in robot.slide]


def empty_recording(sensors: list[str]) -> Recording:
    """A recording of no frames with the given sensors (for column names)."""
    return Recording(
        "", np.zeros(0), {k: PoseSeries(np.zeros((0, 3)), np.zeros((0, 3, 3))) for k in sensors}
    )


@dataclass(frozen=True)
class Channels:
    """Names of the streamed values, derived from the model (any digits, any joints).

    Attributes
    ----------
    angles : list of (digit, joint)
        In the order of the angles CSV's user-axis columns (``<digit>.<joint>``, deg).
    digits : list of str
        Digits with a fingertip (``<digit>.tip.x|y|z``, mm).
    joint_names : list of str
        ROS 2 / URDF joint names, :func:`fingerfit.export.geometry.joint_names`.
    """

    angles: list[tuple[str, str]]
    digits: list[str]
    joint_names: list[str]

    @property
    def angle_labels(self) -> list[str]:
        return [f"{d}.{j}" for d, j in self.angles]

    @property
    def tip_labels(self) -> list[str]:
        return [f"{d}.tip.{c}" for d in self.digits for c in "xyz"]


def channels_of(model: HandModel, kin: Kinematics) -> Channels:
    """The channels of ``model`` from kinematics computed with it (any block)."""
    from ..export.geometry import joint_names

    motions = kin.motions["user_axis"]
    angles = [(d, j) for d, m in motions.items() for j in m.angles]
    return Channels(angles, list(motions), joint_names(model))


@dataclass
class Values:
    """What one block gives every output (time-first arrays).

    Attributes
    ----------
    angles : ndarray, shape (n, n_angles)
        Degrees, user-axis model, :attr:`Channels.angles` order.
    tips : ndarray, shape (n, 3 n_digits)
        mm, tracker frame (or the hand sensor's frame).
    joints : ndarray, shape (n, n_joints)
        Radians, :attr:`Channels.joint_names` order.
    valid : ndarray, shape (n,)
        1.0 when every sensor was present, else 0.0.
    """

    angles: FloatArray
    tips: FloatArray
    joints: FloatArray
    valid: FloatArray


def frames_valid(recording: Recording, sensors: list[str]) -> np.ndarray:
    """Frames in which every sensor of ``sensors`` is present.

    One ``isfinite`` over the sensors' poses side by side (the per-sensor
    :attr:`~fingerfit.session.PoseSeries.valid`, 13 NumPy calls each, cost 20 times more
    for a one-frame block of a whole hand).

    Parameters
    ----------
    recording : Recording
        Poses per sensor, position ``(n, 3)`` mm and rotation ``(n, 3, 3)``.
    sensors : list of str

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    n = recording.n_frames
    poses = [recording.poses[s] for s in sensors]
    parts = [p.position.reshape(n, 3) for p in poses]
    parts += [p.rotation.reshape(n, 9) for p in poses]
    return np.isfinite(np.concatenate(parts, axis=1)).all(axis=1)


def block_values(
    kin: Kinematics, channels: Channels, recording: Recording, sensors: list[str], tips_frame: str
) -> Values:
    """The streamed values of one block (before holding).

    Parameters
    ----------
    kin : Kinematics
        Of ``recording`` (with a ``user_axis`` variant).
    channels : Channels
    recording : Recording
        The block's frames (mm, tracker frame).
    sensors : list of str
        Sensors whose presence makes a frame valid.
    tips_frame : {"tracker", "hand"}

    Returns
    -------
    Values
        Angles in degrees as :func:`~fingerfit.kinematics.kinematics_table` gives
        them; joint positions in radians as
        :func:`~fingerfit.export.trajectory.trajectory_table` gives them (a two-axis
        ab/adduction the model does not have is 0 where the flexion exists).
    """
    motions = kin.motions["user_axis"]
    n = recording.n_frames
    angles = np.empty((n, len(channels.angles)))
    for k, (d, j) in enumerate(channels.angles):
        angles[:, k] = np.degrees(motions[d].angles[j])
    tips = np.empty((n, 3 * len(channels.digits)))
    for k, d in enumerate(channels.digits):
        tips[:, 3 * k : 3 * k + 3] = motions[d].tip
    if tips_frame == "hand":
        hand = recording.poses[HAND_SENSOR]
        t = tips.reshape(n, -1, 3) - hand.position[:, None, :]
        tips = np.einsum("nji,nkj->nki", hand.rotation, t).reshape(n, -1)
    joints = np.empty((n, len(channels.joint_names)))
    for k, name in enumerate(channels.joint_names):
        d, kind = name.split("_", 1)
        a = motions[d].angles
        if kind in a:
            joints[:, k] = a[kind]
        else:  # an ab/adduction not computed: 0 where the joint's flexion exists
            base = kind.removesuffix("_abduction")
            flexion = a[base] if base in a else next(iter(a.values()))
            joints[:, k] = np.where(np.isfinite(flexion), 0.0, np.nan)
    valid = frames_valid(recording, sensors)
    return Values(angles, tips, joints, valid.astype(float))


class FrameValues:
    """The streamed values of one frame, written into buffers allocated once (the robot
    lane's :func:`block_values`, without the per-frame arrays, string splitting and
    validity).

    Parameters
    ----------
    channels : Channels
    tips_frame : {"tracker", "hand"}

    Notes
    -----
    :meth:`values` returns the same arrays every call: a caller that keeps them past
    the next call copies them (the LSL and DDS outputs copy what they push).
    """

    def __init__(self, channels: Channels, tips_frame: str) -> None:
        self.channels = channels
        self.tips_frame = tips_frame
        self.angles = np.empty((1, len(channels.angles)))
        self.tips = np.empty((1, 3 * len(channels.digits)))
        self.joints = np.empty((1, len(channels.joint_names)))
        self.robot: FloatArray | None = None
        # Per joint name: its digit, its angle and, for an ab/adduction the model may not
        # have, the flexion that says whether the joint exists (block_values' rule).
        self._joints = []
        for name in channels.joint_names:
            d, kind = name.split("_", 1)
            self._joints.append((d, kind, kind.removesuffix("_abduction")))

    def values(self, kin: Kinematics, rec: Recording, robot: FloatArray | None) -> dict:
        """``{"angles", "tips", "joints"[, "robot"]}``, each of shape (1, k), as
        :func:`block_values` (and the robot's joints, copied) gives them for the one
        frame of ``rec``.

        Parameters
        ----------
        kin : Kinematics
            Of ``rec`` (one frame, with a ``user_axis`` variant).
        rec : Recording
            One frame (mm, tracker frame).
        robot : ndarray, shape (1, n_robot), optional
            The robot's joints (rad).
        """
        motions = kin.motions["user_axis"]
        a = self.angles[0]
        for k, (d, j) in enumerate(self.channels.angles):
            a[k] = motions[d].angles[j][0]
        np.degrees(a, out=a)
        tips = self.tips.reshape(-1, 3)
        for k, d in enumerate(self.channels.digits):
            tips[k] = motions[d].tip[0]
        if self.tips_frame == "hand":  # R_hand^T (tip - p_hand)
            hand = rec.poses[HAND_SENSOR]
            np.matmul(tips - hand.position[0], hand.rotation[0], out=tips)
        q = self.joints[0]
        for k, (d, kind, base) in enumerate(self._joints):
            angles = motions[d].angles
            if kind in angles:
                q[k] = angles[kind][0]
            else:  # an ab/adduction not computed: 0 where the joint's flexion exists
                flexion = angles[base] if base in angles else next(iter(angles.values()))
                q[k] = 0.0 if math.isfinite(flexion[0]) else math.nan
        out = {"angles": self.angles, "tips": self.tips, "joints": self.joints}
        if robot is not None:
            if self.robot is None or self.robot.shape != robot.shape:
                self.robot = np.empty(robot.shape)
            np.copyto(self.robot, robot)
            out["robot"] = self.robot
        return out


def hold(x: FloatArray, last: FloatArray) -> FloatArray:
    """Fill NaN with the column's previous value.

    Parameters
    ----------
    x : ndarray, shape (n, k)
    last : ndarray, shape (k,)
        The previous block's last (held) row; NaN where nothing was seen yet.

    Returns
    -------
    ndarray, shape (n, k)
        ``x`` with every NaN replaced by the latest finite value above it (or in
        ``last``); NaN only where no value has been seen yet.
    """
    full = np.vstack([last[None, :], x])
    idx = np.where(np.isfinite(full), np.arange(full.shape[0])[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    return full[idx, np.arange(full.shape[1])][1:]


def concat_blocks(blocks: list[Block]) -> Block:
    """Blocks that arrived one after the other, as one block (frames in order).

    Parameters
    ----------
    blocks : list of Block
        Non-empty; every recording with the same sensors.

    Returns
    -------
    Block
        Time ``(n,)`` s, poses per sensor ``(n, 3)`` mm and ``(n, 3, 3)``, arrival ``(n,)``
        s, ``lost`` the sum.
    """
    if len(blocks) == 1:
        return blocks[0]
    recs = [b.recording for b in blocks]
    poses = {
        k: PoseSeries(
            np.concatenate([r.poses[k].position for r in recs]),
            np.concatenate([r.poses[k].rotation for r in recs]),
        )
        for k in recs[0].poses
    }
    rec = Recording(recs[0].name, np.concatenate([r.time for r in recs]), poses)
    return Block(rec, np.concatenate([b.arrival for b in blocks]), sum(b.lost for b in blocks))


def _join(parts: list) -> FloatArray:
    return (
        np.concatenate([np.atleast_1d(np.asarray(x, dtype=float)) for x in parts])
        if parts
        else np.zeros(0)
    )


@dataclass
class Summary:
    """What a stream did: the counts of both lanes and their timings.

    Every frame the source hands over is *received*. The robot lane (live outputs: LSL,
    DDS) then either *sends* it, *skips* it (a newer frame was waiting) or drops it as
    *stale* (older than ``max_age``): ``received = sent + skipped + stale`` when there is
    a live output. The data lane (``--record``, ``--ros2-bag``) writes every frame:
    ``recorded = received`` when there is a file output, once the stream has ended.

    Attributes
    ----------
    received, sent, skipped, stale, recorded : int
        Frame counts, see above (0 for a lane the stream does not have).
    lost : int
        Frames the source lost (device frame-count gaps); not received.
    invalid : int
        Received frames with a missing sensor (values held, ``valid`` 0).
    silences : int
        Times the source fell silent for ``silence`` s (the watchdog fired).
    outages, reconnects : int
        Times a live source was lost (serial port failed, LSL stream gone) and came back
        (the source's ``stats``, copied when the stream ends).
    latency : list of ndarray
        Robot lane, per sent frame: arrival to the moment every live output had it (s);
        :meth:`latency_ms` joins them.
    ages : list of ndarray
        Robot lane, per sent frame: its age (s) when its push began, never above
        ``max_age``; :meth:`age_ms` joins them.
    compute, sizes : list
        Robot lane: seconds of compute per sent frame (kinematics, and the robot's joints
        when retargeting) and the frames computed (1 each).
    data_compute, data_sizes : list
        Data lane: seconds of compute (kinematics, robot joints for the bag) per batch
        and the batch sizes (frames).
    data_lag : float
        Data lane: the longest time (s) from a frame's arrival to its batch being written.
    window : list of ndarray
        Latencies since the status line last read them.
    compute_window : list of float
        Per-frame compute (s) since the status line last read it.
    seconds : float
        Wall time from the first frame's arrival to the end.
    interrupted : bool
        Ended by Ctrl-C.
    """

    received: int = 0
    sent: int = 0
    skipped: int = 0
    stale: int = 0
    recorded: int = 0
    lost: int = 0
    invalid: int = 0
    silences: int = 0
    outages: int = 0
    reconnects: int = 0
    latency: list = field(default_factory=list)
    ages: list = field(default_factory=list)
    compute: list = field(default_factory=list)
    sizes: list = field(default_factory=list)
    data_compute: list = field(default_factory=list)
    data_sizes: list = field(default_factory=list)
    data_lag: float = 0.0
    seconds: float = 0.0
    interrupted: bool = False
    window: list = field(default_factory=list)
    compute_window: list = field(default_factory=list)

    @property
    def frames(self) -> int:
        """Frames received (handed over by the source)."""
        return self.received

    def add(self, latency: FloatArray, compute: float, size: int, age: float | None = None) -> None:
        """Record one robot-lane send; lists are merged into one array now and then (a
        long stream keeps 8 bytes per frame, not a Python object)."""
        self.latency.append(latency)
        self.window.append(latency)
        self.compute.append(compute)
        self.sizes.append(size)
        if age is not None:
            self.ages.append(age)
        if size:
            self.compute_window.append(compute / size)
        if len(self.window) > 4096:  # no status line reads it
            del self.window[:-64]
            del self.compute_window[:-64]
        if len(self.latency) >= 4096:
            self.latency = [_join(self.latency)]
            self.ages = [_join(self.ages)]
            self.compute = [_join(self.compute)]
            self.sizes = [_join(self.sizes)]

    def latency_ms(self) -> FloatArray:
        """Arrival -> sent of every sent frame (ms), shape (sent,)."""
        return 1e3 * _join(self.latency)

    def age_ms(self) -> FloatArray:
        """Age of every sent frame when its push began (ms), shape (sent,)."""
        return 1e3 * _join(self.ages)

    def compute_ms_per_frame(self) -> FloatArray:
        """Robot lane: per-frame compute of every send (ms), shape (sent,); without a
        robot lane, the data lane's per batch (batch compute / its frames)."""
        c, n = (self.compute, self.sizes) if self.compute else (self.data_compute, self.data_sizes)
        c, n = _join(c), _join(n)
        keep = n > 0
        return 1e3 * c[keep] / n[keep]


class DataLane:
    """Every frame to the files (``--record``, ``--ros2-bag``) and the view (``--view``,
    ``--view-save``), on a thread of its own.

    Blocks are queued as they arrive (:meth:`put`); the thread takes everything queued
    every :data:`DATA_PERIOD` s and computes it as one block (at most
    :data:`~fingerfit.live.sources.MAX_BLOCK` frames at a time) -- so a backlog costs one
    vectorised pass, not one per frame -- and writes it. :meth:`finish` writes what is
    still queued and stops the thread: then ``summary.recorded`` = every frame put.

    Parameters
    ----------
    model : HandModel
    summary : Summary
        Where ``recorded``, ``data_compute``, ``data_sizes`` and ``data_lag`` go.
    record : RecordOutput, optional
    bag : BagOutput, optional
    record_units : str
    channels : Channels
    sensors : list of str
    retargeter : fingerfit.retarget.Retargeter, optional
        The bag's and the view's robot joints (its own instance: its warm start follows
        every frame).
    view : fingerfit.view.LiveView, optional
        Gets every block's frames and kinematics (and the robot's joints, with a
        ``retargeter``), after the files.
    wall_offset : float
        System clock minus ``time.monotonic()`` (s), for the bag's stamps.
    """

    def __init__(
        self,
        model: HandModel,
        summary: Summary,
        *,
        record: RecordOutput | None,
        bag: BagOutput | None,
        record_units: str,
        channels: Channels,
        sensors: list[str],
        retargeter: Any = None,
        wall_offset: float = 0.0,
        view: Any = None,
    ) -> None:
        self.model, self.summary = model, summary
        self.record, self.bag, self.view = record, bag, view
        self.record_units = record_units
        self.channels, self.sensors = channels, sensors
        self.retargeter = retargeter if bag is not None or view is not None else None
        both = record is not None or view is not None  # the angles CSV, the view's tips
        variants = ["user_axis"] + (["orthogonal"] if both else [])
        if self.retargeter is not None and self.retargeter.variant not in variants:
            variants.append(self.retargeter.variant)
        self.variants = tuple(variants)
        self.plan = (
            KinematicsPlan(model, self.variants) if model.angle_method == "swing_twist" else None
        )
        self.wall_offset = wall_offset
        self._queue: list[Block] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._last: FloatArray | None = None
        self.error: BaseException | None = None
        self.ok = True
        self._thread = threading.Thread(target=self._run, name="fingerfit-data-lane", daemon=True)
        self._thread.start()

    @property
    def thread(self) -> threading.Thread:
        """The lane's thread (``--realtime`` keeps it off the robot lane's CPU)."""
        return self._thread

    def put(self, block: Block) -> None:
        """Queue a block (cheap: the thread computes it)."""
        with self._lock:
            self._queue.append(block)

    def backlog(self) -> int:
        """Frames queued and not yet written."""
        with self._lock:
            return sum(b.recording.n_frames for b in self._queue)

    def _take(self) -> list[Block]:
        with self._lock:
            blocks, self._queue = self._queue, []
        return blocks

    def _run(self) -> None:
        ok = False
        try:
            while not self._stop.wait(DATA_PERIOD):
                self._write(self._take())
            ok = self.ok
            if ok:
                self._write(self._take())  # what came before the stop
                if self.record is not None and not self.record.started:
                    # No frame at all: still a complete CSV (an empty recording's header).
                    variants = ("user_axis", "orthogonal")
                    kin = compute_kinematics(self.model, empty_recording(self.sensors), variants)
                    self.record.push(kinematics_table(kin, units=self.record_units))
        except BaseException as exc:  # handed to the loop, which raises it
            self.error, ok = exc, False
        # The files are closed on this thread (a bag's SQLite objects belong to it).
        for o in (self.record, self.bag, self.view):
            if o is not None:
                try:
                    o.close(ok)
                except BaseException as exc:
                    self.error = self.error or exc

    def _write(self, blocks: list[Block]) -> None:
        if not blocks:
            return
        block = concat_blocks(blocks)
        n = block.recording.n_frames
        for i in range(0, n, MAX_BLOCK):
            part = Block(
                block.recording.slice(slice(i, i + MAX_BLOCK)), block.arrival[i : i + MAX_BLOCK]
            )
            self._write_one(part)

    def _write_one(self, block: Block) -> None:
        rec, s = block.recording, self.summary
        t = time.perf_counter()
        if self.plan is not None and rec.n_frames:
            kin = self.plan.run(rec)
        else:
            kin = compute_kinematics(self.model, rec, self.variants)
        joints = robot = None
        if self.retargeter is not None:
            robot = self.retargeter.step(rec, kin)[0]
        if self.bag is not None:
            if robot is not None:
                joints = robot
            else:
                joints = block_values(kin, self.channels, rec, self.sensors, "tracker").joints
        compute = time.perf_counter() - t
        if self.record is not None:
            self.record.push(kinematics_table(kin, units=self.record_units))
        if joints is not None and self.bag is not None:
            last = self._last if self._last is not None else np.full(joints.shape[1], np.nan)
            if joints.size and not np.isfinite(joints).all():
                joints = hold(joints, last)
            if joints.shape[0]:
                self._last = joints[-1]
            self.bag.push(joints, block.arrival + self.wall_offset)
        if self.view is not None:
            self.view.push(rec, kin, robot)
        s.data_compute.append(compute)
        s.data_sizes.append(rec.n_frames)
        if len(s.data_compute) >= 4096:
            s.data_compute = [_join(s.data_compute)]
            s.data_sizes = [_join(s.data_sizes)]
        if rec.n_frames:
            s.data_lag = max(s.data_lag, time.monotonic() - float(block.arrival[0]))
        s.recorded += rec.n_frames

    def finish(self, ok: bool = True) -> None:
        """Write every queued frame (``ok``; else discard them), close the files (kept
        when ``ok``) and stop the thread; raise its error, if any (the files are then
        removed)."""
        self.ok = ok
        self._stop.set()
        self._thread.join()
        if self.error is not None:
            raise self.error


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
        self.live = lsl is not None or ros2 is not None
        variants = ["user_axis"]
        if retargeter is not None and retargeter.variant not in variants:
            variants.append(retargeter.variant)  # --orthogonal: computed with the others
        self.variants = tuple(variants)
        self.retargeter = retargeter
        # Names from a probe of no frames; values are then taken by name from every
        # block, so the channel order is fixed for the whole stream.
        self.channels = channels or channels_of(
            model, compute_kinematics(model, empty_recording(self.sensors), ("user_axis",))
        )
        # The model's constants are prepared once (swing-twist models; the paper's
        # projection angles go through compute_kinematics on every block).
        self.plan = (
            KinematicsPlan(model, self.variants)
            if model.angle_method == "swing_twist" and self.live
            else None
        )
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
        valid = frames_valid(block.recording, self.sensors)
        if self.live:
            self._send(block, bool(valid[-1]))
        s.received += n
        s.lost += block.lost
        s.invalid += int(n - np.count_nonzero(valid))
        if self.data is not None:
            if self.data.error is not None:
                raise self.data.error
            self.data.put(block)

    def _send(self, block: Block, valid: bool) -> None:
        """The robot lane: the newest frame of ``block`` (``valid``: every sensor present
        in it) if it is fresh enough."""
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
        kin = (
            self.plan.run(rec)
            if self.plan is not None
            else compute_kinematics(self.model, rec, self.variants)
        )
        robot = self.retargeter.step(rec, kin)[0] if self.retargeter is not None else None
        compute = time.perf_counter() - t
        held = self._frame.values(kin, rec, robot)
        for key, row in held.items():
            self._hold(key, row)
        sent_age = time.monotonic() - arrived
        if sent_age > self.max_age:  # the compute made it too old
            s.stale += 1
            return
        self._valid[0] = 1.0 if valid else 0.0
        self._arrival[0] = arrived
        self._push(held, self._valid, self._arrival, robot is not None)
        done = time.monotonic()
        s.sent += 1
        s.add(done - arrived, compute, 1, sent_age)
        if self._view_sent is not None:  # the view's robot: this frame's sent joints
            self._view_sent.append((s.received + n - 1, held["robot"][0].copy()))

    def _hold(self, key: str, row: FloatArray) -> None:
        """In place: NaN in ``row`` (shape (1, k)) -> the column's last value sent; the
        last values are then ``row``'s (kept in arrays of their own)."""
        last = self._last.get(key)
        if last is None:
            self._last[key] = row[0].copy()
            return
        r = row[0]
        if not np.isfinite(r).all():
            np.copyto(r, last, where=~np.isfinite(r))
        np.copyto(last, r)

    def _push(self, held: dict, valid: FloatArray, arrival: FloatArray, robot: bool) -> None:
        if self.lsl is not None:
            self.lsl.push(held["angles"], held["tips"], valid, arrival, held.get("robot"))
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
            self.lsl.push(held["angles"], held["tips"], np.zeros(1), arrival, held.get("robot"))
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


class StatusLine:
    """One self-overwriting line on stderr: rate, latency, the lanes' counts."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self._t = time.monotonic()
        self._frames = 0

    def update(self, s: Summary, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._t < STATUS_PERIOD and not force:
            return
        rate = (s.received - self._frames) / max(now - self._t, 1e-9)
        lat = 1e3 * np.concatenate(s.window) if s.window else np.zeros(1)
        comp = 1e3 * np.array(s.compute_window) if s.compute_window else np.zeros(1)
        s.window.clear()
        s.compute_window.clear()
        sys.stderr.write(
            f"\r{rate:6.1f} frames/s  latency {np.median(lat):5.2f} ms (max {lat.max():5.2f})"
            f"  compute {np.median(comp):5.2f} ms/frame  lost {s.lost}  held {s.invalid}"
            f"  sent {s.sent}  skipped {s.skipped}  stale {s.stale}  recorded {s.recorded}"
            "\x1b[K"
        )
        sys.stderr.flush()
        self._t, self._frames = now, s.received

    def clear(self) -> None:
        if self.enabled:
            sys.stderr.write("\r\x1b[K")
            sys.stderr.flush()


def check_max_age(ms: float) -> float:
    """``--max-age`` in ms -> s; a clear error unless a positive number."""
    if not (math.isfinite(ms) and ms > 0):
        raise FingerfitError(f"must be a positive number of ms, not {ms:g}", field="--max-age")
    return ms / 1e3


def check_silence(ms: float) -> float:
    """``--silence-ms`` in ms -> s; a clear error unless a positive number."""
    if not (math.isfinite(ms) and ms > 0):
        raise FingerfitError(f"must be a positive number of ms, not {ms:g}", field="--silence-ms")
    return ms / 1e3


@contextlib.contextmanager
def _ctrl_c_sets(flag: threading.Event) -> Iterator[None]:
    """Ctrl-C (SIGINT) sets ``flag`` instead of raising KeyboardInterrupt anywhere: the
    loop stops between blocks, so both lanes have handled every frame received (only in
    the main thread; elsewhere Python delivers no signal)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.SIG_IGN:  # Ctrl-C ignored by whoever started us: keep it so
        yield
        return
    signal.signal(signal.SIGINT, lambda *_: flag.set())
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run(
    source,
    streamer: Streamer,
    *,
    wait: float | None = None,
    status: bool = True,
    duration: float | None = None,
    silence: float | None = DEFAULT_SILENCE_MS / 1e3,
    warn: Callable[[str], None] | None = None,
    realtime: bool = False,
    note: Callable[[str], None] | None = None,
) -> Summary:
    """Stream until the source ends, ``duration`` passes, or Ctrl-C.

    Parameters
    ----------
    source
        A :mod:`.sources` source (``blocks()`` yielding blocks, or None after a poll
        without data; ``close()``; ``live``).
    streamer : Streamer
    wait : float, optional
        Replay only: seconds to wait for a consumer on every network output before
        the first frame (error when none comes).
    status : bool
        Show the status line (only on a terminal).
    duration : float, optional
        Seconds to stream, from the first frame's arrival.
    silence : float, optional
        The watchdog: seconds without a frame (after the first) before
        :meth:`Streamer.silence` and one ``warn`` line; again after frames come back
        and stop again. None: no watchdog.
    warn : callable, optional
        Called with the watchdog's one-line warning, and with a live source's outage
        warning (``source.warn`` is set to it; default: printed on stderr).
    realtime : bool
        Ask for a real-time class for the loop's thread (the robot lane) once streaming
        starts (after ``wait``): SCHED_FIFO, memory locked, CPU affinity
        (:class:`~fingerfit.live.realtime.Realtime`; restored at the end). What was
        granted goes to ``note`` in one line; nothing refused stops the stream.
    note : callable, optional
        Called with the ``--realtime`` line (default: ``realtime: ...`` on stderr).

    Returns
    -------
    Summary
        ``interrupted`` when Ctrl-C ended it. Outputs are closed (files kept, the data
        lane's backlog written first) in every case; an error from the source (a device
        unplugged) is raised after that.
    """
    line = StatusLine(status)
    stop = threading.Event()
    say = warn or (lambda text: print(f"warning: {text}", file=sys.stderr, flush=True))
    if hasattr(source, "warn"):  # a live source's outage warning, past the status line

        def source_warns(text: str) -> None:
            line.clear()
            say(text)

        source.warn = source_warns
    # Installed until the outputs are closed: a Ctrl-C while the data lane writes its
    # backlog lets it finish (the files complete).
    tell = note or (lambda text: print(f"realtime: {text}", file=sys.stderr, flush=True))
    with _ctrl_c_sets(stop):
        _run(source, streamer, line, stop, wait, duration, silence, say, tell if realtime else None)
    return streamer.summary


def _run(
    source,
    streamer: Streamer,
    line: StatusLine,
    stop: threading.Event,
    wait: float | None,
    duration: float | None,
    silence: float | None,
    say: Callable[[str], None],
    realtime: Callable[[str], None] | None = None,
) -> None:
    """:func:`run`'s loop, with Ctrl-C setting ``stop``; ``realtime``: ask for a real-time
    class and tell it what was granted."""
    s = streamer.summary
    ok = True
    t0 = last = None
    silent = False
    rt = contextlib.ExitStack()  # the real-time class, until the outputs are closed
    # The data lane's thread gives the GIL back every SWITCH_INTERVAL (Python's default
    # is 5 ms, which the robot lane would wait on).
    interval = sys.getswitchinterval()
    if streamer.data is not None:
        sys.setswitchinterval(min(interval, SWITCH_INTERVAL))
    try:
        if wait is not None:
            t_end = time.monotonic() + wait
            while not streamer.has_consumers():
                if stop.is_set():
                    raise KeyboardInterrupt
                if time.monotonic() > t_end:
                    raise FingerfitError(
                        f"no consumer within {wait:g} s for every output", field="--wait"
                    )
                time.sleep(0.01)
        if realtime is not None:
            from .realtime import Realtime

            others = [streamer.data.thread] if streamer.data is not None else []
            lane = "robot lane" if streamer.live else "stream loop"
            realtime(rt.enter_context(Realtime(others=others, lane=lane)).line())
        for block in source.blocks():
            if block is not None and block.recording.n_frames:
                if t0 is None:
                    t0 = float(block.arrival[0])
                streamer.process(block)
                last, silent = float(block.arrival[-1]), False
            elif silence is not None and last is not None and not silent:
                now = time.monotonic()
                if now - last > silence:
                    silent = True
                    streamer.silence(now)
                    line.clear()
                    say(
                        f"no frame for {1e3 * silence:g} ms: valid = 0 on the live outputs, "
                        f"robot: {streamer.on_silence}"
                    )
            line.update(s)
            if stop.is_set():
                s.interrupted = True
                break
            if duration is not None and t0 is not None and time.monotonic() - t0 >= duration:
                break
        if t0 is not None:
            s.seconds = time.monotonic() - t0
    except KeyboardInterrupt:
        s.interrupted = True
    except FingerfitError:
        ok = s.received > 0  # a device lost mid-stream: keep what was streamed
        if ok and not silent:  # the robot's last command: valid 0, its policy
            with contextlib.suppress(Exception):
                streamer.invalidate(time.monotonic())
        raise
    except BaseException:
        ok = False
        raise
    finally:
        stats = getattr(source, "stats", None)
        s.outages = getattr(stats, "outages", 0)
        s.reconnects = getattr(stats, "reconnects", 0)
        line.update(s, force=True)  # the final figures, at least once
        line.clear()
        source.close()
        try:
            streamer.close(ok)
        finally:
            sys.setswitchinterval(interval)
            rt.close()
