"""Two-axis MP joint: flexion plus ab/adduction about axes that need not meet.

Model (the simulator's and ``docs/methods.md``): relative to the reference
posture the proximal phalanx turns first about the flexion axis ``a`` and the
result about the ab/adduction axis ``b`` fixed in the hand,

    Q(k) = R(k) R_ref^T = Rot(b, beta_k) Rot(a, theta_k),

with ``a`` and ``b`` in the parent (hand) sensor frame at the reference posture.

**Axes** -- variable projection: for given ``(a, b)`` the per-frame angles come
in closed form from :func:`fingerfit.angles.two_axis_angles` (the same
decomposition the angles use later), and the residual is the small rotation
``vee(E - E^T) / 2`` of ``E = Rot(a, theta)^T Rot(b, beta)^T Q`` (rad).
``scipy.optimize.least_squares`` minimises it (with its analytic Jacobian), first with
``b`` held perpendicular to ``a`` (three parameters), then with the tilt of ``b`` towards
``a`` freed only as far as the grasp cycles determine it (:mod:`.shrink`; the tilt is seen only at second order
and otherwise wanders along a flat valley: ``docs/methods.md``, "Numerical
stability"). Starts: the pooled hinge axis and, for ``b``, the dorsal direction
(finger direction x hinge axis, from the landmarks) -- or, without landmarks, both the
main direction of the swing left off the hinge and the direction perpendicular to it
and to the hinge axis (interior optima first, then the lower cost). With the
ab/adduction partly coupled to flexion during a grasp, the flexion axis is told apart
from the "effective" hinge axis only by the order of the two rotations (second order in
the angles) and by the ab/adduction that varies independently of flexion.

**Points** -- with the angles known the point equations are linear. A point
``u_c`` (child frame) of the flexion axis, ``c_a`` of the same line at the
reference posture and ``c_b`` of the ab/adduction axis (both parent frame):

    R(k) u_c + t(k) = Rot(b, beta_k) (c_a - c_b) + c_b.

The two null directions (along ``a`` and along ``b``) are projected out; the
offset of ``b`` from ``c_a`` perpendicular to ``b`` -- seen only through the few
degrees of ab/adduction -- is held at zero (intersecting axes) unless the grasp cycles
determine it (:mod:`.migration`, :mod:`.shrink`).

The search is bounded: the flexion axis within ``MAX_FLEXION_TILT_DEG`` of the
pooled hinge axis (flexion dominates a grasp, so the hinge axis is the flexion
axis tilted by the coupled ab/adduction) and the ab/adduction axis within
``MAX_ABDUCTION_TURN_DEG`` of its start (perpendicular to the hinge axis). Without
the bounds, data with no ab/adduction let the "second axis" take over the
flexion (``b`` turning onto ``a``).

**Is there a second axis?** (``TwoAxisFit.accepted``, the rule of
:func:`.joint.fit_joint`; the finger and thumb pipeline chooses by held-out prediction
instead, :mod:`.choice`.) Accepted only if (1) the
optimum is inside the bounds, (2) it halves the RMS rotation off the model
(``MAX_RESIDUAL_RATIO``), (3) the ab/adduction spans at least ``MIN_RANGE_DEG``
(5th-95th percentile) and (4) the ab/adduction varies independently of flexion from
grasp cycle to grasp cycle (:func:`rest_abduction_test`): the SD over the cycles of the
ab/adduction at zero flexion (per cycle, the intercept of a line fitted to ``beta``
against ``theta``) exceeds ``REST_SPREAD_RATIO`` times the RMS rotation off the
two-axis model with ``REST_SPREAD_CONFIDENCE`` (one-sided chi-square lower bound over
the cycles). Soft-tissue artefact driven by the finger's flexion repeats in every
cycle and passes (1)-(3) on data without ab/adduction; it fails (4). Otherwise the
joint stays a hinge.

The residual, its Jacobian and the cluster-robust covariance are in
:mod:`.twoaxis_residual`, test (4) in :mod:`.rest_abduction`; their names are importable
from here too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..angles import two_axis_angles
from ..transforms import FloatArray, cross3, orthonormal_basis, skew, unit
from .migration import fit_axis_points
from .rest_abduction import REST_SPREAD_CONFIDENCE as REST_SPREAD_CONFIDENCE
from .rest_abduction import REST_SPREAD_RATIO as REST_SPREAD_RATIO
from .rest_abduction import RestAbductionTest, rest_abduction_test
from .shrink import MIN_DATA_SHARE, data_share
from .twoaxis_residual import (
    _cluster_covariance,
    _hinge_residual,
    _tangent_coords,
    direction_jacobian,
    skew_residual_jacobian,
)
from .twoaxis_residual import _skew_residual as _skew_residual

MAX_RESIDUAL_RATIO = 0.5
MIN_RANGE_DEG = 1.5
MAX_FRAMES = 600  # the direction fit uses at most this many frames (evenly strided)
MAX_FLEXION_TILT_DEG = 20.0  # the flexion axis stays within this of the pooled hinge axis
MAX_ABDUCTION_TURN_DEG = 60.0  # the ab/adduction axis within this of its starting direction
# The tilt of b towards a enters the fit with the data's share 1 / (1 + (sd / HALF)^6) of
# the weight, sd its cluster-robust SD from the data alone; the rest holds it perpendicular.
HALF_TILT_SD_DEG = 1.5
_BOUNDS = np.tan(np.radians([MAX_FLEXION_TILT_DEG] * 2 + [MAX_ABDUCTION_TURN_DEG] * 2))


@dataclass(frozen=True)
class TwoAxisFit:
    """A fitted two-axis joint (parent sensor frame at the reference posture, mm, rad).

    Attributes
    ----------
    flexion_axis : ndarray, shape (3,)
        Unit ``a``.
    flexion_point : ndarray, shape (3,)
        ``c_a``: a point of the flexion axis at the reference posture (mm).
    abduction_axis : ndarray, shape (3,)
        Unit ``b`` (sign not yet oriented).
    abduction_point : ndarray, shape (3,)
        The point of the ab/adduction axis nearest the flexion axis (mm).
    rms_hinge_rad, rms_two_axis_rad : float
        RMS rotation off the model: best hinge vs the two-axis fit.
    abduction_range_deg : float
        5th-95th percentile span of the fitted ab/adduction over the frames.
    accepted : bool
        Whether the data support the second axis (see module docstring).
    interior : bool
        Whether the direction fit found an optimum inside its search bounds.
    flexion_sd_deg, abduction_sd_deg : float
        Cluster-robust SD over the grasp cycles of the flexion axis direction and of
        the turn of the ab/adduction axis about it (deg).
    tilt_sd_deg, tilt_data_share : float
        SD of the tilt of ``b`` towards ``a`` from the data alone (deg) and the data's
        weight in it (0: held perpendicular).
    offset_sd_mm, offset_data_share : float
        SD of the distance between the axes from the data alone (mm) and the data's
        weight in it (0: held intersecting).
    data_condition : float
        Condition number of the direction fit's data Jacobian (four parameters).
    rest_spread_deg, rest_spread_low_deg : float
        SD over the grasp cycles of the ab/adduction at zero flexion (deg) and its
        one-sided ``REST_SPREAD_CONFIDENCE`` lower confidence bound (:func:`rest_abduction_test`).
    rest_cycles : int
        Number of cycles in that test.
    """

    flexion_axis: FloatArray
    flexion_point: FloatArray
    abduction_axis: FloatArray
    abduction_point: FloatArray
    rms_hinge_rad: float
    rms_two_axis_rad: float
    abduction_range_deg: float
    accepted: bool
    interior: bool = True
    flexion_sd_deg: float = 0.0
    abduction_sd_deg: float = 0.0
    tilt_sd_deg: float = 0.0
    tilt_data_share: float = 1.0
    offset_sd_mm: float = 0.0
    offset_data_share: float = 1.0
    data_condition: float = 1.0
    rest_spread_deg: float = float("nan")
    rest_spread_low_deg: float = float("nan")
    rest_cycles: int = 0

    def stability_notes(self, joint: str = "MP", groups: str = "the grasp cycles") -> list[str]:
        """Quality-note sentences on how well the motion determines the two axes.

        ``joint`` names the joint and ``groups`` the groups of frames whose spread gave the
        SDs (the finger pipeline's defaults; :func:`.joint.fit_joint` passes its own).
        """
        z = 1.96
        notes = [
            f"two-axis {joint} conditioning: direction fit condition number "
            f"{self.data_condition:.0f}; flexion axis +/-{z * self.flexion_sd_deg:.2f} deg, "
            f"ab/adduction axis +/-{z * self.abduction_sd_deg:.2f} deg about it "
            f"(95 %, from the spread over {groups})"
        ]
        if self.tilt_data_share < 0.5:
            notes.append(
                f"ab/adduction axis held perpendicular to the flexion axis (data weight "
                f"{100 * self.tilt_data_share:.0f} %): the motion does not determine its "
                f"tilt (+/-{self.tilt_sd_deg:.0f} deg from the data alone)"
            )
        if self.offset_data_share < 0.5:
            notes.append(
                f"{joint} axes held intersecting (data weight {100 * self.offset_data_share:.0f} "
                f"%): the motion does not determine the distance between them "
                f"(+/-{self.offset_sd_mm:.1f} mm from the data alone)"
            )
        return notes


@dataclass(frozen=True)
class TwoAxisDirections:
    """Result of :func:`fit_two_axis_directions` (parent frame at the reference posture).

    Attributes
    ----------
    flexion_axis, abduction_axis : ndarray, shape (3,)
        Unit ``a`` and ``b``.
    rms_rad : float
        RMS residual rotation per frame (rad).
    interior : bool
        False when the optimum lies on the search bounds.
    flexion_sd_deg : float
        Cluster-robust SD of the flexion axis direction (largest over the two
        directions perpendicular to it; deg).
    abduction_sd_deg : float
        Cluster-robust SD of the turn of ``b`` about ``a`` (deg): how well the direction
        of the ab/adduction swing is known.
    tilt_sd_deg : float
        Cluster-robust SD (deg) of the tilt of ``b`` towards ``a`` from the data alone.
    tilt_data_share : float
        Weight (0-1) of the data in that tilt (:func:`.shrink.data_share` with
        ``HALF_TILT_SD_DEG``); the rest holds ``b`` perpendicular to ``a``.
    data_condition : float
        Condition number (largest / smallest singular value) of the data Jacobian
        over the four direction parameters, without the prior.
    """

    flexion_axis: FloatArray
    abduction_axis: FloatArray
    rms_rad: float
    interior: bool
    flexion_sd_deg: float
    abduction_sd_deg: float
    tilt_sd_deg: float
    tilt_data_share: float
    data_condition: float


def _turned(v0: FloatArray, e: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``unit(v0 + x[0] e[0] + x[1] e[1])`` ``(3,)`` and its derivative ``(2, 3)`` by ``x``."""
    v = v0 + x[0] * e[0] + x[1] * e[1]
    norm = np.linalg.norm(v)
    u = v / norm
    return u, (e[:2] - np.outer(e[:2] @ u, u)) / norm


def _free_axes(
    x: FloatArray, a0: FloatArray, ea: FloatArray, b0: FloatArray, eb: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Stage 2's axes: ``a`` turned from ``a0`` by ``x[:2]`` along ``ea[:2]``, ``b`` from
    ``b0`` by ``x[2:]`` along ``eb[:2]`` (:func:`_turned`), and their derivatives ``(4, 3)``
    each by the four parameters."""
    a, da = _turned(a0, ea, x[:2])
    b, db = _turned(b0, eb, x[2:])
    zero = np.zeros((2, 3))
    return a, b, np.concatenate([da, zero]), np.concatenate([zero, db])


def _perpendicular_axes(
    y: FloatArray, a0: FloatArray, ea: FloatArray, b0: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Stage 1's axes: ``a`` turned from ``a0`` by ``y[:2]`` (:func:`_turned`), ``b``
    perpendicular to it, turned by ``y[2]`` (rad) about ``a`` from ``b0``'s part
    perpendicular to ``a``; with their derivatives ``(3, 3)`` each by the three parameters."""
    a, da = _turned(a0, ea, y[:2])
    w = b0 - (b0 @ a) * a
    norm = np.linalg.norm(w)
    u = w / norm
    dw = -np.outer(da @ b0, a) - (b0 @ a) * da
    du = (dw - np.outer(dw @ u, u)) / norm
    c, s = np.cos(y[2]), np.sin(y[2])
    ka = skew(a)
    axu = ka @ u
    b = c * u + s * axu
    # rows: d(a x u) = da x u + a x du
    db = np.vstack([c * du + s * (da @ skew(u) + du @ ka.T), -s * u + c * axu])
    return a, b, np.vstack([da, np.zeros(3)]), db


class _Evaluations:
    """``fun`` and ``jac`` for :func:`scipy.optimize.least_squares` from one function of the
    parameters returning both (residual ``(m,)``, Jacobian ``(m, p)``): the Jacobian
    computed with a residual is handed back when asked for at the same parameters (the
    solver asks for it at each step it accepts, right after the residual)."""

    def __init__(self, both: Callable[..., tuple[FloatArray, FloatArray]]) -> None:
        self.both = both
        self.x: FloatArray | None = None
        self.j = np.zeros((0, 0))

    def fun(self, x: FloatArray, **kwargs: float) -> FloatArray:
        r, self.j = self.both(x, **kwargs)
        self.x = x.copy()
        return r

    def jac(self, x: FloatArray, **kwargs: float) -> FloatArray:
        if self.x is None or not np.array_equal(x, self.x):
            self.fun(x, **kwargs)
        return self.j


def fit_two_axis_directions(
    q: FloatArray,
    flexion_guess: FloatArray,
    weights: FloatArray | None = None,
    finger_direction: FloatArray | None = None,
    groups: FloatArray | None = None,
) -> TwoAxisDirections:
    """Flexion and ab/adduction directions minimising the two-axis residual.

    Two stages (``docs/methods.md``, "Numerical stability"): (1) ``b`` held
    perpendicular to ``a`` (three parameters, well determined); there the
    cluster-robust covariance over the grasp cycles gives how well the data alone
    see the tilt ``gamma`` of ``b`` towards ``a`` (SD ``sigma``); (2) all four
    parameters, with the Gaussian prior ``gamma ~ N(0, PRIOR_PERPENDICULAR_DEG)``
    (``sin gamma = a . b``) weighted against the data by ``sigma``. The tilt is seen
    by the data only at second order, so with realistic errors the prior holds it
    (the fit no longer wanders along a flat valley), while exact data still
    determine it exactly (``sigma = 0``).

    Parameters
    ----------
    q : ndarray, shape (n, 3, 3)
        ``R(k) R_ref^T`` (parent frame).
    flexion_guess : ndarray, shape (3,)
        Starting flexion axis (e.g. the pooled hinge axis).
    weights : ndarray, shape (n,), optional
        Frame weights.
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched finger (parent frame); the dorsal direction
        ``finger_direction x a`` is then the starting ab/adduction axis.
    groups : ndarray, shape (n,), optional
        Grasp cycle of each frame (clusters of the robust covariance); default: ten
        contiguous blocks.

    Returns
    -------
    TwoAxisDirections
        ``interior`` is False when the best solution lies on the bounds of the
        search (the flexion axis ``MAX_FLEXION_TILT_DEG`` from the hinge axis, or the
        ab/adduction axis ``MAX_ABDUCTION_TURN_DEG`` from its start): no two-axis
        optimum in the data.
    """
    a0 = unit(flexion_guess)
    n = q.shape[0]
    sw = np.sqrt(np.ones(n) if weights is None else weights / np.mean(weights))
    if groups is None:
        groups = np.arange(n) * 10 // max(n, 1)
    # Starting ab/adduction axes: the dorsal direction; without it, the main direction of
    # the rotation left off the hinge (the swing of a) and the direction perpendicular to
    # it and to a.
    if finger_direction is not None and np.linalg.norm(cross3(finger_direction, a0)) > 0.1:
        starts = [unit(cross3(finger_direction, a0))]
    else:
        swing = np.cross(a0, q @ a0) * sw[:, None]
        _, _, vt = np.linalg.svd(swing, full_matrices=False)
        pca = unit(vt[0] - (vt[0] @ a0) * a0)
        starts = [pca, cross3(a0, pca)]
    ea = orthonormal_basis(a0)
    lim = np.array([_BOUNDS[0], _BOUNDS[1], np.radians(MAX_ABDUCTION_TURN_DEG)])

    def data(a: FloatArray, b: FloatArray, da: FloatArray, db: FloatArray) -> tuple:
        # Weighted residual (3n,) and Jacobian (3n, p).
        r, jac = skew_residual_jacobian(q, a, b, da, db)
        return (r * sw[:, None]).ravel(), (jac * sw[:, None, None]).reshape(-1, len(da))

    best = None
    best_jac: FloatArray | None = None
    for b0 in starts:
        eb = orthonormal_basis(b0)

        def dirs(x: FloatArray, b0: FloatArray = b0, eb: FloatArray = eb) -> tuple:
            return _free_axes(x, a0, ea, b0, eb)

        def perp(y: FloatArray, b0: FloatArray = b0) -> tuple:
            return _perpendicular_axes(y, a0, ea, b0)

        stage1 = _Evaluations(lambda y, perp=perp: data(*perp(y)))
        s1 = least_squares(
            stage1.fun,
            np.zeros(3),
            jac=stage1.jac,
            bounds=(-lim, lim),
            x_scale=0.05,
            xtol=1e-10,
            ftol=1e-12,
        )
        a1, b1, _, _ = perp(s1.x)
        x1 = np.concatenate([_tangent_coords(a1, a0, ea), _tangent_coords(b1, b0, eb)])
        x1 = np.clip(x1, -0.99 * _BOUNDS, 0.99 * _BOUNDS)

        def resid(x: FloatArray, lam: float, dirs=dirs) -> tuple:
            # The data rows and the prior row on a . b.
            a, b, da, db = dirs(x)
            r, jac = data(a, b, da, db)
            return np.append(r, lam * (a @ b)), np.vstack([jac, lam * (da @ b + db @ a)])

        stage2 = _Evaluations(resid)

        # How well the data alone see the tilt of b towards a (cluster-robust, per
        # cycle), first at the perpendicular solution, then once more at the fit it
        # leads to (at the perpendicular one a real tilt shows up as misfit).
        a, b = a1, b1
        for _ in range(2):
            r, jac, basis = direction_jacobian(q, a, b, sw)
            jac_at = (a, b)
            cov, h_inv = _cluster_covariance(jac, r, groups)
            e = np.concatenate([[0.0, 0.0], unit(basis[2:] @ a)])  # tilt of b towards a
            var_tilt = max(float(e @ cov @ e), 0.0)
            share = data_share(np.degrees(np.sqrt(var_tilt)), HALF_TILT_SD_DEG)
            if share < MIN_DATA_SHARE:
                break
            # Prior row on a . b = sin(tilt): in cost units the data's curvature along the
            # tilt is worth 1 / var_tilt; the prior gets (1 - share) / share times that.
            curv = 1.0 / max(float(e @ h_inv @ e), 1e-300)
            lam = np.sqrt(curv * (1.0 - share) / share)
            sol = least_squares(
                stage2.fun,
                x1,
                jac=stage2.jac,
                bounds=(-_BOUNDS, _BOUNDS),
                x_scale=0.05,
                xtol=1e-12,
                ftol=1e-14,
                kwargs={"lam": lam},
            )
            a, b, _, _ = dirs(sol.x)
        if share < MIN_DATA_SHARE:
            # The data do not determine the tilt: b stays perpendicular to a.
            a, b, cost = a1, b1, s1.cost
            interior = bool(np.all(np.abs(s1.x) < 0.98 * lim))
        else:
            cost = 0.5 * float(np.sum(sol.fun[:-1] ** 2))
            interior = bool(np.all(np.abs(sol.x) < 0.98 * _BOUNDS))
        # Interior optima beat boundary ones; then the lower cost wins.
        if best is None or (interior, -cost) > (best[3], -best[2]):
            phi = np.concatenate([[0.0, 0.0], unit(basis[2:] @ cross3(a, b))])
            # The last Jacobian, kept when it was taken at these axes (the usual case).
            same = np.array_equal(jac_at[0], a) and np.array_equal(jac_at[1], b)
            best = (a, b, cost, interior, var_tilt, cov, share, float(phi @ cov @ phi))
            best_jac = jac if same else None
    a, b, cost, interior, var_tilt, cov1, share, var_phi = best
    jac = best_jac if best_jac is not None else direction_jacobian(q, a, b, sw)[1]
    sv = np.linalg.svd(jac, compute_uv=False)
    tilt_sd = float(np.degrees(np.sqrt(var_tilt))) if var_tilt > 0 else 0.0
    return TwoAxisDirections(
        flexion_axis=a,
        abduction_axis=b,
        rms_rad=float(np.sqrt(2.0 * cost / n)),
        interior=interior,
        flexion_sd_deg=float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(cov1[:2, :2]).max(), 0)))),
        abduction_sd_deg=float(np.degrees(np.sqrt(max(var_phi, 0.0)))),
        tilt_sd_deg=tilt_sd,
        tilt_data_share=float(share),
        data_condition=float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
    )


def _frame_inputs(
    rotation: FloatArray,
    reference_rotation: FloatArray,
    weights: FloatArray | None,
    groups: FloatArray | None,
) -> tuple[FloatArray, FloatArray, np.ndarray, int]:
    """``Q = R R_ref^T (n, 3, 3)``, the frame weights ``(n,)`` (mean 1), the grasp cycle of
    each frame ``(n,)`` (default ten contiguous blocks) and the stride of the direction
    search (at most :data:`MAX_FRAMES` frames)."""
    q = rotation @ reference_rotation.T
    w = np.ones(q.shape[0]) if weights is None else weights / np.mean(weights)
    stride = max(1, -(-q.shape[0] // MAX_FRAMES))
    if groups is None:
        groups = np.arange(q.shape[0]) * 10 // max(q.shape[0], 1)
    return q, w, np.asarray(groups), stride


def two_axis_directions(
    rotation: FloatArray,
    reference_rotation: FloatArray,
    flexion_guess: FloatArray,
    weights: FloatArray | None = None,
    finger_direction: FloatArray | None = None,
    groups: FloatArray | None = None,
) -> TwoAxisDirections:
    """The directions :func:`fit_two_axis` fits, alone (its arguments of the same names).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations (no NaN).
    reference_rotation : ndarray, shape (3, 3)
        Child-in-parent rotation at the reference posture.
    flexion_guess : ndarray, shape (3,)
        Pooled hinge axis (parent frame) to start from.
    weights, groups : ndarray, shape (n,), optional
        Frame weights and grasp cycle of each frame (default ten contiguous blocks).
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched finger in the parent frame.

    Returns
    -------
    TwoAxisDirections
        :func:`fit_two_axis_directions` on at most :data:`MAX_FRAMES` evenly strided frames
        (parent frame at the reference posture); pass it to :func:`fit_two_axis` to
        complete the joint without searching again.
    """
    q, w, groups, stride = _frame_inputs(rotation, reference_rotation, weights, groups)
    return fit_two_axis_directions(
        q[::stride], flexion_guess, w[::stride], finger_direction, groups[::stride]
    )


def fit_two_axis(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    flexion_guess: FloatArray,
    weights: FloatArray | None = None,
    noise_mm: float = 0.5,
    finger_direction: FloatArray | None = None,
    groups: FloatArray | None = None,
    directions: TwoAxisDirections | None = None,
) -> TwoAxisFit:
    """Fit a two-axis joint to the movement frames of one joint.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations (no NaN).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    reference_rotation : ndarray, shape (3, 3)
        Child-in-parent rotation at the reference posture.
    flexion_guess : ndarray, shape (3,)
        Pooled hinge axis (parent frame) to start from.
    weights : ndarray, shape (n,), optional
        Frame weights.
    noise_mm : float
        Per-coordinate SD of the point equations (mm), setting the strength of the
        prior on the offset between the axes.
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched finger in the parent frame (from the dorsal
        landmarks): gives the dorsal starting ab/adduction axis.
    groups : ndarray, shape (n,), optional
        Grasp cycle of each frame: the clusters of the robust variances that weigh the
        priors (``docs/methods.md``, "Numerical stability"); default ten contiguous
        blocks of frames.
    directions : TwoAxisDirections, optional
        :func:`two_axis_directions` of the same arguments, when already found: the
        direction search is not run again.

    Returns
    -------
    TwoAxisFit
    """
    q, w, groups, stride = _frame_inputs(rotation, reference_rotation, weights, groups)
    hinge_rms = float(np.sqrt(np.average(_hinge_residual(q, unit(flexion_guess)) ** 2, weights=w)))
    dr = directions
    if dr is None:
        dr = fit_two_axis_directions(
            q[::stride], flexion_guess, w[::stride], finger_direction, groups[::stride]
        )
    a, b, rms, interior = dr.flexion_axis, dr.abduction_axis, dr.rms_rad, dr.interior
    beta, theta = two_axis_angles(q, a, b)
    lo, hi = np.percentile(beta, [5, 95])
    span = float(np.degrees(hi - lo))
    rest = rest_abduction_test(beta, theta, groups, rms, w)
    accepted = (
        interior and rms <= MAX_RESIDUAL_RATIO * hinge_rms and span >= MIN_RANGE_DEG and rest.passed
    )

    pts = fit_axis_points(
        rotation,
        translation,
        reference_rotation,
        a,
        theta,
        abduction_axis=b,
        beta=beta,
        weights=w,
        noise_mm=noise_mm,
        groups=groups,
    )
    c_a, c_b = pts.centre, pts.abduction_point
    # The ab/adduction axis point nearest the flexion axis (common perpendicular foot).
    w0 = c_b - c_a
    ab = a @ b
    s = (ab * (a @ w0) - b @ w0) / (1.0 - ab * ab)
    return TwoAxisFit(
        a,
        c_a,
        b,
        c_b + s * b,
        hinge_rms,
        rms,
        span,
        bool(accepted),
        interior,
        flexion_sd_deg=dr.flexion_sd_deg,
        abduction_sd_deg=dr.abduction_sd_deg,
        tilt_sd_deg=dr.tilt_sd_deg,
        tilt_data_share=dr.tilt_data_share,
        offset_sd_mm=pts.offset_sd_mm,
        offset_data_share=pts.offset_data_share,
        data_condition=dr.data_condition,
        rest_spread_deg=rest.spread_deg,
        rest_spread_low_deg=rest.low_deg,
        rest_cycles=rest.cycles,
    )


__all__ = [
    "RestAbductionTest",
    "TwoAxisDirections",
    "TwoAxisFit",
    "fit_two_axis",
    "fit_two_axis_directions",
    "rest_abduction_test",
    "two_axis_directions",
]
