"""Outlier frames and cycles, and per-cycle weights, for the pooled hinge fit.

Stated rules (``docs/methods.md``), applied to the residuals of
:func:`~fingerfit.estimate.pooled.pooled_hinge` -- the rotation off the axis
``|a_p - R(k) a_c|`` (rad) and the centre mismatch ``|u_p - R(k) u_c - t(k)|``
(mm) of every movement frame:

1. **Frames** (tracker glitches): a frame whose residual of either kind lies
   more than ``FRAME_Z = 5`` robust standard deviations above the median
   (``1.4826 x MAD``) is rejected; fit and rule alternate until nothing more is
   rejected (at most ``MAX_ROUNDS`` rounds).
2. **Cycles** (a sensor slipping on the skin changes its mounting for the rest of
   the recording, so whole cycles stop agreeing with the others): a cycle whose
   RMS residual of either kind exceeds ``CYCLE_RATIO = 2`` times the median over
   cycles *and* lies more than ``CYCLE_Z = 5`` robust standard deviations above it
   is rejected, worst first, one at a time with a refit in between; never more
   than ``(n_cycles - 1) // 2`` cycles (a majority must agree).
3. **Weights**: each remaining cycle's frames are weighted by the inverse of that
   cycle's mean squared rotation off the axis, normalised to mean 1, so cycles
   that fit the hinge poorly (small range of motion relative to their wobble,
   i.e. poor conditioning) count less.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray
from .cycles import period_labels
from .pooled import PooledHinge, pooled_hinge

FRAME_Z = 5.0
CYCLE_Z = 5.0
CYCLE_RATIO = 2.0
MAX_ROUNDS = 4
_TINY = {"axis": 1e-12, "centre": 1e-9}


@dataclass(frozen=True)
class RobustHinge:
    """Pooled hinge fit after the outlier rules.

    Attributes
    ----------
    fit : PooledHinge
        Fit over the kept frames (with the cycle weights).
    frames : ndarray of int
        Kept frame indices (into the joint's arrays).
    weights : ndarray, shape (len(frames),)
        Weight of each kept frame (mean 1).
    kept_cycles, rejected_cycles : list of int
        Cycle indices (into ``periods``).
    rejected_frames : int
        Frames of kept cycles rejected by the frame rule.
    labels : ndarray of int, shape (len(frames),)
        Cycle index (into ``periods``) of each kept frame.
    """

    fit: PooledHinge
    frames: np.ndarray
    weights: FloatArray
    kept_cycles: list[int]
    rejected_cycles: list[int]
    rejected_frames: int
    labels: np.ndarray | None = None


def robust_z(values: FloatArray) -> FloatArray:
    """``(values - median) / (1.4826 MAD)``, shape of ``values``; MAD floored at 1e-12."""
    med = np.median(values)
    mad = 1.4826 * np.median(np.abs(values - med))
    return (values - med) / max(mad, 1e-12)


def _outlier_frames(fit: PooledHinge) -> np.ndarray:
    """Boolean mask of frames beyond ``FRAME_Z`` robust SDs in either residual."""
    bad = np.zeros(fit.axis_residual.shape, bool)
    for res, tiny in ((fit.axis_residual, _TINY["axis"]), (fit.centre_residual, _TINY["centre"])):
        med = np.median(res)
        scale = max(1.4826 * np.median(np.abs(res - med)), tiny)
        bad |= res > med + FRAME_Z * scale
    return bad


def _cycle_rms(fit: PooledHinge, labels: np.ndarray, cycles: list[int]) -> FloatArray:
    """RMS residuals ``(len(cycles), 2)`` (axis rad, centre mm) per cycle."""
    out = np.empty((len(cycles), 2))
    for i, c in enumerate(cycles):
        k = labels == c
        out[i] = (
            np.sqrt(np.mean(fit.axis_residual[k] ** 2)),
            np.sqrt(np.mean(fit.centre_residual[k] ** 2)),
        )
    return out


def _cycle_weights(fit: PooledHinge, labels: np.ndarray, cycles: list[int]) -> FloatArray:
    """Per-frame weights: inverse mean squared axis residual of the frame's cycle, mean 1."""
    w = np.ones(labels.shape[0])
    for c in cycles:
        k = labels == c
        w[k] = 1.0 / max(np.mean(fit.axis_residual[k] ** 2), 1e-24)
    return w / w.mean()


def robust_hinge(
    rotation: FloatArray,
    translation: FloatArray,
    periods: list[np.ndarray],
    *,
    weighting: bool = True,
) -> RobustHinge:
    """Pooled hinge with outlier frames and cycles rejected and cycles weighted.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations over the recording(s).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    periods : list of ndarray
        Frame indices of each cycle's movement period (no missing samples).
    weighting : bool
        Apply the per-cycle weights (rule 3).

    Returns
    -------
    RobustHinge
    """
    if not periods:
        raise FingerfitError("no movement periods to fit a hinge to")
    frames = np.concatenate(periods)
    labels = period_labels(periods)
    keep = np.ones(frames.size, bool)
    cycles = list(range(len(periods)))
    rejected: list[int] = []
    max_reject = (len(periods) - 1) // 2
    w = np.ones(frames.size)

    def fit_now() -> PooledHinge:
        k = frames[keep]
        return pooled_hinge(rotation[k], translation[k], w[keep])

    fit = fit_now()
    for _ in range(MAX_ROUNDS):
        # Rule 1: frames.
        bad = np.zeros(frames.size, bool)
        bad[np.flatnonzero(keep)] = _outlier_frames(fit)
        changed = bad.any()
        keep &= ~bad
        if changed:
            fit = fit_now()
        # Rule 2: cycles, worst first.
        while len(rejected) < max_reject:
            lab = labels[keep]
            rms = _cycle_rms(fit, lab, cycles)
            med = np.median(rms, axis=0)
            z = np.column_stack([robust_z(rms[:, 0]), robust_z(rms[:, 1])])
            over = (rms > CYCLE_RATIO * np.maximum(med, 1e-12)) & (z > CYCLE_Z)
            score = np.where(over, rms / np.maximum(med, 1e-12), 0.0).max(axis=1)
            if not (score > 0).any():
                break
            worst = cycles[int(np.argmax(score))]
            cycles.remove(worst)
            rejected.append(worst)
            keep &= labels != worst
            changed = True
            fit = fit_now()
        # Rule 3: weights.
        if weighting:
            w_new = np.ones(frames.size)
            w_new[keep] = _cycle_weights(fit, labels[keep], cycles)
            if not np.allclose(w_new[keep], w[keep], rtol=0.05):
                w = w_new
                changed = True
                fit = fit_now()
        if not changed:
            break
    kept_cycle_frames = np.isin(labels, cycles)
    return RobustHinge(
        fit=fit,
        frames=frames[keep],
        weights=w[keep] / w[keep].mean(),
        kept_cycles=cycles,
        rejected_cycles=sorted(rejected),
        rejected_frames=int((kept_cycle_frames & ~keep).sum()),
        labels=labels[keep],
    )


__all__ = ["RobustHinge", "robust_hinge", "robust_z"]
