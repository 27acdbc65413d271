"""Hinge or two axes: the joint model chosen by how well each predicts held-out motion.

A finger's MP and the thumb's MCP may turn about one axis or two. Both candidates are
fitted to every movement cycle -- the hinge by the robust rules of :mod:`.robust`, the
two-axis joint by :mod:`.twoaxis` with uniform weights over every cycle, so that no
outlier rule of one model removes the motion that carries the other's second degree of
freedom (``docs/methods.md``, "Choosing the joint model") -- and compared by
leave-one-cycle-out prediction:

for each cycle ``f``, each model is refitted without it and predicts, in the frames of
``f``, where the child sensor's origin is in the parent frame, from the child's measured
orientation alone: the model's angles (twist about the hinge axis; the two-axis angles)
carried through the model's rotations about its axis line(s),

    hinge:     p(k) = Rot(a, theta_k) (t_ref - c_a) + c_a,
    two axes:  p(k) = Rot(b, beta_k) (Rot(a, theta_k) (t_ref - c_a) + c_a - c_b) + c_b,

``t_ref`` the child origin at the reference posture, ``c_a`` and ``c_b`` points of the
two axis lines (which need not meet). That is the
fingertip's own mechanism: angles from orientations, positions from the geometry. An
orientation change that is not a rotation of the segment about the joint (soft-tissue
artefact tilting a sensor, noise) moves the two-axis prediction but not the sensor, so
it costs the two-axis model held-out error; a real second rotation moves both.

Refits per fold: the hinge axis exactly (SARA's 3 x 3 sum less the fold's); the two-axis
directions by one Gauss-Newton step from the fit to every cycle without the fold's rows
(the held-out influence of the fold); the axis points exactly (linear least squares with
the fold's directions: ``c_a`` perpendicular to ``a``, and ``c_b`` perpendicular to ``b``). The model with the lower held-out mean squared error over every
frame of every cycle is chosen -- no threshold but rounding (:data:`ROUNDING_MM`: on exact
data the two predict equally well, and the hinge is kept); a two-axis fit whose direction
search ended on its bounds is not a candidate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import twist_angle, two_axis_angles
from ..transforms import FloatArray, axis_angle_matrix, orthonormal_basis, unit
from .twoaxis import MAX_FRAMES, TwoAxisFit, direction_jacobian

HINGE = "hinge"
TWO_AXIS = "two_axis"
#: Held-out errors closer than this (mm) are equal: rounding, not evidence (exact data).
ROUNDING_MM = 1e-9
#: The tilt of ``b`` towards ``a`` held in the one-step refits when the fit held it.
_HELD = 1e8


@dataclass(frozen=True)
class ModelChoice:
    """Hinge vs two axes for one joint (:func:`choose_joint_model`).

    Attributes
    ----------
    chosen : {"hinge", "two_axis"}
    hinge_mm, two_axis_mm : float
        Held-out RMS error of the child sensor origin (mm, parent frame) over every frame
        of every cycle, each cycle predicted by the model fitted without it.
    folds : int
        Cycles left out in turn.
    fold_hinge_mm, fold_two_axis_mm : tuple of float
        The same per cycle (mm).
    candidate : bool
        Whether the two-axis fit was a candidate (its direction search ended inside its
        bounds).
    """

    chosen: str
    hinge_mm: float
    two_axis_mm: float
    folds: int
    fold_hinge_mm: tuple[float, ...]
    fold_two_axis_mm: tuple[float, ...]
    candidate: bool = True

    @property
    def note(self) -> str:
        """One sentence for the joint's quality notes."""
        which = "two axes" if self.chosen == TWO_AXIS else "one axis"
        extra = "" if self.candidate else " (the two-axis fit found no optimum inside its bounds)"
        return (
            f"{which} chosen by held-out prediction over {self.folds} cycles: child sensor "
            f"origin {self.hinge_mm:.3f} mm RMS with one axis, {self.two_axis_mm:.3f} mm with "
            f"two{extra}"
        )

    def summary(self) -> dict:
        """JSON-ready record (``model.json``, the fit table)."""
        return {
            "chosen": self.chosen,
            "held_out_hinge_mm": self.hinge_mm,
            "held_out_two_axis_mm": self.two_axis_mm,
            "folds": self.folds,
            "two_axis_candidate": self.candidate,
        }


def _hinge_axes(rotation: FloatArray, labels: np.ndarray, folds: np.ndarray) -> FloatArray:
    """SARA axis (parent frame) without each fold: leading left singular vector of the sum
    of the child-in-parent rotations less the fold's. Returns ``(n_folds, 3)``."""
    s_all = rotation.sum(axis=0)
    s_fold = np.zeros((folds.size, 3, 3))
    np.add.at(s_fold, np.searchsorted(folds, labels), rotation)
    u, _, _ = np.linalg.svd(s_all[None] - s_fold)
    axes = u[:, :, 0]
    ref = np.linalg.svd(s_all)[0][:, 0]
    return axes * np.sign(axes @ ref)[:, None]


def _two_axis_directions(
    q: FloatArray, labels: np.ndarray, folds: np.ndarray, fit: TwoAxisFit
) -> tuple[FloatArray, FloatArray]:
    """Flexion and ab/adduction axes without each fold: one Gauss-Newton step from ``fit``.

    Returns ``(n_folds, 3)`` each. The tilt of ``b`` towards ``a`` stays as fitted when the
    fit held it (``tilt_data_share`` below one half).
    """
    a, b = fit.flexion_axis, fit.abduction_axis
    r, jac, basis = direction_jacobian(q, a, b, np.ones(q.shape[0]))
    h, g = jac.T @ jac, jac.T @ r
    if fit.tilt_data_share < 0.5:
        e = np.concatenate([[0.0, 0.0], unit(basis[2:] @ a)])
        h = h + _HELD * np.trace(h) * np.outer(e, e)
    rows = np.repeat(np.searchsorted(folds, labels), 3)
    hf = np.zeros((folds.size, 4, 4))
    np.add.at(hf, rows, jac[:, :, None] * jac[:, None, :])
    gf = np.zeros((folds.size, 4))
    np.add.at(gf, rows, jac * r[:, None])
    dx = -np.linalg.solve(h[None] - hf, (g[None] - gf)[..., None])[..., 0]
    fa = a + dx[:, :2] @ basis[:2]
    fb = b + dx[:, 2:] @ basis[2:]
    return (
        fa / np.linalg.norm(fa, axis=1, keepdims=True),
        fb / np.linalg.norm(fb, axis=1, keepdims=True),
    )


def _held_out_sq(y: FloatArray, design: FloatArray, out: np.ndarray) -> FloatArray:
    """Squared prediction errors ``(n_out,)`` (mm^2) of the frames ``out`` (bool, ``(n,)``).

    The axis points ``z`` are fitted to the other frames by least squares on
    ``y(k) = design(k) z``: ``y (n, 3)`` mm, ``design (n, 3, p)``.
    """
    k = design.shape[2]
    z = np.linalg.lstsq(design[~out].reshape(-1, k), y[~out].ravel(), rcond=1e-9)[0]
    err = y[out] - design[out] @ z
    return np.einsum("ni,ni->n", err, err)


def choose_joint_model(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    reference_offset: FloatArray,
    labels: np.ndarray,
    two_axis: TwoAxisFit,
) -> ModelChoice:
    """Choose hinge or two axes by leave-one-cycle-out prediction (module docstring).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations of the movement frames of every cycle.
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    reference_rotation : ndarray, shape (3, 3)
    reference_offset : ndarray, shape (3,)
        Child-in-parent rotation and child origin (mm) at the reference posture.
    labels : ndarray of int, shape (n,)
        Cycle of each frame (the folds).
    two_axis : TwoAxisFit
        The two-axis joint fitted to every cycle (ab/adduction axis ``b`` proximal:
        ``Q = Rot(b, beta) Rot(a, theta)``, parent frame at the reference posture).

    Returns
    -------
    ModelChoice
    """
    stride = max(1, -(-rotation.shape[0] // MAX_FRAMES))
    rot, t, lab = rotation[::stride], translation[::stride], np.asarray(labels)[::stride]
    folds = np.unique(lab)
    q = rot @ reference_rotation.T
    hinge_axes = _hinge_axes(rot, lab, folds)
    fa, fb = _two_axis_directions(q, lab, folds, two_axis)
    sq = {HINGE: [], TWO_AXIS: []}
    eye = np.eye(3)[None]
    for i, f in enumerate(folds):
        out = lab == f
        # Hinge: t - Rot_a t_ref = (I - Rot_a) c_a, c_a in the plane normal to a.
        a = hinge_axes[i]
        rot_a = axis_angle_matrix(a, twist_angle(q, a))
        design = (eye - rot_a) @ orthonormal_basis(a)[:2].T
        sq[HINGE].append(_held_out_sq(t - rot_a @ reference_offset, design, out))
        # Two axes: t - Rot_b Rot_a t_ref = Rot_b (I - Rot_a) c_a + (I - Rot_b) c_b.
        beta, theta = two_axis_angles(q, fa[i], fb[i])
        rot_a, rot_b = axis_angle_matrix(fa[i], theta), axis_angle_matrix(fb[i], beta)
        design = np.concatenate(
            [
                rot_b @ (eye - rot_a) @ orthonormal_basis(fa[i])[:2].T,
                (eye - rot_b) @ orthonormal_basis(fb[i])[:2].T,
            ],
            axis=2,
        )
        sq[TWO_AXIS].append(_held_out_sq(t - rot_b @ rot_a @ reference_offset, design, out))
    rms = {k: float(np.sqrt(np.mean(np.concatenate(v)))) for k, v in sq.items()}
    per_fold = {k: tuple(float(np.sqrt(np.mean(s))) for s in v) for k, v in sq.items()}
    better = rms[TWO_AXIS] < rms[HINGE] - ROUNDING_MM
    return ModelChoice(
        TWO_AXIS if (better and two_axis.interior) else HINGE,
        rms[HINGE],
        rms[TWO_AXIS],
        int(folds.size),
        per_fold[HINGE],
        per_fold[TWO_AXIS],
        candidate=two_axis.interior,
    )


__all__ = ["HINGE", "TWO_AXIS", "ModelChoice", "choose_joint_model"]
