"""Two-axis MP joint: flexion plus ab/adduction about axes that need not meet.

Model (the simulator's and ``docs/methods.md``): relative to the reference
posture the proximal phalanx turns first about the flexion axis ``a`` and the
result about the ab/adduction axis ``b`` fixed in the hand,

    Q(k) = R(k) R_ref^T = Rot(b, beta_k) Rot(a, theta_k),

with ``a`` and ``b`` in the parent (hand) sensor frame at the reference posture.

**Axes** -- variable projection: for given ``(a, b)`` the per-frame angles come
in closed form from :func:`fingerfit.kinematics.two_axis_angles` (the same
decomposition the angles use later), and the residual is the small rotation
``vee(E - E^T) / 2`` of ``E = Rot(a, theta)^T Rot(b, beta)^T Q`` (rad).
``scipy.optimize.least_squares`` minimises it over the four direction
parameters, from the pooled hinge axis and, for ``b``, the dorsal direction
(finger direction x hinge axis, from the landmarks) -- or, without landmarks, from
both the main direction of the swing left off the hinge and the direction
perpendicular to it and to the hinge axis (interior optima first, then the lower
cost). With the ab/adduction partly coupled to flexion during a grasp, the
flexion axis is told apart from the "effective" hinge axis only by the order of
the two rotations (second order in the angles) and by the ab/adduction that
varies independently of flexion; the fit starts from the pooled hinge axis.

**Points** -- with the angles known the point equations are linear. A point
``u_c`` (child frame) of the flexion axis, ``c_a`` of the same line at the
reference posture and ``c_b`` of the ab/adduction axis (both parent frame):

    R(k) u_c + t(k) = Rot(b, beta_k) (c_a - c_b) + c_b.

The two null directions (along ``a`` and along ``b``) are projected out, and the
offset of ``b`` from ``c_a`` perpendicular to ``b`` -- seen only through the
few degrees of ab/adduction -- gets a weak prior towards intersecting axes
(:mod:`.migration`).

The search is bounded: the flexion axis within ``MAX_FLEXION_TILT_DEG`` of the
pooled hinge axis (flexion dominates a grasp, so the hinge axis is the flexion
axis tilted by the coupled ab/adduction) and the ab/adduction axis within
``MAX_ABDUCTION_TURN_DEG`` of its start (perpendicular to the hinge axis). Without
the bounds, data with no ab/adduction let the "second axis" take over the
flexion (``b`` turning onto ``a``).

**Is there a second axis?** The two-axis model replaces the hinge only if (1) the
optimum is inside the bounds, (2) it halves the RMS rotation off the model
(``MAX_RESIDUAL_RATIO``) and (3) the ab/adduction spans at least ``MIN_RANGE_DEG``
(5th-95th percentile); otherwise the joint stays a hinge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..kinematics import two_axis_angles
from ..transforms import FloatArray, axis_angle_matrix, orthonormal_basis, unit
from .migration import fit_axis_points

MAX_RESIDUAL_RATIO = 0.5
MIN_RANGE_DEG = 1.5
MAX_FRAMES = 600  # the direction fit uses at most this many frames (evenly strided)
MAX_FLEXION_TILT_DEG = 20.0  # the flexion axis stays within this of the pooled hinge axis
MAX_ABDUCTION_TURN_DEG = 60.0  # the ab/adduction axis within this of its starting direction
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


def _skew_residual(q: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Rotation ``(n, 3)`` (rad, small-angle) left after removing the two-axis motion.

    The angles are :func:`fingerfit.kinematics.two_axis_angles`; the residual is
    ``E = Rot(a, -theta) Rot(b, -beta) Q``.
    """
    beta, theta = two_axis_angles(q, a, b)
    e = axis_angle_matrix(a, -theta) @ (axis_angle_matrix(b, -beta) @ q)
    return 0.5 * np.stack(
        [e[:, 2, 1] - e[:, 1, 2], e[:, 0, 2] - e[:, 2, 0], e[:, 1, 0] - e[:, 0, 1]], axis=1
    )


def _hinge_residual(q: FloatArray, a: FloatArray) -> FloatArray:
    """Per-frame rotation off the hinge axis ``a`` (rad): ``|Q a - a|``."""
    return np.linalg.norm(q @ a - a, axis=1)


def fit_two_axis_directions(
    q: FloatArray,
    flexion_guess: FloatArray,
    weights: FloatArray | None = None,
    finger_direction: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, float, bool]:
    """Flexion and ab/adduction directions minimising the two-axis residual.

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

    Returns
    -------
    a, b : ndarray, shape (3,)
        Unit flexion and ab/adduction axes.
    rms : float
        Weighted RMS residual rotation (rad).
    interior : bool
        False when the best solution lies on the bounds of the search (the flexion
        axis ``MAX_FLEXION_TILT_DEG`` from the hinge axis, or the ab/adduction axis
        ``MAX_ABDUCTION_TURN_DEG`` from its start): no two-axis optimum in the data.
    """
    a0 = unit(flexion_guess)
    sw = np.sqrt(np.ones(q.shape[0]) if weights is None else weights / np.mean(weights))
    # Starting ab/adduction axes: the main direction of the rotation left off the hinge
    # (the swing of a), and the direction perpendicular to it and to a.
    swing = np.cross(a0, q @ a0) * sw[:, None]
    _, _, vt = np.linalg.svd(swing, full_matrices=False)
    pca = unit(vt[0] - (vt[0] @ a0) * a0)
    starts = [pca, np.cross(a0, pca)]
    if finger_direction is not None and np.linalg.norm(np.cross(finger_direction, a0)) > 0.1:
        starts = [unit(np.cross(finger_direction, a0))]
    ea = orthonormal_basis(a0)
    best = None
    for b0 in starts:
        eb = orthonormal_basis(b0)

        def dirs(x: FloatArray, b0: FloatArray = b0, eb: FloatArray = eb) -> tuple:
            a = unit(a0 + x[0] * ea[0] + x[1] * ea[1])
            b = unit(b0 + x[2] * eb[0] + x[3] * eb[1])
            return a, b

        def resid(x: FloatArray, dirs=dirs) -> FloatArray:
            return (_skew_residual(q, *dirs(x)) * sw[:, None]).ravel()

        sol = least_squares(
            resid, np.zeros(4), bounds=(-_BOUNDS, _BOUNDS), x_scale=0.05, xtol=1e-8, ftol=1e-10
        )
        interior = bool(np.all(np.abs(sol.x) < 0.98 * _BOUNDS))
        # Interior optima beat boundary ones; then the lower cost wins.
        if best is None or (interior, -sol.cost) > (best[3], -best[2]):
            best = (*dirs(sol.x), sol.cost, interior)
    a, b, cost, interior = best
    return a, b, float(np.sqrt(2 * cost / q.shape[0])), interior


def fit_two_axis(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    flexion_guess: FloatArray,
    weights: FloatArray | None = None,
    noise_mm: float = 0.5,
    finger_direction: FloatArray | None = None,
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

    Returns
    -------
    TwoAxisFit
    """
    q = rotation @ reference_rotation.T
    w = np.ones(q.shape[0]) if weights is None else weights / np.mean(weights)
    hinge_rms = float(np.sqrt(np.average(_hinge_residual(q, unit(flexion_guess)) ** 2, weights=w)))
    stride = max(1, -(-q.shape[0] // MAX_FRAMES))
    a, b, rms, interior = fit_two_axis_directions(
        q[::stride], flexion_guess, w[::stride], finger_direction
    )
    beta, theta = two_axis_angles(q, a, b)
    lo, hi = np.percentile(beta, [5, 95])
    span = float(np.degrees(hi - lo))
    accepted = interior and rms <= MAX_RESIDUAL_RATIO * hinge_rms and span >= MIN_RANGE_DEG

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
    )
    c_a, c_b = pts.centre, pts.abduction_point
    # The ab/adduction axis point nearest the flexion axis (common perpendicular foot).
    w0 = c_b - c_a
    ab = a @ b
    s = (ab * (a @ w0) - b @ w0) / (1.0 - ab * ab)
    return TwoAxisFit(a, c_a, b, c_b + s * b, hinge_rms, rms, span, bool(accepted), interior)


__all__ = ["TwoAxisFit", "fit_two_axis", "fit_two_axis_directions"]
