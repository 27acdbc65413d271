"""The angle maths of one joint: the angle of a hinge and the two angles of a two-axis joint
from the parent and child sensors, by projection (paper Fig. 6) or by swing-twist.

:mod:`fingerfit.kinematics` runs these over every joint of a recording (its docstring
has the two methods); :mod:`fingerfit.estimate` uses the same twist and two-axis angles,
so a fit and the angles of the fitted model are one implementation.
Angles rad, lengths mm (``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np

from .transforms import FloatArray, cross3, rotate_about_line, skew


def projection_angle(
    parent_rotation: FloatArray,
    parent_position: FloatArray,
    child_position: FloatArray,
    centre: FloatArray,
    axis: FloatArray,
    reference_offset: FloatArray,
) -> FloatArray:
    """Joint angle by the paper's projection method (Fig. 6).

    Parameters
    ----------
    parent_rotation : ndarray, shape (n, 3, 3)
        Parent sensor rotations (sensor -> tracker).
    parent_position, child_position : ndarray, shape (n, 3)
        Parent and child sensor origins, tracker coordinates (mm).
    centre, axis : ndarray, shape (3,)
        Joint centre (mm) and unit axis in the **parent sensor frame**.
    reference_offset : ndarray, shape (3,)
        Child sensor origin in the parent frame at the reference posture (mm).

    Returns
    -------
    ndarray, shape (n,)
        Angle about ``axis`` (rad, right-hand rule), 0 at the reference posture.
    """
    p0 = reference_offset - centre
    p0 = p0 - (p0 @ axis) * axis
    basis = np.column_stack([np.cross(axis, p0), p0])  # (3, 2): u, p0
    # r = R^T (t_c - t_p) is the child origin in the parent frame; d = r - c.
    r = np.einsum("ni,nij->nj", child_position - parent_position, parent_rotation)
    yx = r @ basis
    yx -= centre @ basis
    return np.arctan2(yx[:, 0], yx[:, 1])


def relative_rotation(
    parent_rotation: FloatArray, child_rotation: FloatArray, reference: FloatArray
) -> FloatArray:
    """Rotation of the child away from the reference posture, in the parent sensor frame.

    Parameters
    ----------
    parent_rotation, child_rotation : ndarray, shape (n, 3, 3)
        Sensor -> tracker rotations.
    reference : ndarray, shape (3, 3)
        Child-in-parent rotation ``R_p^T R_c`` at the reference posture.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        ``Q = R_p^T R_c reference^T``: identity at the reference posture; for a
        hinge it is the rotation about the parent-frame axis by the joint angle.
    """
    g = np.matmul(np.swapaxes(parent_rotation, 1, 2), child_rotation)
    return (g.reshape(-1, 3) @ reference.T).reshape(g.shape)


# Swing-twist angles need only traces tr(Q C) for a few constant matrices C (and Q a):
# with Q flattened to (n, 9) each is one column of a single BLAS product.


def _traces(q: FloatArray, mats: FloatArray) -> FloatArray:
    """``tr(Q C_k)`` for ``q (n, 3, 3)`` and ``mats (k, 3, 3)``: ``(n, k)``."""
    n, k = q.shape[0], mats.shape[0]
    return q.reshape(n, 9) @ np.swapaxes(mats, 1, 2).reshape(k, 9).T


def _twist(tr_identity: FloatArray, tr_skew: FloatArray) -> FloatArray:
    """``2 atan2(tr(Q K_a^T), 1 + tr Q)``: the twist about ``a`` (rad)."""
    return 2.0 * np.arctan2(tr_skew, 1.0 + tr_identity)


def twist_angle(rotation: FloatArray, axis: FloatArray) -> FloatArray:
    """Twist angle of rotations about an axis (swing-twist decomposition).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Rotations ``Q`` (e.g. from :func:`relative_rotation`).
    axis : ndarray, shape (3,)
        Unit axis ``a`` in the same frame.

    Returns
    -------
    ndarray, shape (n,)
        ``theta = 2 atan2(vee(Q - Q^T)·a, 1 + tr Q)`` (rad, in (-pi, pi]): the angle
        of the rotation about ``a`` that leaves a pure swing (a rotation about an
        axis perpendicular to ``a``) when removed. Exact for ``Q = Rot(a, theta)``.
    """
    t = _traces(rotation, np.stack([np.eye(3), skew(axis).T]))
    return _twist(t[:, 0], t[:, 1])


def two_axis_angles(
    rotation: FloatArray, distal_axis: FloatArray, proximal_axis: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Angles of a two-axis joint ``Q = Rot(b, beta) Rot(a, theta)``.

    A finger's MP has its ab/adduction axis proximal (``b``) and its flexion axis distal
    (``a``); the thumb's CMC and MCP the reverse (:mod:`fingerfit.digits`).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Rotations ``Q`` away from the reference posture (parent frame).
    distal_axis : ndarray, shape (3,)
        Unit distal axis ``a`` (parent frame at the reference posture; carried by the
        rotation about ``b``).
    proximal_axis : ndarray, shape (3,)
        Unit proximal axis ``b``, fixed in the parent frame, not parallel to ``a``.

    Returns
    -------
    beta, theta : ndarray, shape (n,)
        Angles about the proximal and the distal axis (rad). ``beta`` is the angle
        about ``b`` from the part of ``a`` perpendicular to ``b`` to that of ``Q a``
        (the distal axis is all the proximal rotation moves); ``theta`` is the twist
        of ``Rot(b, -beta) Q`` about ``a``. Exact when ``Q`` is of the two-axis form.
    """
    a, b = distal_axis, proximal_axis
    n = rotation.shape[0]
    ap = a - (a @ b) * b
    # beta = atan2((Q a)·(b x ap), (Q a)·ap), and (Q a)·w = tr(Q a w^T). The twist needs
    # tr(X Rot(b, -beta) Q) = tr(Q X) - sin(beta) tr(Q X K_b) + (1 - cos(beta)) tr(Q X K_b^2)
    # for X = I and K_a^T. All ten traces come from one product.
    kb = skew(b)
    xs, ys = (np.eye(3), skew(a).T), (np.eye(3), kb, kb @ kb)
    mats = [np.outer(a, cross3(b, ap)), np.outer(a, ap)] + [x @ y for x in xs for y in ys]
    t = _traces(rotation, np.stack(mats))
    beta = np.arctan2(t[:, 0], t[:, 1])
    t = t[:, 2:].reshape(n, 2, 3)
    s, c = np.sin(beta)[:, None], (1.0 - np.cos(beta))[:, None]
    tr = t[:, :, 0] - s * t[:, :, 1] + c * t[:, :, 2]
    return beta, _twist(tr[:, 0], tr[:, 1])


def _projected(r: FloatArray, centre: FloatArray, axis: FloatArray, r0: FloatArray) -> FloatArray:
    """Angle ``(n,)`` about the line (centre, axis) from ``r0 (3,)`` to points ``r (n, 3)``."""
    p0 = r0 - centre
    p0 = p0 - (p0 @ axis) * axis
    basis = np.column_stack([np.cross(axis, p0), p0])
    yx = (r - centre) @ basis
    return np.arctan2(yx[:, 0], yx[:, 1])


def two_axis_projection_angles(
    points: FloatArray,
    reference_point: FloatArray,
    distal_point: FloatArray,
    distal_axis: FloatArray,
    proximal_point: FloatArray,
    proximal_axis: FloatArray,
    iterations: int = 8,
) -> tuple[FloatArray, FloatArray]:
    """Two-axis joint angles from the child sensor origin alone (projection family).

    Solves ``r = Rot_b(beta) [Rot_a(theta) (r0 - c_a) + c_a - c_b] + c_b`` for
    ``(beta, theta)`` per frame by Gauss-Newton (vectorised over frames), started
    from the sequential projections about ``b`` and then ``a``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Child sensor origin in the parent sensor frame (mm).
    reference_point : ndarray, shape (3,)
        The same at the reference posture (mm).
    distal_point, distal_axis : ndarray, shape (3,)
        A point (mm) and the unit direction of the distal axis ``a`` (parent frame).
    proximal_point, proximal_axis : ndarray, shape (3,)
        The same for the proximal axis ``b``.
    iterations : int
        Gauss-Newton steps.

    Returns
    -------
    beta, theta : ndarray, shape (n,)
        Angles about the proximal and the distal axis (rad).
    """
    a, b, ca, cb = distal_axis, proximal_axis, distal_point, proximal_point
    beta = _projected(points, cb, b, reference_point)
    theta = _projected(rotate_about_line(points, cb, b, -beta), ca, a, reference_point)
    v = reference_point - ca
    for _ in range(iterations):
        rv = rotate_about_line(v, np.zeros(3), a, theta)  # (n, 3)
        f = rotate_about_line(rv + ca, cb, b, beta)
        jt = rotate_about_line(np.cross(a, rv), np.zeros(3), b, beta)
        jb = np.cross(b, f - cb)
        e = points - f
        g11, g12, g22 = (jt * jt).sum(1), (jt * jb).sum(1), (jb * jb).sum(1)
        r1, r2 = (jt * e).sum(1), (jb * e).sum(1)
        det = g11 * g22 - g12 * g12
        det = np.where(np.abs(det) > 1e-12, det, np.inf)
        theta = theta + (g22 * r1 - g12 * r2) / det
        beta = beta + (g11 * r2 - g12 * r1) / det
    return beta, theta
