"""Centre of rotation from two 6-DOF sensors (O'Brien et al. 2000).

A joint centre has fixed coordinates ``u_p`` in the parent sensor frame and
``u_c`` in the child's. In the relative form, each frame gives
``[I  -R(k)] [u_p; u_c] = t(k)`` with ``R = R_p^T R_c`` and
``t = R_p^T (t_c - t_p)``. Stacked over the frames of one movement period this
is a ``3N x 6`` least-squares problem. For a hinge it is rank-deficient: the
axis ``[a_p; a_c]`` spans the null space, so the **untruncated** solution lies
at a noise-driven place along the axis -- which is what lets the per-cycle
centres of the paper spread along, and so reveal, the axis. Its singular
values tell the conditioning: ``s5/s6`` large means the motion separates the
hinge direction well (``docs/methods.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray


@dataclass(frozen=True)
class CentreFit:
    """Least-squares centre of rotation of one movement period.

    Attributes
    ----------
    parent_point : ndarray, shape (3,)
        ``u_p``: the centre in the parent sensor frame (mm).
    child_point : ndarray, shape (3,)
        ``u_c``: the centre in the child sensor frame (mm).
    singular_values : ndarray, shape (6,)
        Of the stacked system, descending (mm-free: rotation entries).
    null_vector : ndarray, shape (6,)
        Right singular vector of the smallest singular value: ``[a_p; a_c]/sqrt(2)``
        for a hinge.
    rms_mm : float
        Residual RMS per frame (mm).
    rank : int
        Numerical rank (6 when the untruncated solution exists, 5 for exact hinge data).
    n_frames : int
    """

    parent_point: FloatArray
    child_point: FloatArray
    singular_values: FloatArray
    null_vector: FloatArray
    rms_mm: float
    rank: int
    n_frames: int

    @property
    def conditioning(self) -> float:
        """``s5 / s6`` (infinite for an exact hinge)."""
        s = self.singular_values
        return float(s[4] / s[5]) if s[5] > 0 else float("inf")


def centre_of_rotation(rotation: FloatArray, translation: FloatArray) -> CentreFit:
    """Untruncated least-squares centre of rotation (O'Brien et al. 2000).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations ``R_p^T R_c`` of the frames to use (no NaN).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame ``R_p^T (t_c - t_p)`` (mm).

    Returns
    -------
    CentreFit
        The solution is truncated only where the system is numerically
        singular (rank below 6 at machine precision), where it becomes the
        minimum-norm point of the solution line.
    """
    n = rotation.shape[0]
    a = np.empty((n, 3, 6))
    a[:, :, :3] = np.eye(3)
    a[:, :, 3:] = -rotation
    a = a.reshape(3 * n, 6)
    b = translation.reshape(3 * n)
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    tol = s[0] * max(a.shape) * np.finfo(float).eps
    rank = int((s > tol).sum())
    inv = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0), 0.0)
    x = vt.T @ (inv * (u.T @ b))
    resid = a @ x - b
    return CentreFit(
        parent_point=x[:3],
        child_point=x[3:],
        singular_values=s,
        null_vector=vt[-1],
        rms_mm=float(np.sqrt(np.mean(resid.reshape(n, 3) ** 2) * 3)),
        rank=rank,
        n_frames=n,
    )
