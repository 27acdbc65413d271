"""The streaming loop: source -> kinematics -> outputs.

Each block of frames that arrived together goes through
:func:`fingerfit.kinematics.compute_kinematics` -- the function ``fingerfit angles`` uses,
so the streamed numbers are the same -- and then to every output. Per output column, a
frame whose value could not be computed (a sensor missing) holds the column's last value;
the ``valid`` channel says whether every sensor the model uses was present in the frame.
The angles CSV (``--record``) gets the frames as ``fingerfit angles`` writes them (empty
fields where a sensor is missing), not the held values.

With a :class:`fingerfit.retarget.Retargeter` (``--retarget ROBOT``), each block's
kinematics then go through :meth:`~fingerfit.retarget.Retargeter.step`, which keeps the
solver's warm start across blocks (the offline ``fingerfit retarget`` joints); the ROS 2
outputs carry the robot's joints and LSL gets a third outlet ``PREFIX-robot``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..kinematics import Kinematics, KinematicsPlan, compute_kinematics, kinematics_table
from ..model import HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..transforms import FloatArray
from .outputs import BagOutput, LslOutput, RecordOutput, Ros2Output
from .sources import Block

#: Seconds between status-line updates.
STATUS_PERIOD = 0.5


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
    valid = np.ones(n, dtype=bool)
    for s in sensors:
        valid &= recording.poses[s].valid
    return Values(angles, tips, joints, valid.astype(float))


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


@dataclass
class Summary:
    """What a stream did.

    Attributes
    ----------
    frames : int
        Frames sent.
    lost : int
        Frames the source lost (device frame-count gaps).
    invalid : int
        Frames with a missing sensor (values held).
    latency : list of ndarray
        Per block, per frame: arrival to the moment every network output had it (s);
        :meth:`latency_ms` joins them.
    compute, sizes : list
        Seconds of compute per block (kinematics, and the robot's joints when
        retargeting), and the block sizes (frames).
    window : list of ndarray
        Latencies since the status line last read them.
    compute_window : list of float
        Per-frame compute (s: a block's compute / its frames) since the status line last
        read it.
    seconds : float
        Wall time from the first frame's arrival to the end.
    interrupted : bool
        Ended by Ctrl-C.
    """

    frames: int = 0
    lost: int = 0
    invalid: int = 0
    latency: list = field(default_factory=list)
    compute: list = field(default_factory=list)
    sizes: list = field(default_factory=list)
    seconds: float = 0.0
    interrupted: bool = False
    window: list = field(default_factory=list)
    compute_window: list = field(default_factory=list)

    def add(self, latency: FloatArray, compute: float, size: int) -> None:
        """Record one block; lists are merged into one array now and then (a long
        stream keeps 8 bytes per frame, not a Python object)."""
        self.latency.append(latency)
        self.window.append(latency)
        self.compute.append(compute)
        self.sizes.append(size)
        if size:
            self.compute_window.append(compute / size)
        if len(self.window) > 4096:  # no status line reads it
            del self.window[:-64]
            del self.compute_window[:-64]
        if len(self.latency) >= 4096:
            self.latency = [np.concatenate(self.latency)]
            self.compute = [np.concatenate([np.atleast_1d(c) for c in self.compute])]
            self.sizes = [np.concatenate([np.atleast_1d(c) for c in self.sizes])]

    def latency_ms(self) -> FloatArray:
        """Arrival -> sent of every frame (ms), shape (frames,)."""
        return 1e3 * (np.concatenate(self.latency) if self.latency else np.zeros(0))

    def compute_ms_per_frame(self) -> FloatArray:
        """Per-frame compute of every non-empty block (ms): the block's compute divided by
        its frames, shape (blocks,)."""
        if not self.compute:
            return np.zeros(0)
        c = np.concatenate([np.atleast_1d(x) for x in self.compute]).astype(float)
        n = np.concatenate([np.atleast_1d(x) for x in self.sizes]).astype(float)
        keep = n > 0
        return 1e3 * c[keep] / n[keep]


class Streamer:
    """Kinematics and outputs for one model.

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
        Drives a robot hand: every block's kinematics go through its ``step``; the ROS 2
        outputs then carry the robot's joints (``robot.joint_names``, rad) and the LSL
        output its ``-robot`` outlet (built with ``robot_labels``).
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
    ) -> None:
        if tips_frame not in ("tracker", "hand"):
            raise FingerfitError("must be tracker or hand", field="--tips-frame")
        self.model = model
        self.lsl, self.ros2, self.bag, self.record = lsl, ros2, bag, record
        self.record_units = record_units
        self.tips_frame = tips_frame
        self.sensors = model_sensors(model)
        variants = ["user_axis"] + (["orthogonal"] if record is not None else [])
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
            KinematicsPlan(model, self.variants) if model.angle_method == "swing_twist" else None
        )
        self.wall_offset = time.time() - time.monotonic()
        self.summary = Summary()
        self._last: dict[str, FloatArray] = {}

    def outputs(self) -> list:
        return [o for o in (self.lsl, self.ros2, self.bag, self.record) if o is not None]

    def has_consumers(self) -> bool:
        """Whether every network output (LSL, DDS) has a consumer."""
        return all(o.has_consumers() for o in (self.lsl, self.ros2) if o is not None)

    def process(self, block: Block) -> None:
        """Compute and send one block; update the summary."""
        t = time.perf_counter()
        rec = block.recording
        if self.plan is not None and rec.n_frames:
            kin = self.plan.run(rec)
        else:
            kin = compute_kinematics(self.model, rec, self.variants)
        robot = None
        if self.retargeter is not None:
            # The block's kinematics hold every digit in the retargeter's variant.
            robot = (
                self.retargeter.step(rec, kin)[0]
                if rec.n_frames
                else np.zeros((0, self.retargeter.setup.robot.nq))
            )
        compute = time.perf_counter() - t
        v = block_values(kin, self.channels, block.recording, self.sensors, self.tips_frame)
        held = {}
        values = {"angles": v.angles, "tips": v.tips, "joints": v.joints}
        if robot is not None:
            values["robot"] = robot
        for key, x in values.items():
            last = self._last.get(key, np.full(x.shape[1], np.nan))
            held[key] = hold(x, last) if x.size and not np.isfinite(x).all() else x
            if x.shape[0]:
                self._last[key] = held[key][-1]
        if self.lsl is not None:
            self.lsl.push(held["angles"], held["tips"], v.valid, block.arrival, held.get("robot"))
        if self.ros2 is not None or self.bag is not None:
            wall = block.arrival + self.wall_offset
            joints = held["robot"] if robot is not None else held["joints"]
            if self.ros2 is not None:
                self.ros2.push(joints, wall)
            if self.bag is not None:
                self.bag.push(joints, wall)
        done = time.monotonic()
        if self.record is not None:  # after the network outputs: not on the latency path
            self.record.push(kinematics_table(kin, units=self.record_units))
        s = self.summary
        s.add(done - block.arrival, compute, block.recording.n_frames)
        s.frames += block.recording.n_frames
        s.lost += block.lost
        s.invalid += int((v.valid == 0).sum())

    def close(self, ok: bool = True) -> None:
        """Close every output; files are kept (``ok``) or removed."""
        if self.record is not None and not self.record.started and ok:
            # No frame at all: still a complete CSV (the header of an empty recording).
            kin = compute_kinematics(self.model, empty_recording(self.sensors), self.variants)
            self.record.push(kinematics_table(kin, units=self.record_units))
        errors = []
        for o in self.outputs():
            try:
                o.close(ok) if isinstance(o, (BagOutput, RecordOutput)) else o.close()
            except FingerfitError as exc:
                errors.append(exc)
        if errors:
            raise errors[0]


class StatusLine:
    """One self-overwriting line on stderr: rate, latency, lost and held frames."""

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
        rate = (s.frames - self._frames) / max(now - self._t, 1e-9)
        lat = 1e3 * np.concatenate(s.window) if s.window else np.zeros(1)
        comp = 1e3 * np.array(s.compute_window) if s.compute_window else np.zeros(1)
        s.window.clear()
        s.compute_window.clear()
        sys.stderr.write(
            f"\r{rate:6.1f} frames/s  latency {np.median(lat):5.2f} ms (max {lat.max():5.2f})"
            f"  compute {np.median(comp):5.2f} ms/frame"
            f"  lost {s.lost}  held {s.invalid}  sent {s.frames}\x1b[K"
        )
        sys.stderr.flush()
        self._t, self._frames = now, s.frames

    def clear(self) -> None:
        if self.enabled:
            sys.stderr.write("\r\x1b[K")
            sys.stderr.flush()


def run(
    source,
    streamer: Streamer,
    *,
    wait: float | None = None,
    status: bool = True,
    duration: float | None = None,
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

    Returns
    -------
    Summary
        ``interrupted`` when Ctrl-C ended it. Outputs are closed (files kept) in every
        case; an error from the source (a device unplugged) is raised after that.
    """
    line = StatusLine(status)
    s = streamer.summary
    ok = True
    try:
        if wait is not None:
            t_end = time.monotonic() + wait
            while not streamer.has_consumers():
                if time.monotonic() > t_end:
                    raise FingerfitError(
                        f"no consumer within {wait:g} s for every output", field="--wait"
                    )
                time.sleep(0.01)
        t0 = None
        for block in source.blocks():
            if block is not None:
                if t0 is None:
                    t0 = float(block.arrival[0])
                streamer.process(block)
            line.update(s)
            if duration is not None and t0 is not None and time.monotonic() - t0 >= duration:
                break
        if t0 is not None:
            s.seconds = time.monotonic() - t0
    except KeyboardInterrupt:
        s.interrupted = True
    except FingerfitError:
        ok = s.frames > 0  # a device lost mid-stream: keep what was streamed
        raise
    except BaseException:
        ok = False
        raise
    finally:
        line.update(s, force=True)  # the final figures, at least once
        line.clear()
        source.close()
        streamer.close(ok)
    return s
