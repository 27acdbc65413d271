"""The residual of the two-axis model and what the direction fits build on it: the
rotation left per frame after removing ``Rot(b, beta) Rot(a, theta)`` (and off a hinge),
its Jacobian in tangent coordinates of the two directions, and the cluster-robust
(sandwich) covariance of the direction parameters over grasp cycles. :mod:`.twoaxis`
fits the finger MP with them, :mod:`.saddle` the thumb's CMC, :mod:`.choice` chooses
between one and two axes."""

from __future__ import annotations

import numpy as np

from ..angles import two_axis_angles
from ..transforms import FloatArray, orthonormal_basis, skew, unit
from .shrink import cluster_score_outer

# L_k = skew(e_k)^T: tr(M L_k) = M[r, c] - M[c, r] for (r, c) = (2, 1), (0, 2), (1, 0).
_VEE = np.stack([skew(e).T for e in np.eye(3)])


def _skew_residual(q: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Rotation ``(n, 3)`` (rad, small-angle) left after removing the two-axis motion.

    The angles are :func:`fingerfit.angles.two_axis_angles`; the residual is
    ``vee(E - E^T) / 2`` of ``E = Rot(a, -theta) Rot(b, -beta) Q``.

    With Rodrigues' ``Rot(a, -theta) = sum_i c_i K_a^i`` (``c = 1, -sin theta,
    1 - cos theta``; likewise ``d`` for ``b`` and ``beta``), each component ``k`` is
    ``sum_ij c_i d_j tr(Q L_k K_a^i K_b^j) / 2`` with ``L_k = skew(e_k)^T``: 27 fixed
    linear functionals of ``Q``, one matrix product for all frames (no per-frame 3 x 3
    products; the least-squares fits evaluate this hundreds of times per joint).
    """
    beta, theta = two_axis_angles(q, a, b)
    n = q.shape[0]
    ka, kb = skew(a), skew(b)
    pa = np.stack([np.eye(3), ka, ka @ ka])
    pb = np.stack([np.eye(3), kb, kb @ kb])
    # Row (i, j, k): tr(Q C) = sum(Q * C^T) for C = L_k K_a^i K_b^j.
    w = 0.5 * np.einsum("kxy,iyz,jzw->ijkwx", _VEE, pa, pb).reshape(27, 9)
    t = (w @ q.reshape(n, 9).T).reshape(3, 3, 3, n)
    u = t[:, 0] - np.sin(beta) * t[:, 1] + (1.0 - np.cos(beta)) * t[:, 2]
    return (u[0] - np.sin(theta) * u[1] + (1.0 - np.cos(theta)) * u[2]).T


def _hinge_residual(q: FloatArray, a: FloatArray) -> FloatArray:
    """Per-frame rotation off the hinge axis ``a`` (rad): ``|Q a - a|``."""
    return np.linalg.norm(q @ a - a, axis=1)


def _tangent_coords(v: FloatArray, v0: FloatArray, basis: FloatArray) -> FloatArray:
    """Coordinates ``x (2,)`` with ``unit(v0 + x[0] e0 + x[1] e1) = v`` (``v . v0 > 0``)."""
    return np.array([v @ basis[0], v @ basis[1]]) / (v @ v0)


def direction_jacobian(
    q: FloatArray, a: FloatArray, b: FloatArray, sw: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Weighted residual ``(3n,)`` and its Jacobian ``(3n, 4)`` in tangent coordinates.

    The four coordinates turn ``a`` and ``b`` (rad) towards the two vectors of
    :func:`orthonormal_basis` perpendicular to each; returned with those vectors
    ``(4, 3)`` (two for ``a``, then two for ``b``).
    """
    ta, tb = orthonormal_basis(a), orthonormal_basis(b)

    def res(z: FloatArray) -> FloatArray:
        aa = unit(a + z[0] * ta[0] + z[1] * ta[1])
        bb = unit(b + z[2] * tb[0] + z[3] * tb[1])
        return (_skew_residual(q, aa, bb) * sw[:, None]).ravel()

    h = 1e-6
    jac = np.stack([(res(h * e) - res(-h * e)) / (2 * h) for e in np.eye(4)], axis=1)
    return res(np.zeros(4)), jac, np.concatenate([ta[:2], tb[:2]])


def _cluster_covariance(
    jac: FloatArray, resid: FloatArray, groups: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Cluster-robust (sandwich) covariance of the direction parameters.

    Parameters
    ----------
    jac : ndarray, shape (3n, p)
    resid : ndarray, shape (3n,)
    groups : ndarray, shape (n,)
        Cluster label of each frame (grasp cycle).

    Returns
    -------
    cov : ndarray, shape (p, p)
        ``H^+ M H^+`` with ``H = J^T J`` and ``M`` the covariance of the per-cluster
        scores ``J_c^T r_c`` (centred, times ``G / (G - 1)``): a systematic error
        repeated within a cycle counts once per cycle, not once per frame.
    h_inv : ndarray, shape (p, p)
        ``H^+``.
    """
    outer, g = cluster_score_outer(jac * resid[:, None], np.repeat(np.asarray(groups), 3))
    m = outer * (g / max(g - 1, 1))
    h_inv = np.linalg.pinv(jac.T @ jac)
    return h_inv @ m @ h_inv, h_inv
