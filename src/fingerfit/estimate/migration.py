"""Joint axis points, with or without rolling-contact migration, once the axes are known.

With the axes and the per-frame angles known, the point equations are linear.
For a hinge, the material point of the joint axis that is at ``p(theta) = c +
theta m`` (parent frame, reference coordinates) is fixed by the motion at angle
``theta`` (the rolling contact of the simulator and of ``docs/methods.md``). Its
child-sensor coordinates are ``R_ref^T (c + theta m - t_ref)``, so every frame
gives

    R(k) u_c - c + theta_k (Q_k - I) m = -t(k),      Q_k = R(k) R_ref^T,

with ``u_c = R_ref^T (c - t_ref)`` left free (the SCoRE form: no reliance on the
reference recording for the point itself). For a two-axis joint the flexion
axis point is carried by the ab/adduction ``Rot(b, beta_k)`` about ``c_b``:

    R(k) u_c + theta_k (Q_k - Rot_b) m - Rot_b c_a + (Rot_b - I) c_b = -t(k).

Unknowns ``u_c, c (or c_a), [c_b], [m]``; the directions along the axes are
null (any point of a line serves; ``(Q - I) a = 0``) and are projected out.
The ab/adduction point and the migration get weak zero-mean priors
(``docs/methods.md``) because they are seen only through a few degrees of
ab/adduction and through a term quadratic in the flexion angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray, axis_angle_matrix

PRIOR_OFFSET_MM = 5.0  # SD of the ab/adduction axis offset from the flexion centre
PRIOR_MIGRATION = 2.0  # SD of each migration component (mm/rad)


@dataclass(frozen=True)
class AxisPoints:
    """Points of the fitted axes (parent sensor frame at the reference posture, mm).

    Attributes
    ----------
    centre : ndarray, shape (3,)
        A point of the flexion axis (``c``, or ``c_a`` of a two-axis joint).
    centre_child : ndarray, shape (3,)
        The same point in the child sensor frame (``u_c``).
    abduction_point : ndarray, shape (3,) or None
        A point of the ab/adduction axis (two-axis joints).
    migration : ndarray, shape (3,) or None
        Centre migration per radian of flexion (mm/rad), perpendicular to the axis.
    rms_mm : float
        RMS residual of the point equations per frame (mm).
    """

    centre: FloatArray
    centre_child: FloatArray
    abduction_point: FloatArray | None
    migration: FloatArray | None
    rms_mm: float


def fit_axis_points(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    axis: FloatArray,
    theta: FloatArray,
    *,
    abduction_axis: FloatArray | None = None,
    beta: FloatArray | None = None,
    migration: bool = False,
    weights: FloatArray | None = None,
    noise_mm: float = 0.5,
) -> AxisPoints:
    """Least-squares points of known axes (and optionally the migration).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations (no NaN).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    reference_rotation : ndarray, shape (3, 3)
        Child-in-parent rotation at the reference posture.
    axis : ndarray, shape (3,)
        Unit flexion axis (parent frame).
    theta : ndarray, shape (n,)
        Flexion angle per frame (rad, 0 at the reference posture).
    abduction_axis : ndarray, shape (3,), optional
        Unit ab/adduction axis of a two-axis joint (parent frame).
    beta : ndarray, shape (n,), optional
        Ab/adduction angle per frame (rad), with ``abduction_axis``.
    migration : bool
        Also fit the rolling-contact migration ``m``.
    weights : ndarray, shape (n,), optional
        Frame weights.
    noise_mm : float
        Per-coordinate SD of the equations (mm): scales the priors.

    Returns
    -------
    AxisPoints
    """
    n = rotation.shape[0]
    w = np.ones(n) if weights is None else weights / np.mean(weights)
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    q = rotation @ reference_rotation.T
    two = abduction_axis is not None
    rb = axis_angle_matrix(abduction_axis, beta) if two else eye
    cols = [rotation, -rb]
    if two:
        cols.append(rb - eye)
    if migration:
        cols.append(theta[:, None, None] * (q - rb))
    blocks = np.concatenate(cols, axis=2)
    p = blocks.shape[2]
    sw = np.sqrt(w)
    big = (blocks * sw[:, None, None]).reshape(3 * n, p)
    rhs = (-translation * sw[:, None]).reshape(3 * n)
    ata = big.T @ big
    atb = big.T @ rhs
    nulls = [np.concatenate([reference_rotation.T @ axis, axis, np.zeros(p - 6)]) / np.sqrt(2)]
    lam = noise_mm**2
    k = 6
    if two:
        b = abduction_axis
        nulls.append(np.concatenate([np.zeros(6), b, np.zeros(p - 9)]))
        pb = np.eye(3) - np.outer(b, b)
        d = np.zeros((3, p))
        d[:, 3:6], d[:, 6:9] = -pb, pb
        ata += lam / PRIOR_OFFSET_MM**2 * (d.T @ d)
        k = 9
    if migration:
        e = np.zeros(p)
        e[k : k + 3] = axis
        nulls.append(e)
        d = np.zeros((3, p))
        d[:, k : k + 3] = np.eye(3)
        ata += lam / PRIOR_MIGRATION**2 * (d.T @ d)
    nv = np.array(nulls)
    proj = np.eye(p) - nv.T @ nv
    x = proj @ np.linalg.lstsq(proj @ ata @ proj + nv.T @ nv, proj @ atb, rcond=None)[0]
    resid = big @ x - rhs
    rms = float(np.sqrt(resid @ resid / max(w.sum(), 1e-12)))
    return AxisPoints(
        centre=x[3:6],
        centre_child=x[:3],
        abduction_point=x[6:9] if two else None,
        migration=x[k : k + 3] if migration else None,
        rms_mm=rms,
    )


__all__ = ["AxisPoints", "fit_axis_points"]
