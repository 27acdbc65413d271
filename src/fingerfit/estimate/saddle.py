"""Saddle joint (thumb CMC): two axes with large ranges, neither perpendicular nor meeting.

Model (Hollister et al. 1992; ``docs/methods.md``, "Thumb CMC (saddle joint)"): relative
to the reference posture the child segment turns about the *distal* axis ``d`` and the
result about the *proximal* axis ``p``, fixed in the parent segment,

    Q(k) = R(k) R_ref^T = Rot(p, alpha_k) Rot(d, delta_k),

``p`` and ``d`` unit vectors in the parent sensor frame at the reference posture. The
positions follow the lines: a child point turns about the line ``(c_d, d)`` and then about
``(c_p, p)``. ``order="flexion_first"`` (thumb CMC, Hollister: flexion-extension axis in
the trapezium) makes ``p`` the flexion axis and ``d`` the ab/adduction axis;
``"abduction_first"`` the reverse (the finger MP convention of :mod:`.twoaxis`).

**Directions.** To first order the rotation vector of ``Q`` is ``alpha p + delta d``: the
rotation vectors of a motion that turns both axes fill a plane holding both axes
(a principal-component fit, through the origin: ``Q = I`` at the reference posture). Every
pair of directions of that plane fits to first order; which pair, and which of the two is
proximal, shows at second order (``Q`` differs from ``Rot(p, alpha + ...) Rot(d, ...)`` by
about ``alpha delta (p x d) / 2``), which is large when both angles span tens of degrees. A
coarse search over the pairs of directions of the plane (``GRID_STEP_DEG``; ``p`` and
``d`` apart by at least ``MIN_AXIS_ANGLE_DEG``) scores each pair by the rotation residual;
its best local minima (and the caller's guesses) start ``scipy.optimize.least_squares``
with both axes free (four parameters). The residual is :mod:`.twoaxis_residual`'s: per frame the
small rotation left in ``Rot(d, -delta) Rot(p, -alpha) Q`` with the angles in closed form
from :func:`fingerfit.angles.two_axis_angles` (variable projection). Unlike the finger
MP fit there is no bound on how far the flexion axis may turn from a hinge axis and no
prior on the angle between the axes: both angles have large ranges, so both directions and
their angle are determined by the data.

**Points.** With the angles known the point equations are linear
(:func:`.migration.fit_axis_points` with the distal axis in the role of its flexion axis and
the proximal axis in that of its ab/adduction axis, without priors). Both ranges being
large, the offset between the lines is seen at first order. Each axis is reported with
its point nearest the other line; the signed offset is ``(c_abd - c_flex) . n`` with
``n = unit(flexion_axis x abduction_axis)``.

**Uncertainty.** Delete-one-cluster jackknife over ``groups`` (default
``DEFAULT_BLOCKS`` contiguous blocks of frames): the whole fit (directions from the full
solution, angles, points) is repeated without each cluster; a systematic error repeated
within a cluster counts once, one shared by every cluster (the tracker's distortion field,
skin sliding that follows the angles) is not seen.

**Refusals** (:class:`fingerfit.errors.FingerfitError`, one line): a motion that leaves
less than ``MIN_OFF_HINGE_DEG`` off its best hinge (a hinge, or both axes turning in a
fixed ratio) cannot tell two axes apart; an axis whose fitted angle spans less than
``MIN_RANGE_DEG`` is not determined (see the constants); with both guesses, a fit whose
proximal axis is the other one than ``order`` says is refused. The missing axis is named
only when the guesses tell which it is: when one axis hardly turns, the data cannot say
which of the two is proximal, so ``order`` alone would name it at random.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from ..angles import two_axis_angles
from ..errors import FingerfitError
from ..transforms import FloatArray, angle_between_axes, orthonormal_basis, rotation_vector, unit
from .bootstrap import jackknife_sd
from .migration import fit_axis_points
from .pooled import sara_axis
from .twoaxis_residual import _skew_residual

Order = Literal["flexion_first", "abduction_first"]
ORDERS: tuple[str, ...] = ("flexion_first", "abduction_first")

# Each axis's angle must span (5th-95th percentile) at least this much. The two directions
# are told apart, and the proximal one from the distal one, by the second-order term
# alpha * delta / 2 of the rotation: at 10 deg on both axes that is 0.87 deg, about six
# times the Polhemus Liberty's orientation error (0.15 deg RMS, the simulator's distortion
# field), and the lines' offset is seen through rotations of 10 deg = 0.17 rad, i.e. a
# 5 mm offset moves the child by about 0.9 mm, seven times the tracker's 0.12 mm noise.
# Below it the fitted axes follow the tracker's errors; the active CMC range in vivo is about
# 76 deg (flexion) and 43 deg (ab/adduction; Chang & Pollard 2008).
MIN_RANGE_DEG = 10.0
# Before any fit, the rotation off the best hinge axis must span at least this much (5th-95th
# percentile, deg): a second axis turned by MIN_RANGE_DEG at 60-90 deg from the first leaves
# 8.7-10 deg, so half of MIN_RANGE_DEG refuses only motions that MIN_RANGE_DEG would refuse
# after the fit, and keeps the fit away from a hinge's data.
MIN_OFF_HINGE_DEG = 0.5 * MIN_RANGE_DEG
# The search keeps the two axes at least this far apart: below it the two-axis angles are
# ill-conditioned (their errors grow as 1 / sin of the angle between the axes); saddle
# joints' axes are far from parallel (MyoHand's thumb CMC axes are 81 deg apart).
MIN_AXIS_ANGLE_DEG = 20.0
GRID_STEP_DEG = 9.0  # coarse search step over the directions of the plane
GRID_FRAMES = 150  # the coarse search uses at most this many frames (evenly strided)
MAX_FRAMES = 1500  # the direction fit uses at most this many frames (evenly strided)
STARTS = 3  # refine this many of the coarse search's best local minima
DEFAULT_BLOCKS = 10  # jackknife clusters without ``groups``: contiguous blocks of frames
MIN_FRAMES = 30

_NAMES = {"flexion": "flexion-extension", "abduction": "ab/adduction"}
_ADVICE = "record thumb circumduction or opposition"


@dataclass(frozen=True)
class SaddleFit:
    """A fitted saddle joint (parent sensor frame at the reference posture; mm, rad).

    Attributes
    ----------
    order : str
        ``"flexion_first"`` (the flexion axis is proximal, fixed in the parent) or
        ``"abduction_first"`` (the ab/adduction axis is proximal).
    flexion_axis, abduction_axis : ndarray, shape (3,)
        Unit axes, parent frame at the reference posture. Signed towards the caller's
        guesses when given, otherwise so that the median of the axis's angle is >= 0.
    flexion_point, abduction_point : ndarray, shape (3,)
        The point of each axis's line nearest the other line (mm, parent frame at the
        reference posture).
    flexion_angle, abduction_angle : ndarray, shape (n,)
        Per-frame angles (rad, 0 at the reference posture), exactly
        :func:`fingerfit.angles.two_axis_angles` of ``Q = R R_ref^T`` about these axes.
    axis_angle_deg : float
        Angle between the two lines (deg, 0-90).
    offset_mm : float
        Length of the common perpendicular of the lines, signed: ``(abduction_point -
        flexion_point) . unit(flexion_axis x abduction_axis)`` (mm).
    rms_rotation_deg : float
        RMS over the frames of the rotation left off the model (deg).
    rms_position_mm : float
        RMS over the frames of the child-origin position residual (mm).
    flexion_range_deg, abduction_range_deg : float
        5th-95th percentile span of each angle (deg).
    flexion_sd_deg, abduction_sd_deg : float
        Jackknife SD of each axis direction over the clusters (deg): the RMS angle by
        which the axis is expected to be off (both directions perpendicular to it).
    offset_sd_mm : float
        Jackknife SD of ``offset_mm`` (mm).
    clusters : int
        Number of clusters of the jackknife (the SDs are NaN with fewer than two). The
        SDs show the errors that differ between clusters (noise, cycle-to-cycle
        variation), not a bias every cluster shares (the tracker's smooth distortion
        field, skin sliding that follows the angles alike in every cycle).
    guesses_swapped_deg : tuple of float, optional
        With ``strict_order=False``: when the fitted axes lie nearer each other's guesses,
        the mean angle (deg) of the axes to the guesses swapped and as named; None when
        the names agree with the guesses (or without guesses).
    """

    order: str
    flexion_axis: FloatArray
    abduction_axis: FloatArray
    flexion_point: FloatArray
    abduction_point: FloatArray
    flexion_angle: FloatArray
    abduction_angle: FloatArray
    axis_angle_deg: float
    offset_mm: float
    rms_rotation_deg: float
    rms_position_mm: float
    flexion_range_deg: float
    abduction_range_deg: float
    flexion_sd_deg: float
    abduction_sd_deg: float
    offset_sd_mm: float
    clusters: int
    guesses_swapped_deg: tuple[float, float] | None = None

    @property
    def proximal_axis(self) -> FloatArray:
        """The axis fixed in the parent segment ``(3,)``."""
        return self.flexion_axis if self.order == "flexion_first" else self.abduction_axis

    @property
    def distal_axis(self) -> FloatArray:
        """The axis carried by the proximal rotation ``(3,)`` (reference posture)."""
        return self.abduction_axis if self.order == "flexion_first" else self.flexion_axis


def _rms_deg(q: FloatArray, p: FloatArray, d: FloatArray, w: FloatArray) -> float:
    """Weighted RMS (deg) of the rotation left off ``Q = Rot(p) Rot(d)`` (``w`` mean 1)."""
    r = _skew_residual(q, d, p)
    return float(np.degrees(np.sqrt(np.sum(w * np.sum(r * r, axis=1)) / np.sum(w))))


def _plane(q: FloatArray, w: FloatArray) -> FloatArray:
    """Principal directions ``(3, 3)`` (rows) of the rotation vectors of ``Q`` through the
    origin (``Q = I`` at the reference posture); the first two span the axes' plane."""
    rv = rotation_vector(q)
    _, _, vt = np.linalg.svd(rv * np.sqrt(w)[:, None], full_matrices=False)
    return vt


def _off_hinge_spread(q: FloatArray, w: FloatArray) -> tuple[FloatArray, float]:
    """The best hinge axis ``(3,)`` (parent frame, :func:`.pooled.sara_axis`) and the
    5th-95th percentile span (deg) of the rotation off it along its main direction.

    A motion about one axis (whatever the posture it starts from) leaves nothing off the
    hinge; a second axis turned by ``x`` deg at an angle ``g`` to the first leaves about
    ``x sin(g)``.
    """
    a_p, a_c, _ = sara_axis(q, w)
    swing = np.cross(a_p, q @ a_c)
    swing -= np.average(swing, axis=0, weights=w)
    _, _, vt = np.linalg.svd(swing * np.sqrt(w)[:, None], full_matrices=False)
    return a_p, _range_deg((swing @ vt[0])[w > 0])


def _coarse_starts(q: FloatArray, w: FloatArray, plane: FloatArray) -> list[tuple]:
    """The best local minima ``[(p, d), ...]`` of the residual over pairs of directions of
    the plane spanned by ``plane[0]``, ``plane[1]`` (``GRID_STEP_DEG`` apart)."""
    ang = np.radians(np.arange(0.0, 180.0, GRID_STEP_DEG))
    dirs = np.cos(ang)[:, None] * plane[0] + np.sin(ang)[:, None] * plane[1]
    m = ang.size
    cost = np.full((m, m), np.inf)
    for i in range(m):
        for j in range(m):
            sep = abs(ang[i] - ang[j])
            if min(sep, np.pi - sep) >= np.radians(MIN_AXIS_ANGLE_DEG):
                cost[i, j] = _rms_deg(q, dirs[i], dirs[j], w)
    # Local minima on the torus of line directions (each index wraps at 180 deg).
    local = np.isfinite(cost)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                local &= cost <= np.roll(np.roll(cost, di, axis=0), dj, axis=1)
    cand = np.argwhere(local)
    cand = cand[np.argsort(cost[local])][:STARTS]
    return [(dirs[i], dirs[j]) for i, j in cand]


def _refine(
    q: FloatArray, sw: FloatArray, p0: FloatArray, d0: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Least-squares ``(p, d)`` from ``(p0, d0)``; returns them and the cost."""
    ep, ed = orthonormal_basis(p0)[:2], orthonormal_basis(d0)[:2]

    def dirs(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return unit(p0 + x[0] * ep[0] + x[1] * ep[1]), unit(d0 + x[2] * ed[0] + x[3] * ed[1])

    def resid(x: FloatArray) -> FloatArray:
        p, d = dirs(x)
        return (_skew_residual(q, d, p) * sw[:, None]).ravel()

    sol = least_squares(resid, np.zeros(4), x_scale=0.05, xtol=1e-12, ftol=1e-14, gtol=1e-14)
    p, d = dirs(sol.x)
    return p, d, float(sol.cost)


def _nearest_points(
    c1: FloatArray, u1: FloatArray, c2: FloatArray, u2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Feet ``(3,)``, ``(3,)`` of the common perpendicular of the lines ``(c1, u1)``,
    ``(c2, u2)`` (unit directions, not parallel)."""
    w0 = c1 - c2
    b = u1 @ u2
    den = 1.0 - b * b
    s = (b * (u2 @ w0) - u1 @ w0) / den
    t = (u2 @ w0 - b * (u1 @ w0)) / den
    return c1 + s * u1, c2 + t * u2


def _range_deg(angle: FloatArray) -> float:
    lo, hi = np.percentile(angle, [5, 95])
    return float(np.degrees(hi - lo))


@dataclass(frozen=True)
class _Solution:
    flexion_axis: FloatArray
    abduction_axis: FloatArray
    flexion_point: FloatArray
    abduction_point: FloatArray
    flexion_angle: FloatArray
    abduction_angle: FloatArray
    offset_mm: float
    rms_position_mm: float


def _solve(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    w: FloatArray,
    p: FloatArray,
    d: FloatArray,
    flexion_first: bool,
) -> _Solution:
    """Angles, points and offset for given proximal/distal axes (already signed)."""
    q = rotation @ reference_rotation.T
    alpha, delta = two_axis_angles(q, d, p)
    pts = fit_axis_points(
        rotation,
        translation,
        reference_rotation,
        d,
        delta,
        abduction_axis=p,
        beta=alpha,
        weights=w,
        noise_mm=0.0,
    )
    c_p, c_d = pts.abduction_point, pts.centre
    n_p, n_d = _nearest_points(c_p, p, c_d, d)
    if flexion_first:
        f, a, cf, ca, tf, ta = p, d, n_p, n_d, alpha, delta
    else:
        f, a, cf, ca, tf, ta = d, p, n_d, n_p, delta, alpha
    offset = float((ca - cf) @ unit(np.cross(f, a)))
    return _Solution(f, a, cf, ca, tf, ta, offset, pts.rms_mm)


def _sign(axis: FloatArray, guess: FloatArray | None, angle: FloatArray) -> float:
    """+1 or -1: towards ``guess`` if given, else so that the median angle is >= 0."""
    if guess is not None:
        return 1.0 if axis @ guess >= 0 else -1.0
    return 1.0 if np.median(angle) >= 0 else -1.0


def _check_inputs(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    order: str,
    flexion_guess: FloatArray | None,
    abduction_guess: FloatArray | None,
    groups: FloatArray | None,
    weights: FloatArray | None,
) -> None:
    n = rotation.shape[0] if rotation.ndim == 3 else -1
    if order not in ORDERS:
        raise FingerfitError(f"unknown axis order {order!r}; use one of {ORDERS}", field="order")
    if rotation.shape != (n, 3, 3) or translation.shape != (n, 3):
        raise FingerfitError(
            f"rotation must be (n, 3, 3) and translation (n, 3); got {rotation.shape} and "
            f"{translation.shape}",
            field="rotation",
        )
    if reference_rotation.shape != (3, 3):
        raise FingerfitError("reference_rotation must be (3, 3)", field="reference_rotation")
    for name, arr in (("rotation", rotation), ("translation", translation)):
        if not np.isfinite(arr).all():
            raise FingerfitError("contains NaN or infinite values", field=name)
    if n < MIN_FRAMES:
        raise FingerfitError(f"{n} frames; a saddle-joint fit needs {MIN_FRAMES}", field="rotation")
    for name, g in (("flexion_guess", flexion_guess), ("abduction_guess", abduction_guess)):
        if g is not None and (g.shape != (3,) or not np.linalg.norm(g) > 0):
            raise FingerfitError("must be a non-zero 3-vector", field=name)
    for name, v in (("groups", groups), ("weights", weights)):
        if v is not None and v.shape != (n,):
            raise FingerfitError(f"must have one value per frame ({n})", field=name)
    if weights is not None and (not np.isfinite(weights).all() or (weights < 0).any()):
        raise FingerfitError("must be finite and non-negative", field="weights")
    if weights is not None and not weights.sum() > 0:
        raise FingerfitError("all weights are zero", field="weights")


def fit_saddle(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    *,
    order: Order = "flexion_first",
    flexion_guess: FloatArray | None = None,
    abduction_guess: FloatArray | None = None,
    groups: FloatArray | None = None,
    weights: FloatArray | None = None,
    strict_order: bool = True,
) -> SaddleFit:
    """Fit a saddle joint (two non-intersecting, non-perpendicular axes) to a motion.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child sensor rotation in the parent sensor frame, ``x_parent = R u_child + t``,
        over the calibration frames (circumduction, opposition).
    translation : ndarray, shape (n, 3)
        Child sensor origin in the parent sensor frame (mm).
    reference_rotation : ndarray, shape (3, 3)
        ``R`` at the reference posture (the angles are 0 there).
    order : {"flexion_first", "abduction_first"}
        Which axis is proximal (fixed in the parent): the flexion axis (thumb CMC,
        ``Q = Rot(flexion) Rot(abduction)``) or the ab/adduction axis (finger MP).
    flexion_guess, abduction_guess : ndarray, shape (3,), optional
        Rough axes (parent frame): they sign the fitted axes, start one more search and
        name the axis a one-axis motion did not excite.
    groups : ndarray, shape (n,), optional
        Cluster of each frame (e.g. a trial or a circumduction cycle) for the jackknife;
        default ``DEFAULT_BLOCKS`` contiguous blocks of frames.
    weights : ndarray, shape (n,), optional
        Non-negative frame weights.
    strict_order : bool
        With both guesses, refuse a fit whose axes lie nearer each other's guesses (the
        names ``order`` gives would be swapped). False: name them by ``order`` (the data
        place the proximal axis) and report the disagreement in
        :attr:`SaddleFit.guesses_swapped_deg` -- for a caller whose order is anatomy's
        and whose guesses are rough.

    Returns
    -------
    SaddleFit
        Axes and points in the parent sensor frame at the reference posture (mm).

    Raises
    ------
    FingerfitError
        Bad input shapes or values; a motion that turned the joint about one axis only; an
        axis whose angle spans less than ``MIN_RANGE_DEG``.
    """
    rotation = np.asarray(rotation, dtype=float)
    translation = np.asarray(translation, dtype=float)
    reference_rotation = np.asarray(reference_rotation, dtype=float)
    fg = None if flexion_guess is None else np.asarray(flexion_guess, dtype=float)
    ag = None if abduction_guess is None else np.asarray(abduction_guess, dtype=float)
    groups = None if groups is None else np.asarray(groups)
    weights = None if weights is None else np.asarray(weights, dtype=float)
    _check_inputs(rotation, translation, reference_rotation, order, fg, ag, groups, weights)
    fg = None if fg is None else unit(fg)
    ag = None if ag is None else unit(ag)
    n = rotation.shape[0]
    w = np.ones(n) if weights is None else weights / np.mean(weights)
    flexion_first = order == "flexion_first"
    q = rotation @ reference_rotation.T

    hinge, spread = _off_hinge_spread(q, w)
    if spread < MIN_OFF_HINGE_DEG:
        _refuse_one_axis(hinge, spread, fg, ag)
    plane = _plane(q, w)

    # Coarse search in the plane, then both axes free from its best minima (and guesses).
    g = max(1, -(-n // GRID_FRAMES))
    starts = _coarse_starts(q[::g], w[::g], plane)
    if fg is not None and ag is not None:
        starts.append((fg, ag) if flexion_first else (ag, fg))
    s = max(1, -(-n // MAX_FRAMES))
    qs, sws = q[::s], np.sqrt(w[::s])
    # Optima with nearly parallel axes fit the tracker's errors, not a second axis.
    fits = [_refine(qs, sws, p0, d0) for p0, d0 in starts]
    fits = [r for r in fits if _line_angle(r[0], r[1]) >= MIN_AXIS_ANGLE_DEG]
    if not fits:
        _refuse_one_axis(hinge, spread, fg, ag)
    p, d, _ = min(fits, key=lambda r: r[2])

    # Signs: towards the guesses, else a non-negative median angle.
    alpha, delta = two_axis_angles(q, d, p)
    p = p * _sign(p, fg if flexion_first else ag, alpha)
    d = d * _sign(d, ag if flexion_first else fg, delta)
    sol = _solve(rotation, translation, reference_rotation, w, p, d, flexion_first)
    used = w > 0
    ranges = {
        "flexion": _range_deg(sol.flexion_angle[used]),
        "abduction": _range_deg(sol.abduction_angle[used]),
    }
    low = min(ranges, key=lambda key: ranges[key])
    if ranges[low] < MIN_RANGE_DEG:
        _refuse_low_range(sol, low, ranges[low], fg, ag)
    swapped = None
    if fg is not None and ag is not None:
        swapped = _check_order(sol, order, fg, ag, strict_order)

    labels = np.arange(n) * DEFAULT_BLOCKS // n if groups is None else groups
    fl_sd, ab_sd, off_sd, clusters = _jackknife(
        rotation, translation, reference_rotation, w, labels, p, d, flexion_first
    )
    return SaddleFit(
        order=order,
        flexion_axis=sol.flexion_axis,
        abduction_axis=sol.abduction_axis,
        flexion_point=sol.flexion_point,
        abduction_point=sol.abduction_point,
        flexion_angle=sol.flexion_angle,
        abduction_angle=sol.abduction_angle,
        axis_angle_deg=float(np.degrees(angle_between_axes(sol.flexion_axis, sol.abduction_axis))),
        offset_mm=sol.offset_mm,
        rms_rotation_deg=_rms_deg(q, p, d, w),
        rms_position_mm=sol.rms_position_mm,
        flexion_range_deg=ranges["flexion"],
        abduction_range_deg=ranges["abduction"],
        flexion_sd_deg=fl_sd,
        abduction_sd_deg=ab_sd,
        offset_sd_mm=off_sd,
        clusters=clusters,
        guesses_swapped_deg=swapped,
    )


def _jackknife(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    w: FloatArray,
    labels: FloatArray,
    p: FloatArray,
    d: FloatArray,
    flexion_first: bool,
) -> tuple[float, float, float, int]:
    """Delete-one-cluster jackknife SDs of the flexion and ab/adduction axis directions
    (deg) and of the offset (mm), and the number of clusters (NaN SDs below two).

    Without each cluster the directions are refitted from the full solution ``(p, d)``,
    then the angles, points and offset; the SD is :func:`.bootstrap.jackknife_sd` (for an
    axis, of the 3-vector: the RMS angle off in both directions across it).
    """
    uniq, idx = np.unique(labels, return_inverse=True)
    q = rotation @ reference_rotation.T
    fl, ab, off = [], [], []
    for c in range(uniq.size if uniq.size > 1 else 0):
        keep = idx != c
        kq, kw = q[keep], w[keep]
        if not kw.sum() > 0:
            continue
        s = max(1, -(-kq.shape[0] // MAX_FRAMES))
        jp, jd, _ = _refine(kq[::s], np.sqrt(kw[::s]), p, d)
        jp, jd = jp * np.sign(jp @ p), jd * np.sign(jd @ d)
        js = _solve(
            rotation[keep], translation[keep], reference_rotation, kw, jp, jd, flexion_first
        )
        fl.append(js.flexion_axis)
        ab.append(js.abduction_axis)
        off.append([js.offset_mm])
    g = len(off)
    if g < 2:
        return float("nan"), float("nan"), float("nan"), g
    return (
        float(np.degrees(jackknife_sd(np.array(fl)))),
        float(np.degrees(jackknife_sd(np.array(ab)))),
        jackknife_sd(np.array(off)),
        g,
    )


def _line_angle(u: FloatArray, v: FloatArray) -> float:
    return float(np.degrees(angle_between_axes(u, v)))


def _refuse_one_axis(
    excited: FloatArray, spread: float, fg: FloatArray | None, ag: FloatArray | None
) -> None:
    """Raise the refusal of a motion whose rotations span one direction; it names the
    missing axis when the guesses tell which (the excited direction is nearer the other)."""
    need = f"need {MIN_OFF_HINGE_DEG:.0f} deg"
    if fg is not None and ag is not None:
        missing = "abduction" if _line_angle(excited, fg) <= _line_angle(excited, ag) else "flexion"
        raise FingerfitError(
            f"the motion did not excite the {_NAMES[missing]} axis (the rotations spread "
            f"{spread:.1f} deg off one axis; {need}): {_ADVICE}"
        )
    raise FingerfitError(
        f"the motion turned the joint about one axis only (the rotations spread {spread:.1f} "
        f"deg off it; {need}): {_ADVICE}, which turn both axes"
    )


def _refuse_low_range(
    sol: _Solution, key: str, span: float, fg: FloatArray | None, ag: FloatArray | None
) -> None:
    """Raise the refusal of a fitted axis whose angle spans less than ``MIN_RANGE_DEG``.

    When one axis hardly turns, the data cannot tell which of the two is proximal (a
    rotation about a fixed axis commutes past the other), so the order alone does not name
    it; the guesses do (the little-turned axis is the one nearer its guess)."""
    need = f"need {MIN_RANGE_DEG:.0f} deg"
    if fg is not None and ag is not None:
        axis = sol.flexion_axis if key == "flexion" else sol.abduction_axis
        missing = "flexion" if _line_angle(axis, fg) <= _line_angle(axis, ag) else "abduction"
        raise FingerfitError(
            f"the motion did not excite the {_NAMES[missing]} axis (its angle spans "
            f"{span:.1f} deg; {need}): {_ADVICE}"
        )
    raise FingerfitError(
        f"the motion hardly turned the joint about a second axis (the less-turned axis's "
        f"angle spans {span:.1f} deg; {need}): {_ADVICE}, which turn both axes"
    )


def _check_order(
    sol: _Solution, order: str, fg: FloatArray, ag: FloatArray, strict: bool
) -> tuple[float, float] | None:
    """Whether the data make the other axis proximal than ``order`` says.

    The data tell the proximal axis from the distal one (second order); ``order`` only
    names them. If both fitted axes lie nearer the other axis's guess, the names would be
    swapped: a plausible-looking wrong answer, refused (``strict``) or returned as the
    mean angles (deg) of the axes to the guesses swapped and as named.
    """
    kept = _line_angle(sol.flexion_axis, fg) + _line_angle(sol.abduction_axis, ag)
    swapped = _line_angle(sol.flexion_axis, ag) + _line_angle(sol.abduction_axis, fg)
    if swapped >= kept:
        return None
    if not strict:
        return swapped / 2, kept / 2
    proximal = "abduction" if order == "flexion_first" else "flexion"
    raise FingerfitError(
        f"the data make the {_NAMES[proximal]} axis the proximal one (fixed in the "
        f"parent), against order={order!r} (the guessed axes fit "
        f"{swapped / 2:.0f} deg vs {kept / 2:.0f} deg swapped vs as ordered): check the "
        "axis order or the guesses"
    )


__all__ = ["MIN_RANGE_DEG", "SaddleFit", "fit_saddle"]
