"""The residual of the two-axis model and what the direction fits build on it: the
rotation left per frame after removing ``Rot(b, beta) Rot(a, theta)`` (and off a hinge),
its Jacobian in tangent coordinates of the two directions, and the cluster-robust
(sandwich) covariance of the direction parameters over grasp cycles. :mod:`.twoaxis`
fits the finger MP with them, :mod:`.saddle` the thumb's CMC, :mod:`.choice` chooses
between one and two axes."""

from __future__ import annotations

import numpy as np

from ..angles import two_axis_angles
from ..transforms import FloatArray, orthonormal_basis, skew
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


def _vee2(m: FloatArray) -> FloatArray:
    """``vee(M - M^T)`` ``(3, n)`` of matrices ``m (3, 3, n)`` (frames last):
    ``tr(M K_v^T) = v . vee(M - M^T)``."""
    return np.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])


def _left(k: FloatArray, m: FloatArray) -> FloatArray:
    """``k @ m[..., i]`` for every frame ``i``: ``(r // 3, 3, c, n)`` from ``k (r, 3)`` (``r //
    3`` stacked ``3 x 3`` matrices) and ``m (3, c, n)``, frames last; one matrix product."""
    return (k @ m.reshape(3, -1)).reshape(k.shape[0] // 3, 3, *m.shape[1:])


def _times(m: FloatArray, v: FloatArray) -> FloatArray:
    """``m[..., i] @ v[..., i]`` for every frame ``i``: ``(r, p, n)`` from matrices ``m (r, 3,
    n)`` and vectors ``v (3, p, n)``, frames last."""
    return m[:, 0, None] * v[0] + m[:, 1, None] * v[1] + m[:, 2, None] * v[2]


def skew_residual_jacobian(
    q: FloatArray, a: FloatArray, b: FloatArray, da: FloatArray, db: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`_skew_residual` and its derivative along moves of the two axes, analytically.

    Parameters
    ----------
    q : ndarray, shape (n, 3, 3)
        ``R(k) R_ref^T`` (parent frame).
    a, b : ndarray, shape (3,)
        Unit flexion and ab/adduction axes (parent frame).
    da, db : ndarray, shape (p, 3)
        Per parameter, the rate of change of ``a`` and of ``b`` (per unit of the
        parameter; each row perpendicular to its axis: unit vectors stay unit).

    Returns
    -------
    r : ndarray, shape (n, 3)
        The residual (rad; :func:`_skew_residual`'s up to rounding, from the ``E`` below).
    jac : ndarray, shape (n, 3, p)
        ``d r(k) / d x_p`` (rad per unit of the parameter), ``r`` the residual
        ``vee(E - E^T) / 2`` of ``E = Rot(a, -theta) Rot(b, -beta) Q`` with the angles of
        :func:`fingerfit.angles.two_axis_angles` carried along (variable projection: the
        angles are closed-form functions of the axes, not minimisers of the residual).

    Notes
    -----
    Every rotation moves by a small rotation of its own: ``d Rot(u, phi) =
    [w]x Rot(u, phi)`` with ``w = u dphi + sin(phi) du + (1 - cos(phi)) u x du`` (``u``
    unit, ``du`` perpendicular to it). With ``M = Rot(b, -beta) Q`` and ``E = Rot(a,
    -theta) M`` that gives ``dM = -[nu]x M``, ``nu = Rot(b, -beta) w_b``, and ``dE =
    -[Omega]x E``, ``Omega = Rot(a, -theta) (w_a + nu)``; then ``dr = -(tr(E) I - E)
    Omega / 2`` (``[w]x E + E^T [w]x = [(tr(E) I - E) w]x``). The angles' own
    derivatives follow from their formulas: ``beta = atan2(Qa . (b x a), Qa . a_perp)``
    (``a_perp = a - (a . b) b``) and ``theta = 2 atan2(a . vee(M - M^T), 1 + tr M)``.
    Every per-frame array has the frames last (long inner loops, as in
    :func:`_skew_residual`).
    """
    n, p = q.shape[0], da.shape[0]
    ka, kb = skew(a), skew(b)
    ab = a @ b
    ba, ap = kb @ a, a - ab * b
    # beta = atan2(s1, c1): s1 = Qa . (b x a) = tr(Q a (b x a)^T), c1 = Qa . a_perp, and
    # their derivatives, all linear functionals of Q: (2 + 2p, n). (The angles are those
    # of two_axis_angles, from the same traces.)
    d_ba = db @ ka - da @ kb  # d(b x a) = db x a + b x da, rows
    d_ap = da - np.outer(da @ b + db @ a, b) - ab * db
    w = np.concatenate(
        [
            [np.outer(ba, a), np.outer(ap, a)],
            ba[None, :, None] * da[:, None, :] + d_ba[:, :, None] * a,
            ap[None, :, None] * da[:, None, :] + d_ap[:, :, None] * a,
        ]
    )
    f = w.reshape(-1, 9) @ q.reshape(n, 9).T
    s1, c1, ds1, dc1 = f[0], f[1], f[2 : 2 + p], f[2 + p :]
    beta = np.arctan2(s1, c1)
    dbeta = (c1 * ds1 - s1 * dc1) / (s1 * s1 + c1 * c1)  # (p, n)
    # d Rot(b, beta) = [w_b]x Rot(b, beta); nu = Rot(b, -beta) w_b = b dbeta + sin(beta) db
    # - (1 - cos(beta)) b x db, (3, p, n); M = Rot(b, -beta) Q, (3, 3, n).
    sb, cb = np.sin(beta), 1.0 - np.cos(beta)
    nu = np.stack([db.T, -(db @ kb.T).T], axis=2).reshape(3 * p, 2) @ np.stack([sb, cb])
    nu = nu.reshape(3, p, n) + b[:, None, None] * dbeta
    qt = np.ascontiguousarray(q.transpose(1, 2, 0))
    kq = _left(np.vstack([kb, kb @ kb]), qt)
    m = qt - sb * kq[0] + cb * kq[1]
    vm, trm = _vee2(m), m[0, 0] + m[1, 1] + m[2, 2]
    # theta = 2 atan2(S, C): S = a . vee(M - M^T), C = 1 + tr M; dM = -[nu]x M gives
    # dC = nu . vee(M - M^T) and dS = da . vee(M - M^T) + nu . (M^T a - tr(M) a).
    big_s, big_c = a @ vm, 1.0 + trm
    theta = 2.0 * np.arctan2(big_s, big_c)
    dc, ds = _times(np.stack([vm, np.tensordot(a, m, axes=(0, 0)) - trm * a[:, None]]), nu)
    ds += da @ vm
    dtheta = 2.0 * (big_c * ds - big_s * dc) / (big_s * big_s + big_c * big_c)
    # E = Rot(a, -theta) M, dE = -[Omega]x E with Omega = Rot(a, -theta) (w_a + nu) and
    # Rot(a, -theta) w_a = a dtheta + sin(theta) da - (1 - cos(theta)) a x da:
    # Omega = a dtheta + nu + sin(theta) (da - a x nu) + (1 - cos(theta)) (a x a x nu - a x da).
    st, ct = np.sin(theta), 1.0 - np.cos(theta)
    k2 = np.vstack([ka, ka @ ka])
    km = _left(k2, m)
    e = m - st * km[0] + ct * km[1]
    knu = _left(k2, nu)
    omega = nu + a[:, None, None] * dtheta
    omega += (da.T[:, :, None] - knu[0]) * st
    omega += (knu[1] - (da @ ka.T).T[:, :, None]) * ct
    # dr = -(tr(E) I - E) Omega / 2, (3, p, n), returned as (n, 3, p).
    dr = _times(e, omega) - (e[0, 0] + e[1, 1] + e[2, 2]) * omega
    return 0.5 * _vee2(e).T, 0.5 * dr.transpose(2, 0, 1)


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
    ``(4, 3)`` (two for ``a``, then two for ``b``). The Jacobian is analytic
    (:func:`skew_residual_jacobian`); ``sw (n,)`` weighs each frame's three rows.
    """
    ta, tb = orthonormal_basis(a), orthonormal_basis(b)
    zero = np.zeros((2, 3))
    da, db = np.concatenate([ta[:2], zero]), np.concatenate([zero, tb[:2]])
    r, jac = skew_residual_jacobian(q, a, b, da, db)
    r, jac = r * sw[:, None], jac * sw[:, None, None]
    return r.ravel(), jac.reshape(-1, 4), np.concatenate([ta[:2], tb[:2]])


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
