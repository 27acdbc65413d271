"""Fit a session into an individual :class:`~fingerfit.model.HandModel`.

Per finger and joint (paper section 3):

1. relative poses of the child sensor in the parent sensor over every grasp
   recording; grasp cycles and their movement periods (:mod:`.cycles`);
2. the axis by the chosen estimator (``METHODS`` of :mod:`.methods`, ``docs/methods.md``),
   oriented so flexion is positive;
3. the joint centre where the axis meets the sagittal plane (:mod:`.sagittal`);
4. segment lengths, fingertip, local frames and the orthogonal-axis variant;
5. the pads of digits that pinch, fitted to the pinch holds (:mod:`.pads`).

A joint whose motion cannot determine an axis (too few cycles, a joint that barely
moved, rotation about no single axis where one axis is fitted) is refused with a message
naming it, unless ``force`` is set, in which case the problem is recorded in the joint's
quality notes and warned about. Weak evidence from real motion (a range of motion below
what a calibration should reach, an axis known to only several degrees) is fitted, warned
about and noted with the axis's confidence, not refused: a refusal stops the whole hand.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from ..digits import DIGITS, FLEXION_FIRST
from ..errors import FingerfitError
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
from ..track.statistics import tracking_statistics
from ..transforms import FloatArray, relative_pose, rotation_vector
from .axis import AxisFit, orient_flexion
from .bootstrap import Z95, cycle_axis_ci_deg
from .choice import ModelChoice
from .cycles import extract_cycles
from .methods import (
    ANGLE_SUMMARY,
    DEFAULT_METHOD,
    METHOD_ANGLES,
    METHOD_SUMMARY,
    METHODS,
    AxisEstimate,
    FitError,
    JointData,
)
from .pads import pinch_pads
from .plausibility import check_model, check_session, enforce
from .saddle import SaddleFit, fit_saddle
from .sagittal import joint_centre, sagittal_plane
from .twoaxis import TwoAxisFit


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
        The median cycle range of motion a calibration should reach (deg; ``fingerfit
        capture`` asks for it). Below it the joint is fitted with a warning and a quality
        note giving its axis confidence (weak evidence, real motion).
    rom_floor_deg : float
        A median cycle range of motion below this refuses the joint (deg): it barely
        moved. On simulated index fingers of 3-4 deg the MP's fitted axis was 4-60 deg
        off (``bench/rom_floor.py``; ``docs/methods.md``, *Quality gates*).
    max_null_disagreement_deg : float
        A one-axis joint whose axis is further than this from the cycles' own rotation axis
        (SVD null vectors) is refused (deg): the centres did not spread along it.
    force : bool
        Fit anyway, with warnings, instead of refusing.
    fingers : tuple of str, optional
        Fit only these fingers (default: all in the session).
    angle_method : {"projection", "swing_twist"}, optional
        How the model computes joint angles (recorded in the model file); default:
        the method's own (``projection`` for ``tang2018``, as in the paper;
        ``swing_twist`` for the others -- ``docs/methods.md`` has the measurement).
    min_conditioning : float
        Pooled methods: a joint fitted with one axis whose pooled ``s5/s6`` is below this
        -- rotation about the best axis less than this many times the rotation off it --
        is refused. A joint that may have a second axis is judged after the model choice
        (``twoaxis``, ``rolling``): when two axes are chosen, this one-axis figure does not
        apply.
    max_axis_ci_deg : float
        A flexion axis whose 95 % confidence half-angle over the grasp cycles
        (:func:`axis_ci_deg`) exceeds this gets a warning and a quality note (deg; the
        joint is still fitted): its direction is known less well than people's axes
        differ (9 deg: the mean deviation of 24 subjects' thumb CMC flexion axes from
        their mean in vivo, Chang & Pollard 2008; ``docs/capture.md``). ``fingerfit
        capture`` asks for more cycles until the figure is below it.
    """

    method: str = DEFAULT_METHOD
    min_cycles: int = 3
    min_rom_deg: float = 15.0
    rom_floor_deg: float = 5.0
    max_null_disagreement_deg: float = 20.0
    force: bool = False
    fingers: tuple[str, ...] | None = None
    angle_method: str | None = None
    min_conditioning: float = 3.0
    max_axis_ci_deg: float = 9.0


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


def digit_direction(session: Session, finger: str) -> FloatArray:
    """Unit direction ``(3,)`` of the stretched digit, tracker frame at the reference
    posture: the least-squares line through its dorsal landmarks, proximal to distal."""
    landmarks = np.array([session.landmark(f"{finger}.{k}") for k in DIGITS[finger].landmarks])
    _, _, vt = np.linalg.svd(landmarks - landmarks.mean(axis=0))
    return vt[0] if vt[0] @ (landmarks[-1] - landmarks[0]) > 0 else -vt[0]


def digit_data(
    session: Session, finger: str, reference: dict, along: FloatArray | None
) -> dict[str, JointData]:
    """Every joint's :class:`JointData` of one digit as the estimators get it.

    Parameters
    ----------
    session : Session
    finger : str
    reference : dict
        :func:`reference_poses`.
    along : ndarray, shape (3,), optional
        :func:`digit_direction` (tracker frame); ``finger_direction`` stays None without it.
    """
    digit = DIGITS[finger]
    out = {}
    for j, (parent, child) in digit.joint_sensors().items():
        data = joint_data(session, parent, child, reference, j)
        fd = None if along is None else reference[parent][1].T @ along
        order = digit.order.get(j) if j in digit.second_axes else None
        out[j] = replace(data, finger_direction=fd, second_axis=order)
    return out


def axis_ci_deg(
    data: JointData,
    abduction: TwoAxisFit | SaddleFit | None = None,
    choice: ModelChoice | None = None,
) -> float:
    """95 % confidence half-angle (deg) of a joint's flexion axis from its cycles: the
    figure ``FitOptions.max_axis_ci_deg`` bounds, in ``fingerfit fit`` and ``capture``.

    ``Z95`` times a delete-one jackknife SD (:func:`.bootstrap.jackknife_sd`): of the
    saddle fit's flexion axis over its clusters (the thumb's CMC, ``abduction`` a
    :class:`SaddleFit`); of the held-out choice's axis refitted without each cycle (a joint
    that may have a second axis, ``choice``: :attr:`.choice.ModelChoice.axis_ci_deg`);
    otherwise of the SARA axis refitted without each cycle
    (:func:`.bootstrap.cycle_axis_ci_deg`). NaN with fewer than two cycles.
    """
    if isinstance(abduction, SaddleFit):
        return float(Z95 * abduction.flexion_sd_deg)
    if choice is not None:
        return choice.axis_ci_deg
    return cycle_axis_ci_deg(data.rotation, data.periods)


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


def _shown_below(value: float, bound: float) -> str:
    """``value`` printed with as many decimals (1 to 6) as it takes to read below
    ``bound`` (14.96 against 15 is "14.96", not "15.0")."""
    for decimals in range(1, 7):
        text = f"{value:.{decimals}f}"
        if float(text) < bound:
            break
    return text


def _check(finger: str, joint: str, data: JointData, options: FitOptions) -> tuple[list, list]:
    """``(problems, weak)`` of the motion before the fit: problems make the joint
    undeterminable (raises unless ``force``); ``weak`` is evidence to fit and warn about."""
    problems, weak = [], []
    n = len(data.periods)
    rom = float(np.degrees(np.median(data.rom))) if n else 0.0
    if n < max(options.min_cycles, 2):
        problems.append(f"only {n} grasp cycle(s) found (need {options.min_cycles})")
    elif rom < options.rom_floor_deg:
        problems.append(
            f"the joint barely moved: median range of motion "
            f"{_shown_below(rom, options.rom_floor_deg)} deg is below {options.rom_floor_deg:g} deg"
        )
    elif rom < options.min_rom_deg:
        weak.append(
            f"median range of motion {_shown_below(rom, options.min_rom_deg)} deg is below the "
            f"{options.min_rom_deg:g} deg a calibration should reach"
        )
    _refuse_or_warn(finger, joint, problems, options, hard=n < 2)
    return problems, weak


def _one_axis_problems(
    data: JointData, est: AxisEstimate, options: FitOptions
) -> tuple[list[str], list[str]]:
    """``(problems, weak)`` of the one-axis gates after the fit: the pooled system does not
    single out one axis, or the per-cycle centres do not spread along it.

    A joint fitted with two axes is not judged by them as one: the rotation off its flexion
    axis is its second axis (the thumb's CMC; a joint the model choice gave two). Its
    flexion axis far from the cycles' own rotation axis is weak evidence, fitted and warned
    about, not refused.
    """
    if isinstance(est.abduction, SaddleFit):
        return [], []
    far = est.axis.null_agreement_deg > options.max_null_disagreement_deg
    if est.abduction is not None:
        weak = [
            f"the two-axis fit's flexion axis is {est.axis.null_agreement_deg:.0f} deg from the "
            "cycles' own rotation axis (SVD null vectors)"
        ]
        return [], weak if far else []
    problems = []
    c = est.pooled_conditioning
    if c is not None and c < options.min_conditioning:
        hint = ""
        if est.choice is None and data.second_axis is not None:
            hint = "; the joint may have a second axis: method 'twoaxis' tests for it"
        problems.append(
            f"the motion does not determine a hinge axis: rotation about the best axis is only "
            f"{_shown_below(c, options.min_conditioning)} times the rotation off it (s5/s6 "
            f"below {options.min_conditioning:g}){hint}"
        )
    if far:
        problems.append(
            f"the per-cycle centres do not spread along one axis (fitted axis "
            f"{est.axis.null_agreement_deg:.0f} deg from the cycles' own rotation axis); "
            f"method '{options.method}' is unreliable for this motion"
        )
    return problems, []


def _quality(data: JointData, est: AxisEstimate, notes: list[str], ci: float) -> JointQuality:
    """Quality figures of one joint (``ci``: :func:`axis_ci_deg`, NaN when not known)."""
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
        axis_ci_deg=float(ci) if np.isfinite(ci) else None,
    )


def saddle_estimate(
    data: JointData, flexion_guess: FloatArray | None, abduction_guess: FloatArray | None
) -> AxisEstimate:
    """A joint that always has two axes (the thumb's CMC): :func:`.saddle.fit_saddle` over
    every calibration frame with both sensors' samples, grouped by recording cycles where
    there are any; the guesses (parent frame) sign the axes and name the one a recording
    did not excite. The axes are named by the digit's axis order, which anatomy gives and
    the data place, also where they lie nearer each other's guesses
    (``SaddleFit.guesses_swapped_deg``): the guesses come from the next joint and can be
    far off (tens of degrees on simulated thumbs with three times the usual obliquities,
    whose axes the order named right)."""
    groups = None
    if len(data.periods) >= 2:
        groups = np.full(data.rotation.shape[0], -1)
        for i, idx in enumerate(data.periods):
            groups[idx] = i
        if (groups < 0).any():  # frames outside the cycles form blocks of their own
            rest = np.flatnonzero(groups < 0)
            groups[rest] = len(data.periods) + rest * 4 // data.rotation.shape[0]
    ok = np.isfinite(data.rotation).all(axis=(1, 2)) & np.isfinite(data.translation).all(axis=1)
    if not ok.all():  # a frame missing a sensor's sample (a dropout) tells nothing
        groups = None if groups is None else groups[ok]
    sf = fit_saddle(
        data.rotation if ok.all() else data.rotation[ok],
        data.translation if ok.all() else data.translation[ok],
        data.reference_rotation,
        order=data.second_axis or FLEXION_FIRST,
        flexion_guess=flexion_guess,
        abduction_guess=abduction_guess,
        groups=groups,
        strict_order=False,
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
    # joint -> parent, child, axis point, axis (tracker), estimate, data, notes, axis CI deg
    fitted: dict[
        str, tuple[str, str, FloatArray, FloatArray, AxisEstimate, JointData, list[str], float]
    ] = {}
    landmarks = np.array([session.landmark(f"{finger}.{k}") for k in digit.landmarks])
    along = digit_direction(session, finger)
    joints_data = digit_data(session, finger, reference, along)
    # Joints that always have two axes last: the next joint's flexion axis guides them.
    for j, (parent, child) in sorted(
        digit.joint_sensors().items(), key=lambda item: item[0] in digit.required_second
    ):
        data = joints_data[j]
        if j in digit.required_second:
            # Guesses: the next joint's flexion axis, and the digit direction x that axis
            # (the sense positive ab/adduction turns about, below), in the parent frame.
            nxt = fitted[digit.joints[digit.joints.index(j) + 1]][3]
            side = 1.0 if session.hand == "right" else -1.0
            guesses = np.stack([nxt, side * np.cross(along, nxt)]) @ reference[parent][1]
            try:
                est, notes, weak = saddle_estimate(data, guesses[0], guesses[1]), [], []
            except FingerfitError as exc:
                raise FitError(f"{finger} {j}: {exc.reason}") from None
            swapped = (
                est.abduction.guesses_swapped_deg if isinstance(est.abduction, SaddleFit) else None
            )
            if swapped is not None:
                weak = [
                    f"the fitted axes lie nearer each other's guesses ({swapped[0]:.0f} vs "
                    f"{swapped[1]:.0f} deg as named), the guesses being the next joint's "
                    "flexion axis and its perpendicular: named by the axis order, flexion "
                    "proximal, which the data place"
                ]
        else:
            notes, weak = _check(finger, j, data, options)
            est = estimator(data)
        problems, weak_fit = _one_axis_problems(data, est, options)
        ci = axis_ci_deg(data, est.abduction, est.choice)
        for w in [*weak, *weak_fit]:
            # Fitted, not refused: the motion is real, the axis's confidence says how well
            # it is known.
            known = f"+/-{ci:.1f} deg (95 %)" if np.isfinite(ci) else "not known (one cycle)"
            w = f"weak evidence: {w}; fitted, the flexion axis is known to {known}"
            warnings.warn(f"{finger} {j}: {w}", FitWarning, stacklevel=2)
            notes = [*notes, w]
        if ci > options.max_axis_ci_deg:
            # A warning, not a refusal: cycles of different recordings (grasp, opposition)
            # need not agree, and a good session can exceed the bound (docs/capture.md).
            uncertain = (
                f"the flexion axis is known only to +/-{ci:.1f} deg (95 %, from the spread "
                f"over the cycles; capture asks for <= {options.max_axis_ci_deg:g} deg): "
                "more cycles would pin it down"
            )
            warnings.warn(f"{finger} {j}: {uncertain}", FitWarning, stacklevel=2)
            notes = [*notes, uncertain]
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
        fitted[j] = (parent, child, pr @ est.axis.point + pp, pr @ a_parent, est, data, notes, ci)
    fitted = {j: fitted[j] for j in digit.joints}  # proximal to distal again

    plane = sagittal_plane(landmarks, np.array([f[3] for f in fitted.values()]), finger)
    tip = session.landmark(f"{finger}.tip")
    joints = {}
    migration = {}
    for j, (parent, child, point, a, est, data, notes, ci) in fitted.items():
        centre, off_plane = joint_centre(plane, point, a, session.landmark(f"{finger}.{j}"))
        if off_plane is not None:
            notes = [*notes, off_plane]
        joints[j] = (parent, child, centre, a, _quality(data, est, notes, ci))
        if est.migration is not None:
            # The migration is per radian of the angle about the estimator's axis sense.
            sense = np.sign(a @ (reference[parent][1] @ est.axis.direction))
            migration[j] = sense * (reference[parent][1] @ est.migration)
    second_axes = {}
    axis_order = {}
    for j, (parent, child, _, a, est, *_) in fitted.items():
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
    tip_sd = session.landmark_sd.get(f"{finger}.tip")
    return replace(model, pad=pad, pad_source=source, tip_sd_mm=tip_sd)


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
    # What tracking with fewer sensors needs: each sensor's spread about the model and
    # each angle's range and speed, on the calibration recordings (fingerfit.track).
    model = replace(model, tracking=tracking_statistics(model, session.grasp))
    forced += enforce(check_model(model, session), options.force)
    return replace(model, warnings=tuple(forced))


__all__ = [
    "ANGLE_SUMMARY",
    "DEFAULT_METHOD",
    "JOINTS",
    "METHODS",
    "METHOD_ANGLES",
    "METHOD_SUMMARY",
    "AxisEstimate",
    "FitError",
    "FitOptions",
    "FitWarning",
    "JointData",
    "fit_session",
]
