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
from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]


def matrix_from_quat_wxyz(quat: FloatArray) -> FloatArray:
    """Rotation matrices from scalar-first unit quaternions.

    Parameters
    ----------
    quat : ndarray, shape (n, 4) or (4,)
        Quaternions ``(w, x, y, z)``; need not be exactly unit (they are
        normalised). Rows containing NaN give NaN matrices.

    Returns
    -------
    ndarray, shape (n, 3, 3) or (3, 3)
        Rotation matrices (sensor -> tracker when the quaternion is a sensor
        orientation).
    """
    q = np.asarray(quat, dtype=float)
    single = q.ndim == 1
    q = np.atleast_2d(q)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty((q.shape[0], 3, 3))
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - z * w)
    out[:, 0, 2] = 2 * (x * z + y * w)
    out[:, 1, 0] = 2 * (x * y + z * w)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - x * w)
    out[:, 2, 0] = 2 * (x * z - y * w)
    out[:, 2, 1] = 2 * (y * z + x * w)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out[0] if single else out


def quat_wxyz_from_matrix(matrix: FloatArray) -> FloatArray:
    """Scalar-first unit quaternions from rotation matrices.

    Parameters
    ----------
    matrix : ndarray, shape (n, 3, 3) or (3, 3)
        Rotation matrices; rows with NaN give NaN quaternions.

    Returns
    -------
    ndarray, shape (n, 4) or (4,)
        Quaternions ``(w, x, y, z)`` with ``w >= 0``.
    """
    m = np.asarray(matrix, dtype=float)
    single = m.ndim == 2
    m = m.reshape(-1, 3, 3)
    out = np.full((m.shape[0], 4), np.nan)
    ok = np.isfinite(m).all(axis=(1, 2))
    if ok.any():
        xyzw = Rotation.from_matrix(m[ok]).as_quat()
        wxyz = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
        wxyz *= np.where(wxyz[:, :1] < 0, -1.0, 1.0)
        out[ok] = wxyz
    return out[0] if single else out


def axis_angle_matrix(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rotation matrices about one fixed unit axis (Rodrigues' formula).

    Parameters
    ----------
    axis : ndarray, shape (3,)
        Unit rotation axis.
    angle : ndarray, shape (n,)
        Angles in radians, right-hand rule about ``axis``.

    Returns
    -------
    ndarray, shape (n, 3, 3)
    """
    a = np.asarray(axis, dtype=float)
    th = np.asarray(angle, dtype=float)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    s = np.sin(th)[:, None, None]
    c = (1.0 - np.cos(th))[:, None, None]
    return np.eye(3) + s * k + c * (k @ k)


def rotate_about_line(
    points: FloatArray, centre: FloatArray, axis: FloatArray, angle: FloatArray
) -> FloatArray:
    """Rotate points about a fixed line, one angle per frame.

    Parameters
    ----------
    points : ndarray, shape (n, 3) or (3,)
        Points in the same frame as ``centre`` and ``axis`` (mm).
    centre : ndarray, shape (3,)
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
    a = np.asarray(axis, dtype=float)
    th = np.asarray(angle, dtype=float)
    v = np.asarray(points, dtype=float) - centre
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    cos, sin = np.cos(th), np.sin(th)
    # Rodrigues: v cos + (a x v) sin + a (a.v)(1 - cos), with BLAS products and in place.
    out = np.multiply.outer(sin, v @ k.T) if v.ndim == 1 else (v @ k.T) * sin[:, None]
    out += v * cos[:, None]
    out += np.multiply.outer((v @ a) * (1.0 - cos), a)
    out += centre
    return out


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


def rotation_vector(matrix: FloatArray) -> FloatArray:
    """Rotation vectors ``(n, 3)`` (axis times angle, rad) of matrices ``(n, 3, 3)``; NaN-safe."""
    m = np.asarray(matrix, dtype=float)
    out = np.full((m.shape[0], 3), np.nan)
    ok = np.isfinite(m).all(axis=(1, 2))
    if ok.any():
        out[ok] = Rotation.from_matrix(m[ok]).as_rotvec()
    return out
