"""The spread of a fitted joint: block bootstrap of the axis direction and of a ball joint's
centre over resamples of contiguous time blocks (seeded, reproducible), and the
leave-one-cycle-out jackknife of a hinge axis over grasp cycles
(:func:`cycle_axis_ci_deg`, the axis confidence of ``fingerfit fit`` and
``fingerfit capture``)."""

from __future__ import annotations

import numpy as np

from ..transforms import FloatArray, angle_between_axes
from .cycles import period_labels
from .pooled import leave_one_out_axes

#: Block bootstrap of the axis direction: resamples and blocks (contiguous in time).
BOOTSTRAP_RESAMPLES = 200
BOOTSTRAP_BLOCKS = 20
#: Half-width of a two-sided 95 % normal interval in SDs: an axis's 95 % confidence
#: half-angle is this many jackknife SDs of its direction.
Z95 = 1.96


def jackknife_sd(values: FloatArray) -> float:
    """Delete-one jackknife SD of an estimate from its ``G`` leave-one-out values
    ``(G,)`` or ``(G, k)``: ``sqrt((G - 1) / G * sum_g |x_g - mean|^2)``, in their unit (NaN
    below two). For unit axes ``(G, 3)`` (signed alike) it is the RMS angle (rad) by which
    the axis is expected to be off, both directions across it together."""
    values = np.asarray(values, dtype=float)
    g = values.shape[0]
    if g < 2:
        return float("nan")
    dev = values - values.mean(axis=0)
    return float(np.sqrt((g - 1) / g * np.sum(dev * dev)))


def cycle_axis_ci_deg(rotation: FloatArray, periods: list[np.ndarray]) -> float:
    """95 % confidence half-angle (deg) of a joint's hinge axis from its grasp cycles.

    The SARA axis (:func:`.pooled.sara_axis`) is refitted without each cycle in turn
    (:func:`.pooled.leave_one_out_axes`: one batched 3 x 3 SVD, whatever the length) and
    the half-angle is ``Z95`` times the jackknife SD of those axes (:func:`jackknife_sd`).
    It sees what differs from cycle to cycle (noise, a slipping sensor, ab/adduction that
    varies between cycles), not a bias every cycle shares (soft-tissue artefact that
    follows the angles, the tracker's distortion field: ``docs/accuracy.md``).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations of the joint (frames the periods index; NaN elsewhere
        allowed).
    periods : list of ndarray
        Frame indices of each cycle's movement period (``Cycles.periods``; no NaN frames).

    Returns
    -------
    float
        Degrees; NaN with fewer than two cycles.
    """
    if len(periods) < 2:
        return float("nan")
    frames = np.concatenate(periods)
    axes = leave_one_out_axes(rotation[frames], period_labels(periods), np.arange(len(periods)))
    return float(np.degrees(Z95 * jackknife_sd(axes)))


def _block_sums(values: FloatArray, n_blocks: int) -> FloatArray:
    """Sums of ``values (n, ...)`` over ``n_blocks`` contiguous blocks: ``(n_blocks, ...)``."""
    edges = np.linspace(0, values.shape[0], n_blocks + 1).astype(int)
    return np.add.reduceat(values, edges[:-1], axis=0)


def _resample_counts(n_blocks: int, seed: int) -> FloatArray:
    """``(BOOTSTRAP_RESAMPLES, n_blocks)`` counts of each block in each resample."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, n_blocks, size=(BOOTSTRAP_RESAMPLES, n_blocks))
    counts = np.zeros((BOOTSTRAP_RESAMPLES, n_blocks))
    np.add.at(counts, (np.arange(BOOTSTRAP_RESAMPLES)[:, None], pick), 1.0)
    return counts


def axis_bootstrap_deg(
    rotation: FloatArray, axis: FloatArray, weights: FloatArray | None = None, seed: int = 0
) -> float:
    """95th percentile angle (deg) between the SARA axis and its block-bootstrap replicates.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations in time order.
    axis : ndarray, shape (3,)
        The fitted axis (parent frame).
    weights : ndarray, shape (n,), optional
        Frame weights of the fit.
    seed : int
        Seed of the resampling (results are reproducible).

    Returns
    -------
    float
        Each replicate resamples ``BOOTSTRAP_BLOCKS`` contiguous time blocks with
        replacement; the SARA axis of a replicate is the leading left singular vector of
        its summed rotation matrix (:func:`.pooled.sara_axis`), all replicates in one
        batched SVD.
    """
    n_blocks = min(BOOTSTRAP_BLOCKS, rotation.shape[0] // 2)
    w = np.ones(rotation.shape[0]) if weights is None else weights
    sums = _block_sums(w[:, None, None] * rotation, n_blocks)
    s = np.einsum("bk,kij->bij", _resample_counts(n_blocks, seed), sums)
    u, _, _ = np.linalg.svd(s)
    return float(np.degrees(np.percentile(angle_between_axes(u[:, :, 0], axis), 95)))


def _centre_bootstrap_mm(
    rotation: FloatArray, translation: FloatArray, centre: FloatArray
) -> float:
    """95th percentile distance (mm) of block-bootstrap O'Brien centres from ``centre``."""
    n = rotation.shape[0]
    n_blocks = min(BOOTSTRAP_BLOCKS, n // 2)
    # Normal equations of [I  -R] [u_p; u_c] = t per frame: A^T A (6 x 6) and A^T t (6,).
    ata = np.empty((n, 6, 6))
    ata[:, :3, :3] = np.eye(3)
    ata[:, :3, 3:] = -rotation
    ata[:, 3:, :3] = -np.swapaxes(rotation, 1, 2)
    ata[:, 3:, 3:] = np.eye(3)
    atb = np.concatenate([translation, -np.einsum("nji,nj->ni", rotation, translation)], axis=1)
    counts = _resample_counts(n_blocks, 1)
    m = np.einsum("bk,kij->bij", counts, _block_sums(ata, n_blocks))
    rhs = np.einsum("bk,ki->bi", counts, _block_sums(atb, n_blocks))
    sol = np.linalg.solve(m + 1e-9 * np.eye(6), rhs[..., None])[..., 0]
    return float(np.percentile(np.linalg.norm(sol[:, :3] - centre, axis=1), 95))
