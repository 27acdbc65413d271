"""The retargeting pipeline: a person's recording -> robot joint angles per frame.

:func:`resolve` finds the robot and its map, :func:`setup` prepares the palm frames,
scales and limits of one model on one robot, :func:`retarget` runs the ``tip`` or
``joint`` method over a recording (``docs/retargeting.md``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from ..kinematics import Kinematics
from ..model import HandModel
from ..session import Recording
from ..track import track_recording
from ..transforms import FloatArray
from .joint import AngleCopy
from .limits import Limits, limits_of
from .maps import BUILTIN, RobotMap, builtin_map, check_map, pad_point_name, parse_map
from .palm import (
    Frame,
    digit_base,
    in_palm,
    person_chain_length,
    person_palm,
    robot_digit,
    robot_palm,
)
from .robots import Robot, load_robot
from .solve import MM, TipOptions, TipProblem, TipSolver

METHODS = ("tip", "joint")
#: Person's pad distance (mm) below which the pinch term starts to weigh.
PINCH_FAR_MM = 30.0
#: Person's pad-point distance counted as touching (mm) for a pair of digits the model has
#: no pinch holds of (:class:`fingerfit.model.PinchContact`) and no ``--contact-mm``:
#: digitised pulp skin points of touching pads lie 3.5-8 mm apart in the simulated
#: whole-hand pinches (docs/retargeting.md).
CONTACT_MM = 8.0


@dataclass
class Setup:
    """A robot, its map and everything fixed about retargeting one model onto it.

    Attributes
    ----------
    robot : Robot
    rmap : RobotMap
    limits : Limits
    hold : ndarray, shape (nq,)
        Neutral configuration (rad), within limits and couplings.
    digits : list of str
        Digits both the model and the map have (the retargeted ones).
    free : ndarray of int
        Joints the ``tip`` method solves for.
    palm, robot_palm : Frame
        Person's (tracker, mm) and robot's (robot world, m) palm frames.
    scale : dict[str, float]
        Per-digit robot/person chain length.
    person_base, robot_base : dict[str, ndarray (3,)]
        Digit base in the person's palm frame (mm) and the robot's (mm).
    mirror : bool
        The person's hand is the other side than the robot's (palm-frame y flipped).
    """

    robot: Robot
    rmap: RobotMap
    limits: Limits
    hold: FloatArray
    digits: list[str]
    free: np.ndarray
    palm: Frame
    robot_palm: Frame
    scale: dict[str, float]
    person_base: dict[str, FloatArray]
    robot_base: dict[str, FloatArray]
    mirror: bool
    notes: list[str] = field(default_factory=list)


def resolve(robot: str | Path, map_path: str | Path | None, hand: str) -> tuple[Robot, RobotMap]:
    """Robot and map from ``--robot`` (a built-in name or a .urdf/.xml file) and ``--map``.

    Raises
    ------
    FingerfitError
        Unknown robot name, a robot file without a map, a bad map, a missing package.
    """
    name = str(robot)
    if map_path is not None:
        rmap = parse_map(map_path)
    elif name in BUILTIN:
        rmap = builtin_map(name, hand)
    elif name.lower().endswith((".urdf", ".xml")):
        raise FingerfitError(
            "a robot file needs a map: give --map MAP.toml (docs/retargeting.md)", field="--map"
        )
    else:
        raise FingerfitError(
            f"unknown robot '{shown(name)}': one of {', '.join(BUILTIN)} or a .urdf/.xml file",
            field="--robot",
        )
    if name.lower().endswith((".urdf", ".xml")):
        file = Path(name)
    elif rmap.robot_file is not None:
        file = rmap.robot_file
    elif name in BUILTIN:
        file = builtin_map(name, hand).robot_file  # type: ignore[assignment]
    else:
        raise FingerfitError("the map names no robot file ([robot] file)", path=rmap.path)
    r = load_robot(file)
    check_map(rmap, r)
    digits = dict(rmap.digits)
    for d, dm in rmap.digits.items():
        if dm.pad_offset is not None:
            name = pad_point_name(d)
            r.add_point(name, dm.pad, dm.pad_offset)
            digits[d] = replace(dm, pad=name)
    return r, replace(rmap, digits=digits)


def setup(model: HandModel, robot: Robot, rmap: RobotMap) -> Setup:
    """Fix frames, anchors, scales, held joints and limits for one model on one robot.

    Raises
    ------
    FingerfitError
        The model and the map share no digit, or the map's couplings are infeasible.
    """
    limits = limits_of(robot, rmap)
    digits = [d for d in rmap.digits if d in model.fingers]
    if not digits:
        raise FingerfitError(
            f"the model's digits ({', '.join(model.fingers)}) are none of the map's "
            f"({', '.join(rmap.digits)})",
            path=rmap.path,
            field="digits",
        )
    idx = {n: i for i, n in enumerate(robot.joint_names)}
    hold = np.zeros(robot.nq)
    for j, v in rmap.neutral.items():
        hold[idx[j]] = v
    hold = limits.project(np.clip(hold, robot.lower, robot.upper))
    palm_joints = set(robot.ancestors(rmap.palm))
    chains = {d: set(robot.ancestors(rmap.digits[d].tip)) - palm_joints for d in rmap.digits}
    held = {idx[j] for j in rmap.neutral}
    free = np.array(sorted(set().union(*(chains[d] for d in digits)) - held), dtype=int)
    rpalm = robot_palm(robot, rmap, hold)
    palm = person_palm(model)
    scale, pbase, rbase = {}, {}, {}
    for d in digits:
        base, length = robot_digit(robot, rmap, rpalm, hold, d)
        person = person_chain_length(model, d)
        given = rmap.digits[d].scale
        scale[d] = given if given is not None else length * MM / person
        pbase[d] = (digit_base(model, d) - palm.origin) @ palm.rotation
        rbase[d] = base * MM
    notes = []
    absent = [d for d in rmap.digits if d not in model.fingers]
    if absent:
        notes.append(f"digits the model lacks hold the neutral posture: {', '.join(absent)}")
    unused = [d for d in model.fingers if d not in rmap.digits]
    if unused:
        notes.append(f"the robot has no {', '.join(unused)}: not retargeted")
    mirror = model.hand in ("right", "left") and model.hand != rmap.hand
    if mirror:
        notes.append(f"{model.hand} hand mirrored onto the {rmap.hand} robot hand")
    return Setup(
        robot, rmap, limits, hold, digits, free, palm, rpalm, scale, pbase, rbase, mirror, notes
    )


def targets(s: Setup, points: FloatArray, digits: list[str]) -> FloatArray:
    """Person's points in their palm frame -> robot targets (robot palm frame, mm).

    Parameters
    ----------
    points : ndarray, shape (n, k, 3)
        Person's palm frame (mm), one column per digit of ``digits``.

    Returns
    -------
    ndarray, shape (n, k, 3)
        ``B_robot + s M (P - B_person)`` (``docs/retargeting.md``).
    """
    m = np.array([1.0, -1.0 if s.mirror else 1.0, 1.0])
    base_p = np.array([s.person_base[d] for d in digits])
    base_r = np.array([s.robot_base[d] for d in digits])
    k = np.array([s.scale[d] for d in digits])[:, None]
    return base_r + k * (points - base_p) * m


def robot_points(s: Setup, q: FloatArray, frames: list[str]) -> FloatArray:
    """Robot frame positions ``(n, k, 3)`` in the robot palm frame (mm) for ``q (n, nq)``."""
    p = s.robot.positions(q, frames)
    return (p - s.robot_palm.origin) @ s.robot_palm.rotation * MM


@dataclass(frozen=True)
class Retargeting:
    """A robot joint trajectory.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Seconds.
    joint_names : tuple of str
        Every robot joint (``nq``), coupled and held ones included.
    q : ndarray, shape (n, nq)
        rad (m for slide joints).
    method : {"tip", "joint"}
    digits : list of str
    targets : ndarray, shape (n, k, 3)
        Scaled fingertip targets of ``digits`` (robot palm frame, mm).
    tips : ndarray, shape (n, k, 3)
        Robot tips reached (robot palm frame, mm).
    seconds : ndarray, shape (n,)
        Per-frame solve time (``tip``; the vectorised ``joint`` copy: total / n).
    violations : int
        Limit and coupling violations of ``q`` (0).
    notes : list of str
        Mirroring, digits held or dropped, frames with missing data.
    """

    time: FloatArray
    joint_names: tuple[str, ...]
    q: FloatArray
    method: str
    digits: list[str]
    targets: FloatArray
    tips: FloatArray
    seconds: FloatArray
    violations: int
    notes: list[str]


def pinch_terms(
    s: Setup, pads: dict[str, FloatArray], contact_mm: float | FloatArray = CONTACT_MM
) -> tuple[list[tuple[str, str]], FloatArray, FloatArray, FloatArray]:
    """Pinch pairs, target vectors, weights and the person's pad distances.

    Parameters
    ----------
    pads : dict[str, ndarray (n, 3)]
        Digit -> pad point in the person's palm frame (mm).
    contact_mm : float or ndarray, shape (p,)
        The person's pad-point distance that counts as touching, one for every pair or
        one per pair (mm; :meth:`Retargeter.contact`).

    Returns
    -------
    pairs : list of (str, str)
    vectors : ndarray, shape (n, p, 3)
        Target of robot ``pad_a - pad_b`` (robot palm frame, mm): the person's vector,
        mirrored, scaled by the pair's mean scale, times ``u``: 0 at and below
        ``contact_mm``, rising linearly to 1 at :data:`PINCH_FAR_MM` and beyond. The
        robot's gap is then flat near contact (a touch the model sees 3 mm wider than its
        contact distance asks the robot's pads for a gap under 1 mm at a pair scale of 1),
        and the person's own gap, scaled, where the pinch term stops weighing.
    weights : ndarray, shape (n, p)
        ``1 - u``: 0 beyond :data:`PINCH_FAR_MM`, rising linearly to 1 at ``contact_mm``.
    distance : ndarray, shape (n, p)
        Person's pad distance (mm).
    """
    pairs = [(a, b) for a, b in s.rmap.pinch if a in pads and b in pads]
    n = len(next(iter(pads.values()))) if pads else 0
    m = np.array([1.0, -1.0 if s.mirror else 1.0, 1.0])
    if not pairs:
        return pairs, np.zeros((n, 0, 3)), np.zeros((n, 0)), np.zeros((n, 0))
    v = (np.stack([pads[a] for a, _ in pairs], 1) - np.stack([pads[b] for _, b in pairs], 1)) * m
    dist = np.linalg.norm(v, axis=2)
    k = np.array([0.5 * (s.scale[a] + s.scale[b]) for a, b in pairs])
    contact_mm = np.broadcast_to(np.asarray(contact_mm, dtype=float), (len(pairs),))
    span = np.maximum(PINCH_FAR_MM - contact_mm, 1e-9)
    u = np.clip((dist - contact_mm) / span, 0.0, 1.0)
    vec = k[:, None] * v * u[:, :, None]
    return pairs, vec, np.nan_to_num(1.0 - u), dist


def person_points(
    s: Setup, model: HandModel, kin: Kinematics, recording: Recording, variant: str, attr: str
) -> dict[str, FloatArray]:
    """Digit -> ``(n, 3)`` person's ``tip`` or ``pad`` trajectory in their palm frame (mm)."""
    out = {}
    for d in s.digits:
        motion = kin.motions[variant][d]
        pts = getattr(motion, attr, None)
        if pts is not None:
            out[d] = in_palm(model, s.palm, recording, np.asarray(pts)[:, None, :])[:, 0]
    return out


class Retargeter:
    """One model on one robot, block of frames by block of frames (offline: one block).

    Holds what carries from one frame to the next: the ``tip`` solver's warm start and
    the ``joint`` method's last value of each angle (a missing sensor keeps it), so
    :meth:`step` over blocks as they arrive gives the same joints as over the whole
    recording at once (``fingerfit stream --retarget``).

    Parameters
    ----------
    model : HandModel
    robot, rmap : Robot, RobotMap
        From :func:`resolve`.
    method : {"tip", "joint"}
    variant : {"user_axis", "orthogonal"}
        The model variant whose kinematics drive the robot.
    options : TipOptions, optional
    contact_mm : float, optional
        The person's pad distance that counts as touching for every pinch pair (mm;
        ``--contact-mm``). Default: per pair, the model's
        :class:`~fingerfit.model.PinchContact` of the variant (how close the person's
        pads came in their own pinch holds), else :data:`CONTACT_MM`.

    Attributes
    ----------
    setup : Setup
    frames : list of str
        The robot's tip frames of ``setup.digits``.
    notes : list of str
        Mirroring, digits held or dropped, pinch term off, each pinch pair's contact
        distance and where it comes from.
    contact : ndarray, shape (p,)
        The contact distance of each pinch pair the ``tip`` method uses (mm).
    held, missing : int
        Frames so far where a missing angle kept its value (``joint``) and frames with a
        missing sensor whose digits kept their pose (``tip``).
    """

    def __init__(
        self,
        model: HandModel,
        robot: Robot,
        rmap: RobotMap,
        method: str = "tip",
        variant: str = "user_axis",
        options: TipOptions | None = None,
        contact_mm: float | None = None,
    ) -> None:
        if method not in METHODS:
            raise FingerfitError(f"must be one of {', '.join(METHODS)}", field="--method")
        self.model, self.method, self.variant = model, method, variant
        self.setup = s = setup(model, robot, rmap)
        self.frames = [rmap.digits[d].tip for d in s.digits]
        self.notes = list(s.notes)
        self.held = self.missing = 0
        self.copy = AngleCopy(
            rmap,
            robot.joint_names,
            s.hold,
            s.limits,
            [(d, a) for d in s.digits for a in model.fingers[d].angle_names()],
        )
        # Digits of the pinch pairs, whose pads the tip method needs (none: no pinch term).
        self._padded: list[str] = []
        self.contact = np.zeros(0)
        self.solver: TipSolver | None = None
        if method == "tip":
            padded = {d for d in s.digits if model.fingers[d].pad is not None}
            if not padded and rmap.pinch:
                self.notes.append("the model has no pad points: pinch term off")
            # the pairs pinch_terms gives: both digits retargeted and with a pad point
            pairs = [(a, b) for a, b in rmap.pinch if a in padded and b in padded]
            self.contact = np.array([self._contact(model, a, b, contact_mm) for a, b in pairs])
            self._padded = [d for d in s.digits if d in padded and any(d in p for p in pairs)]
            pad_frames = [rmap.digits[d].pad for pair in pairs for d in pair]
            frames = self.frames + [f for f in dict.fromkeys(pad_frames) if f not in self.frames]
            pidx = [
                (frames.index(rmap.digits[a].pad), frames.index(rmap.digits[b].pad))
                for a, b in pairs
            ]
            problem = TipProblem(robot, s.robot_palm, frames, s.free, s.hold, s.limits)
            self.solver = TipSolver(problem, pidx, options)

    def _contact(self, model: HandModel, a: str, b: str, override: float | None) -> float:
        """The contact distance of pinch pair ``a``-``b`` (mm), announced in :attr:`notes`."""
        evidence = model.pinch_contact(a, b)
        if override is not None:
            mm, why = override, "--contact-mm"
        elif evidence is not None:
            mm = evidence.contact_mm[self.variant]
            why = f"the person's {evidence.events} pinch hold(s) in the model"
        else:
            mm, why = CONTACT_MM, "no pinch holds of the pair in the model: the default"
        self.notes.append(f"pinch {a}-{b}: the pads touch below {mm:.1f} mm ({why})")
        return float(mm)

    def kinematics(self, recording: Recording) -> Kinematics:
        """The person's kinematics :meth:`step` needs (the retargeted digits, one variant;
        frames with a missing sensor solved by the model, :mod:`fingerfit.track`)."""
        return track_recording(
            self.model, recording, variants=(self.variant,), fingers=self.setup.digits
        ).kinematics

    def step(
        self, recording: Recording, kin: Kinematics | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Robot joints for the next block of frames.

        Parameters
        ----------
        recording : Recording
            The block's frames (mm, tracker frame), hand sensor and retargeted digits.
        kin : Kinematics, optional
            Its :meth:`kinematics` (computed when not given).

        Returns
        -------
        q : ndarray, shape (n, nq)
            rad (m for slide joints), every robot joint, within limits and couplings.
        targets : ndarray, shape (n, k, 3)
            Scaled fingertip targets of ``setup.digits`` (robot palm frame, mm).
        seconds : ndarray, shape (n,)
            Per-frame solve time (``joint``: the block's time / n).
        """
        s, model, variant = self.setup, self.model, self.variant
        kin = kin or self.kinematics(recording)
        motions = kin.motions[variant]
        # The tips of every digit and the pads of the pinching ones, into the palm frame
        # at once.
        pts = [motions[d].tip for d in s.digits] + [motions[d].pad for d in self._padded]
        palm = in_palm(model, s.palm, recording, np.stack(pts, axis=1))
        k = len(s.digits)
        tgt = targets(s, palm[:, :k], s.digits)
        start = time.perf_counter()
        angles = np.empty((recording.n_frames, len(self.copy.keys)))
        for i, (d, a) in enumerate(self.copy.keys):
            angles[:, i] = motions[d].angles[a]
        q_joint, held = self.copy(angles)
        self.held += held
        if self.solver is None:
            q = q_joint
            seconds = np.full(len(q), (time.perf_counter() - start) / max(len(q), 1))
            return q, tgt, seconds
        self.missing += int(np.sum(~np.isfinite(tgt).all(axis=(1, 2))))
        vec = w = None
        if self._padded:
            pads = {d: palm[:, k + i] for i, d in enumerate(self._padded)}
            _, vec, w, _ = pinch_terms(s, pads, self.contact)
        res = self.solver.solve(tgt, None, vec, w, prior=q_joint)
        return res.q, tgt, res.seconds


def retarget(
    model: HandModel,
    recording: Recording,
    robot: Robot,
    rmap: RobotMap,
    method: str = "tip",
    variant: str = "user_axis",
    options: TipOptions | None = None,
    contact_mm: float | None = None,
    kin: Kinematics | None = None,
) -> Retargeting:
    """Retarget a recording of the person's hand onto a robot hand.

    Parameters
    ----------
    model : HandModel
    recording : Recording
        With the hand sensor and every sensor of the retargeted digits.
    robot, rmap : Robot, RobotMap
        From :func:`resolve`.
    method : {"tip", "joint"}
    variant : {"user_axis", "orthogonal"}
        The model variant whose kinematics drive the robot.
    options : TipOptions, optional
    contact_mm : float, optional
        See :class:`Retargeter`.
    kin : Kinematics, optional
        Precomputed :func:`fingerfit.kinematics.compute_kinematics` of ``recording``.

    Returns
    -------
    Retargeting
    """
    r = Retargeter(model, robot, rmap, method, variant, options, contact_mm)
    q, tgt, seconds = r.step(recording, kin)
    notes = list(r.notes)
    if r.held:
        notes.append(f"{r.held} frame(s) with a missing angle kept the previous value")
    if r.missing:
        notes.append(f"{r.missing} frame(s) with a missing sensor: those digits kept their pose")
    return Retargeting(
        time=np.asarray(recording.time, dtype=float),
        joint_names=robot.joint_names,
        q=q,
        method=method,
        digits=r.setup.digits,
        targets=tgt,
        tips=robot_points(r.setup, q, r.frames),
        seconds=seconds,
        violations=r.setup.limits.violations(q),
        notes=notes,
    )
