"""Pooled hinge fit over all movement frames: SARA axis and SCoRE centre.

A direction fixed in both segments satisfies ``a_p = R(k) a_c`` every frame
(``R = R_p^T R_c``). Stacking ``[I  -R(k)] [a_p; a_c] = 0`` over the frames
gives the SARA system (Ehrig et al. 2007); its least-squares solution is the
right singular vector of the smallest singular value. Because every block is
``[I  -R(k)]``, the 6 x 6 normal matrix is

    M = [[W I, -S], [-S^T, W I]],   S = sum_k w_k R(k),  W = sum_k w_k,

whose eigenvalues are ``W +- sigma_i(S)``. So the axis is the leading singular
pair of the 3 x 3 matrix ``S`` -- ``a_p = u_1``, ``a_c = v_1`` -- and the
singular values of the stacked system are ``s6 = sqrt(W - sigma_1)``,
``s5 = sqrt(W - sigma_2)``: one pass over the frames and a 3 x 3 SVD, whatever
the recording length. For a hinge ``s5/s6`` is the RMS rotation about the axis
over the RMS rotation off it (the conditioning).

The centre is the SCoRE solution (Ehrig et al. 2006) of
``[I  -R(k)] [u_p; u_c] = t(k)`` through the same normal matrix, truncated in
the axis direction (the null vector): the point of the axis nearest the
sensors' origins. Where along the axis the joint centre lies is fixed later by
the sagittal plane (``docs/methods.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray


@dataclass(frozen=True)
class PooledHinge:
    """A hinge fitted to many frames at once (parent/child sensor frames, mm).

    Attributes
    ----------
    axis_parent, axis_child : ndarray, shape (3,)
        Unit axis in the parent and the child sensor frame (same sense:
        ``axis_parent ~ R(k) axis_child``).
    centre_parent, centre_child : ndarray, shape (3,)
        A point of the axis in each frame (mm); together they are the SCoRE
        centre truncated along the axis.
    singular_values : ndarray, shape (2,)
        ``(s5, s6)`` of the weighted stacked system (weights normalised to mean 1).
    axis_residual : ndarray, shape (n,)
        Per frame ``|a_p - R(k) a_c|`` (rad, small-angle): the rotation off the axis.
    centre_residual : ndarray, shape (n,)
        Per frame ``|u_p - R(k) u_c - t(k)|`` (mm).
    """

    axis_parent: FloatArray
    axis_child: FloatArray
    centre_parent: FloatArray
    centre_child: FloatArray
    singular_values: FloatArray
    axis_residual: FloatArray
    centre_residual: FloatArray

    @property
    def conditioning(self) -> float:
        """``s5 / s6``: RMS rotation about the axis over RMS rotation off it (inf if exact)."""
        s5, s6 = self.singular_values
        return float(s5 / s6) if s6 > 0 else float("inf")


def sara_axis(
    rotation: FloatArray, weights: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """SARA hinge axis from the summed rotation matrix.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations ``R_p^T R_c`` (no NaN).
    weights : ndarray, shape (n,), optional
        Non-negative frame weights (default 1).

    Returns
    -------
    axis_parent, axis_child : ndarray, shape (3,)
        Unit axis in the parent and child frames (``a_p ~ R(k) a_c``).
    singular_values : ndarray, shape (2,)
        ``(s5, s6)`` of the stacked system with weights normalised to mean 1.
    """
    w = np.ones(rotation.shape[0]) if weights is None else weights / np.mean(weights)
    s = np.einsum("n,nij->ij", w, rotation)
    u, sig, vt = np.linalg.svd(s)
    total = w.sum()
    s6, s5 = np.sqrt(np.maximum(total - sig[:2], 0.0))
    return u[:, 0], vt[0], np.array([s5, s6])


def pooled_hinge(
    rotation: FloatArray, translation: FloatArray, weights: FloatArray | None = None
) -> PooledHinge:
    """SARA axis and axis-truncated SCoRE centre over all given frames.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations (no NaN).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    weights : ndarray, shape (n,), optional
        Frame weights (default 1).

    Returns
    -------
    PooledHinge
    """
    n = rotation.shape[0]
    w = np.ones(n) if weights is None else weights / np.mean(weights)
    a_p, a_c, sv = sara_axis(rotation, w)
    # Normal equations of sum_k w |u_p - R u_c - t|^2:
    # [[W I, -S], [-S^T, W I]] [u_p; u_c] = [sum w t; -sum w R^T t].
    total = w.sum()
    s = np.einsum("n,nij->ij", w, rotation)
    m = np.block([[total * np.eye(3), -s], [-s.T, total * np.eye(3)]])
    rt = np.einsum("n,nji,nj->i", w, rotation, translation)
    rhs = np.concatenate([w @ translation, -rt])
    # Solve with the axis direction [a_p; a_c] projected out (the truncated solution).
    null = np.concatenate([a_p, a_c]) / np.sqrt(2.0)
    proj = np.eye(6) - np.outer(null, null)
    x = proj @ np.linalg.lstsq(proj @ m @ proj + np.outer(null, null), proj @ rhs, rcond=None)[0]
    u_p, u_c = x[:3], x[3:]
    axis_res = np.linalg.norm(a_p - rotation @ a_c, axis=1)
    centre_res = np.linalg.norm(u_p - rotation @ u_c - translation, axis=1)
    return PooledHinge(a_p, a_c, u_p, u_c, sv, axis_res, centre_res)


def leave_one_out_axes(rotation: FloatArray, labels: np.ndarray, folds: np.ndarray) -> FloatArray:
    """SARA axis (parent frame) without each fold: the leading left singular vector of the
    sum of the child-in-parent rotations less the fold's (one batched 3 x 3 SVD).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations (no NaN).
    labels : ndarray of int, shape (n,)
        Fold of each frame (e.g. its grasp cycle).
    folds : ndarray of int, shape (n_folds,)
        The folds, sorted (``np.unique(labels)``).

    Returns
    -------
    ndarray, shape (n_folds, 3)
        Unit axes, signed towards the SARA axis of every frame.
    """
    s_all = rotation.sum(axis=0)
    member = np.searchsorted(folds, labels)[None, :] == np.arange(folds.size)[:, None]
    s_fold = (member.astype(float) @ rotation.reshape(-1, 9)).reshape(-1, 3, 3)
    u, _, _ = np.linalg.svd(s_all[None] - s_fold)
    axes = u[:, :, 0]
    ref = np.linalg.svd(s_all)[0][:, 0]
    return axes * np.sign(axes @ ref)[:, None]


__all__ = ["PooledHinge", "leave_one_out_axes", "pooled_hinge", "sara_axis"]
