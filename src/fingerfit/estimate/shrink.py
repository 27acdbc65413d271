"""Smooth weighting of weakly determined parameters against their prior mean.

Some parameters of the two-axis MP joint are seen by the data only at second order
(the tilt of the ab/adduction axis towards the flexion axis, the offset between the
two axes). With realistic errors their least-squares values wander along a nearly
flat valley (``docs/methods.md``, "Numerical stability"). Each is given the data's
share ``1 / (1 + (sd / half)^6)`` of the weight, ``sd`` being its cluster-robust
(per grasp cycle) SD from the data alone: exact data (``sd = 0``) determine it fully,
data that do not see it hold it at the prior mean (perpendicular, intersecting axes),
with a smooth passage in between instead of a threshold that rounding could cross.
"""

from __future__ import annotations

import numpy as np

MIN_DATA_SHARE = 1e-6  # below this share the prior mean is used exactly


def data_share(sd: float, half: float) -> float:
    """Weight ``1 / (1 + (sd / half)^6)`` (0-1) of the data against the prior mean.

    Parameters
    ----------
    sd : float
        Cluster-robust SD of a weakly determined parameter from the data alone.
    half : float
        The SD at which data and prior weigh equally (same units as ``sd``).

    Returns
    -------
    float
        1 for ``sd = 0``, 0.5 at ``sd = half``, 0 for a non-finite ``sd``.
    """
    if not np.isfinite(sd):
        return 0.0
    return float(1.0 / (1.0 + (sd / half) ** 6))


__all__ = ["MIN_DATA_SHARE", "data_share"]


def cluster_score_outer(contributions: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, int]:
    """The outer product of the per-cluster scores of a least-squares fit: the "meat" of a
    cluster-robust (sandwich) covariance, where a systematic error repeated within a
    cluster (a grasp cycle) counts once per cluster, not once per row.

    Parameters
    ----------
    contributions : ndarray, shape (n_rows, p)
        Each row's score ``J_row^T r_row`` (Jacobian row times residual, or a frame's
        block of them).
    labels : ndarray, shape (n_rows,)
        The cluster of each row.

    Returns
    -------
    outer : ndarray, shape (p, p)
        ``S^T S`` of the per-cluster sums ``S`` (clusters x p), centred over the clusters;
        a covariance multiplies it by ``G / (G - 1)`` and puts ``H^+`` on both sides.
    clusters : int
        ``G``, the number of clusters.
    """
    uniq, idx = np.unique(np.asarray(labels), return_inverse=True)
    scores = np.zeros((uniq.size, contributions.shape[1]))
    np.add.at(scores, idx, contributions)
    scores -= scores.mean(axis=0)
    return scores.T @ scores, int(uniq.size)
