"""Symmetric matrices of every frame, stored as their upper triangle and written over whole
rows of frames.

A chain of ``L`` angles has an ``L x L`` normal matrix per frame; ``m`` frames of ``D``
chains keep it as ``(D, P, m)`` with ``P = L (L + 1) / 2`` rows in :func:`pairs` order
(frames last, so each entry is one contiguous row over the frames). The Cholesky factor and
the solves below run entry by entry over those rows: no Python loop per frame.
"""

from __future__ import annotations

import functools

import numpy as np

from ..transforms import FloatArray


@functools.cache
def pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of each entry of an ``n x n`` upper triangle, row by row."""
    return np.triu_indices(n)


@functools.cache
def diagonal(L: int) -> np.ndarray:
    """Rows of the diagonal in the packed upper triangle."""
    rows, cols = pairs(L)
    return np.flatnonzero(rows == cols)


#: Frames up to which small-batch code paths (one ``matmul`` or ``solve`` over views)
#: are faster than loops over a matrix's entries written over whole rows of frames.
SMALL = 16


def gram_rows(j: FloatArray) -> FloatArray:
    """``J J^T`` of every frame's ``(L, k)`` matrix, ``j (D, L, k, m)``, as its upper triangle
    ``(D, P, m)`` (:func:`pairs` order)."""
    n_chain, L, _, m = j.shape
    rows, cols = pairs(L)
    if m <= SMALL:
        f = j.transpose(0, 3, 1, 2)  # (D, m, L, k)
        full = f @ f.transpose(0, 1, 3, 2)  # (D, m, L, L)
        return full[..., rows, cols].transpose(0, 2, 1)
    out = np.empty((n_chain, rows.size, m))
    for p, (r, c) in enumerate(zip(rows, cols, strict=True)):
        np.einsum("dkm,dkm->dm", j[:, r], j[:, c], out=out[:, p])
    return out


def cholesky_packed(h: FloatArray) -> dict[tuple[int, int], FloatArray]:
    """The upper Cholesky factor ``U`` (``H = U^T U``) of symmetric positive definite
    matrices given as their upper triangle ``(..., P, m)`` (:func:`pairs` order), written
    over whole rows of frames: ``(i, j) -> (..., m)`` for ``j >= i``."""
    P = h.shape[-2]
    L = round((np.sqrt(8 * P + 1) - 1) / 2)
    idx = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(*pairs(L), strict=True))}
    u: dict[tuple[int, int], FloatArray] = {}
    for i in range(L):
        acc = h[..., idx[i, i], :].copy()
        for k in range(i):
            acc -= u[k, i] * u[k, i]
        root = np.sqrt(np.maximum(acc, 1e-300))
        u[i, i] = root
        for j in range(i + 1, L):
            acc = h[..., idx[i, j], :].copy()
            for k in range(i):
                acc -= u[k, i] * u[k, j]
            u[i, j] = acc / root
    return u


def solve_cholesky(u: dict[tuple[int, int], FloatArray], g: FloatArray) -> FloatArray:
    """``H^-1 g`` from :func:`cholesky_packed`'s factor and ``g (..., L, m)``."""
    L = g.shape[-2]
    y: list[FloatArray] = []  # U^T y = g
    for i in range(L):
        acc = g[..., i, :].copy()
        for k in range(i):
            acc -= u[k, i] * y[k]
        y.append(acc / u[i, i])
    x: list[FloatArray] = [y[0]] * L  # U x = y
    for i in reversed(range(L)):
        acc = y[i].copy()
        for k in range(i + 1, L):
            acc -= u[i, k] * x[k]
        x[i] = acc / u[i, i]
    return np.stack(x, axis=-2)


def solve_packed(h: FloatArray, g: FloatArray) -> FloatArray:
    """``H^-1 g`` for symmetric positive definite ``H`` given as its upper triangle
    ``(..., P, m)`` (:func:`pairs` order), ``g (..., L, m)``."""
    L, m = g.shape[-2], g.shape[-1]
    if m <= SMALL:
        rows, cols = pairs(L)
        full = np.empty((*h.shape[:-2], m, L, L))
        packed = np.swapaxes(h, -1, -2)  # (..., m, P)
        full[..., rows, cols] = packed
        full[..., cols, rows] = packed
        x = np.linalg.solve(full, np.swapaxes(g, -1, -2)[..., None])  # (..., m, L, 1)
        return np.swapaxes(x[..., 0], -1, -2)
    return solve_cholesky(cholesky_packed(h), g)


def packed_matvec(h: FloatArray, x: FloatArray) -> FloatArray:
    """``H x`` for symmetric ``H`` given as its upper triangle ``(..., P, m)`` and
    ``x (..., L, m)``."""
    L = x.shape[-2]
    rows, cols = pairs(L)
    full = np.zeros((*h.shape[:-2], L, L, h.shape[-1]))
    full[..., rows, cols, :] = h
    full[..., cols, rows, :] = h
    return (full * x[..., None, :, :]).sum(axis=-2)
