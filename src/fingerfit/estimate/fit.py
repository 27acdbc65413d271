"""Fit a session into an individual :class:`~fingerfit.model.HandModel`.

Per finger and joint (paper section 3):

1. relative poses of the child sensor in the parent sensor over every grasp
   recording; grasp cycles and their movement periods (:mod:`.cycles`);
2. a centre of rotation per cycle (:mod:`.centre`);
3. the axis through those centres (:mod:`.axis`), oriented so flexion is positive;
4. the joint centre where the axis meets the sagittal plane (:mod:`.sagittal`);
5. segment lengths, fingertip, local frames and the orthogonal-axis variant.

A joint whose motion cannot determine an axis (too few cycles, too little
range of motion, a degenerate system) is refused with a message naming it,
unless ``force`` is set, in which case the problem is recorded in the joint's
quality notes and warned about.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..model import FingerModel, HandModel, JointModel, JointQuality, SegmentFrame
from ..session import HAND_SENSOR, JOINTS, SEGMENTS, Session, joint_sensors
from ..transforms import FloatArray, relative_pose, rotation_vector, unit
from .axis import AxisFit, line_through_centres, orient_flexion
from .centre import CentreFit, centre_of_rotation
from .cycles import extract_cycles
from .sagittal import intersect, sagittal_plane


class FitError(FingerfitError):
    """The motion cannot determine a joint (named in the message)."""


@dataclass(frozen=True)
class FitOptions:
    """Options of :func:`fit_session`.

    Attributes
    ----------
    method : str
        Axis estimator (``tang2018``: the paper's line through per-cycle centres).
    min_cycles : int
        Fewer movement periods than this refuse the joint.
    min_rom_deg : float
        A median cycle range of motion below this refuses the joint (deg).
    max_null_disagreement_deg : float
        An axis further than this from the cycles' own rotation axis (SVD null
        vectors) refuses the joint (deg): the centres did not spread along it.
    force : bool
        Fit anyway, with warnings, instead of refusing.
    fingers : tuple of str, optional
        Fit only these fingers (default: all in the session).
    """

    method: str = "tang2018"
    min_cycles: int = 3
    min_rom_deg: float = 15.0
    max_null_disagreement_deg: float = 20.0
    force: bool = False
    fingers: tuple[str, ...] | None = None


@dataclass(frozen=True)
class JointData:
    """Everything an axis estimator may use for one joint (parent sensor frame, mm, rad).

    Attributes
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations over all grasp recordings (concatenated).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    periods : list of ndarray
        Frame indices (into the arrays above) of each cycle's movement period.
    rom : ndarray, shape (n_cycles,)
        Range of motion per cycle (rad).
    reference_rotation : ndarray, shape (3, 3)
    reference_offset : ndarray, shape (3,)
        Relative pose at the reference posture.
    """

    rotation: FloatArray
    translation: FloatArray
    periods: list[np.ndarray]
    rom: FloatArray
    reference_rotation: FloatArray
    reference_offset: FloatArray


@dataclass(frozen=True)
class AxisEstimate:
    """An estimator's result: the axis (parent frame) plus per-cycle diagnostics."""

    axis: AxisFit
    centres: list[CentreFit]


def tang2018(data: JointData) -> AxisEstimate:
    """The paper's estimator: untruncated O'Brien centre per cycle, line through them (eq. 1)."""
    centres = [centre_of_rotation(data.rotation[p], data.translation[p]) for p in data.periods]
    return AxisEstimate(line_through_centres(centres), centres)


METHODS: dict[str, Callable[[JointData], AxisEstimate]] = {"tang2018": tang2018}


def joint_data(session: Session, parent: str, child: str, reference: dict) -> JointData:
    """Relative poses and grasp cycles of one joint over all grasp recordings."""
    (pp, pr), (cp, cr) = reference[parent], reference[child]
    ref_rot = pr.T @ cr
    rots, trans, periods, roms = [], [], [], []
    offset = 0
    for rec in session.grasp:
        p, c = rec.pose(parent), rec.pose(child)
        r, t = relative_pose(p.rotation, p.position, c.rotation, c.position)
        cyc = extract_cycles(r, ref_rot, session.rate_hz)
        rots.append(r)
        trans.append(t)
        periods += [idx + offset for idx in cyc.periods]
        roms.append(cyc.rom)
        offset += rec.n_frames
    return JointData(
        np.concatenate(rots),
        np.concatenate(trans),
        periods,
        np.concatenate(roms),
        ref_rot,
        pr.T @ (cp - pp),
    )


def reference_poses(session: Session) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Mean pose ``(position (3,), rotation (3, 3))`` of every sensor in the reference recording."""
    out = {}
    for name, series in session.reference.poses.items():
        if series.valid.any():
            out[name] = series.mean()
    return out


def _refuse_or_warn(
    finger: str, joint: str, problems: list[str], options: FitOptions, hard: bool
) -> None:
    """Raise :class:`FitError` for the first problem unless ``force`` (and not ``hard``); else warn."""
    if problems and (hard or not options.force):
        hint = "" if hard else "; use --force to fit anyway"
        raise FitError(f"{finger} {joint}: {problems[0]}{hint}")
    for p in problems:
        warnings.warn(f"{finger} {joint}: {p} (fitted anyway)", stacklevel=3)


def _check(finger: str, joint: str, data: JointData, options: FitOptions) -> list[str]:
    """Problems with the motion that make a joint undeterminable; raises unless ``force``."""
    problems = []
    n = len(data.periods)
    if n < max(options.min_cycles, 2):
        problems.append(f"only {n} grasp cycle(s) found (need {options.min_cycles})")
    elif np.degrees(np.median(data.rom)) < options.min_rom_deg:
        problems.append(
            f"median range of motion {np.degrees(np.median(data.rom)):.1f} deg is below "
            f"{options.min_rom_deg:g} deg"
        )
    _refuse_or_warn(finger, joint, problems, options, hard=n < 2)
    return problems


def fit_finger(session: Session, finger: str, reference: dict, options: FitOptions) -> FingerModel:
    """Fit one finger (see module docstring); tracker coordinates at the reference posture."""
    estimator = METHODS[options.method]
    fitted: dict[
        str, tuple[str, str, FloatArray, FloatArray, AxisEstimate, JointData, list[str]]
    ] = {}
    for j, (parent, child) in joint_sensors(finger).items():
        data = joint_data(session, parent, child, reference)
        notes = _check(finger, j, data, options)
        est = estimator(data)
        if est.axis.null_agreement_deg > options.max_null_disagreement_deg:
            problem = (
                f"the per-cycle centres do not spread along one axis (fitted axis "
                f"{est.axis.null_agreement_deg:.0f} deg from the cycles' own rotation axis); "
                f"method '{options.method}' is unreliable for this motion"
            )
            _refuse_or_warn(finger, j, [problem], options, hard=False)
            notes = [*notes, problem]
        moving = np.concatenate(data.periods)
        rv = rotation_vector(data.rotation[moving] @ data.reference_rotation.T)
        a_parent = orient_flexion(est.axis.direction, rv)
        pp, pr = reference[parent]
        fitted[j] = (parent, child, pr @ est.axis.point + pp, pr @ a_parent, est, data, notes)

    landmarks = np.array([session.landmark(f"{finger}.{k}") for k in ("mp", "pip", "dip", "tip")])
    plane = sagittal_plane(landmarks, np.array([f[3] for f in fitted.values()]), finger)
    tip = session.landmark(f"{finger}.tip")
    centres = {j: intersect(plane, f[2], f[3], f"{finger} {j}") for j, f in fitted.items()}
    ends = [centres["mp"], centres["pip"], centres["dip"], tip]
    bones = [unit(ends[i + 1] - ends[i]) for i in range(3)]
    # Orthogonal axis of each joint: y of the local frame of the segment ending at it
    # (the metacarpal is not digitised; at the stretched posture it is taken
    # collinear with the proximal phalanx).
    bone_at = {"mp": bones[0], "pip": bones[0], "dip": bones[1]}
    joints: dict[str, JointModel] = {}
    for j, (parent, child, _, a, est, data, notes) in fitted.items():
        x = bone_at[j]
        y = unit(a - (a @ x) * x)
        quality = JointQuality(
            cycles=len(data.periods),
            rom_deg=[float(v) for v in np.degrees(data.rom)],
            centre_distance_mm=[float(v) for v in est.axis.distances],
            conditioning=[min(c.conditioning, 1e12) for c in est.centres],
            spread_mm=est.axis.spread_mm,
            residual_mm=[c.rms_mm for c in est.centres],
            null_agreement_deg=est.axis.null_agreement_deg,
            notes=notes
            + (["exact data: axis from the cycles' null vectors"] if est.axis.degenerate else []),
        )
        joints[j] = JointModel(j, parent, child, centres[j], a, y, quality)
    frames = {}
    axes_at_end = [joints["pip"].axis, joints["dip"].axis, joints["dip"].axis]
    for i, s in enumerate(SEGMENTS):
        x = bones[i]
        z = unit(np.cross(x, axes_at_end[i]))
        frames[s] = SegmentFrame(ends[i + 1], np.column_stack([x, np.cross(z, x), z]))
    lengths = {s: float(np.linalg.norm(ends[i + 1] - ends[i])) for i, s in enumerate(SEGMENTS)}
    return FingerModel(finger, joints, tip, lengths, frames)


def fit_session(session: Session, options: FitOptions | None = None) -> HandModel:
    """Fit every finger of a session.

    Parameters
    ----------
    session : Session
    options : FitOptions, optional

    Returns
    -------
    HandModel
        Joint centres, user and orthogonal axes, fingertip, segment lengths and
        frames in tracker coordinates at the reference posture (mm), with
        per-joint quality figures.

    Raises
    ------
    FitError
        When a joint cannot be determined and ``force`` is not set.
    """
    options = options or FitOptions()
    if options.method not in METHODS:
        raise FingerfitError(
            f"unknown method '{options.method}' (have: {', '.join(METHODS)})", field="method"
        )
    reference = reference_poses(session)
    fingers = list(options.fingers or session.fingers)
    for f in fingers:
        if f not in session.fingers:
            raise FingerfitError(f"session has no finger '{f}'", path=session.path, field="fingers")
    model_fingers = {f: fit_finger(session, f, reference, options) for f in fingers}
    used = {HAND_SENSOR} | {j.child for f in model_fingers.values() for j in f.joints.values()}
    return HandModel(
        subject=session.subject,
        hand=session.hand,
        session_units=session.units,
        method=options.method,
        reference_poses={k: v for k, v in reference.items() if k in used},
        fingers=model_fingers,
    )


__all__ = ["JOINTS", "METHODS", "FitError", "FitOptions", "JointData", "fit_session"]
