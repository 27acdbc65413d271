"""Hinge or two axes, and which axis proximal: the joint model chosen by how well each
predicts held-out motion.

A finger's MP and the thumb's MCP may turn about one axis or two, and a two-axis joint's
ab/adduction axis may lie proximal to its flexion axis (fixed in the parent, the usual
finger MP model) or distal to it (fixed in the child: MyoHand's MP, the thumb's MCP after
Hollister). The candidates -- a hinge and a two-axis joint in each order -- are fitted to
every movement cycle -- the hinge by the robust rules of :mod:`.robust`, each two-axis
joint by :mod:`.twoaxis` with uniform weights over every cycle, so that no outlier rule of
one model removes the motion that carries the other's second degree of freedom
(``docs/methods.md``, "Choosing the joint model") -- and compared by leave-one-cycle-out
prediction:

for each cycle ``f``, each model is refitted without it and predicts, in the frames of
``f``, where the child sensor's origin is in the parent frame, from the child's measured
orientation alone: the model's angles (twist about the hinge axis; the two-axis angles)
carried through the model's rotations about its axis line(s),

    hinge:                     p(k) = Rot(a, theta_k) (t_ref - c_a) + c_a,
    two axes, ab/adduction 1st: p(k) = Rot(b, beta_k) (Rot(a, theta_k) (t_ref - c_a) + c_a - c_b) + c_b,
    two axes, flexion 1st:      p(k) = Rot(a, theta_k) (Rot(b, beta_k) (t_ref - c_b) + c_b - c_a) + c_a,

``t_ref`` the child origin at the reference posture, ``c_a`` and ``c_b`` points of the
two axis lines (which need not meet). That is the
fingertip's own mechanism: angles from orientations, positions from the geometry. An
orientation change that is not a rotation of the segment about the joint (soft-tissue
artefact tilting a sensor, noise) moves the two-axis prediction but not the sensor, so
it costs the two-axis model held-out error; a real second rotation moves both.

Refits per fold: the hinge axis exactly (SARA's 3 x 3 sum less the fold's); the two-axis
directions by one Gauss-Newton step from the fit to every cycle without the fold's rows
(the held-out influence of the fold); the axis points exactly (linear least squares with
the fold's directions: ``c_a`` perpendicular to ``a``, and ``c_b`` perpendicular to ``b``).
A flexion-first joint is fitted, and its directions refitted, as the ab/adduction-first
form seen from the child (:meth:`fingerfit.estimate.methods.JointData.reversed`) and brought
back to the parent frame, so that every candidate predicts the same thing.

The **order** is chosen first, by the held-out **orientations**: the two orders have the
same number of parameters and differ only in how the two rotations compose, so each
fold's refitted axes and angles rebuild the fold's relative orientations and the angle of
what they leave is the order's held-out error. A joint leaves its digit's usual order only
when the other explains the held-out orientations better in so many cycles that a
one-sided sign test rejects "no better" at :data:`ORDER_SIGNIFICANCE`: ab/adduction that
mostly follows flexion makes the two orders nearly the same motion, and their per-cycle
differences noise. Then **hinge or two axes**: the hinge against the chosen order by the
held-out position error over every frame of every cycle -- no threshold but rounding
(:data:`ROUNDING_MM`: on exact data the models predict equally well and the hinge is
kept); a two-axis fit whose direction search ended on its bounds is not a candidate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import binomtest

from ..angles import twist_angle, two_axis_angles
from ..digits import ABDUCTION_FIRST, FLEXION_FIRST
from ..transforms import FloatArray, axis_angle_matrix, orthonormal_basis, unit
from .bootstrap import Z95, jackknife_sd
from .pooled import leave_one_out_axes
from .twoaxis import MAX_FRAMES, TwoAxisDirections, TwoAxisFit, direction_jacobian

HINGE = "hinge"
TWO_AXIS = "two_axis"
#: Held-out errors closer than this (mm) are equal: rounding, not evidence (exact data).
ROUNDING_MM = 1e-9
#: Level of the sign test over the cycles that must reject "the other order is no better"
#: before a joint leaves its digit's usual axis order: the held-out cycles must agree.
ORDER_SIGNIFICANCE = 0.01
#: The tilt of ``b`` towards ``a`` held in the one-step refits when the fit held it.
_HELD = 1e8


@dataclass(frozen=True)
class ModelChoice:
    """Hinge vs two axes, and the two axes' order, for one joint (:func:`choose_joint_model`).

    Attributes
    ----------
    chosen : {"hinge", "two_axis"}
    hinge_mm, two_axis_mm : float
        Held-out RMS error of the child sensor origin (mm, parent frame) over every frame
        of every cycle, each cycle predicted by the model fitted without it; the two-axis
        figure is that of :attr:`order`.
    folds : int
        Cycles left out in turn.
    fold_hinge_mm, fold_two_axis_mm : tuple of float
        The same per cycle (mm).
    candidate : bool
        Whether a two-axis fit was a candidate (its direction search ended inside its
        bounds).
    order : str
        The two-axis order with the lower held-out error (``abduction_first`` or
        ``flexion_first``; the proximal axis first): the chosen one when
        :attr:`chosen` is ``two_axis``.
    two_axis_by_order_mm : dict[str, float]
        Held-out RMS error (mm) of each two-axis order fitted.
    orientation_by_order_deg : dict[str, float]
        Held-out RMS angle (deg) of each order's orientation residual: the child's
        relative orientation in each held-out frame against the model's rotations by that
        frame's angles. The order is chosen by it (the two orders have the same number of
        parameters; what tells them apart is how the two rotations compose).
    fold_orientation_by_order_deg : dict[str, tuple of float]
        The same per cycle (deg).
    axis_ci_deg : float
        95 % confidence half-angle (deg) of the chosen model's flexion axis: ``Z95`` times
        the jackknife SD (:func:`.bootstrap.jackknife_sd`) of the axes refitted without
        each cycle above (the hinge's SARA axes, or the chosen order's one-step refits).
    """

    chosen: str
    hinge_mm: float
    two_axis_mm: float
    folds: int
    fold_hinge_mm: tuple[float, ...]
    fold_two_axis_mm: tuple[float, ...]
    candidate: bool = True
    order: str = ABDUCTION_FIRST
    two_axis_by_order_mm: dict[str, float] = field(default_factory=dict)
    orientation_by_order_deg: dict[str, float] = field(default_factory=dict)
    fold_orientation_by_order_deg: dict[str, tuple[float, ...]] = field(default_factory=dict)
    axis_ci_deg: float = float("nan")

    @property
    def note(self) -> str:
        """One sentence for the joint's quality notes."""
        which = "two axes" if self.chosen == TWO_AXIS else "one axis"
        if self.chosen == TWO_AXIS:
            which += f" ({_PROXIMAL[self.order]} proximal)"
        extra = "" if self.candidate else " (the two-axis fit found no optimum inside its bounds)"
        orders = ", ".join(
            f"{v:.3f} mm with two, {_PROXIMAL[k]} proximal"
            for k, v in self.two_axis_by_order_mm.items()
        )
        return (
            f"{which} chosen by held-out prediction over {self.folds} cycles: child sensor "
            f"origin {self.hinge_mm:.3f} mm RMS with one axis, "
            f"{orders or f'{self.two_axis_mm:.3f} mm with two'}{extra}"
        )

    def summary(self) -> dict:
        """JSON-ready record (``model.json``, the fit table)."""
        return {
            "chosen": self.chosen,
            "held_out_hinge_mm": self.hinge_mm,
            "held_out_two_axis_mm": self.two_axis_mm,
            "folds": self.folds,
            "two_axis_candidate": self.candidate,
            "order": self.order,
            "held_out_two_axis_by_order_mm": dict(self.two_axis_by_order_mm),
            "held_out_orientation_by_order_deg": dict(self.orientation_by_order_deg),
        }


_PROXIMAL = {ABDUCTION_FIRST: "ab/adduction", FLEXION_FIRST: "flexion"}


def _one_hot(rows: np.ndarray, count: int) -> FloatArray:
    """``(count, len(rows))``: 1 where column ``k`` belongs to fold ``rows[k]``; times a
    matrix of per-row values it sums them by fold."""
    return (rows[None, :] == np.arange(count)[:, None]).astype(float)


def _two_axis_directions(
    q: FloatArray, labels: np.ndarray, folds: np.ndarray, fit: TwoAxisFit | TwoAxisDirections
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
    one_hot = _one_hot(np.repeat(np.searchsorted(folds, labels), 3), folds.size)
    hf = (one_hot @ (jac[:, :, None] * jac[:, None, :]).reshape(-1, 16)).reshape(-1, 4, 4)
    gf = one_hot @ (jac * r[:, None])
    dx = -np.linalg.solve(h[None] - hf, (g[None] - gf)[..., None])[..., 0]
    fa = a + dx[:, :2] @ basis[:2]
    fb = b + dx[:, 2:] @ basis[2:]
    return (
        fa / np.linalg.norm(fa, axis=1, keepdims=True),
        fb / np.linalg.norm(fb, axis=1, keepdims=True),
    )


def _held_out_sq(y: FloatArray, design: FloatArray, out: np.ndarray) -> FloatArray:
    """Squared prediction errors ``(F, n)`` (mm^2) of every frame by each fold's axis points.

    Fold ``f``'s points ``z_f`` are fitted to the frames not in ``out[f]`` by least squares
    on ``y_f(k) = design_f(k) z_f``.

    Parameters
    ----------
    y : ndarray, shape (F, n, 3)
        Per fold and frame, what the points must explain (mm, parent frame).
    design : ndarray, shape (F, n, 3, p)
    out : ndarray of bool, shape (F, n)
        The frames each fold holds out.
    """
    p = design.shape[3]
    z = np.stack(
        [
            np.linalg.lstsq(d[~o].reshape(-1, p), v[~o].ravel(), rcond=1e-9)[0]
            for d, v, o in zip(design, y, out, strict=True)
        ]
    )
    err = y - (design @ z[:, None, :, None])[..., 0]
    return np.einsum("fni,fni->fn", err, err)


def _bases(axes: FloatArray) -> FloatArray:
    """``(F, 1, 3, 2)``: per axis ``(F, 3)``, the two unit vectors perpendicular to it
    (:func:`orthonormal_basis`) as columns, to multiply every frame's ``(3, 3)``."""
    return np.swapaxes(orthonormal_basis(axes)[:, :2], 1, 2)[:, None]


def _two_axis_folds(
    q: FloatArray,
    labels: np.ndarray,
    folds: np.ndarray,
    fit: TwoAxisFit | TwoAxisDirections,
    order: str,
    reference_rotation: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per fold, the refitted axes and every frame's rotations about them, parent frame:
    ``a, b (F, 3)`` and ``Rot_a, Rot_b (F, n, 3, 3)``; ``Q = Rot_b Rot_a`` (ab/adduction
    first) or ``Q = Rot_a Rot_b`` (flexion first)."""
    if order == ABDUCTION_FIRST:
        fa, fb = _two_axis_directions(q, labels, folds, fit)
        angles = [two_axis_angles(q, a, b) for a, b in zip(fa, fb, strict=True)]
        sign = 1.0
    else:
        # Seen from the child: Q' = R^T R_ref = R_ref^T Q^T R_ref = Rot(b', -beta)
        # Rot(a', -theta) with a' = R_ref^T a, b' = R_ref^T b.
        ref = reference_rotation
        q_child = ref.T @ np.swapaxes(q, 1, 2) @ ref
        fa, fb = _two_axis_directions(q_child, labels, folds, fit)
        angles = [two_axis_angles(q_child, a, b) for a, b in zip(fa, fb, strict=True)]
        fa, fb, sign = fa @ ref.T, fb @ ref.T, -1.0
    beta, theta = np.array(angles).transpose(1, 0, 2)  # (F, n) each
    return fa, fb, axis_angle_matrix(fa, sign * theta), axis_angle_matrix(fb, sign * beta)


def _order(turn: dict[str, list[FloatArray]], candidates: list[str], usual: str) -> str:
    """The two-axis order (module docstring): the usual one unless the other is a
    candidate whose held-out orientations are explained better in so many cycles that a
    one-sided sign test over the cycles rejects "no better" at :data:`ORDER_SIGNIFICANCE`
    (every cycle up to 10 cycles, 10 of 11; fewer than 7 cycles keep the usual order)."""
    others = [o for o in candidates if o != usual]
    if not others:
        return usual if usual in turn else next(iter(turn))
    other = others[0]
    if usual not in candidates:
        return other
    ms = {k: np.array([np.mean(x) for x in turn[k]]) for k in (usual, other)}
    wins = int(np.sum(ms[other] < ms[usual]))
    p = float(binomtest(wins, ms[usual].size, 0.5, alternative="greater").pvalue)
    return other if p < ORDER_SIGNIFICANCE else usual


def choose_joint_model(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    reference_offset: FloatArray,
    labels: np.ndarray,
    two_axis: dict[str, TwoAxisFit | TwoAxisDirections],
    usual: str = ABDUCTION_FIRST,
) -> ModelChoice:
    """Choose hinge or two axes, and their order, by leave-one-cycle-out prediction
    (module docstring).

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
    two_axis : dict[str, TwoAxisFit or TwoAxisDirections]
        Order -> the two-axis joint fitted to every cycle in the ab/adduction-first form
        ``Q = Rot(b, beta) Rot(a, theta)``: ``abduction_first`` in the parent frame,
        ``flexion_first`` seen from the child (``JointData.reversed``: child frame at the
        reference posture). One or both. Only the directions are used (the axes,
        ``interior`` and ``tilt_data_share``), so the direction search's result serves.
    usual : str
        The digit's usual order (:mod:`fingerfit.digits`), kept when the two orders
        predict equally well.

    Returns
    -------
    ModelChoice
    """
    stride = max(1, -(-rotation.shape[0] // MAX_FRAMES))
    rot, t, lab = rotation[::stride], translation[::stride], np.asarray(labels)[::stride]
    folds = np.unique(lab)
    q = rot @ reference_rotation.T
    hinge_axes = leave_one_out_axes(rot, lab, folds)
    outs = lab[None, :] == folds[:, None]  # (F, n): each fold's held-out frames
    eye = np.eye(3)
    # Hinge: t - Rot_a t_ref = (I - Rot_a) c_a, c_a in the plane normal to a.
    rot_a = axis_angle_matrix(hinge_axes, np.array([twist_angle(q, a) for a in hinge_axes]))
    err = _held_out_sq(t - rot_a @ reference_offset, (eye - rot_a) @ _bases(hinge_axes), outs)
    sq: dict[str, list[FloatArray]] = {HINGE: [e[o] for e, o in zip(err, outs, strict=True)]}
    turn: dict[str, list[FloatArray]] = {}
    fold_axes = {HINGE: hinge_axes}
    for order, fit in two_axis.items():
        fa, fb, rot_a, rot_b = _two_axis_folds(q, lab, folds, fit, order, reference_rotation)
        fold_axes[order] = fa  # signed as the fit's axis
        ca, cb = _bases(fa), _bases(fb)
        if order == ABDUCTION_FIRST:
            # t - Rot_b Rot_a t_ref = Rot_b (I - Rot_a) c_a + (I - Rot_b) c_b.
            moved = rot_b @ rot_a
            design = np.concatenate([rot_b @ ((eye - rot_a) @ ca), (eye - rot_b) @ cb], axis=3)
        else:
            # t - Rot_a Rot_b t_ref = (I - Rot_a) c_a + Rot_a (I - Rot_b) c_b.
            moved = rot_a @ rot_b
            design = np.concatenate([(eye - rot_a) @ ca, rot_a @ ((eye - rot_b) @ cb)], axis=3)
        err = _held_out_sq(t - moved @ reference_offset, design, outs)
        # What the fold's angles leave of its orientations: the angle of moved^T Q, from
        # the trace.
        cos = 0.5 * (np.einsum("fnij,nij->fn", moved, q) - 1.0)
        ang2 = np.arccos(np.clip(cos, -1.0, 1.0)) ** 2
        sq[order] = [e[o] for e, o in zip(err, outs, strict=True)]
        turn[order] = [x[o] for x, o in zip(ang2, outs, strict=True)]
    rms = {k: float(np.sqrt(np.mean(np.concatenate(v)))) for k, v in sq.items()}
    per_fold = {k: tuple(float(np.sqrt(np.mean(s))) for s in v) for k, v in sq.items()}
    off = {k: float(np.degrees(np.sqrt(np.mean(np.concatenate(v))))) for k, v in turn.items()}
    candidates = [o for o, fit in two_axis.items() if fit.interior]
    best = _order(turn, candidates, usual)
    better = best in candidates and rms[best] < rms[HINGE] - ROUNDING_MM
    ci = Z95 * jackknife_sd(fold_axes[best if better else HINGE])
    return ModelChoice(
        TWO_AXIS if better else HINGE,
        rms[HINGE],
        rms[best],
        int(folds.size),
        per_fold[HINGE],
        per_fold[best],
        candidate=bool(candidates),
        order=best,
        two_axis_by_order_mm={o: rms[o] for o in two_axis},
        orientation_by_order_deg=off,
        fold_orientation_by_order_deg={
            k: tuple(float(np.degrees(np.sqrt(np.mean(x)))) for x in v) for k, v in turn.items()
        },
        axis_ci_deg=float(np.degrees(ci)),
    )


__all__ = ["HINGE", "TWO_AXIS", "ModelChoice", "choose_joint_model"]
