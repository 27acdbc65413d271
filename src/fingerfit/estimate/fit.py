"""Fit a session into an individual :class:`~fingerfit.model.HandModel`.

Per finger and joint (paper section 3):

1. relative poses of the child sensor in the parent sensor over every grasp
   recording; grasp cycles and their movement periods (:mod:`.cycles`);
2. the axis by the chosen estimator (``METHODS``, ``docs/methods.md``):

   * ``tang2018`` -- the paper: a centre of rotation per cycle (:mod:`.centre`)
     and the line through them (:mod:`.axis`);
   * ``pooled`` -- SARA axis and SCoRE centre over all movement frames (:mod:`.pooled`);
   * ``robust`` -- ``pooled`` after the outlier-frame and -cycle rules, with
     per-cycle weights (:mod:`.robust`);
   * ``twoaxis`` -- ``robust``, and a two-axis MP joint (flexion + ab/adduction,
     :mod:`.twoaxis`) where the data show the second axis;
   * ``rolling`` -- ``twoaxis`` plus rolling-contact migration of every centre
     (:mod:`.migration`);

   oriented so flexion is positive;
3. the joint centre where the axis meets the sagittal plane (:mod:`.sagittal`);
4. segment lengths, fingertip, local frames and the orthogonal-axis variant.

A joint whose motion cannot determine an axis (too few cycles, too little
range of motion, a degenerate system) is refused with a message naming it,
unless ``force`` is set, in which case the problem is recorded in the joint's
quality notes and warned about.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..digits import ABDUCTION_FIRST, DIGITS, FLEXION_FIRST
from ..errors import FingerfitError
from ..kinematics import twist_angle, two_axis_angles
from ..model import (
    ANGLE_METHODS,
    DigitModel,
    HandModel,
    JointModel,
    JointQuality,
    assemble_digit,
    estimated_pad,
)
from ..session import HAND_SENSOR, JOINTS, Session
from ..transforms import FloatArray, angle_between_axes, relative_pose, rotation_vector
from .axis import AxisFit, mean_null_axis, orient_flexion
from .centre import CentreFit, centre_of_rotation
from .choice import TWO_AXIS, ModelChoice, choose_joint_model
from .cycles import extract_cycles, period_labels
from .joint import estimate_hinge, estimate_two_axis
from .migration import fit_axis_points
from .pads import pinch_pads
from .plausibility import check_model, check_session, enforce
from .saddle import SaddleFit, fit_saddle
from .sagittal import intersect, sagittal_plane
from .twoaxis import TwoAxisFit

DEFAULT_METHOD = "twoaxis"


class FitError(FingerfitError):
    """The motion cannot determine a joint (named in the message)."""


class FitWarning(UserWarning):
    """A joint fitted despite a quality problem (``force``); stored in the model's warnings."""


@dataclass(frozen=True)
class FitOptions:
    """Options of :func:`fit_session`.

    Attributes
    ----------
    method : str
        Axis estimator, one of ``METHODS`` (``docs/methods.md``); the default is the
        most accurate one measured (``docs/accuracy.md``); ``tang2018`` is the
        paper's line through per-cycle centres.
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
    angle_method : {"projection", "swing_twist"}, optional
        How the model computes joint angles (recorded in the model file); default:
        the method's own (``projection`` for ``tang2018``, as in the paper;
        ``swing_twist`` for the others -- ``docs/methods.md`` has the measurement).
    min_conditioning : float
        Pooled methods: a pooled ``s5/s6`` below this -- rotation about the best
        axis less than this many times the rotation off it -- refuses the joint.
    """

    method: str = DEFAULT_METHOD
    min_cycles: int = 3
    min_rom_deg: float = 15.0
    max_null_disagreement_deg: float = 20.0
    force: bool = False
    fingers: tuple[str, ...] | None = None
    angle_method: str | None = None
    min_conditioning: float = 3.0


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
    joint : str
        The joint's name (``mp``, ``pip``, ``dip``; ``cmc``, ``mcp``, ``ip``).
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched digit in the parent frame (least-squares
        line through the dorsal landmarks, proximal to distal).
    second_axis : str, optional
        For a joint that may have a second (ab/adduction) axis, its order
        (``abduction_first`` or ``flexion_first``, :mod:`fingerfit.digits`); the
        ``twoaxis`` and ``rolling`` estimators then test for it.
    """

    rotation: FloatArray
    translation: FloatArray
    periods: list[np.ndarray]
    rom: FloatArray
    reference_rotation: FloatArray
    reference_offset: FloatArray
    joint: str = ""
    finger_direction: FloatArray | None = None
    second_axis: str | None = None

    def reversed(self) -> JointData:
        """The same joint seen from the child: parent-in-child poses (child frame, mm).

        A joint ``Q = Rot(a, theta) Rot(b, beta)`` with ``a`` proximal becomes
        ``Q' = Rot(b', -beta) Rot(a', -theta)`` with ``b' = R_ref^T b`` proximal, so an
        estimator of the ab/adduction-first form fits a flexion-first joint this way.
        """
        rot = np.swapaxes(self.rotation, 1, 2)
        ref = self.reference_rotation
        fd = None if self.finger_direction is None else ref.T @ self.finger_direction
        return replace(
            self,
            rotation=rot,
            translation=-np.einsum("nij,nj->ni", rot, self.translation),
            reference_rotation=ref.T,
            reference_offset=-ref.T @ self.reference_offset,
            finger_direction=fd,
        )


@dataclass(frozen=True)
class AxisEstimate:
    """An estimator's result (parent sensor frame, mm) plus diagnostics.

    Attributes
    ----------
    axis : AxisFit
        The flexion axis: ``point`` and ``direction``; ``distances`` of the
        per-cycle centres to it.
    centres : list of CentreFit
        Per-cycle O'Brien centres (of the cycles used).
    abduction : TwoAxisFit or SaddleFit, optional
        The second axis when a two-axis joint was fitted and accepted (parent frame).
    migration : ndarray, shape (3,), optional
        Centre migration (mm/rad, parent frame).
    pooled_conditioning : float, optional
        ``s5/s6`` of the pooled hinge system.
    rejected_frames : int
    rejected_cycles : list of int
    notes : list of str
        Facts worth keeping in the joint's quality notes.
    choice : ModelChoice, optional
        Hinge vs two axes by held-out prediction (joints that may have a second axis,
        ``twoaxis`` and ``rolling``).
    """

    axis: AxisFit
    centres: list[CentreFit]
    abduction: TwoAxisFit | SaddleFit | None = None
    migration: FloatArray | None = None
    pooled_conditioning: float | None = None
    rejected_frames: int = 0
    rejected_cycles: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    choice: ModelChoice | None = None


def tang2018(data: JointData) -> AxisEstimate:
    """The paper's estimator: untruncated O'Brien centre per cycle, line through them (eq. 1)."""
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "tang2018", data.periods)
    assert est.line is not None
    return AxisEstimate(est.line, est.centres)


def _cycle_centres(data: JointData, cycles: list[int]) -> list[CentreFit]:
    """Per-cycle O'Brien centres (quality figures: paper Fig. 8)."""
    return [
        centre_of_rotation(data.rotation[data.periods[i]], data.translation[data.periods[i]])
        for i in cycles
    ]


def _axis_fit(point: FloatArray, direction: FloatArray, centres: list[CentreFit]) -> AxisFit:
    """An :class:`AxisFit` for a line found by a pooled method, with per-cycle diagnostics."""
    c = np.array([f.parent_point for f in centres])
    distances = np.linalg.norm(np.cross(c - point, direction), axis=1)
    along = (c - c.mean(axis=0)) @ direction
    spread = float(np.sqrt(np.mean(along**2)))
    agreement = float(np.degrees(angle_between_axes(direction, mean_null_axis(centres))))
    return AxisFit(point, direction, distances, spread, False, agreement)


def _need_cycles(data: JointData) -> None:
    """Refuse (one line) a joint without movement cycles: the estimators pool their frames."""
    if not data.periods:
        raise FitError(
            f"{data.joint or 'joint'}: no movement cycles found, nothing to fit (for continuous "
            "motion or one swing use fingerfit.estimate.fit_joint or 'fingerfit joint')"
        )


def pooled(data: JointData) -> AxisEstimate:
    """SARA axis and axis-truncated SCoRE centre over all movement frames (:mod:`.pooled`)."""
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "sara", data.periods)
    centres = _cycle_centres(data, list(range(len(data.periods))))
    return AxisEstimate(
        _axis_fit(est.point, est.axis, centres),
        centres,
        pooled_conditioning=est.conditioning,
    )


def robust(data: JointData) -> AxisEstimate:
    """``pooled`` after the outlier-frame and -cycle rules, with cycle weights (:mod:`.robust`)."""
    return _robust_family(data, two_axis=False, migration=False)


def twoaxis(data: JointData) -> AxisEstimate:
    """``robust``, with a second axis at a finger's MP or the thumb's MCP where the data show
    one (:mod:`.twoaxis`)."""
    return _robust_family(data, two_axis=True, migration=False)


def rolling(data: JointData) -> AxisEstimate:
    """``twoaxis`` plus rolling-contact migration of every joint centre (:mod:`.migration`)."""
    return _robust_family(data, two_axis=True, migration=True)


def _robust_family(data: JointData, *, two_axis: bool, migration: bool) -> AxisEstimate:
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "robust", data.periods)
    rh = est.robust
    assert rh is not None
    k = est.frames
    centres = _cycle_centres(data, rh.kept_cycles)
    point, direction = est.point, est.axis
    notes = []
    if rh.rejected_cycles:
        notes.append(
            f"cycles {', '.join(str(i + 1) for i in rh.rejected_cycles)} rejected as "
            "inconsistent with the others (sensor slip?)"
        )
    if rh.rejected_frames:
        notes.append(f"{rh.rejected_frames} outlier frame(s) rejected")
    abduction = None
    choice = None
    name = data.joint.upper() or "joint"
    if two_axis and data.second_axis is not None:
        tf, choice = _second_axis(data)
        if choice.chosen == TWO_AXIS:
            abduction = tf
            point, direction = tf.flexion_point, tf.flexion_axis
            notes.append(
                f"two-axis {name}: ab/adduction spans {tf.abduction_range_deg:.1f} deg; rotation "
                f"off the model {np.degrees(tf.rms_hinge_rad):.2f} -> "
                f"{np.degrees(tf.rms_two_axis_rad):.2f} deg RMS"
            )
            notes.extend(tf.stability_notes())
        notes.append(f"{name}: {choice.note}")
    mig = None
    if migration and not (
        abduction is not None and choice is not None and choice.order == FLEXION_FIRST
    ):
        q = data.rotation[k] @ data.reference_rotation.T
        if abduction is not None:
            beta, theta = two_axis_angles(q, direction, abduction.abduction_axis)
            extra = {"abduction_axis": abduction.abduction_axis, "beta": beta}
        else:
            theta, extra = twist_angle(q, direction), {}
        pts = fit_axis_points(
            data.rotation[k],
            data.translation[k],
            data.reference_rotation,
            direction,
            theta,
            migration=True,
            weights=est.weights,
            noise_mm=est.noise_mm,
            groups=est.groups,
            **extra,
        )
        point, mig = pts.centre, pts.migration
        if abduction is not None:
            abduction = replace(abduction, flexion_point=point)
    return AxisEstimate(
        _axis_fit(point, direction, centres),
        centres,
        abduction=abduction,
        migration=mig,
        pooled_conditioning=est.conditioning,
        rejected_frames=rh.rejected_frames,
        rejected_cycles=rh.rejected_cycles,
        notes=notes,
        choice=choice,
    )


def _second_axis(data: JointData) -> tuple[TwoAxisFit, ModelChoice]:
    """The two-axis candidate of a joint that may have a second axis, and the choice.

    A candidate of each order is fitted to every movement frame of every cycle with
    uniform weights (the hinge's outlier rules and cycle weights would discard or
    down-weight exactly the cycles that carry the second degree of freedom), started from
    the SARA hinge axis, and the hinge and both are compared by
    :func:`.choice.choose_joint_model`.

    ``estimate_two_axis`` fits ``Q = Rot(b, beta) Rot(a, theta)`` with the ab/adduction
    axis ``b`` proximal; the flexion-first joint is that form seen from the child
    (:meth:`JointData.reversed`): fitted there and brought back to the parent frame.
    Returns the fit of the order :attr:`ModelChoice.order` names, parent frame.
    """
    fits = {}
    for order in (ABDUCTION_FIRST, FLEXION_FIRST):
        d = data.reversed() if order == FLEXION_FIRST else data
        start = estimate_hinge(d.rotation, d.translation, "sara", d.periods)
        fits[order] = estimate_two_axis(
            d.rotation,
            d.translation,
            d.reference_rotation,
            replace(start, groups=period_labels(d.periods)),
            d.finger_direction,
        )
    frames = np.concatenate(data.periods)
    choice = choose_joint_model(
        data.rotation[frames],
        data.translation[frames],
        data.reference_rotation,
        data.reference_offset,
        period_labels(data.periods),
        fits,
        data.second_axis or ABDUCTION_FIRST,
    )
    tf = fits[choice.order]
    if choice.order == ABDUCTION_FIRST:
        return tf, choice
    ref, off = data.reference_rotation, data.reference_offset
    back = replace(
        tf,
        flexion_axis=ref @ tf.flexion_axis,
        abduction_axis=ref @ tf.abduction_axis,
        flexion_point=ref @ tf.flexion_point + off,
        abduction_point=ref @ tf.abduction_point + off,
    )
    return back, choice


METHODS: dict[str, Callable[[JointData], AxisEstimate]] = {
    "tang2018": tang2018,
    "pooled": pooled,
    "robust": robust,
    "twoaxis": twoaxis,
    "rolling": rolling,
}
# One sentence per method and angle method, for reports.
METHOD_SUMMARY = {
    "tang2018": "the paper's estimator: a centre of rotation per grasp cycle (O'Brien et al. "
    "2000, untruncated least squares) and the line through those centres (Tang et al. 2018, "
    "eq. 1)",
    "pooled": "the SARA hinge axis over all movement frames (Ehrig et al. 2007)",
    "robust": "the SARA hinge axis after rejecting outlier frames and cycles, cycles weighted "
    "by their residual",
    "twoaxis": "robust SARA hinge axes, with a second (ab/adduction) axis at a finger's MP "
    "and the thumb's MCP where it predicts held-out grasp cycles better than one axis (the "
    "two axes' order, ab/adduction or flexion proximal, chosen by the held-out cycles' "
    "orientations)",
    "rolling": "twoaxis, with rolling-contact migration of each joint centre",
}
ANGLE_SUMMARY = {
    "projection": "projection of the child sensor's position on the plane normal to each "
    "axis (paper Fig. 6)",
    "swing_twist": "the twist of the child sensor's relative orientation about each axis "
    "(swing-twist decomposition; a two-axis joint: its proximal axis, then its distal one -- "
    "a finger's MP ab/adduction then flexion, the thumb's CMC and MCP flexion then "
    "ab/adduction)",
}
# Angle method each estimator's models use unless FitOptions.angle_method says otherwise.
METHOD_ANGLES = {"tang2018": "projection"} | {m: "swing_twist" for m in METHODS if m != "tang2018"}


def joint_data(
    session: Session, parent: str, child: str, reference: dict, joint: str = ""
) -> JointData:
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
        joint,
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
        warnings.warn(f"{finger} {joint}: {p} (fitted anyway)", FitWarning, stacklevel=3)


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


def _conditioning_problem(est: AxisEstimate, options: FitOptions) -> list[str]:
    """A refusal message when the pooled system does not single out one axis."""
    c = est.pooled_conditioning
    if c is None or c >= options.min_conditioning:
        return []
    return [
        f"the motion does not determine a hinge axis: rotation about the best axis is only "
        f"{c:.1f} times the rotation off it (s5/s6 below {options.min_conditioning:g})"
    ]


def _quality(data: JointData, est: AxisEstimate, notes: list[str]) -> JointQuality:
    """Quality figures of one joint."""
    extra = ["exact data: axis from the cycles' null vectors"] if est.axis.degenerate else []
    pc = est.pooled_conditioning
    return JointQuality(
        cycles=len(data.periods),
        rom_deg=[float(v) for v in np.degrees(data.rom)],
        centre_distance_mm=[float(v) for v in est.axis.distances],
        conditioning=[min(c.conditioning, 1e12) for c in est.centres],
        spread_mm=est.axis.spread_mm,
        residual_mm=[c.rms_mm for c in est.centres],
        null_agreement_deg=est.axis.null_agreement_deg,
        notes=notes + est.notes + extra,
        pooled_conditioning=None if pc is None else min(pc, 1e12),
        rejected_frames=est.rejected_frames,
        rejected_cycles=list(est.rejected_cycles),
        model_choice=None if est.choice is None else est.choice.summary(),
    )


def _saddle(
    data: JointData, flexion_guess: FloatArray | None, abduction_guess: FloatArray | None
) -> AxisEstimate:
    """A joint that always has two axes (the thumb's CMC): :func:`.saddle.fit_saddle` over
    every calibration frame, grouped by recording cycles where there are any; the guesses
    (parent frame) sign the axes and name the one a recording did not excite."""
    groups = None
    if len(data.periods) >= 2:
        groups = np.full(data.rotation.shape[0], -1)
        for i, idx in enumerate(data.periods):
            groups[idx] = i
        if (groups < 0).any():  # frames outside the cycles form blocks of their own
            rest = np.flatnonzero(groups < 0)
            groups[rest] = len(data.periods) + rest * 4 // data.rotation.shape[0]
    sf = fit_saddle(
        data.rotation,
        data.translation,
        data.reference_rotation,
        order=data.second_axis or FLEXION_FIRST,
        flexion_guess=flexion_guess,
        abduction_guess=abduction_guess,
        groups=groups,
    )
    direction = sf.flexion_axis
    axis = AxisFit(sf.flexion_point, direction, np.zeros(0), 0.0, False, 0.0)
    notes = [
        f"two-axis {data.joint.upper()}: flexion spans {sf.flexion_range_deg:.1f} deg, "
        f"ab/adduction {sf.abduction_range_deg:.1f} deg; axes {sf.axis_angle_deg:.1f} deg "
        f"apart, {sf.offset_mm:.1f} mm between them; rotation off the model "
        f"{sf.rms_rotation_deg:.2f} deg RMS, position {sf.rms_position_mm:.2f} mm RMS"
    ]
    return AxisEstimate(axis, [], abduction=sf, notes=notes)


def fit_finger(session: Session, finger: str, reference: dict, options: FitOptions) -> DigitModel:
    """Fit one digit (see module docstring); tracker coordinates at the reference posture.

    Every calibration (``grasp``) recording is used; a joint the recordings do not move
    is refused (or, with ``force``, fitted with a warning). A joint that always has two
    axes (the thumb's CMC) is fitted as a saddle joint (:mod:`.saddle`); a joint that may
    have one (a finger's MP, the thumb's MCP) by the ``twoaxis``/``rolling`` test.
    """
    digit = DIGITS[finger]
    estimator = METHODS[options.method]
    fitted: dict[str, tuple[str, str, FloatArray, FloatArray, AxisEstimate, JointData, list[str]]]
    fitted = {}
    landmarks = np.array([session.landmark(f"{finger}.{k}") for k in digit.landmarks])
    _, _, vt = np.linalg.svd(landmarks - landmarks.mean(axis=0))
    along = vt[0] if vt[0] @ (landmarks[-1] - landmarks[0]) > 0 else -vt[0]
    # Joints that always have two axes last: the next joint's flexion axis guides them.
    for j, (parent, child) in sorted(
        digit.joint_sensors().items(), key=lambda item: item[0] in digit.required_second
    ):
        data = joint_data(session, parent, child, reference, j)
        order = digit.order.get(j) if j in digit.second_axes else None
        data = replace(data, finger_direction=reference[parent][1].T @ along, second_axis=order)
        if j in digit.required_second:
            # Guesses: the next joint's flexion axis, and the digit direction x that axis
            # (the sense positive ab/adduction turns about, below), in the parent frame.
            nxt = fitted[digit.joints[digit.joints.index(j) + 1]][3]
            side = 1.0 if session.hand == "right" else -1.0
            guesses = np.stack([nxt, side * np.cross(along, nxt)]) @ reference[parent][1]
            try:
                est, notes = _saddle(data, guesses[0], guesses[1]), []
            except FingerfitError as exc:
                raise FitError(f"{finger} {j}: {exc.reason}") from None
        else:
            notes = _check(finger, j, data, options)
            est = estimator(data)
        problems = _conditioning_problem(est, options)
        if est.axis.null_agreement_deg > options.max_null_disagreement_deg:
            problems.append(
                f"the per-cycle centres do not spread along one axis (fitted axis "
                f"{est.axis.null_agreement_deg:.0f} deg from the cycles' own rotation axis); "
                f"method '{options.method}' is unreliable for this motion"
            )
        if problems:
            _refuse_or_warn(finger, j, problems, options, hard=False)
            notes = [*notes, *problems]
        pp, pr = reference[parent]
        if j in digit.required_second:
            a_parent = est.axis.direction  # signed by the guess: the next joint's flexion
        else:
            moving = np.concatenate(data.periods)
            rv = rotation_vector(data.rotation[moving] @ data.reference_rotation.T)
            a_parent = orient_flexion(est.axis.direction, rv)
        fitted[j] = (parent, child, pr @ est.axis.point + pp, pr @ a_parent, est, data, notes)
    fitted = {j: fitted[j] for j in digit.joints}  # proximal to distal again

    plane = sagittal_plane(landmarks, np.array([f[3] for f in fitted.values()]), finger)
    tip = session.landmark(f"{finger}.tip")
    joints = {}
    migration = {}
    for j, (parent, child, point, a, est, data, notes) in fitted.items():
        centre = intersect(plane, point, a, f"{finger} {j}")
        joints[j] = (parent, child, centre, a, _quality(data, est, notes))
        if est.migration is not None:
            # The migration is per radian of the angle about the estimator's axis sense.
            sense = np.sign(a @ (reference[parent][1] @ est.axis.direction))
            migration[j] = sense * (reference[parent][1] @ est.migration)
    second_axes = {}
    axis_order = {}
    for j, (parent, child, _, a, est, _, _) in fitted.items():
        if est.abduction is None:
            continue
        if est.choice is not None and est.choice.order != digit.order[j]:
            axis_order[j] = est.choice.order
        pp, pr = reference[parent]
        b = pr @ est.abduction.abduction_axis
        # Positive ab/adduction turns the digit towards the side its flexion axis points
        # to (docs/conventions.md): b . (x x a) > 0 for a right hand and < 0 for a left
        # one, x the digit direction. For a finger that is radial deviation.
        side = 1.0 if session.hand == "right" else -1.0
        if side * (b @ np.cross(plane.direction, a)) < 0:
            b = -b
        second_axes[j] = JointModel(
            f"{j}_abduction", parent, child, pr @ est.abduction.abduction_point + pp, b, b,
            joints[j][4],
        )  # fmt: skip
    model = replace(
        assemble_digit(finger, joints, tip, second_axes, migration), axis_order=axis_order
    )
    pad, source = session.landmarks.get(f"{finger}.pad"), "landmark"
    if pad is None:
        last = digit.joints[-1]
        depth = float(np.linalg.norm(session.landmark(f"{finger}.{last}") - joints[last][2]))
        pad, source = estimated_pad(model, 2.0 * depth), "geometry"
    return replace(model, pad=pad, pad_source=source)


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
    PlausibilityError
        When the data or the fitted model are physically implausible (wrong units, wrong
        quaternion convention; ``docs/plausibility.md``) and ``force`` is not set. With
        ``force`` every such problem, and every joint fitted despite a quality problem,
        is warned about and stored in :attr:`HandModel.warnings`.
    """
    options = options or FitOptions()
    if options.method not in METHODS:
        raise FingerfitError(
            f"unknown method '{options.method}' (have: {', '.join(METHODS)})", field="method"
        )
    if options.angle_method is not None and options.angle_method not in ANGLE_METHODS:
        raise FingerfitError(
            f"unknown angle method '{options.angle_method}' (have: {', '.join(ANGLE_METHODS)})",
            field="angle_method",
        )
    reference = reference_poses(session)
    fingers = list(options.fingers or session.fingers)
    for f in fingers:
        if f not in session.fingers:
            raise FingerfitError(f"session has no finger '{f}'", path=session.path, field="fingers")
    # Physical plausibility first (units, landmarks, quaternion convention): a wrong unit
    # or quaternion order fits without complaint (fingerfit.estimate.plausibility).
    forced = enforce(check_session(session, fingers, reference), options.force)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model_fingers = {f: fit_finger(session, f, reference, options) for f in fingers}
    for w in caught:
        warnings.warn(w.message, stacklevel=2)
        if issubclass(w.category, FitWarning):
            forced.append(str(w.message))
    used = {HAND_SENSOR} | {j.child for f in model_fingers.values() for j in f.joints.values()}
    model = HandModel(
        subject=session.subject,
        hand=session.hand,
        session_units=session.units,
        method=options.method,
        reference_poses={k: v for k, v in reference.items() if k in used},
        fingers=model_fingers,
        angle_method=options.angle_method or METHOD_ANGLES[options.method],
    )
    model = pinch_pads(session, model)
    forced += enforce(check_model(model, session), options.force)
    return replace(model, warnings=tuple(forced))


__all__ = [
    "DEFAULT_METHOD",
    "JOINTS",
    "METHODS",
    "METHOD_ANGLES",
    "AxisEstimate",
    "FitError",
    "FitOptions",
    "FitWarning",
    "JointData",
    "fit_session",
]
