"""Rotation and rigid-transform helpers on time-first arrays.

Conventions (see ``docs/conventions.md``):

* rotation matrices ``R`` of shape ``(n, 3, 3)`` map sensor (body) coordinates
  into the parent/tracker frame: ``p_tracker = R @ p_sensor + t``;
* quaternions are scalar-first ``(w, x, y, z)`` in every array and file of this
  package; scipy's scalar-last order appears only inside this module;
* angles are radians, lengths millimetres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def matrix_from_quat_wxyz(quat: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """Rotation matrices from scalar-first unit quaternions.

    Parameters
    ----------
    quat : ndarray, shape (n, 4) or (4,)
        Quaternions ``(w, x, y, z)``; need not be exactly unit (they are
        normalised). Rows containing NaN give NaN matrices. Any strides.
    out : ndarray, shape (n, 3, 3), optional
        Where to write the matrices (float64, any strides, e.g. a run of rows of a
        recording's rotation array); no ``(n, 3, 3)`` temporary is made then.

    Returns
    -------
    ndarray, shape (n, 3, 3) or (3, 3)
        Rotation matrices (sensor -> tracker when the quaternion is a sensor
        orientation); ``out`` when given. The same bits with or without ``out``.
    """
    q = np.asarray(quat, dtype=float)
    single = q.ndim == 1
    q = np.atleast_2d(q)
    n = q.shape[0]
    if out is None:
        out = np.empty((n, 3, 3))
    elif out.shape != (n, 3, 3) or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape ({n}, 3, 3); got {out.dtype} {out.shape}")
    # A block of rows at a time, every temporary in cache; the operations are those of
    # q / np.linalg.norm(q, axis=1) and the formula below, in the same order (same bits).
    m = min(n, _QUAT_BLOCK)
    w, x, y, z, s, a, b, c, d, e = (np.empty(m) for _ in range(10))
    for lo in range(0, n, _QUAT_BLOCK):
        hi = min(lo + _QUAT_BLOCK, n)
        k = hi - lo
        qb, ob = q[lo:hi], out[lo:hi]
        w_, x_, y_, z_, s_ = w[:k], x[:k], y[:k], z[:k], s[:k]
        a_, b_, c_, d_, e_ = a[:k], b[:k], c[:k], d[:k], e[:k]
        # the norm: ((w^2 + x^2) + y^2) + z^2, as np.linalg.norm sums a row of 4
        np.multiply(qb[:, 0], qb[:, 0], out=s_)
        for j in (1, 2, 3):
            np.multiply(qb[:, j], qb[:, j], out=a_)
            s_ += a_
        np.sqrt(s_, out=s_)
        np.divide(qb[:, 0], s_, out=w_)
        np.divide(qb[:, 1], s_, out=x_)
        np.divide(qb[:, 2], s_, out=y_)
        np.divide(qb[:, 3], s_, out=z_)
        np.multiply(x_, x_, out=a_)  # a = x x, b = y y, c = z z
        np.multiply(y_, y_, out=b_)
        np.multiply(z_, z_, out=c_)
        _one_minus_twice(b_, c_, ob[:, 0, 0], s_)  # 1 - 2 (y y + z z)
        _one_minus_twice(a_, c_, ob[:, 1, 1], s_)  # 1 - 2 (x x + z z)
        _one_minus_twice(a_, b_, ob[:, 2, 2], s_)  # 1 - 2 (x x + y y)
        for u, v, p, r, lo_out, hi_out in (
            (x_, y_, z_, w_, ob[:, 0, 1], ob[:, 1, 0]),  # 2 (x y -+ z w)
            (x_, z_, y_, w_, ob[:, 2, 0], ob[:, 0, 2]),  # 2 (x z -+ y w)
            (y_, z_, x_, w_, ob[:, 1, 2], ob[:, 2, 1]),  # 2 (y z -+ x w)
        ):
            np.multiply(u, v, out=d_)
            np.multiply(p, r, out=e_)
            np.subtract(d_, e_, out=a_)
            np.multiply(a_, 2, out=lo_out)
            np.add(d_, e_, out=a_)
            np.multiply(a_, 2, out=hi_out)
    return out[0] if single else out


#: Rows per block of :func:`matrix_from_quat_wxyz` and :func:`quat_wxyz_columns` (their
#: temporaries stay in cache).
_QUAT_BLOCK = 4096


def _one_minus_twice(u: FloatArray, v: FloatArray, out: FloatArray, tmp: FloatArray) -> None:
    """``out = 1 - 2 (u + v)`` in that order of operations."""
    np.add(u, v, out=tmp)
    tmp *= 2
    np.subtract(1.0, tmp, out=out)


def quat_wxyz_from_matrix(matrix: FloatArray) -> FloatArray:
    """Scalar-first unit quaternions from rotation matrices.

    Markley's method, the one scipy's ``Rotation.from_matrix`` uses, vectorised: the
    quaternion is the column of the symmetric matrix built from ``R`` whose diagonal
    entry is largest (no component is found as a small difference of large numbers).
    It agrees with scipy to 2.3e-16 on rotation matrices; a matrix that is orthonormal only
    to rounding gives the quaternion of a rotation as close to it.

    Parameters
    ----------
    matrix : ndarray, shape (n, 3, 3) or (3, 3)
        Rotation matrices (sensor -> parent); rows with NaN or inf give NaN quaternions.

    Returns
    -------
    ndarray, shape (n, 4) or (4,)
        Quaternions ``(w, x, y, z)`` with ``w >= 0`` (C-contiguous).

    Raises
    ------
    ValueError
        A matrix with a non-positive determinant (a reflection or a null frame), named by
        its index.
    """
    m = np.asarray(matrix, dtype=float)
    q = quat_wxyz_columns(m)
    return np.ascontiguousarray(q[:, 0] if m.ndim == 2 else q.T)


def quat_wxyz_columns(matrix: FloatArray) -> FloatArray:
    """:func:`quat_wxyz_from_matrix` with the four components as rows: ``w``, ``x``, ``y``
    and ``z`` each a contiguous array (the columns of a table), the same bits.

    Parameters
    ----------
    matrix : ndarray, shape (n, 3, 3) or (3, 3)
        Rotation matrices (sensor -> parent), any strides.

    Returns
    -------
    ndarray, shape (4, n)
        ``w, x, y, z`` of each matrix, ``w >= 0``; NaN for a matrix with NaN or inf.

    Raises
    ------
    ValueError
        As :func:`quat_wxyz_from_matrix`.
    """
    m = np.asarray(matrix, dtype=float).reshape(-1, 3, 3)
    n = m.shape[0]
    out = np.empty((4, n))
    # A block of matrices at a time, every temporary in cache.
    for lo in range(0, n, _QUAT_BLOCK):
        hi = min(lo + _QUAT_BLOCK, n)
        _markley(m[lo:hi], out[:, lo:hi], lo)
    return out


#: The component (row of the candidates of :func:`_markley`) of ``w, x, y, z`` (rows) for
#: each largest diagonal entry (columns: ``R_xx``, ``R_yy``, ``R_zz``, the trace).
_PICK = np.array([[0, 1, 2, 3], [4, 7, 8, 0], [7, 5, 9, 1], [8, 9, 6, 2]], dtype=np.intp)


def _markley(m: FloatArray, out: FloatArray, first: int) -> None:
    """Quaternions ``out (4, k)`` of the rotation matrices ``m (k, 3, 3)`` (the ``first``-th
    on of an array, for the error); see :func:`quat_wxyz_from_matrix`."""
    k = m.shape[0]
    r = np.empty((9, k))
    r[...] = m.reshape(k, 9).T  # r[3 a + b] = R_ab, each contiguous
    ok = np.isfinite(r).all(axis=0)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    with np.errstate(invalid="ignore", over="ignore"):
        det = (
            r00 * (r11 * r22 - r12 * r21)
            - r01 * (r10 * r22 - r12 * r20)
            + r02 * (r10 * r21 - r11 * r20)
        )
        bad = np.flatnonzero(ok & ~(det > 0))
        if bad.size:
            raise ValueError(
                f"non-positive determinant {det[bad[0]]:.6g} (a reflection or a null frame) "
                f"in rotation matrix {first + bad[0]}"
            )
        trace = r00 + r11 + r22
        # the candidates: 4 w x, 4 w y, 4 w z, 4 w^2, 4 x^2, 4 y^2, 4 z^2, 4 x y, 4 x z, 4 y z
        c = np.empty((10, k))
        np.subtract(r21, r12, out=c[0])
        np.subtract(r02, r20, out=c[1])
        np.subtract(r10, r01, out=c[2])
        np.add(1, trace, out=c[3])
        for j, rjj in enumerate((r00, r11, r22)):
            c[4 + j] = 1 - trace + 2 * rjj
        np.add(r10, r01, out=c[7])
        np.add(r20, r02, out=c[8])
        np.add(r21, r12, out=c[9])
        # the first largest of R_xx, R_yy, R_zz, trace (as np.argmax picks it; a NaN only
        # in a matrix with NaN or inf, whose quaternion is NaN whatever is picked)
        top = np.maximum(r00, r11)
        later = (r22 > top).view(np.int8)
        later <<= 1
        choice = np.maximum((r11 > r00).view(np.int8), later)
        np.maximum(top, r22, out=top)
        later = (trace > top).view(np.int8)
        later *= 3
        np.maximum(choice, later, out=choice)
        at = _PICK[:, choice]
        at *= k
        at += np.arange(k)
        c.ravel().take(at, out=out)
        # divided by the norm, summed ((w^2 + x^2) + y^2) + z^2 as np.linalg.norm sums a row
        sq = out * out
        norm = sq[0] + sq[1]
        norm += sq[2]
        norm += sq[3]
        np.sqrt(norm, out=norm)
        out /= norm
    out *= np.where(out[0] < 0, -1.0, 1.0)
    out[:, ~ok] = np.nan


def axis_angle_matrix(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rotation matrices about one fixed unit axis (Rodrigues' formula).

    Parameters
    ----------
    axis : ndarray, shape (3,) or (m, 3)
        Unit rotation axis; or ``m`` axes, one per row of ``angle``.
    angle : ndarray, shape (n,) or (m, n)
        Angles in radians, right-hand rule about ``axis``.

    Returns
    -------
    ndarray, shape (n, 3, 3) or (m, n, 3, 3)
        With ``m`` axes, row ``i`` is ``axis_angle_matrix(axis[i], angle[i])``.
    """
    a = np.asarray(axis, dtype=float)
    th = np.asarray(angle, dtype=float)
    k = skew(a) if a.ndim == 1 else skew(a)[:, None]
    s = np.sin(th)[..., None, None]
    c = (1.0 - np.cos(th))[..., None, None]
    return np.eye(3) + s * k + c * (k @ k)


def skew(a: FloatArray) -> FloatArray:
    """Cross-product matrix ``(3, 3)`` of ``a (3,)``: ``skew(a) @ v == a x v``; of a stack
    ``(m, 3)``, ``(m, 3, 3)``."""
    if np.ndim(a) == 1:
        return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    a = np.asarray(a, dtype=float)
    k = np.zeros((*a.shape[:-1], 3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = a[..., 2], -a[..., 1], a[..., 0]
    return k


def cross3(u: FloatArray, v: FloatArray) -> FloatArray:
    """``u x v`` ``(3,)`` of two vectors ``(3,)``: the bits of :func:`numpy.cross` without its
    per-call cost (tens of microseconds; the joint fits take thousands of single products)."""
    u0, u1, u2 = np.asarray(u, dtype=float).tolist()
    v0, v1, v2 = np.asarray(v, dtype=float).tolist()
    return np.array([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0])


def orthonormal_basis(axis: FloatArray) -> FloatArray:
    """Rows ``e1, e2, a`` ``(3, 3)``: a right-handed orthonormal basis whose last row is the
    unit ``axis`` (``e2 = a x e1``); its transpose is a rotation taking z to ``axis``.

    ``axis`` may stack several axes, ``(m, 3)``: then ``(m, 3, 3)``, one basis each (the
    same bits as one at a time)."""
    a = unit(axis)
    helper = np.eye(3)[np.argmin(np.abs(a), axis=-1)]
    cross = cross3 if a.ndim == 1 else np.cross
    e1 = unit(cross(a, helper))
    return np.stack([e1, cross(a, e1), a], axis=-2)


def rotate_about_lines(
    points: FloatArray, steps: list[tuple[FloatArray, FloatArray, FloatArray]]
) -> FloatArray:
    """Rotate points about several lines in turn, one angle per frame for each line.

    Parameters
    ----------
    points : ndarray, shape (n, 3) or (3,)
        Points in the frame of the lines (mm).
    steps : list of (centre, axis, angle)
        Applied in order. ``centre``: a point on the line, ``(3,)`` or per frame
        ``(n, 3)`` (a migrating centre, mm); ``axis``: unit direction ``(3,)``;
        ``angle``: ``(n,)`` rad, right-hand rule about ``axis``.

    Returns
    -------
    ndarray, shape (n, 3)

    Notes
    -----
    Coordinates are kept in each line's orthonormal basis (``(3, n)`` layout), where
    the rotation is a 2D one; consecutive lines are joined by one constant 3x3
    product, so each step costs one BLAS product plus a few vector operations.
    """
    x = y = basis = centre_t = None
    for centre, axis, angle in steps:
        b = orthonormal_basis(axis)
        c = np.asarray(centre, dtype=float)
        c_t = c.T if c.ndim == 2 else c[:, None]  # (3, n) or (3, 1)
        if y is None:
            p = np.asarray(points, dtype=float)
            x = b @ ((p.T if p.ndim == 2 else p[:, None]) - c_t)
        else:
            x = (b @ basis.T) @ y + b @ (centre_t - c_t)
        cos, sin = np.cos(angle), np.sin(angle)
        y = np.empty((3, cos.shape[0]))
        np.subtract(x[0] * cos, x[1] * sin, out=y[0])
        np.add(x[0] * sin, x[1] * cos, out=y[1])
        y[2] = x[2]
        basis, centre_t = b, c_t
    out = basis.T @ y
    out += centre_t
    return np.ascontiguousarray(out.T)


def rotate_about_line(
    points: FloatArray, centre: FloatArray, axis: FloatArray, angle: FloatArray
) -> FloatArray:
    """Rotate points about a fixed line, one angle per frame.

    Parameters
    ----------
    points : ndarray, shape (n, 3) or (3,)
        Points in the same frame as ``centre`` and ``axis`` (mm).
    centre : ndarray, shape (3,) or (n, 3)
        A point on the line (mm).
    axis : ndarray, shape (3,)
        Unit direction of the line.
    angle : ndarray, shape (n,)
        Rotation angle per frame (rad, right-hand rule about ``axis``).

    Returns
    -------
    ndarray, shape (n, 3)
        Rotated points (mm).
    """
    return rotate_about_lines(points, [(centre, axis, np.asarray(angle, dtype=float))])


def apply_pose(rotation: FloatArray, translation: FloatArray, points: FloatArray) -> FloatArray:
    """Map points through per-frame rigid transforms: ``R @ p + t``.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
    translation : ndarray, shape (n, 3)
    points : ndarray, shape (n, 3) or (3,)
        One point per frame, or one fixed point.

    Returns
    -------
    ndarray, shape (n, 3)
    """
    p = np.broadcast_to(np.asarray(points, dtype=float), translation.shape)
    return np.einsum("nij,nj->ni", rotation, p) + translation


def apply_inverse_pose(
    rotation: FloatArray, translation: FloatArray, points: FloatArray
) -> FloatArray:
    """Map points through inverted per-frame transforms: ``R.T @ (p - t)``.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
    translation : ndarray, shape (n, 3)
    points : ndarray, shape (n, 3) or (3,)

    Returns
    -------
    ndarray, shape (n, 3)
    """
    d = np.asarray(points, dtype=float) - translation
    return np.einsum("nji,nj->ni", rotation, d)


def transform_from_pr(position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Homogeneous transforms from positions and rotation matrices.

    Parameters
    ----------
    position : ndarray, shape (n, 3) or (3,)
    rotation : ndarray, shape (n, 3, 3) or (3, 3)

    Returns
    -------
    ndarray, shape (n, 4, 4) or (4, 4)
    """
    p = np.asarray(position, dtype=float)
    r = np.asarray(rotation, dtype=float)
    out = np.zeros((*p.shape[:-1], 4, 4))
    out[..., :3, :3] = r
    out[..., :3, 3] = p
    out[..., 3, 3] = 1.0
    return out


def unit(v: FloatArray) -> FloatArray:
    """Normalise vectors along the last axis."""
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def row_norms(rows: FloatArray) -> FloatArray:
    """Euclidean norms of rows: ``(n,)`` from ``(n, k)``, any stride, in the rows' units
    (e.g. unit-free quaternion norms in any component order, mm for positions or steps).

    The same sum in the same order as ``np.linalg.norm(rows, axis=1)`` (so the same bits,
    an overflow giving inf alike) without its ``(n, k)`` temporaries, column by column
    (NumPy's reduction over a short last axis goes row by row): several times faster on
    a long recording.
    """
    s = rows[:, 0] * rows[:, 0]
    for j in range(1, rows.shape[1]):
        c = rows[:, j]
        s += c * c
    return np.sqrt(s, out=s)


def angle_between_axes(a: FloatArray, b: FloatArray) -> FloatArray:
    """Angle between two lines' directions ``(..., 3)``, ignoring sign (rad, in [0, pi/2]).

    Computed as ``atan2(|a x b|, |a . b|)``, accurate for tiny angles (unlike arccos).
    """
    ua, ub = unit(a), unit(b)
    return np.arctan2(np.linalg.norm(np.cross(ua, ub), axis=-1), np.abs(np.sum(ua * ub, axis=-1)))


def distance_point_to_line(point: FloatArray, centre: FloatArray, axis: FloatArray) -> FloatArray:
    """Distance of points ``(..., 3)`` to the line through ``centre`` along ``axis`` (mm)."""
    d = np.asarray(point, dtype=float) - centre
    return np.linalg.norm(np.cross(d, unit(axis)), axis=-1)


def distance_between_lines(c1: FloatArray, a1: FloatArray, c2: FloatArray, a2: FloatArray) -> float:
    """Shortest distance (mm) between the line through ``c1 (3,)`` along ``a1 (3,)`` and the
    line through ``c2`` along ``a2`` (the length of their common perpendicular; for
    parallel lines, the distance of ``c2`` to the first line)."""
    n = np.cross(a1, a2)
    norm = np.linalg.norm(n)
    if norm < 1e-12:  # parallel lines
        return float(distance_point_to_line(c2, c1, a1))
    return float(abs((np.asarray(c2) - c1) @ n) / norm)


def relative_pose(
    parent_rotation: FloatArray,
    parent_position: FloatArray,
    child_rotation: FloatArray,
    child_position: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Pose of a child sensor in its parent sensor's frame, per frame.

    Parameters
    ----------
    parent_rotation, child_rotation : ndarray, shape (n, 3, 3)
        Sensor -> tracker rotations.
    parent_position, child_position : ndarray, shape (n, 3)
        Sensor origins in tracker coordinates (mm).

    Returns
    -------
    R : ndarray, shape (n, 3, 3)
        ``R_p^T R_c`` (child -> parent coordinates).
    t : ndarray, shape (n, 3)
        ``R_p^T (t_c - t_p)``: the child origin in parent coordinates (mm).
    """
    r = np.matmul(np.swapaxes(parent_rotation, -1, -2), child_rotation)
    return r, apply_inverse_pose(parent_rotation, parent_position, child_position)


def rotation_angle(matrix: FloatArray) -> FloatArray:
    """Rotation angles ``(n,)`` (rad, in [0, pi]) of rotation matrices ``(n, 3, 3)``; NaN-safe.

    The norm of :func:`rotation_vector`, from the matrix directly:
    ``atan2(|axial(R)|, (trace(R) - 1) / 2)`` with ``axial(R)`` the sine-scaled axis
    ``(R32 - R23, R13 - R31, R21 - R12) / 2`` (accurate near 0 and near pi, unlike the
    arccosine of the trace alone). A matrix with a NaN gives NaN.
    """
    m = np.asarray(matrix, dtype=float)
    axial = np.stack(
        [m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1
    )
    cos = 0.5 * (m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2] - 1.0)
    return np.arctan2(0.5 * np.sqrt(np.einsum("ij,ij->i", axial, axial)), cos)


def rotation_vector(matrix: FloatArray) -> FloatArray:
    """Rotation vectors ``(n, 3)`` (axis times angle, rad) of matrices ``(n, 3, 3)``; NaN-safe."""
    m = np.asarray(matrix, dtype=float)
    out = np.full((m.shape[0], 3), np.nan)
    ok = np.isfinite(m).all(axis=(1, 2))
    if ok.any():
        from scipy.spatial.transform import Rotation  # on use: importing it takes 0.2-0.3 s

        out[ok] = Rotation.from_matrix(m[ok]).as_rotvec()
    return out
