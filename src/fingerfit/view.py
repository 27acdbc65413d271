"""The person's fitted hand, frame by frame, in the Rerun viewer (``fingerfit view``).

:func:`hand_scene` computes, with NumPy over the whole recording, everything the view
shows of the person: the joint centres and axes carried through the model's chain (the
same turns that move the tips in :mod:`fingerfit.kinematics`), the tips and pads of both
model variants, the joint angles and the sensors. :func:`robot_scene` poses a robot hand
by the retarget of the same frames. :func:`log_scene` sends it all to a Rerun recording
stream, each entity as whole columns (``send_columns``), on the time lines ``frame``
(0-based) and ``time`` (s, the recording's own).

Units and frames (``docs/view.md``): millimetres in the tracker frame, as everywhere in
fingerfit (``docs/conventions.md``); the robot is placed beside the person in the
person's palm frame and moves with the hand. Rerun (the extra ``view``) is imported by
:func:`require_rerun` only.
"""

from __future__ import annotations

import collections
import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from .kinematics import Kinematics, compute_kinematics
from .model import HandModel
from .session import HAND_SENSOR, Recording
from .transforms import FloatArray, rotate_about_lines

#: The optional extra that installs Rerun.
EXTRA = "view"
#: Length of the arrows drawn along each joint axis (mm).
AXIS_ARROW_MM = 15.0
#: Length of each sensor's three axes (mm).
SENSOR_AXIS_MM = 10.0
#: Sideways distance of the robot hand from the person's (mm, along the palm frame's y,
#: towards the person's ulnar side).
ROBOT_OFFSET_MM = 200.0
#: Application id of the Rerun recordings fingerfit writes.
APPLICATION_ID = "fingerfit"

# Colours (RGB) of the view's entities.
_COLOURS = {
    "skeleton": (230, 230, 230),
    "joints": (250, 250, 250),
    "flexion": (255, 140, 0),
    "abduction": (170, 80, 255),
    "tips": (255, 60, 60),
    "pads": (255, 170, 200),
    "orthogonal": (60, 160, 255),
    "truth": (40, 220, 90),
    "robot": (160, 160, 160),
    "robot_tips": (255, 215, 0),
}
_SENSOR_AXIS_COLOURS = ((230, 40, 40), (40, 200, 40), (60, 90, 255))


def require_rerun() -> ModuleType:
    """Import ``rerun`` (the extra ``view``), or end in one line naming the extra."""
    from .extras import require

    return require("rerun", EXTRA, "the 3D view")


@dataclass
class RobotScene:
    """A robot hand posed by the retarget, placed beside the person (tracker frame, mm).

    Attributes
    ----------
    name : str
        The map's robot name.
    joint_names : tuple of str
    q : ndarray, shape (n, nq)
        Joint values (rad; m for slide joints).
    points : ndarray, shape (n, k, 3)
        The palm frame's origin, then the anchors of every joint of the retargeted digits'
        chains and their tip frames (tracker frame, mm).
    strips : list of ndarray of int
        Per digit, indices into ``points``: palm origin, chain anchors, tip.
    tips : ndarray, shape (n, d, 3)
        The robot digits' tip frames (tracker frame, mm).
    digits : list of str
        Every digit of the robot's map (those the model lacks hold the neutral posture).
    notes : list of str
    """

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    points: FloatArray
    strips: list[np.ndarray]
    tips: FloatArray
    digits: list[str]
    notes: list[str] = field(default_factory=list)


@dataclass
class Scene:
    """What ``fingerfit view`` shows, per frame (tracker frame, mm; angles rad).

    Attributes
    ----------
    time : ndarray, shape (n,)
        Seconds.
    digits : list of str
    kinematics : Kinematics
        :func:`~fingerfit.kinematics.compute_kinematics` of the recording (both variants):
        tips, pads, angles.
    centres : ndarray, shape (n, d, 3, 3)
        Per digit its three flexion joint centres, proximal first, carried by the joints
        before them and the hand (the thumb's CMC, MCP, IP; a finger's MP, PIP, DIP).
    axes : list of (str, str, str)
        ``(digit, axis name, kind)`` of every axis (``flexion`` or ``abduction``), in
        chain order.
    axis_origins, axis_vectors : ndarray, shape (n, a, 3)
        Each axis's point (its centre) and direction times :data:`AXIS_ARROW_MM`.
    sensors : dict[str, tuple[ndarray, ndarray]]
        Sensor -> ``(position (n, 3), rotation (n, 3, 3))``, as recorded.
    truth_tips : dict[str, ndarray], optional
        Digit -> true tip ``(n, 3)`` of a simulated session.
    robot : RobotScene, optional
    notes : list of str
    """

    time: FloatArray
    digits: list[str]
    kinematics: Kinematics
    centres: FloatArray
    axes: list[tuple[str, str, str]]
    axis_origins: FloatArray
    axis_vectors: FloatArray
    sensors: dict[str, tuple[FloatArray, FloatArray]]
    truth_tips: dict[str, FloatArray] | None = None
    robot: RobotScene | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])


def _carry(model: HandModel, recording: Recording, points: FloatArray) -> FloatArray:
    """Reference-posture points ``(n, k, 3)`` carried by the hand sensor's motion (mm)."""
    hand = recording.pose(HAND_SENSOR)
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = (points - p0) @ r0  # r0^T (p - p0), row-wise
    return np.einsum("nij,nkj->nki", hand.rotation, local) + hand.position[:, None, :]


def hand_scene(model: HandModel, recording: Recording, kin: Kinematics | None = None) -> Scene:
    """The person's hand over a recording: joint centres and axes, tips, pads, angles.

    Parameters
    ----------
    model : HandModel
    recording : Recording
        With the hand sensor and the sensors of every digit of the model (mm).
    kin : Kinematics, optional
        Its :func:`~fingerfit.kinematics.compute_kinematics` with both variants (computed
        when not given).

    Returns
    -------
    Scene
        Joint centres and axes of the fitted (user-axis) model: each axis's line at the
        reference posture turned about every axis before it in the digit's chain
        (``DigitModel.chain``; a migrating centre moved by ``theta * migration`` first),
        then carried by the hand sensor's motion -- the turns that move the tip in
        :mod:`fingerfit.kinematics`.
    """
    kin = kin or compute_kinematics(model, recording)
    n = recording.n_frames
    digits = list(model.fingers)
    angles = kin.motions["user_axis"]
    centres = np.empty((n, len(digits), 3, 3))
    axes: list[tuple[str, str, str]] = []
    origins, heads = [], []
    for d_i, d in enumerate(digits):
        fm = model.fingers[d]
        a = angles[d].angles
        chain = fm.chain()
        steps = []  # the turns of the axes before the current one, distal first
        flexion_index = 0
        for jm in chain:
            centre = jm.center
            if jm.migration is not None:
                centre = centre + np.multiply.outer(a[jm.name], jm.migration)
            pts = np.broadcast_to(centre, (n, 3))
            ends = pts + AXIS_ARROW_MM * jm.axis
            if steps:
                pts = rotate_about_lines(pts, steps)
                ends = rotate_about_lines(ends, steps)
            kind = "abduction" if jm.name.endswith("_abduction") else "flexion"
            axes.append((d, jm.name, kind))
            origins.append(pts)
            heads.append(ends)
            if kind == "flexion":
                centres[:, d_i, flexion_index] = pts
                flexion_index += 1
            steps.insert(0, (centre, jm.axis, a[jm.name]))
    o = np.stack(origins, axis=1) if origins else np.zeros((n, 0, 3))
    h = np.stack(heads, axis=1) if heads else np.zeros((n, 0, 3))
    o, h = _carry(model, recording, o), _carry(model, recording, h)
    flat = _carry(model, recording, centres.reshape(n, -1, 3)).reshape(centres.shape)
    sensors = {s: (p.position, p.rotation) for s, p in recording.poses.items()}
    return Scene(
        time=np.asarray(recording.time, dtype=float),
        digits=digits,
        kinematics=kin,
        centres=flat,
        axes=axes,
        axis_origins=o,
        axis_vectors=h - o,
        sensors=sensors,
    )


def truth_tips(recording_path: Path, n_frames: int) -> tuple[dict[str, FloatArray] | None, str]:
    """The true tips of a simulated session's recording, when ``truth/<recording>`` is
    beside it (``fingerfit simulate``; :func:`fingerfit.evaluate.truth.load_truth`).

    Returns
    -------
    tips : dict or None
        Digit -> ``(n, 3)`` mm, tracker frame.
    note : str
        Why there are none (empty when there are).
    """
    from .evaluate.truth import load_truth

    folder = Path(recording_path).resolve().parent
    if not (folder / "truth" / Path(recording_path).name).is_file():
        return None, ""
    truth = load_truth(folder)
    if truth is None:
        return None, f"no truth.json beside {recording_path}: no true tips shown"
    tips = truth.tips.get(Path(recording_path).name)
    if not tips:
        return None, ""
    rows = next(iter(tips.values())).shape[0]
    if rows != n_frames:
        return None, (
            f"truth/{Path(recording_path).name} has {rows} rows, the recording {n_frames} "
            "frames: no true tips shown"
        )
    return tips, ""


def robot_scene(
    model: HandModel,
    recording: Recording,
    robot,
    rmap,
    method: str = "tip",
    variant: str = "user_axis",
    kin: Kinematics | None = None,
    offset_mm: float = ROBOT_OFFSET_MM,
) -> RobotScene:
    """A robot hand posed by the retarget of ``recording``, placed beside the person.

    The robot's joints come from :class:`fingerfit.retarget.Retargeter` (``method``,
    ``variant``); every digit of the robot is drawn. Robot points are taken into the
    robot's palm frame (mm), shifted so the mean of the retargeted digits' bases lands on
    the person's and then ``offset_mm``
    along the person's palm-frame y, towards the person's ulnar side, put in the person's
    palm frame (``fingerfit.retarget.palm.person_palm``) and carried by the hand sensor's
    motion: a rigid placement, so a right robot hand stays a right hand beside a left one.

    Parameters
    ----------
    robot, rmap : Robot, RobotMap
        From :func:`fingerfit.retarget.resolve`.
    """
    from .retarget import Retargeter

    r = Retargeter(model, robot, rmap, method, variant)
    kin_v = kin if kin is not None and variant in kin.motions else None
    q, _, _ = r.step(recording, kin_v)
    placement = RobotPlacement(model, robot, rmap, r.setup, offset_mm)
    return placement.scene(q, recording, notes=list(r.notes))


class RobotPlacement:
    """Where a robot hand's points go beside the person (:func:`robot_scene`), prepared
    once; :meth:`scene` poses it by joint values of any frames.

    Parameters
    ----------
    model : HandModel
    robot, rmap : Robot, RobotMap
        From :func:`fingerfit.retarget.resolve`; ``robot`` is used by :meth:`scene` only
        (its MuJoCo / Pinocchio data: one thread at a time).
    setup : fingerfit.retarget.Setup
        ``fingerfit.retarget.setup(model, robot, rmap)`` (a Retargeter's ``setup``).
    offset_mm : float
    """

    def __init__(self, model: HandModel, robot, rmap, setup, offset_mm: float = ROBOT_OFFSET_MM):
        from .retarget.solve import MM

        self.model, self.robot, self.rmap, self.setup = model, robot, rmap, setup
        self.mm = MM
        self.digits = list(rmap.digits)  # every robot digit: those the model lacks held
        chains = []
        for d in self.digits:
            dm = rmap.digits[d]
            chain = robot.ancestors(dm.tip)
            base = robot.joint_names.index(dm.base)
            chains.append(chain[chain.index(base) :] if base in chain else chain)
        self.used = sorted({j for c in chains for j in c})
        self.tip_frames = [rmap.digits[d].tip for d in self.digits]
        u = len(self.used)
        self.strips = [
            np.array([0] + [1 + self.used.index(j) for j in c] + [1 + u + k])
            for k, c in enumerate(chains)
        ]
        s = setup
        self.shift = np.mean([s.person_base[d] for d in s.digits], axis=0) - np.mean(
            [s.robot_base[d] for d in s.digits], axis=0
        )
        side = 1.0 if model.hand == "left" else -1.0  # palm y is ulnar on a left hand
        self.shift = self.shift + np.array([0.0, side * offset_mm, 0.0])

    def scene(self, q: FloatArray, recording: Recording, notes=None) -> RobotScene:
        """The robot posed by ``q`` (n, nq) at the frames of ``recording`` (n frames)."""
        robot, s = self.robot, self.setup
        n = q.shape[0]
        anchors = np.empty((n, len(self.used), 3))
        for i in range(n):
            anchors[i] = robot.anchors(q[i])[self.used]
        tips = robot.positions(q, self.tip_frames)  # (n, d, 3) m, robot world
        origin = np.broadcast_to(s.robot_palm.origin, (n, 1, 3))
        world = np.concatenate([origin, anchors, tips], axis=1)
        # Robot world (m) -> robot palm frame (mm) -> the person's palm frame, beside the hand.
        local = (world - s.robot_palm.origin) @ s.robot_palm.rotation * self.mm + self.shift
        ref = s.palm.origin + local @ s.palm.rotation.T
        points = _carry(self.model, recording, ref)
        return RobotScene(
            name=self.rmap.name,
            joint_names=tuple(robot.joint_names),
            q=q,
            points=points,
            strips=self.strips,
            tips=points[:, 1 + len(self.used) :],
            digits=list(self.digits),
            notes=list(notes or []),
        )


# --- Logging ---------------------------------------------------------------------------------


def _indexes(rr, time: FloatArray, frames: np.ndarray) -> list:
    return [
        rr.TimeColumn("frame", sequence=np.asarray(frames, dtype=np.int64)),
        rr.TimeColumn("time", duration=np.asarray(time, dtype=float)),
    ]


def _static(rr, stream, entity: str, archetype) -> None:
    rr.log(entity, archetype, static=True, recording=stream)


def _points(rr, stream, entity: str, idx, pts: FloatArray, extra=()) -> None:
    """Points ``(n, k, 3)``: positions per frame (with the ``extra`` component columns in
    the same rows)."""
    n, k = pts.shape[:2]
    columns = rr.Points3D.columns(positions=pts.reshape(-1, 3)).partition(np.full(n, k))
    rr.send_columns(entity, indexes=idx, columns=[*columns, *extra], recording=stream)


def _strips(rr, stream, entity: str, idx, pts: FloatArray, strips: list[np.ndarray]) -> None:
    """Line strips through ``pts (n, k, 3)``, each strip a list of point indices."""
    n = pts.shape[0]
    lines = [pts[i, s] for i in range(n) for s in strips]
    rr.send_columns(
        entity,
        indexes=idx,
        columns=rr.LineStrips3D.columns(strips=lines).partition(np.full(n, len(strips))),
        recording=stream,
    )


def _arrows(rr, stream, entity: str, idx, origins: FloatArray, vectors: FloatArray) -> None:
    n, k = origins.shape[:2]
    rr.send_columns(
        entity,
        indexes=idx,
        columns=rr.Arrows3D.columns(
            origins=origins.reshape(-1, 3), vectors=vectors.reshape(-1, 3)
        ).partition(np.full(n, k)),
        recording=stream,
    )


def blueprint(robot: bool = False):
    """The default layout: the 3D scene beside the joint angles' time series (and the
    robot's joints, with a ``robot``)."""
    import rerun.blueprint as rrb

    series = [rrb.TimeSeriesView(origin="angles", name="joint angles (deg)")]
    if robot:
        series.append(rrb.TimeSeriesView(origin="robot_angles", name="robot joints (deg)"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                origin="/",
                contents=["/person/**", "/sensors/**", "/truth/**", "/robot/**"],
                name="hand (mm, tracker frame)",
            ),
            rrb.Vertical(*series),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def _padded(scene: Scene) -> list[str]:
    return [g for g in scene.digits if scene.kinematics.motions["user_axis"][g].pad is not None]


def _truth_digits(scene: Scene) -> list[str]:
    return [g for g in scene.digits if g in scene.truth_tips] if scene.truth_tips else []


def log_static(scene: Scene, stream) -> None:
    """What does not change from frame to frame (colours, radii, labels, the scene's
    axes), logged once; ``scene`` may be any block of frames of the recording (its
    digits, axes, sensors and variants are the recording's)."""
    rr = require_rerun()
    kin = scene.kinematics
    _static(rr, stream, "/", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    _static(
        rr,
        stream,
        "person/skeleton",
        rr.LineStrips3D.from_fields(colors=[_COLOURS["skeleton"]], radii=[1.2]),
    )
    _static(
        rr,
        stream,
        "person/joints",
        rr.Points3D.from_fields(colors=[_COLOURS["joints"]], radii=[2.5]),
    )
    colours = [_COLOURS[kind] for _, _, kind in scene.axes]
    _static(rr, stream, "person/axes", rr.Arrows3D.from_fields(colors=colours, radii=[0.6]))
    _static(
        rr,
        stream,
        "person/tips",
        rr.Points3D.from_fields(colors=[_COLOURS["tips"]], radii=[3.0], labels=scene.digits),
    )
    padded = _padded(scene)
    if padded:
        _static(
            rr,
            stream,
            "person/pads",
            rr.Points3D.from_fields(colors=[_COLOURS["pads"]], radii=[2.5], labels=padded),
        )
    if "orthogonal" in kin.motions:
        _static(
            rr,
            stream,
            "person/orthogonal/tips",
            rr.Points3D.from_fields(colors=[_COLOURS["orthogonal"]], radii=[3.0]),
        )
    if scene.sensors:
        colours = list(_SENSOR_AXIS_COLOURS) * len(scene.sensors)
        _static(rr, stream, "sensors", rr.Arrows3D.from_fields(colors=colours, radii=[0.6]))
    have = _truth_digits(scene)
    if have:
        _static(
            rr,
            stream,
            "truth/tips",
            rr.Points3D.from_fields(colors=[_COLOURS["truth"]], radii=[2.0], labels=have),
        )
    if scene.robot is not None:
        log_robot_static(scene.robot.digits, stream)


def log_robot_static(digits: list[str], stream) -> None:
    """The robot's colours, radii and labels, logged once."""
    rr = require_rerun()
    _static(
        rr,
        stream,
        "robot/skeleton",
        rr.LineStrips3D.from_fields(colors=[_COLOURS["robot"]], radii=[2.0]),
    )
    _static(
        rr, stream, "robot/joints", rr.Points3D.from_fields(colors=[_COLOURS["robot"]], radii=[3.0])
    )
    _static(
        rr,
        stream,
        "robot/tips",
        rr.Points3D.from_fields(colors=[_COLOURS["robot_tips"]], radii=[4.0], labels=digits),
    )


def log_frames(scene: Scene, stream, first: int = 0) -> None:
    """Send a block of frames of a :class:`Scene` (whose first frame is the recording's
    frame ``first``) to a Rerun recording stream, each entity as whole columns.

    Entities (``docs/view.md``): ``person/skeleton`` (per digit: joint centre to joint
    centre to tip), ``person/joints``, ``person/axes`` (every axis, flexion orange,
    ab/adduction purple), ``person/tips`` (with ``tip_mm``, the same tips in float64:
    Rerun stores positions in float32), ``person/pads``, ``person/orthogonal/tips``,
    ``sensors`` (each sensor's x, y, z axes), ``angles/<digit>/<angle>`` (deg),
    ``truth/tips``, and the robot's (:func:`log_robot_frames`). Their colours and labels
    are :func:`log_static`'s.
    """
    rr = require_rerun()
    n = scene.n_frames
    if n == 0:
        return
    idx = _indexes(rr, scene.time, first + np.arange(n))
    kin = scene.kinematics
    d = len(scene.digits)
    # The person: each digit's skeleton, joint centre to joint centre to tip.
    tips = np.stack([kin.motions["user_axis"][g].tip for g in scene.digits], axis=1)
    skeleton = np.concatenate([scene.centres, tips[:, :, None, :]], axis=2)  # (n, d, 4, 3)
    strips = [np.arange(4) + 4 * k for k in range(d)]
    _strips(rr, stream, "person/skeleton", idx, skeleton.reshape(n, -1, 3), strips)
    _points(rr, stream, "person/joints", idx, scene.centres.reshape(n, -1, 3))
    _arrows(rr, stream, "person/axes", idx, scene.axis_origins, scene.axis_vectors)
    exact = rr.AnyValues.columns(tip_mm=tips.reshape(-1).astype(np.float64))
    _points(rr, stream, "person/tips", idx, tips, extra=exact.partition(np.full(n, 3 * d)))
    padded = _padded(scene)
    if padded:
        pads = np.stack([kin.motions["user_axis"][g].pad for g in padded], axis=1)
        _points(rr, stream, "person/pads", idx, pads)
    if "orthogonal" in kin.motions:
        ortho = np.stack([kin.motions["orthogonal"][g].tip for g in scene.digits], axis=1)
        _points(rr, stream, "person/orthogonal/tips", idx, ortho)
    # The sensors: each one's x, y, z axes.
    names = list(scene.sensors)
    if names:
        pos = np.stack([scene.sensors[s][0] for s in names], axis=1)  # (n, s, 3)
        rot = np.stack([scene.sensors[s][1] for s in names], axis=1)  # (n, s, 3, 3)
        origins = np.repeat(pos, 3, axis=1)
        vectors = SENSOR_AXIS_MM * np.swapaxes(rot, 2, 3).reshape(n, -1, 3)
        _arrows(rr, stream, "sensors", idx, origins, vectors)
    # Joint angles (deg), one series per angle.
    for g in scene.digits:
        for name, a in kin.motions["user_axis"][g].angles.items():
            rr.send_columns(
                f"angles/{g}/{name}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.degrees(a)),
                recording=stream,
            )
    have = _truth_digits(scene)
    if have:
        truth = np.stack([scene.truth_tips[g] for g in have], axis=1)
        _points(rr, stream, "truth/tips", idx, truth)
    if scene.robot is not None:
        log_robot_frames(scene.robot, stream, first + np.arange(n), scene.time)


def log_robot_frames(robot: RobotScene, stream, frames: np.ndarray, time: FloatArray) -> None:
    """Send a robot hand's frames (``robot/skeleton|joints|tips``, ``robot_angles/<joint>``
    in degrees) at the recording's frames ``frames`` (n,) and times ``time`` (n,) s."""
    rr = require_rerun()
    if robot.q.shape[0] == 0:
        return
    idx = _indexes(rr, time, frames)
    _strips(rr, stream, "robot/skeleton", idx, robot.points, robot.strips)
    _points(rr, stream, "robot/joints", idx, robot.points[:, 1 : -len(robot.digits)])
    _points(rr, stream, "robot/tips", idx, robot.tips)
    for j, name in enumerate(robot.joint_names):
        rr.send_columns(
            f"robot_angles/{name}",
            indexes=idx,
            columns=rr.Scalars.columns(scalars=np.degrees(robot.q[:, j])),
            recording=stream,
        )


def log_scene(scene: Scene, stream) -> None:
    """Send a whole :class:`Scene` to a Rerun recording stream: :func:`log_static`, then
    every frame as whole columns (:func:`log_frames`)."""
    log_static(scene, stream)
    log_frames(scene, stream)


def new_stream(recording_id: str | None = None):
    """A Rerun recording stream of application ``fingerfit``, not the global one."""
    rr = require_rerun()
    return rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)


def save_rrd(scene: Scene, path: str | Path) -> Path:
    """Write ``scene`` to a Rerun ``.rrd`` file, atomically (all of it or nothing)."""
    from .io.atomic import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=".part.rrd") as tmp, no_usage_reporting():
        stream = new_stream()
        stream.save(tmp, default_blueprint=blueprint(scene.robot is not None))
        log_scene(scene, stream)
        stream.flush()
        stream.disconnect()
    return path


class LiveView:
    """The view of ``fingerfit stream --view`` / ``--view-save``, fed block by block.

    :meth:`push` is called by the stream's data lane (its own thread, every frame, in
    blocks) with the kinematics it computed: the same :func:`hand_scene`,
    :func:`log_static` and :func:`log_frames` as ``fingerfit view``, with frames counted
    on from block to block. The robot (``placement``) is posed by the joints the data
    lane's own retargeter gives for every frame (:meth:`push`'s ``q``), or else by the
    joints the robot lane sent (:attr:`sent`, filled by the robot lane: one row per sent
    frame, at that frame).

    Parameters
    ----------
    model : HandModel
    save : Path, optional
        Write a Rerun file (atomically, when :meth:`close` is called with ``ok``);
        otherwise the native viewer is spawned (its usage reporting off).
    placement : RobotPlacement, optional
        The robot beside the hand, on a robot of its own (used on the data lane's thread).
    """

    def __init__(
        self, model: HandModel, save: Path | None = None, placement: RobotPlacement | None = None
    ) -> None:
        from .io.atomic import atomic_path

        require_rerun()
        self.model, self.placement = model, placement
        self.frames = 0
        #: (frame, joints (nq,)) of every frame the robot lane sent, when the view's robot
        #: follows it (appended by the robot lane, taken by :meth:`push`).
        self.sent: collections.deque | None = None
        self._stack = contextlib.ExitStack()
        self.stream = new_stream()
        layout = blueprint(placement is not None)
        if save is not None:
            tmp = self._stack.enter_context(atomic_path(save, suffix=".part.rrd"))
            self.stream.save(tmp, default_blueprint=layout)
        else:
            with no_usage_reporting():
                self.stream.spawn(default_blueprint=layout)
        self._started = False

    def push(self, recording: Recording, kin: Kinematics, q: FloatArray | None = None) -> None:
        """Log a block of frames (the next ones of the stream).

        Parameters
        ----------
        recording : Recording
            The block's frames (mm, tracker frame).
        kin : Kinematics
            Their :func:`~fingerfit.kinematics.compute_kinematics` (``user_axis``, and
            ``orthogonal`` for its tips).
        q : ndarray, shape (n, nq), optional
            The robot's joints at every frame of the block.
        """
        n = recording.n_frames
        if n == 0:
            return
        scene = hand_scene(self.model, recording, kin)
        if not self._started:
            log_static(scene, self.stream)
            if self.placement is not None:
                log_robot_static(self.placement.digits, self.stream)
            self._started = True
        first = self.frames
        log_frames(scene, self.stream, first)
        if self.placement is not None:
            rows = np.arange(n)
            if q is None:
                rows, q = self._sent_until(first + n)
                rows = rows - first
            if rows.size:
                robot = self.placement.scene(q, recording.slice(rows))
                log_robot_frames(robot, self.stream, first + rows, recording.time[rows])
        self.frames += n

    def _sent_until(self, end: int) -> tuple[np.ndarray, FloatArray]:
        """The robot lane's sent frames before frame ``end``: their frames and joints."""
        rows, qs = [], []
        sent = self.sent
        while sent and sent[0][0] < end:
            frame, joints = sent.popleft()
            rows.append(frame)
            qs.append(joints)
        if not rows:
            return np.zeros(0, dtype=int), np.zeros((0, 0))
        return np.array(rows), np.stack(qs)

    def close(self, ok: bool = True) -> None:
        """Flush the stream; the file (``save``) is kept when ``ok``, else removed."""
        try:
            self.stream.flush()
            self.stream.disconnect()
        finally:
            if ok:
                self._stack.close()
            else:
                with contextlib.suppress(BaseException):
                    self._stack.__exit__(RuntimeError, RuntimeError("stream failed"), None)


#: The environment variable that turns the native Rerun viewer's usage reporting off for one
#: process. Rerun 0.41's viewer reads no opt-out variable of its own: its analytics
#: pipeline starts only when its config (``rerun analytics disable`` writes it) allows and
#: ``CI`` is unset (``re_analytics``, ``native/pipeline.rs``); ``FORCE_RERUN_ANALYTICS``
#: would override both, so it is removed for the viewer too.
NO_ANALYTICS_ENV = {"CI": "1"}


@contextlib.contextmanager
def no_usage_reporting() -> Iterator[None]:
    """Rerun's usage reporting off inside the block, for this process (the web viewer's
    server) and a native viewer spawned in it, which inherits the environment
    (:data:`NO_ANALYTICS_ENV`); the environment is restored after."""
    saved = {k: os.environ.get(k) for k in [*NO_ANALYTICS_ENV, "FORCE_RERUN_ANALYTICS"]}
    os.environ.update(NO_ANALYTICS_ENV)
    os.environ.pop("FORCE_RERUN_ANALYTICS", None)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def has_display() -> bool:
    """Whether a native viewer window can open here (a display, or macOS / Windows)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
