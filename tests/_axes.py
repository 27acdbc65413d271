"""Joint-axis estimates used by the real-data tests.

The hinge axis is fingerfit's own SARA estimator; the dominant rotation axis is an
independent check of it; the elbow's two-axis fit (one axis fixed in the parent,
one in the child frame) is a test-only model, since fingerfit's two-axis joint is
the MP's (both axes known in the parent frame at the reference posture).
Rotation matrices ``(n, 3, 3)`` map child (or sensor) coordinates into parent (or
tracker) coordinates; axes are unit vectors ``(3,)``; angles in degrees unless named.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from fingerfit.estimate.pooled import sara_axis as pooled_sara_axis
from fingerfit.transforms import angle_between_axes, unit


def axis_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two lines (sign of the directions ignored), degrees in [0, 90]."""
    return float(np.degrees(angle_between_axes(a, b)))


def relative_rotations(parent: np.ndarray, child: np.ndarray) -> np.ndarray:
    """``R_p^T R_c`` per frame, ``(n, 3, 3)``: child -> parent coordinates."""
    return np.matmul(np.swapaxes(parent, 1, 2), child)


def sara_axis(rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The product's SARA hinge axis (:func:`fingerfit.estimate.pooled.sara_axis`) in the
    parent and the child frame, so the real-data tests exercise fingerfit's own estimator."""
    axis_parent, axis_child, _ = pooled_sara_axis(rel)
    return axis_parent, axis_child


def dominant_axis(rel: np.ndarray) -> np.ndarray:
    """Dominant rotation direction (parent frame) of ``R(k) R_mean^T``.

    For a pure hinge every ``R(k) R_ref^T`` is a rotation about the same parent-frame
    axis, so its rotation vectors all lie along it: the first right singular vector
    of the stacked rotation vectors.
    """
    ref = Rotation.from_matrix(rel).mean()
    rv = (Rotation.from_matrix(rel) * ref.inv()).as_rotvec()
    return unit(np.linalg.svd(rv, full_matrices=False)[2][0])


def _axis_from_angles(p: np.ndarray) -> np.ndarray:
    th, ph = p
    return np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])


def _angles_from_axis(a: np.ndarray) -> np.ndarray:
    a = unit(a)
    return np.array([np.arccos(np.clip(a[2], -1, 1)), np.arctan2(a[1], a[0])])


def two_axis_fit(
    rel: np.ndarray,
    flexion_guess: np.ndarray,
    *,
    n_starts: int = 8,
    seed: int = 0,
    fix_a1: bool = False,
) -> dict:
    """Two-axis joint: ``R(k) = Rot(a1, t1_k) R0 Rot(a2, t2_k)``.

    ``a1`` (flexion) is fixed in the parent frame, ``a2`` (e.g. pronation/supination)
    in the child frame. Fitted by nonlinear least squares on the rotation-vector
    residual ``log(model^T R(k))`` with a sparse Jacobian; several starting
    directions for ``a2`` (the best is kept). ``fix_a1`` holds ``a1`` at the guess.

    Returns
    -------
    dict
        ``a1`` (parent frame), ``a2`` (child frame), ``R0``, ``t1``, ``t2`` (rad, per
        frame) and ``rms_deg`` (RMS residual rotation).
    """
    n = rel.shape[0]
    target = Rotation.from_matrix(rel)
    ref = target.mean()

    def unpack(x):
        a1 = _axis_from_angles(x[0:2])
        a2 = _axis_from_angles(x[2:4])
        r0 = Rotation.from_rotvec(x[4:7])
        return a1, a2, r0, x[7 : 7 + n], x[7 + n :]

    fixed = _angles_from_axis(flexion_guess)
    g = 5 if fix_a1 else 7

    def full(p):
        return np.concatenate([fixed, p]) if fix_a1 else p

    def resid(p):
        a1, a2, r0, t1, t2 = unpack(full(p))
        model = Rotation.from_rotvec(t1[:, None] * a1) * r0 * Rotation.from_rotvec(t2[:, None] * a2)
        return (model.inv() * target).as_rotvec().ravel()

    sparsity = lil_matrix((3 * n, g + 2 * n), dtype=int)
    sparsity[:, :g] = 1
    rows = np.arange(3 * n)
    sparsity[rows, g + rows // 3] = 1
    sparsity[rows, g + n + rows // 3] = 1

    rng = np.random.default_rng(seed)
    a1 = unit(flexion_guess)
    # Initial flexion angles: rotation of R(k) ref^T about a1.
    rv = (target * ref.inv()).as_rotvec()
    t1_0 = rv @ a1
    best = None
    guesses = [unit(v) for v in rng.normal(size=(n_starts, 3))]
    for a2 in guesses:
        x0 = np.concatenate(
            [_angles_from_axis(a1), _angles_from_axis(a2), ref.as_rotvec(), t1_0, np.zeros(n)]
        )
        if fix_a1:
            x0 = x0[2:]
        sol = least_squares(resid, x0, jac_sparsity=sparsity, method="trf", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    a1, a2, r0, t1, t2 = unpack(full(best.x))
    rms = np.degrees(np.sqrt(2 * best.cost / n))
    return {"a1": a1, "a2": a2, "R0": r0.as_matrix(), "t1": t1, "t2": t2, "rms_deg": float(rms)}
