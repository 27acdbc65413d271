"""A marker session fitted into the individual hand model, digit by digit.

Each digit's chain (:func:`.chain.chain_layout`) is started and adjusted by :mod:`.start`
and :mod:`.bundle` on the reference and calibration (grasp) recordings. The thumb's CMC
always has two axes; a finger's MP and the thumb's MCP get a second (ab/adduction) axis
when the markers call for it (``mp_axes="auto"``, :func:`fit_digit`; else a hinge, said
in one line; the note of a second axis also says how it predicts held-out markers),
proximal or distal to the flexion axis as the lower cost decides. A line whose direction or point
the markers leave undetermined (the noise's standard deviation above
:data:`UNDETERMINED_SD_DEG` / :data:`UNDETERMINED_SD_MM`, or no information at all) is
held at its start and said in one line naming the joint; the lines' uncertainty holds
the skin's slide (:mod:`.uncertainty`). The result is the usual
:class:`~fingerfit.model.HandModel` (``method`` ``markers``) plus each marker's place
(:attr:`HandModel.markers`).
"""

from __future__ import annotations

import math
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace

import numpy as np

from ...digits import ABDUCTION_FIRST, DIGITS, FLEXION_FIRST, HAND_SENSOR, second_axis
from ...errors import FingerfitError
from ...io.rigid import technical_frame
from ...model import HandModel, JointModel, JointQuality, assemble_digit
from ...session import Session, joint_sensors, sensor_name
from ...track.solver import wrap
from ...transforms import FloatArray, unit
from .bundle import NEAR, BundleResult, adjust, line_covariance
from .chain import ChainLayout, Lines, chain_layout
from .heldout import HeldOutComparison, compare_held_out
from .observe import DigitMarkers, carry_back, digit_markers, hand_shape
from .start import flexion_sign, staged_start
from .uncertainty import slide_uncertainty

#: The choices of a finger's MP (the thumb's MCP) axes (:func:`fit_marker_session`).
MP_AXES = ("auto", "hinge", "two")
#: A finger's MP (the thumb's MCP) keeps its second axis when it lowers the cost by more
#: than this many standard deviations of what its unknowns absorb of the noise
#: (:func:`fit_digit`).
SECOND_AXIS_Z = 5.0
#: A line's direction with a larger SD (deg), or its point with a larger SD (mm), is not
#: determined by the markers.
UNDETERMINED_SD_DEG = 20.0
UNDETERMINED_SD_MM = 20.0
#: The adjustments after the staged start stop after this many iterations, or when an
#: iteration lowers the cost by less than this fraction of it (``1e-10`` of a cost of
#: ``1e4`` mm^2 is ``1e-6`` mm^2: nothing the figures show), or when they are near the
#: minimum (:data:`.bundle.NEAR`).
MAX_ITER = 60
TOL = 1e-10
#: No joint of a digit turns through half a turn: a two-axis MP minimum whose axes' angles
#: span more (5th to 95th percentile, deg) has two nearly parallel axes turning against
#: each other to soak up the skin's slide, and is left out (:func:`fit_digit`).
HALF_TURN_DEG = 180.0
#: Chi-square 95 % quantile with two degrees of freedom: an axis direction's (or a
#: line point's) 95 % region is ``x^T C^-1 x <= CHI2_95``.
CHI2_95 = 5.991


@dataclass
class DigitFit:
    """One digit's marker fit.

    Attributes
    ----------
    digit : str
    layout : ChainLayout
    data : DigitMarkers
    result : BundleResult
    covariance : ndarray, shape (L, 4, 4)
        Each line's two direction (rad) and two point (mm) unknowns: the camera noise's
        and the skin slide's (:func:`.uncertainty.slide_uncertainty`) for a fit of fixed
        marker places, the noise's (:func:`.bundle.line_covariance`) for one that
        estimated the slides; NaN where held.
    notes : list of str
        One line per parameter held or choice made.
    slide_sd : ndarray, shape (6,) or None
        The skin slide's SD along the bone, across and dorsal (mm/rad) of the digit's
        markers, then of the hand's, estimated from the recording
        (:class:`.uncertainty.SlideUncertainty`).
    """

    digit: str
    layout: ChainLayout
    data: DigitMarkers
    result: BundleResult
    covariance: FloatArray
    notes: list[str] = field(default_factory=list)
    slide_sd: FloatArray | None = None

    def axis_sd_deg(self, level: int) -> float:
        """The largest SD of the direction of ``level`` (deg)."""
        return math.degrees(math.sqrt(np.linalg.eigvalsh(self.covariance[level, :2, :2])[-1]))

    def centre_sd_mm(self, level: int) -> float:
        """The largest SD of the point of ``level`` across its line (mm)."""
        return math.sqrt(np.linalg.eigvalsh(self.covariance[level, 2:, 2:])[-1])

    def axis_ci_deg(self, level: int) -> float:
        """The 95 % half-angle of the direction of ``level`` (deg): the largest angle of its
        95 % region."""
        return math.sqrt(CHI2_95) * self.axis_sd_deg(level)


def _undetermined(fit: DigitFit) -> np.ndarray:
    """Global unknowns (``4 L + 3 M``) the markers do not determine: every unknown of a
    line whose direction or point exceeds the limits."""
    bad = np.zeros(fit.result.free.size, dtype=bool)
    for k, name in enumerate(fit.layout.names):
        if not np.isfinite(fit.covariance[k]).all():
            continue  # held already
        if fit.axis_sd_deg(k) > UNDETERMINED_SD_DEG or fit.centre_sd_mm(k) > UNDETERMINED_SD_MM:
            bad[4 * k : 4 * k + 4] = True
            fit.notes.append(
                f"{fit.digit} {name}: not determined by the markers "
                f"(axis SD {fit.axis_sd_deg(k):.3g} deg, point SD {fit.centre_sd_mm(k):.3g} mm); "
                "held at its start"
            )
    return bad


def slide_free(data: DigitMarkers, levels: int) -> np.ndarray:
    """The global unknowns (``4 L + 6 M``) of a fit with slides: every one, but the slide
    of a marker alone on its segment (its slide cannot be told from the joint's angle:
    held at 0)."""
    M = len(data.labels)
    alone = np.bincount(data.segment, minlength=3)[data.segment] == 1
    free = np.ones(4 * levels + 6 * M, dtype=bool)
    free[4 * levels + 3 * M :] = ~np.repeat(alone, 3)
    return free


def fit_chain(
    data: DigitMarkers,
    digit: str,
    two_axis: bool,
    start: BundleResult | None = None,
    slide: bool = True,
    order: str = ABDUCTION_FIRST,
    threads: int = 1,
) -> DigitFit:
    """Start, adjust and check one digit's chain (:func:`chain_layout`): from the staged
    start, or (the choice joint's two axes, in ``order``: a finger's MP, the thumb's MCP)
    from its hinge fit ``start`` with the second axis added, perpendicular to the flexion
    axis and the child segment, at angle 0. ``threads``: :func:`.bundle.adjust`'s."""
    layout = chain_layout(digit, two_axis, order)

    def again(
        r: BundleResult, lines: Lines, q: FloatArray, free: np.ndarray | None
    ) -> BundleResult:
        return _again(data, layout, r, lines, q, free, threads)

    if start is None:
        result = staged_start(data, layout, threads=threads)
        if slide:
            result.slide = np.zeros((len(data.labels), 3))
            result = again(
                result, result.lines, result.q, slide_free(data, layout.structure.levels)
            )
    else:
        c = layout.choice
        flex = chain_layout(digit, False).first[c]
        lines = start.lines
        near = start.u[data.segment == c].mean(axis=0)
        bone = unit(near - lines.centre[flex])
        extra = unit(np.cross(bone, lines.axis[flex]))
        at = layout.second[c]  # the hinge chain's levels from here on move one down
        two = Lines(
            np.insert(lines.axis, at, extra, axis=0),
            np.insert(lines.centre, at, lines.centre[flex], axis=0),
        )
        q = np.insert(start.q, at, 0.0, axis=0)
        free = None if start.slide is None else slide_free(data, layout.structure.levels)
        result = again(start, two, q, free)
        layout, result = _labelled(data, digit, layout, result, threads)
    return _finish(data, digit, layout, result, threads)


def _not_a_joint(fit: DigitFit, flexion_deg: float) -> str | None:
    """Why the choice joint's two axes in ``fit`` are not a joint's motion, or None: an
    axis turns through more than :data:`HALF_TURN_DEG`, or the axis with the smaller
    range (the ab/adduction's) turns further than the joint flexes as a hinge
    (``flexion_deg``, its hinge fit's range): then the two axes turn against each other
    (nearly parallel, the segment slid by their centres' offset) to soak up the skin's
    slide."""
    c = fit.layout.choice
    small, large = sorted(
        motion_range_deg(fit.result.q[k]) for k in (fit.layout.first[c], fit.layout.second[c])
    )
    if large > HALF_TURN_DEG:
        return f"turns an axis through {large:.3g} deg"
    if small > flexion_deg:
        return (
            f"turns both axes further than the joint flexes as a hinge ({small:.3g} and "
            f"{large:.3g} deg against {flexion_deg:.3g}: they turn against each other)"
        )
    return None


def motion_range_deg(q: FloatArray) -> float:
    """The range of an axis's angles ``(n,)`` (deg): the spread of their 5th to 95th
    percentile."""
    lo, hi = np.percentile(q, [5.0, 95.0])
    return math.degrees(float(hi - lo))


def _labelled(
    data: DigitMarkers, digit: str, layout: ChainLayout, result: BundleResult, threads: int = 1
) -> tuple[ChainLayout, BundleResult]:
    """The choice joint's two axes named by their motion: the axis with the larger range is the
    flexion axis.

    The two orders are one chain (a proximal and a distal line); only the names differ.
    Started with the ab/adduction axis distal, an adjustment can end with the distal axis
    carrying the flexion: then it is named so (the lines and angles unchanged; with
    slides, which follow the flexion angle, adjusted again).
    """
    flex, second = layout.first[layout.choice], layout.second[layout.choice]
    if motion_range_deg(result.q[second]) <= motion_range_deg(result.q[flex]):
        return layout, result
    other = FLEXION_FIRST if layout.order == ABDUCTION_FIRST else ABDUCTION_FIRST
    named = chain_layout(digit, True, other)
    if result.slide is not None:
        result = _again(data, named, result, result.lines, result.q, result.free, threads)
    return named, result


def _finish(
    data: DigitMarkers,
    digit: str,
    layout: ChainLayout,
    result: BundleResult,
    threads: int = 1,
) -> DigitFit:
    """An adjusted chain checked: the angles within a turn and each flexion axis pointed
    so that flexion is positive (the same motion; adjusted again when either changed),
    then the lines the markers do not determine held at their start."""
    turned = np.abs(result.q) > np.pi
    q = np.where(turned, wrap(result.q), result.q)
    flipped = [k for k in layout.first if flexion_sign(q[k]) < 0]
    if flipped or turned.any():
        axis = result.lines.axis.copy()
        axis[flipped], q[flipped] = -axis[flipped], -q[flipped]
        lines = Lines(axis, result.lines.centre)
        result = _again(data, layout, result, lines, q, result.free, threads)
    fit = DigitFit(digit, layout, data, result, line_covariance(result))
    bad = _undetermined(fit)
    if bad.any():
        held = result.free & ~bad
        result = _again(data, layout, result, result.lines, result.q, held, threads)
        fit.result, fit.covariance = result, line_covariance(result)
    return fit


def _again(
    data: DigitMarkers,
    layout: ChainLayout,
    r: BundleResult,
    lines: Lines,
    q: FloatArray,
    free: np.ndarray | None,
    threads: int = 1,
) -> BundleResult:
    """The adjustment of ``layout``'s chain from ``lines``, ``q`` and ``r``'s places,
    slides and hand frames."""
    return adjust(
        data,
        layout.structure,
        lines,
        r.u,
        q,
        hand=r.hand,
        slide=r.slide,
        free=free,
        max_iter=MAX_ITER,
        tol=TOL,
        near=NEAR,
        threads=threads,
    )


def with_slide_uncertainty(fit: DigitFit) -> DigitFit:
    """``fit`` with the covariance of its lines holding the skin's slide
    (:func:`.uncertainty.slide_uncertainty`), for a fit of fixed marker places."""
    if fit.result.slide is None:
        uncertainty = slide_uncertainty(fit.data, fit.layout.structure, fit.result)
        fit.covariance = uncertainty.covariance
        fit.slide_sd = uncertainty.slide_sd
    return fit


def _chosen(fit: DigitFit) -> DigitFit:
    """The chosen fit of a finger, with the covariance of its lines
    (:func:`with_slide_uncertainty`) and a note when its adjustment stopped at the
    iteration cap."""
    if not fit.result.converged:
        fit.notes.append(
            f"{fit.digit}: warning: the adjustment stopped at its {MAX_ITER}-iteration cap, "
            "not converged (its axes may still move)"
        )
    return with_slide_uncertainty(fit)


def fit_digit(
    data: DigitMarkers, digit: str, mp_axes: str, slide: bool = True, threads: int = 1
) -> DigitFit:
    """A digit with its choice joint (a finger's MP, the thumb's MCP,
    :attr:`.chain.ChainLayout.choice`) a hinge, two axes, or (``auto``) two axes when the
    second explains the markers beyond what its per-frame angle absorbs of the noise;
    ``mp_axes`` says which.

    The two-axis fits start from the hinge's, the second axis inserted proximal to the
    flexion axis and distal to it: one chain of two lines from two starts; the lower
    cost wins, and the axis with the larger range of motion is named flexion
    (:func:`_labelled`), which gives the order. A minimum that is not a joint's motion
    (an axis turned through more than :data:`HALF_TURN_DEG`, or both further than the
    hinge flexes: :func:`_not_a_joint`) is left out. The second axis's ``n + 4`` more
    unknowns (an angle per frame, the line) lower the cost by about ``(n + 4) sigma^2``
    on noise alone (a chi-square with that many degrees of freedom); ``auto`` keeps the
    second axis when the drop exceeds that by more than :data:`SECOND_AXIS_Z` of its
    standard deviations ``sqrt(2 (n + 4))``, ``sigma^2`` the two-axis fit's residual
    variance. The test takes the residuals for white noise, and the skin's slide is
    not: a kept second axis is also compared with the hinge on held-out markers
    (:func:`.heldout.compare_held_out`), and its note says how they are predicted
    (worse: it may follow the slide). That evidence is reported, not used: as the rule
    it gave the fingertip away in worlds whose skin slides more (``docs/markers.md``).
    """
    hinge = fit_chain(data, digit, False, slide=slide, threads=threads)
    c = hinge.layout.choice
    joint = f"{digit} {DIGITS[digit].joints[c]}"
    if mp_axes == "hinge":
        return _chosen(hinge)
    orders = [
        fit_chain(data, digit, True, start=hinge.result, slide=slide, order=o, threads=threads)
        for o in (ABDUCTION_FIRST, FLEXION_FIRST)
    ]
    flexion = motion_range_deg(hinge.result.q[hinge.layout.first[c]])
    why = [_not_a_joint(f, flexion) for f in orders]
    turning = [f for f, w in zip(orders, why, strict=True) if w]
    plausible = [f for f, w in zip(orders, why, strict=True) if not w] or orders
    if mp_axes == "auto" and len(turning) == len(orders):
        hinge.notes.append(
            f"{joint}: a hinge (neither two-axis minimum is a joint's motion: one "
            f"{why[0]}, the other {why[1]})"
        )
        return _chosen(hinge)
    two, *rest = sorted(plausible, key=lambda f: f.result.cost)
    other = rest[0] if rest else turning[0]
    extra = data.frames + 4
    sigma2 = two.result.normal.sigma2
    z = ((hinge.result.cost - two.result.cost) / sigma2 - extra) / math.sqrt(2 * extra)
    if mp_axes == "two" or z > SECOND_AXIS_Z:
        held = compare_held_out(
            data,
            (hinge.layout.structure, hinge.result.point),
            (two.layout.structure, two.result.point),
        )
        proximal = "ab/adduction" if two.layout.order == ABDUCTION_FIRST else "flexion"
        gap = (other.result.cost - two.result.cost) / sigma2
        flex, ab = (
            motion_range_deg(two.result.q[k]) for k in (two.layout.first[c], two.layout.second[c])
        )
        if any(other is f for f in turning):
            lower = f" ({-gap:.3g} sigma^2 lower)" if gap < 0 else ""
            beyond = (
                f"the other start's minimum{lower} {_not_a_joint(other, flexion)}: "
                "not a joint's motion"
            )
        else:
            beyond = f"the other start's minimum {gap:.3g} sigma^2 higher"
        if not other.result.converged:
            beyond += f" where it stopped at the {MAX_ITER}-iteration cap"
        two.notes.append(
            f"{joint}: two axes (the second lowers the cost by {z:.3g} SD; held-out "
            f"markers {_held_out(held)}), the {proximal} axis proximal (ranges of "
            f"motion: flexion {flex:.3g} deg, ab/adduction {ab:.3g} deg; {beyond})"
        )
        if held.worse:
            two.notes.append(
                f"{joint}: the second axis predicts held-out markers worse than the hinge: "
                "it may follow the skin's slide, not a joint's motion (--mp-axes hinge "
                "fits the hinge; docs/markers.md)"
            )
        if any(two is f for f in turning):
            two.notes.append(
                f"{joint}: warning: neither two-axis minimum is a joint's motion (the lower "
                f"{_not_a_joint(two, flexion)}); mp_axes='two' kept it"
            )
        return _chosen(two)
    hinge.notes.append(
        f"{joint}: a hinge (a second axis lowers the cost by {z:.3g} SD, "
        f"not above {SECOND_AXIS_Z:g})"
    )
    return _chosen(hinge)


def _held_out(held: HeldOutComparison) -> str:
    """A held-out comparison of the hinge and the two axes in words."""
    if not held.predictions:
        return "not compared: no marker shares its segment"
    way = "better" if held.gain_mm2 >= 0 else "worse"
    return (
        f"predicted {abs(held.gain_mm2):.2g} mm^2 {way} than with the hinge, "
        f"{abs(held.t):.2g} SE, {held.predictions} predictions"
    )


@dataclass
class MarkerFit:
    """A marker session's fit.

    Attributes
    ----------
    model : HandModel
    digits : dict[str, DigitFit]
    notes : list of str
        Every digit's notes, and the frames without a hand frame.
    """

    model: HandModel
    digits: dict[str, DigitFit]
    notes: list[str]


def fit_marker_session(
    session: Session,
    *,
    mp_axes: str = "auto",
    slide: bool = False,
    executor: Executor | None = None,
    threads: int = 1,
) -> MarkerFit:
    """Fit the individual hand model of a marker session.

    Parameters
    ----------
    session : Session
        With a ``marker_map`` (checked when it was loaded: the hand 3 or more markers,
        every segment of every digit one or more; the thumb's metacarpal two or more:
        refused in one line here) and marker recordings: the reference (the angles'
        zero) and the grasp recordings are fitted.
    mp_axes : {"auto", "hinge", "two"}
        A finger's MP, the thumb's MCP: two axes when the markers determine the second,
        a hinge, or two (the thumb's CMC always has two, :func:`.chain.chain_layout`).
    slide : bool
        Estimate each marker's skin slide with the joint below it
        (:func:`.chain.places`, against the prior :data:`.chain.SLIDE_PRIOR`). Off by
        default: the slide and the angle enter as a product, and the adjustment then
        crawls (``docs/markers.md``, measured).
    executor : concurrent.futures.Executor, optional
        Fits the digits side by side (each digit's fit is independent of the others';
        the result is the same). Default: one after the other, in this process.
    threads : int
        Threads of each digit's adjustment (its frames' blocks side by side,
        :func:`.bundle.adjust`; the result is the same for any number).

    Returns
    -------
    MarkerFit
        The model (tracker coordinates at the reference posture, mm): joint lines,
        tips (the ``<digit>.tip`` landmark, else the digit's most distal marker, said in
        a note), segment frames, each marker's place; ``reference_poses`` the hand
        markers' technical frame and, per segment, its markers' centroid with the
        segment's frame.
    """
    if not session.marker_map:
        raise FingerfitError("not a marker session (no marker map)", path=session.path)
    if mp_axes not in MP_AXES:
        raise FingerfitError(f"must be auto, hinge or two, not {mp_axes!r}", field="--mp-axes")
    for d in session.fingers:
        for joint in DIGITS[d].required_second:
            seg = sensor_name(d, DIGITS[d].segments[DIGITS[d].joints.index(joint)])
            if len(session.marker_map.get(seg, [])) == 1:
                raise FingerfitError(
                    f"{seg} has one marker: {d} {joint}'s two axes need two or more (one "
                    "marker's direction from the joint has as many degrees of freedom as the "
                    "joint; docs/markers.md)",
                    path=None if session.path is None else session.path / "markers.toml",
                )
    for d in session.fingers:
        for j, seg in enumerate(DIGITS[d].segments):
            if not session.marker_map.get(sensor_name(d, seg)):
                joints = DIGITS[d].joints
                raise FingerfitError(
                    f"{sensor_name(d, seg)} has no marker: the markers cannot split "
                    f"{d} {joints[j]} from {joints[min(j + 1, 2)] if j < 2 else joints[1]} "
                    "(each phalanx needs a marker; docs/markers.md)",
                    path=None if session.path is None else session.path / "markers.toml",
                )
    shape = hand_shape(session)
    moving, lost = carry_back(session, session.grasp, shape)
    reference, lost_ref = carry_back(session, [session.reference], shape)
    notes = []
    if lost or lost_ref:
        notes.append(f"{lost + lost_ref} frames without 3 hand markers left out")
    datas = {d: digit_markers(session, d, moving, reference) for d in session.fingers}
    try:
        if executor is None:
            fits = {d: fit_digit(data, d, mp_axes, slide, threads) for d, data in datas.items()}
        else:
            futures = {
                d: executor.submit(fit_digit, data, d, mp_axes, slide, threads)
                for d, data in datas.items()
            }
            fits = {d: f.result() for d, f in futures.items()}
    except FingerfitError as exc:  # what a digit's motion cannot give: name the session
        if exc.path is not None or session.path is None:
            raise
        raise FingerfitError(exc.reason, path=session.path, field=exc.field) from None
    for d in session.fingers:
        sd = fits[d].slide_sd
        if sd is not None:
            fits[d].notes.append(
                f"{d}: skin slide SD along the bone, across and dorsal {sd[0]:.2g}, "
                f"{sd[1]:.2g}, {sd[2]:.2g} mm/rad (the hand's markers {sd[3]:.2g}, "
                f"{sd[4]:.2g}, {sd[5]:.2g}), estimated from the recording: the axes' "
                "intervals hold it"
            )
        notes += fits[d].notes
    model = _model(session, shape, fits, notes)
    return MarkerFit(model, fits, notes)


def _centre_on_line(axis: FloatArray, point: FloatArray, near: FloatArray) -> FloatArray:
    """The point of the line ``(point, axis)`` nearest ``near`` (mm)."""
    return point + ((near - point) @ axis) * axis


def _model(
    session: Session, shape: FloatArray, fits: dict[str, DigitFit], notes: list
) -> HandModel:
    """The HandModel of the digits' fits."""
    rot, origin = technical_frame(shape)
    side = 1.0 if session.hand == "right" else -1.0
    poses: dict[str, tuple[FloatArray, FloatArray]] = {HAND_SENSOR: (origin, rot)}
    markers = {
        label: (HAND_SENSOR, p, np.zeros(3))
        for label, p in zip(session.marker_map[HAND_SENSOR], shape, strict=True)
    }
    digits = {}
    for d, fit in fits.items():
        r, data = fit.result, fit.data
        sensors = joint_sensors(d)
        joints, seconds = {}, {}
        names = DIGITS[d].joints
        nears = [r.u[data.segment == j].mean(axis=0) for j in range(len(names))]
        for j, joint in enumerate(names):
            level = fit.layout.first[j]
            centre = _centre_on_line(r.lines.axis[level], r.lines.centre[level], nears[j])
            joints[joint] = (*sensors[joint], centre, r.lines.axis[level], _quality(fit, level))
        for j, k in fit.layout.second.items():
            joint = names[j]
            c2 = _centre_on_line(r.lines.axis[k], r.lines.centre[k], nears[j])
            beyond = joints[names[j + 1]][2] if j + 1 < len(names) else nears[j]
            bone = beyond - joints[joint][2]
            # Positive ab/adduction (docs/conventions.md): the axis on the side of
            # bone x flexion axis for a right hand (a finger's radial deviation, the
            # thumb's palmar abduction), the other for a left one.
            a2 = r.lines.axis[k] * math.copysign(
                1.0, side * (r.lines.axis[k] @ np.cross(bone, joints[joint][3]))
            )
            seconds[joint] = JointModel(
                second_axis(joint), *sensors[joint], c2, a2, a2, _quality(fit, k)
            )
        tip_name = f"{d}.tip"
        if tip_name in session.landmarks:
            tip = session.landmarks[tip_name]
        else:
            last = np.flatnonzero(data.segment == 2)
            far = last[
                np.argmax(np.linalg.norm(r.u[last] - joints[DIGITS[d].joints[2]][2], axis=1))
            ]
            tip = r.u[far]
            notes.append(
                f"{d} tip: not determined by the markers (no {tip_name} landmark): "
                f"marker {data.labels[far]} taken as the tip"
            )
        dm = assemble_digit(d, joints, tip, seconds)
        orders = {
            names[j]: fit.layout.order_of(j)
            for j in fit.layout.second
            if fit.layout.order_of(j) != DIGITS[d].order[names[j]]
        }
        if orders:
            dm = replace(dm, axis_order=orders)
        digits[d] = dm
        for s, seg in enumerate(DIGITS[d].segments):
            name = sensor_name(d, seg)
            poses[name] = (r.u[data.segment == s].mean(axis=0), dm.frames[seg].rotation)
        slides = np.zeros_like(r.u) if r.slide is None else r.slide
        markers |= {
            label: (sensor_name(d, DIGITS[d].segments[s]), r.u[i], slides[i])
            for i, (label, s) in enumerate(zip(data.labels, data.segment, strict=True))
        }
    ordered = {d: digits[d] for d in DIGITS if d in digits}
    return HandModel(
        subject=session.subject,
        hand=session.hand,
        session_units=session.units,
        method="markers",
        reference_poses=poses,
        fingers=ordered,
        angle_method="swing_twist",
        warnings=tuple(notes),
        markers=markers,
    )


def _quality(fit: DigitFit, level: int) -> JointQuality:
    """What the fit says of one line: its range of motion, the residual, the 95 %
    half-angle of its direction."""
    q = fit.result.q[level]
    rom = math.degrees(float(np.ptp(q))) if q.size else 0.0
    ci = fit.axis_ci_deg(level)
    return JointQuality(
        cycles=0,
        rom_deg=[rom],
        centre_distance_mm=[],
        conditioning=[],
        spread_mm=0.0,
        residual_mm=[fit.result.rms_mm],
        notes=[
            f"marker bundle adjustment: axis SD {fit.axis_sd_deg(level):.3g} deg "
            + ("(noise and skin slide)" if fit.slide_sd is not None else "(noise)")
        ],
        axis_ci_deg=ci if math.isfinite(ci) else None,
    )


__all__ = ["MP_AXES", "DigitFit", "MarkerFit", "fit_digit", "fit_marker_session"]
