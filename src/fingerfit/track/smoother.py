"""The temporal prior between consecutive frames: the angles of a whole block together.

:func:`smooth` adds ``((q_t - q_{t-1}) / (v_k dt))^2`` between linked frames to the cost of
:mod:`.solver`; the Gauss-Newton normal equations are then block tridiagonal (one ``L x L``
block per frame) and are solved per chain as one symmetric banded system
(``scipy.linalg.solveh_banded``).
"""

from __future__ import annotations

import numpy as np

from ..transforms import FloatArray
from .chains import Chains
from .packed import diagonal, pairs
from .solver import MAX_STEP, RIDGE, Observed, Solution, Weights, bound_terms, data_terms, wrap

#: :func:`smooth` has converged when its step would lower a chain's cost by less than this
#: per frame on average (chi-square units; a hundred times :data:`.solver.DECREMENT`: the
#: smoother runs on every frame, from starts already solved frame by frame or interpolated
#: between them).
SMOOTH_DECREMENT = 1e-4


def smooth(
    chains: Chains,
    weights: Weights,
    obs: Observed,
    time: FloatArray,
    linked: np.ndarray,
    q0: FloatArray,
    anchor: tuple[FloatArray, float] | None = None,
    *,
    max_iter: int = 4,
    decrement: float = SMOOTH_DECREMENT,
) -> Solution:
    """The angles of consecutive frames together, with the temporal prior between them.

    ``sum_t cost_t(q_t) + sum_k ((q_{t,k} - q_{t-1,k}) / (v_k (time_t - time_{t-1})))^2``
    over the linked pairs: Gauss-Newton whose normal equations are block tridiagonal (one
    ``L x L`` block per frame), solved per chain as a symmetric banded system, with a
    chain's step halved while its total cost grows.

    Parameters
    ----------
    chains, weights, obs
        As :func:`solve_frames` (``m`` frames).
    time : ndarray, shape (m,)
        Seconds.
    linked : ndarray of bool, shape (m,)
        Whether frame ``t`` is linked to frame ``t - 1`` (``linked[0]`` is ignored).
    q0 : ndarray, shape (D, L, m)
        Start (rad).
    anchor : (ndarray, float), optional
        ``(q (D, L) rad, time s)``: the frame before these (already solved; a live
        stream's previous batch), linked to the first frame by the same prior; NaN
        angles are not linked.
    max_iter : int
    decrement : float
        Stop when every chain's step would lower its cost by less than this per frame
        (chi-square units).

    Returns
    -------
    Solution
    """
    from scipy.linalg import solveh_banded  # on use: SciPy's import costs 0.15-0.2 s

    n_chain, L, m = q0.shape
    pad = (~chains.active)[..., None]
    diag = diagonal(L)
    rows, cols = pairs(L)
    dt = np.maximum(np.diff(time), 1e-6)
    with np.errstate(divide="ignore", over="ignore"):
        link = 1.0 / (weights.speed[..., None] * dt) ** 2  # (D, L, m - 1)
    link = np.where(linked[1:] & ~pad, link, 0.0)
    first = np.zeros((n_chain, L))  # the anchor's weight on the first frame
    qa = np.zeros((n_chain, L))
    if anchor is not None:
        qa = np.nan_to_num(anchor[0])
        with np.errstate(divide="ignore", over="ignore"):
            w0 = 1.0 / (weights.speed * max(float(time[0]) - anchor[1], 1e-6)) ** 2
        first = np.where(np.isfinite(anchor[0]) & chains.active, np.nan_to_num(w0, posinf=0.0), 0.0)
    band = np.zeros((n_chain, L + 1, m * L))  # upper band storage: row L + r - c, column t L + c

    def evaluate(
        x: FloatArray,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Normal matrix (the sensors' part with ``added`` on its diagonal), right-hand
        side, each chain's cost, the residual and ``added`` at ``x``."""
        t = data_terms(chains, weights, obs, x)
        bd, bg, bc = bound_terms(weights, x)
        h = t.hessian
        added = bd + RIDGE + pad
        added[:, :, 0] += first
        h[:, diag] += added
        g = t.gradient + bg
        diff = x[..., 1:] - x[..., :-1]  # (D, L, m - 1)
        pull = link * diff
        g[..., 1:] -= pull
        g[..., :-1] += pull
        g[..., 0] += first * (qa - x[..., 0])
        g *= ~pad
        cost = (t.cost + bc).sum(axis=-1) + (link * diff * diff).sum(axis=(1, 2))  # (D,)
        cost += (first * (x[..., 0] - qa) ** 2).sum(axis=1)
        return h, g, cost, t.rms_mm, added

    q = np.where(pad, 0.0, q0)
    h, g, cost, rms, added = evaluate(q)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        band[:] = 0.0
        for p, (r, c) in enumerate(zip(rows, cols, strict=True)):
            band[:, L + r - c, c::L] = h[:, p]
        band[:, L, : (m - 1) * L] += link.transpose(0, 2, 1).reshape(n_chain, -1)
        band[:, L, L:] += link.transpose(0, 2, 1).reshape(n_chain, -1)
        band[:, 0, L:] = -link.transpose(0, 2, 1).reshape(n_chain, -1)
        rhs = g.transpose(0, 2, 1).reshape(n_chain, -1)
        step = np.stack(
            [solveh_banded(band[d], rhs[d], check_finite=False) for d in range(n_chain)]
        )
        step = step.reshape(n_chain, m, L).transpose(0, 2, 1)
        if ((step * g).sum(axis=(1, 2)) < decrement * m).all():
            break
        np.clip(step, -MAX_STEP, MAX_STEP, out=step)
        alpha = np.ones(n_chain)
        for _ in range(6):
            trial = wrap(q + step * alpha[:, None, None])
            h2, g2, cost2, rms2, added2 = evaluate(trial)
            ok = cost2 <= cost * (1.0 + 1e-12) + 1e-12
            if ok.all():
                break
            alpha = np.where(ok, alpha, alpha / 2.0)
        keep = ok[:, None, None]
        q = np.where(keep, trial, q)
        h, g, added = np.where(keep, h2, h), np.where(keep, g2, g), np.where(keep, added2, added)
        rms = np.where(ok[:, None], rms2, rms)
        cost = np.where(ok, cost2, cost)
    h[:, diag] -= added  # the sensors' part alone, for the uncertainty
    return Solution(q, rms, h, it)
