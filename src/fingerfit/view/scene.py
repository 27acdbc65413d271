"""What the view shows, computed over whole recordings: the person's hand per frame
(:func:`hand_scene`), the true tips, the robot posed by the retarget (:func:`robot_scene`,
:class:`RobotPlacement`); millimetres, tracker frame."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from ..kinematics import Kinematics, compute_kinematics
from ..model import HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..transforms import FloatArray, rotate_about_lines
from .robotgeometry import RobotGeometry, robot_geometry

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
    "markers": (0, 220, 220),
    "model_markers": (255, 0, 200),
}
_SENSOR_AXIS_COLOURS = ((230, 40, 40), (40, 200, 40), (60, 90, 255))


def require_rerun() -> ModuleType:
    """Import ``rerun`` (the extra ``view``), or end in one line naming the extra."""
    from ..extras import require

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
    geometry : RobotGeometry, optional
        The robot's own visual shapes (:mod:`.robotgeometry`); None or without a shape:
        the robot is drawn as lines through ``points``.
    link_translation : ndarray, shape (n, L, 3), optional
        Each link of ``geometry`` per frame: its origin (m, robot world frame) ...
    link_rotation : ndarray, shape (n, L, 3, 3), optional
        ... and its axes (link -> robot world).
    placement_translation : ndarray, shape (n, 3), optional
        The robot world's origin per frame (tracker frame, mm) ...
    placement_rotation : ndarray, shape (n, 3, 3), optional
        ... and its axes (robot world -> tracker): a point ``x`` (m) of the robot world is
        at ``placement_translation + 1000 * placement_rotation @ x`` mm, as ``points``
        are placed. NaN at frames without the hand sensor's sample (logged as the frame
        before: :func:`fingerfit.view.log_robot_frames`).
    """

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    points: FloatArray
    strips: list[np.ndarray]
    tips: FloatArray
    digits: list[str]
    notes: list[str] = field(default_factory=list)
    geometry: RobotGeometry | None = None
    link_translation: FloatArray | None = None
    link_rotation: FloatArray | None = None
    placement_translation: FloatArray | None = None
    placement_rotation: FloatArray | None = None

    @property
    def drawn(self) -> bool:
        """Whether the robot is drawn with its own shapes (else as lines)."""
        return self.geometry is not None and bool(self.geometry.visuals)


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
    markers : MarkerPoints, optional
        A model fitted from markers: the measured markers beside where the model puts
        them (:func:`marker_scene`).
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
    markers: MarkerPoints | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class MarkerPoints:
    """A marker model's markers over a recording (tracker frame, mm).

    Attributes
    ----------
    labels : list of str
        The model's markers, in its order.
    measured : ndarray, shape (n, M, 3)
        As recorded; NaN where unseen.
    model : ndarray, shape (n, M, 3)
        Where the model puts them at the solved angles and the hand's pose
        (:func:`fingerfit.kinematics.markers.model_marker_positions`).
    """

    labels: list[str]
    measured: FloatArray
    model: FloatArray


def _carry(model: HandModel, recording: Recording, points: FloatArray) -> FloatArray:
    """Reference-posture points ``(n, k, 3)`` carried by the hand sensor's motion (mm)."""
    hand = recording.pose(HAND_SENSOR)
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = (points - p0) @ r0  # r0^T (p - p0), row-wise
    return np.einsum("nij,nkj->nki", hand.rotation, local) + hand.position[:, None, :]


def _carry_axes(model: HandModel, recording: Recording, axes: FloatArray) -> FloatArray:
    """Reference-posture axes ``(3, 3)`` (columns) carried by the hand sensor's rotation:
    ``(n, 3, 3)``, the turn :func:`_carry` gives points."""
    hand = recording.pose(HAND_SENSOR)
    r0 = model.reference_poses[HAND_SENSOR][1]
    return hand.rotation @ (r0.T @ axes)


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


def marker_scene(model: HandModel, recording: Recording, kin: Kinematics | None = None) -> Scene:
    """The hand of a model fitted from markers over a marker recording: :func:`hand_scene`
    with the hand's pose of its markers' rigid fit (shown as the ``hand`` sensor's axes),
    and the measured markers beside where the model puts them.

    Parameters
    ----------
    model : HandModel
        Fitted from markers.
    recording : Recording
        The model's markers over ``n`` frames (mm, tracker frame; NaN: unseen).
    kin : Kinematics, optional
        Its :func:`fingerfit.live.markers.marker_kinematics` (computed when not given).

    Returns
    -------
    Scene
        User-axis model only (a marker model has no orthogonal variant); ``markers`` set.
    """
    from ..kinematics.markers import model_marker_positions, with_hand
    from ..live.markers import marker_kinematics

    rec, kin = with_hand(model, recording, kin or marker_kinematics(model, recording)[0])
    scene = hand_scene(model, Recording(rec.name, rec.time, rec.poses), kin)
    labels, placed = model_marker_positions(model, rec.poses[HAND_SENSOR], kin)
    measured = np.stack([recording.markers[k] for k in labels], axis=1)
    scene.markers = MarkerPoints(labels, measured, placed)
    return scene


def hand_recording(scene: Scene, recording: Recording) -> Recording:
    """The frames of a marker model's :func:`marker_scene` as a robot is placed by them:
    ``recording``'s time with the hand's pose of its markers' rigid fit (the scene's
    ``hand`` sensor; mm, tracker frame) as the hand sensor's poses."""
    position, rotation = scene.sensors[HAND_SENSOR]
    return Recording(recording.name, recording.time, {HAND_SENSOR: PoseSeries(position, rotation)})


def truth_tips(recording_path: Path, n_frames: int) -> tuple[dict[str, FloatArray] | None, str]:
    """The true tips of a simulated session's recording, when ``truth/<recording>`` is
    beside it (``fingerfit simulate``; :func:`fingerfit.evaluate.truth.load_truth`); for
    a marker recording ``X.trc`` (``fingerfit simulate markers``), ``truth/X.csv``.

    Returns
    -------
    tips : dict or None
        Digit -> ``(n, 3)`` mm, tracker frame.
    note : str
        Why there are none (empty when there are).
    """
    from ..evaluate.truth import load_truth
    from ..io.markers import is_marker_file

    path = Path(recording_path)
    folder = path.resolve().parent
    name = Path(path.stem).with_suffix(".csv").name if is_marker_file(path) else path.name
    if not (folder / "truth" / name).is_file():
        return None, ""
    truth = load_truth(folder)
    if truth is None:
        return None, f"no truth.json beside {recording_path}: no true tips shown"
    tips = truth.tips.get(name)
    if not tips:
        return None, ""
    rows = next(iter(tips.values())).shape[0]
    if rows != n_frames:
        return None, (
            f"truth/{name} has {rows} rows, the recording {n_frames} frames: no true tips shown"
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
    from ..retarget import Retargeter

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
        from ..retarget.solve import MM

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
        self.geometry = robot_geometry(robot, rmap.palm)

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
        points = self._place(recording, world)
        out = RobotScene(
            name=self.rmap.name,
            joint_names=tuple(robot.joint_names),
            q=q,
            points=points,
            strips=self.strips,
            tips=points[:, 1 + len(self.used) :],
            digits=list(self.digits),
            notes=list(notes or []),
            geometry=self.geometry,
        )
        if out.drawn:
            out.link_translation, out.link_rotation = self.geometry.link_poses(q)
            # The same placement as the points: the robot world's origin and axes.
            out.placement_translation = self._place(recording, np.zeros((n, 1, 3)))[:, 0]
            axes = s.palm.rotation @ s.robot_palm.rotation.T  # robot world -> person's palm
            out.placement_rotation = _carry_axes(self.model, recording, axes)
        return out

    def _place(self, recording: Recording, world: FloatArray) -> FloatArray:
        """Robot-world points ``(n, k, 3)`` (m) beside the person: tracker frame, mm."""
        s = self.setup
        # Robot world (m) -> robot palm frame (mm) -> the person's palm frame, beside the hand.
        local = (world - s.robot_palm.origin) @ s.robot_palm.rotation * self.mm + self.shift
        ref = s.palm.origin + local @ s.palm.rotation.T
        return _carry(self.model, recording, ref)


# --- Logging ---------------------------------------------------------------------------------


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
