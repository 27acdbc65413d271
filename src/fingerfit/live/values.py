"""What a block of streamed frames becomes on the outputs: the channels of a model, each
frame's values and validity, held values where a sensor is missing, and the blocks the
data lane joins (:mod:`.stream` runs them)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..kinematics import Kinematics
from ..model import HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording, concat_recordings
from ..transforms import FloatArray
from .markers import is_marker_model, marker_presence, markers_of, model_markers
from .sources import Block


def model_sensors(model: HandModel) -> list[str]:
    """Sensors the model's kinematics read: the hand sensor, then each digit's in joint order;
    for a model fitted from markers its markers (:func:`.markers.model_markers`)."""
    if is_marker_model(model):
        return model_markers(model)
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


def empty_recording(sensors: list[str], markers: bool = False) -> Recording:
    """A recording of no frames with the given sensors (for column names); ``markers``:
    the names are markers (a marker recording)."""
    if markers:
        return Recording("", np.zeros(0), {}, markers={k: np.zeros((0, 3)) for k in sensors})
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

    @property
    def source_labels(self) -> list[str]:
        """``<digit>.source``: what each digit's values in a frame come from
        (:data:`fingerfit.track.live.FROM_SENSORS`, ``FROM_MODEL``, ``HELD``)."""
        return [f"{d}.source" for d in self.digits]


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
    source : ndarray, shape (n, n_digits)
        Per digit (:attr:`Channels.digits` order): 0 from its sensors, 1 solved by the
        model (a sensor missing), 2 held (not solvable: the hand sensor or every sensor
        of the digit missing).
    """

    angles: FloatArray
    tips: FloatArray
    joints: FloatArray
    valid: FloatArray
    source: FloatArray


def sensor_presence(recording: Recording, sensors: list[str]) -> np.ndarray:
    """Whether each sensor of ``sensors`` is present in each frame, ``(n, S)`` bool: one
    ``isfinite`` over the sensors' poses side by side (a sensor the recording lacks is
    absent in every frame); of a marker recording, each marker
    (:func:`.markers.marker_presence`)."""
    if recording.markers:
        return marker_presence(recording, sensors)
    n = recording.n_frames
    poses = [recording.poses.get(s) for s in sensors]
    have = [p for p in poses if p is not None]
    if not have:
        return np.zeros((n, len(sensors)), dtype=bool)
    k = len(have)
    ok = np.isfinite(np.concatenate([p.position.reshape(n, 3) for p in have], axis=1))
    out_pos = ok.reshape(n, k, 3).all(axis=2)
    ok = np.isfinite(np.concatenate([p.rotation.reshape(n, 9) for p in have], axis=1))
    present = out_pos & ok.reshape(n, k, 9).all(axis=2)
    if k == len(sensors):
        return present
    out = np.zeros((n, len(sensors)), dtype=bool)
    out[:, [i for i, p in enumerate(poses) if p is not None]] = present
    return out


def source_codes(
    presence: np.ndarray, sensors: list[str], model: HandModel, digits: list[str], solves: bool
) -> np.ndarray:
    """What each digit's values in each frame come from, ``(n, n_digits)`` (``Values.source``).

    Parameters
    ----------
    presence : ndarray of bool, shape (n, S)
        :func:`sensor_presence` of ``sensors``.
    sensors : list of str
    model : HandModel
    digits : list of str
    solves : bool
        Whether frames with a missing sensor are solved by the model (a model with
        calibration statistics); else they are held. A model fitted from markers
        (``sensors`` its markers) solves a digit with three hand markers and one of its
        own seen.
    """
    col = {s: i for i, s in enumerate(sensors)}
    if is_marker_model(model):  # the hand's frame from any three of its markers
        hand = presence[:, [col[k] for k in markers_of(model, HAND_SENSOR)]]
        hand_all, hand_ok, solves = hand.all(axis=1), hand.sum(axis=1) >= 3, True
        owns = {d: [col[k] for k in markers_of(model, d)] for d in digits}
    else:
        hand_all = hand_ok = presence[:, col[HAND_SENSOR]]
        owns = {d: [col[jm.child] for jm in model.fingers[d].joints.values()] for d in digits}
    out = np.zeros((presence.shape[0], len(digits)))
    for k, d in enumerate(digits):
        own = presence[:, owns[d]]
        complete = hand_all & own.all(axis=1)
        solvable = hand_ok & own.any(axis=1) & solves
        out[:, k] = np.where(complete, 0.0, np.where(solvable, 1.0, 2.0))
    return out


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
        Of a marker recording (``sensors`` its markers): every marker seen.
    """
    if recording.markers:
        return marker_presence(recording, sensors).all(axis=1)
    n = recording.n_frames
    poses = [recording.poses[s] for s in sensors]
    parts = [p.position.reshape(n, 3) for p in poses]
    parts += [p.rotation.reshape(n, 9) for p in poses]
    return np.isfinite(np.concatenate(parts, axis=1)).all(axis=1)


def block_values(
    kin: Kinematics,
    channels: Channels,
    recording: Recording,
    sensors: list[str],
    tips_frame: str,
    source: FloatArray | None = None,
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
    source : ndarray, shape (n, n_digits), optional
        :func:`source_codes` of the block (default: 0, from the sensors).

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
    if source is None:
        source = np.zeros((n, len(channels.digits)))
    return Values(angles, tips, joints, valid.astype(float), source)


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
        self.source = np.zeros((1, len(channels.digits)))
        self.joints = np.empty((1, len(channels.joint_names)))
        self.robot: FloatArray | None = None
        # Per joint name: its digit, its angle and, for an ab/adduction the model may not
        # have, the flexion that says whether the joint exists (block_values' rule).
        self._joints = []
        for name in channels.joint_names:
            d, kind = name.split("_", 1)
            self._joints.append((d, kind, kind.removesuffix("_abduction")))

    def values(
        self,
        kin: Kinematics,
        rec: Recording,
        robot: FloatArray | None,
        source: dict[str, int] | None = None,
    ) -> dict:
        """``{"angles", "tips", "joints", "source"[, "robot"]}``, each of shape (1, k), as
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
        source : dict, optional
            Digit -> what its values come from (:data:`fingerfit.track.live.FROM_SENSORS`
            ...); default: every digit from its sensors.
        """
        motions = kin.motions["user_axis"]
        src = self.source[0]
        if source is None:
            src[:] = 0.0
        else:
            for k, d in enumerate(self.channels.digits):
                src[k] = source[d]
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
        out = {
            "angles": self.angles,
            "tips": self.tips,
            "joints": self.joints,
            "source": self.source,
        }
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
    rec = concat_recordings([b.recording for b in blocks])
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
        Received frames with a missing sensor (``valid`` 0).
    held : int
        Of those, frames with a digit the model could not solve (the hand sensor or every
        sensor of the digit missing, or a model without calibration statistics): its
        values held. The others were solved by the model.
    unconverged, data_unconverged : int
        A model fitted from markers: solves (a digit in a frame each) that stopped
        unconverged, their angles the last iterate's, among the frames sent (robot lane)
        and among those computed for the files (data lane).
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
    view_dropped, view_logged : int
        The live view (``--view``, ``--view-save``): frames the data lane dropped because
        the view's process was behind (``--view`` only), and frames that process logged
        (known when the stream has ended; ``view_logged + view_dropped = recorded``).
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
    held: int = 0
    unconverged: int = 0
    data_unconverged: int = 0
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
    view_dropped: int = 0
    view_logged: int = 0
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
