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
The migration gets a weak zero-mean prior (``docs/methods.md``) because it is
seen only through a term quadratic in the flexion angle. The offset between the two
axes, seen only through a few degrees of ab/adduction, gets the same weak prior
without ``groups``; with them (the grasp cycles) it gets the data's weight from its
cluster-robust SD (:mod:`.shrink`) and, on realistic data, the axes are held
intersecting (``docs/methods.md``, "Numerical stability").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray, axis_angle_matrix
from .shrink import MIN_DATA_SHARE, cluster_score_outer, data_share

PRIOR_OFFSET_MM = 5.0  # SD of the ab/adduction axis offset from the flexion centre
PRIOR_MIGRATION = 2.0  # SD of each migration component (mm/rad)
# The offset between the axes of a two-axis joint enters with the data's share
# 1 / (1 + (sd / HALF)^6) of the weight (twoaxis.data_share); the rest holds them intersecting.
HALF_OFFSET_SD_MM = 0.15


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
    offset_sd_mm : float
        Two-axis joints fitted with ``groups``: cluster-robust SD (mm) of the distance
        between the axes from the data alone (NaN otherwise).
    offset_data_share : float
        The data's weight (0-1) in that offset (:func:`.shrink.data_share`; 0: the axes
        are held intersecting; NaN without ``groups``).
    """

    centre: FloatArray
    centre_child: FloatArray
    abduction_point: FloatArray | None
    migration: FloatArray | None
    rms_mm: float
    offset_sd_mm: float = float("nan")
    offset_data_share: float = float("nan")


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
    groups: FloatArray | None = None,
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
    groups : ndarray, shape (n,), optional
        Grasp cycle of each frame. With it, the prior on the offset between the two
        axes of a two-axis joint is weighted against the data by the cluster-robust
        (per-cycle) variance of that offset instead of ``noise_mm`` (``docs/methods.md``,
        "Numerical stability").

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
    data_ata = ata.copy()
    atb = big.T @ rhs
    prior = np.zeros((p, p))  # both priors
    extra = np.zeros((p, p))  # the migration prior only
    d_off = np.zeros((3, p))
    offset_sd = share = float("nan")
    nulls = [np.concatenate([reference_rotation.T @ axis, axis, np.zeros(p - 6)]) / np.sqrt(2)]
    lam = noise_mm**2
    k = 6
    if two:
        b = abduction_axis
        nulls.append(np.concatenate([np.zeros(6), b, np.zeros(p - 9)]))
        pb = np.eye(3) - np.outer(b, b)
        d_off[:, 3:6], d_off[:, 6:9] = -pb, pb
        prior += lam / PRIOR_OFFSET_MM**2 * (d_off.T @ d_off)
        k = 9
    if migration:
        e = np.zeros(p)
        e[k : k + 3] = axis
        nulls.append(e)
        d = np.zeros((3, p))
        d[:, k : k + 3] = np.eye(3)
        extra += lam / PRIOR_MIGRATION**2 * (d.T @ d)
    prior += extra
    nv = np.array(nulls)
    proj = np.eye(p) - nv.T @ nv

    def solve(normal: FloatArray) -> FloatArray:
        return proj @ np.linalg.lstsq(proj @ normal @ proj + nv.T @ nv, proj @ atb, rcond=None)[0]

    x = solve(ata + prior)
    if two and groups is not None:
        # Offset along the common perpendicular of the axes: how well the data alone see
        # it, per cycle (cluster-robust); the prior then weighs 1 / PRIOR_OFFSET_MM^2
        # against that.
        nrm = np.cross(axis, abduction_axis)
        h_inv = proj @ np.linalg.pinv(proj @ data_ata @ proj) @ proj
        r = (big @ x - rhs).reshape(n, 3)
        outer, g = cluster_score_outer(np.einsum("nij,ni->nj", big.reshape(n, 3, p), r), groups)
        cov = h_inv @ outer @ h_inv * (g / max(g - 1, 1))
        # Both directions across b: along the common perpendicular and along a.
        scales, var_d = [], 0.0
        for v in (nrm, axis - (axis @ abduction_axis) * abduction_axis):
            g = np.zeros(p)
            g[3:6], g[6:9] = -v, v
            g /= max(np.linalg.norm(v), 1e-12)
            var = float(g @ cov @ g)
            var_d = var_d if v is not nrm else var
            scales.append(var / max(float(g @ h_inv @ g), 1e-300))
        offset_sd = float(np.sqrt(max(var_d, 0.0)))
        share = data_share(offset_sd, HALF_OFFSET_SD_MM)
        if share < MIN_DATA_SHARE:
            # The axes are held intersecting: c_b = c_a (the c_b columns join c_a's).
            keep = [i for i in range(p) if not 6 <= i < 9]
            merged = big.copy()
            merged[:, 3:6] += big[:, 6:9]
            sub = merged[:, keep]
            sub_ata = sub.T @ sub + extra[np.ix_(keep, keep)]
            snv = np.array([nv[0][keep]] + ([nv[-1][keep]] if migration else []))
            sproj = np.eye(len(keep)) - snv.T @ snv
            y = (
                sproj
                @ np.linalg.lstsq(
                    sproj @ sub_ata @ sproj + snv.T @ snv, sproj @ (sub.T @ rhs), rcond=None
                )[0]
            )
            x = np.zeros(p)
            x[keep] = y
            x[6:9] = y[3:6]
        else:
            # The data's curvature along the offset is worth 1 / var; the prior gets
            # (1 - share) / share times that, i.e. scale (1 - share) / (share var) per mm^2.
            scale = float(np.mean(scales)) * (1.0 - share) / (share * max(var_d, 1e-300))
            x = solve(data_ata + extra + scale * (d_off.T @ d_off))
    resid = big @ x - rhs
    rms = float(np.sqrt(resid @ resid / max(w.sum(), 1e-12)))
    return AxisPoints(
        centre=x[3:6],
        centre_child=x[:3],
        abduction_point=x[6:9] if two else None,
        migration=x[k : k + 3] if migration else None,
        rms_mm=rms,
        offset_sd_mm=offset_sd,
        offset_data_share=share,
    )


__all__ = ["AxisPoints", "fit_axis_points"]
