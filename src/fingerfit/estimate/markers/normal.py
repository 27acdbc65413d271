"""The normal equations of the marker adjustment (:mod:`.bundle`) and their damped step.

Each frame's unknowns (its angles, then its hand frame's rotation and translation: ``K =
L + 6``) are coupled only to the global ones (the lines, the markers' places, their
slides). The normal equations are reduced to the global unknowns by the Schur complement,
all frames at once (batched ``K x K`` inverses), and the frames' steps follow by
back-substitution. The Jacobian of a marker in its frame's angles is analytic (``a_k x
(p - c_k)`` with the axes where the chain puts them), in its place ``u_i`` the segment's
rotation, in the lines :func:`line_columns`, in the hand frame :func:`frame_columns`.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from ...track.chains import matvec_rows
from ...transforms import FloatArray, orthonormal_basis
from .chain import (
    SLIDE_PRIOR,
    Lines,
    Point,
    Structure,
    marker_residuals,
    over_blocks,
    reference_residual,
)
from .observe import DigitMarkers

#: Added to each frame's angle block (1/rad^2 in mm^2): an angle no marker of the frame
#: determines stays where it is.
RIDGE = 1e-9
#: Damping (Marquardt: the diagonal times ``1 + lam``) of the adjustment and of the
#: frames' solves: the start and the floor (:func:`damping`).
LAM_START, LAM_MIN = 1e-4, 1e-9
#: The damping's factor after a refused step, and after a taken one by the ratio of its
#: gain to the gain its linear model promised: above GOOD, below POOR, between.
LAM_UP, LAM_DOWN, LAM_POOR, LAM_SAME = 4.0, 1.0 / 3.0, 2.0, 1.0
GOOD, POOR = 0.75, 0.25


def damping(
    lam: FloatArray | float, taken: np.ndarray | bool, ratio: FloatArray | float
) -> FloatArray:
    """The next damping after a step (one or one per frame): up by :data:`LAM_UP` when
    refused; when ``taken``, by the ``ratio`` of its gain to the gain the linear model
    promised (:func:`promised`): down when the model held (above :data:`GOOD`), up when
    the step lowered the cost by far less (across a curved valley, below :data:`POOR`),
    else kept; never below :data:`LAM_MIN`. Shaped as ``lam`` (a NumPy scalar for a
    float)."""
    factor = np.where(ratio > GOOD, LAM_DOWN, np.where(ratio < POOR, LAM_POOR, LAM_SAME))
    return np.maximum(lam * np.where(taken, factor, LAM_UP), LAM_MIN)


def promised(nq: Normal, dq: FloatArray, dg: FloatArray) -> float:
    """The decrease of the cost (mm^2) that the linear model promises for the step
    ``dq (n, K)``, ``dg (G,)`` from ``nq``'s point: ``2 b^T d - d^T A d`` (``A`` the
    undamped normal matrix)."""
    b = float(np.vdot(nq.bq, dq) + nq.bg @ dg)
    frames = np.einsum("nk,nkl,nl->", dq, nq.qq, dq)
    cross = np.einsum("nk,nkg->g", dq, nq.qg) @ dg
    return 2.0 * b - float(frames + 2.0 * cross + dg @ nq.gg @ dg)


def cross_rows(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a x b`` over whole rows of frames, ``(..., 3, n)`` (broadcast): the components on
    the second-to-last axis (:func:`numpy.cross` moves that axis last and back)."""
    a0, a1, a2 = a[..., 0, :], a[..., 1, :], a[..., 2, :]
    b0, b1, b2 = b[..., 0, :], b[..., 1, :], b[..., 2, :]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-2)


def line_columns(
    structure: Structure,
    lines: Lines,
    segment: np.ndarray,
    p: FloatArray,
    q: FloatArray,
    proximal: FloatArray,
    axes: FloatArray,
    centres: FloatArray,
) -> FloatArray:
    """``d p / d (line unknowns)`` ``(M, 3, n, 4 L)``: per level two direction (rad) and
    two point (mm) unknowns of :meth:`Lines.moved`.

    With the line where the proximal axes put it (direction ``a``, point ``c``, rotation
    ``R`` by ``q`` about it) and ``w`` a unit vector perpendicular to the reference
    axis, carried by the proximal rotation: a point of the line moved by ``w`` moves the
    marker by ``(I - R) w = w (1 - cos q) - (a x w) sin q``; the direction moved by ``w``
    moves it by ``(w x v) sin q + (w (a.v) + a (w.v)) (1 - cos q)``, ``v = R^T (p - c)``
    the marker before that rotation.
    """
    return np.moveaxis(
        _line_rows(structure, lines, segment, (p, q, proximal, axes, centres)), 0, -1
    )


def _line_rows(
    structure: Structure, lines: Lines, segment: np.ndarray, posed: tuple[FloatArray, ...]
) -> FloatArray:
    """:func:`line_columns` unknown first, ``(4 L, M, 3, n)`` (each column written whole);
    ``posed`` its ``p, q, proximal, axes, centres``."""
    p, q, proximal, axes, centres = posed
    L = structure.levels
    moves = np.arange(L)[None, :] < structure.depth[segment][:, None]  # (M, L)
    out = np.zeros((4 * L, *p.shape))
    sin, cos1 = np.sin(q), 1.0 - np.cos(q)  # (L, n)
    for k in range(L):
        m = np.flatnonzero(moves[:, k])
        basis = orthonormal_basis(lines.axis[k])[:2]  # (2, 3)
        a, c = axes[k], centres[k]  # (3, n)
        d = p[m] - c  # (m, 3, n)
        ad = (a * d).sum(axis=1, keepdims=True)
        v = d * (1.0 - cos1[k]) - cross_rows(a, d) * sin[k] + a * ad * cos1[k]
        av = (a * v).sum(axis=1, keepdims=True)
        for i in range(2):
            w = matvec_rows(proximal[k], basis[i][:, None])  # (3, n)
            wv = (w * v).sum(axis=1, keepdims=True)
            out[4 * k + i, m] = cross_rows(w, v) * sin[k] + (w * av + a * wv) * cos1[k]
            out[4 * k + 2 + i, m] = w * cos1[k] - cross_rows(a, w) * sin[k]
    return out


@dataclass
class Normal:
    """The normal equations at a point, frames first (``K = L + 6`` unknowns per frame:
    the angles, then the hand's rotation and translation).

    Attributes
    ----------
    qq : ndarray, shape (n, K, K)
    qg : ndarray, shape (n, K, G)
    gg : ndarray, shape (G, G)
    bq : ndarray, shape (n, K)
    bg : ndarray, shape (G,)
        ``J^T r`` (``r`` measured minus predicted).
    cost : float
    count : int
        Scalar observations (3 per seen marker, reference means included).
    frame_cost : ndarray, shape (n,), optional
        Each frame's part of ``cost`` (its digit's and hand's markers, mm^2).
    """

    qq: FloatArray
    qg: FloatArray
    gg: FloatArray
    bq: FloatArray
    bg: FloatArray
    cost: float
    count: int
    frame_cost: FloatArray | None = None

    @property
    def sigma2(self) -> float:
        """The residual variance per coordinate (mm^2): the cost over the observations
        less the frames' and the global unknowns."""
        n, k = self.qq.shape[:2]
        return self.cost / max(self.count - n * k - self.gg.shape[0], 1)


def frame_columns(points: FloatArray, pivot: FloatArray) -> FloatArray:
    """``d p / d (omega, tau)`` of carried-back points ``(K, 3, n)``: ``(n, K, 3, 6)``
    (``J = -d y / d x``: ``-[y - h]x`` and ``I``)."""
    d = (points - pivot[:, None]).transpose(2, 0, 1)  # (n, K, 3)
    out = np.zeros((*d.shape, 6))
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    # -[d]x = [[0, z, -y], [-z, 0, x], [y, -x, 0]]
    out[..., 0, 1], out[..., 0, 2] = z, -y
    out[..., 1, 0], out[..., 1, 2] = -z, x
    out[..., 2, 0], out[..., 2, 1] = y, -x
    out[..., 0, 3] = out[..., 1, 4] = out[..., 2, 5] = 1.0
    return out


def normal_equations(
    data: DigitMarkers,
    structure: Structure,
    point: Point,
    free: np.ndarray,
    pool: Executor | None = None,
) -> tuple[Normal, FloatArray]:
    """The normal equations of every frame and of the global unknowns at ``point``, the
    frames by blocks (:func:`.chain.over_blocks`, with ``pool`` side by side).

    Parameters
    ----------
    point : Point
        With slides (mm/rad, :func:`.chain.places`), those are unknowns too, with the
        prior of :data:`.chain.SLIDE_PRIOR`.
    free : ndarray of bool, shape (4 L + 3 M,) or, with slides, (4 L + 6 M,)
        Global unknowns that move (lines first, then the markers' places, then their
        slides).
    pool : concurrent.futures.Executor, optional
        A thread pool that works through the frames' blocks side by side (the result is
        the same without it).

    Returns
    -------
    normal : Normal
        Over the free global unknowns ``G``.
    scores : ndarray, shape (n, K + G)
        Each frame's ``J^T r`` (frame unknowns, then the global ones), for the
        covariance's clusters.

    Notes
    -----
    A marker's place enters only its own three rows, through its segment's rotation:
    the places' columns are block-diagonal, and their products are formed marker by
    marker, never as a dense ``(3 M, 3 M)`` block.
    """
    M, L, n = len(data.labels), structure.levels, data.frames
    slide = point.slide
    K, G = L + 6, 4 * L + 3 * M * (1 if slide is None else 2)
    g = int(free.sum())
    qq, bq, frame_cost = np.empty((n, K, K)), np.empty((n, K)), np.empty(n)
    qg, sg = np.zeros((n, K, g)), np.zeros((n, g))

    def block(frames: slice) -> FloatArray:
        d = data.take(frames)
        f = frame_terms(d, structure, point.take(frames))
        qq[frames], bq[frames], frame_cost[frames] = f.qq, f.bq, f.cost
        if not g:  # the model held (the angles of a recording): no global column to build
            return np.zeros((0, 0))
        masked = f.rot * d.present[:, None, None]
        qgb, ggb, sgb = _global_products(
            structure, point.lines, d, f.posed, masked, f.jf, f.rr, slide
        )
        if g < G:
            qgb, ggb, sgb = qgb[..., free], ggb[np.ix_(free, free)], sgb[:, free]
        qg[frames], sg[frames] = qgb, sgb
        return ggb

    gg = sum(over_blocks(block, n, pool), start=np.zeros((g, g)))
    bg = sg.sum(axis=0)
    ref = reference_residual(data, point.u)
    uw = np.zeros(G)
    uw[4 * L : 4 * L + 3 * M] = np.repeat(data.reference_count, 3)
    ref_b = np.zeros(G)
    ref_b[4 * L : 4 * L + 3 * M] = (ref * np.sqrt(data.reference_count)[:, None]).ravel()
    prior = 0.0
    if slide is not None:
        uw[4 * L + 3 * M :] = 1.0 / SLIDE_PRIOR**2
        ref_b[4 * L + 3 * M :] = -slide.ravel() / SLIDE_PRIOR**2
        prior = float((slide * slide).sum()) / SLIDE_PRIOR**2
    gg[np.diag_indices_from(gg)] += uw[free]
    bg += ref_b[free]
    cost = float(frame_cost.sum() + (ref * ref).sum()) + prior
    count = 3 * int(data.present.sum() + data.hand_present.sum() + (data.reference_count > 0).sum())
    normal = Normal(qq, qg, gg, bq, bg, cost, count, frame_cost)
    return normal, np.concatenate([bq, sg], axis=1)


@dataclass
class FrameTerms:
    """Each frame's part of the normal equations (``K = L + 6`` unknowns: the angles,
    then the hand frame's rotation and translation).

    Attributes
    ----------
    qq : ndarray, shape (n, K, K)
    bq : ndarray, shape (n, K)
        ``J^T r`` (``r`` measured minus predicted).
    cost : ndarray, shape (n,)
        Each frame's sum of squared residuals, its digit's and hand's markers (mm^2).
    jf : ndarray, shape (n, 3 M, K)
        The digit markers' columns (0 where unseen).
    rr : ndarray, shape (n, 3 M)
        Their residuals (mm; 0 where unseen).
    rot : ndarray, shape (M, 3, 3, n)
        Each marker's segment rotation.
    posed : tuple
        ``p, q, proximal, axes, centres`` of :func:`line_columns`.
    """

    qq: FloatArray
    bq: FloatArray
    cost: FloatArray
    jf: FloatArray
    rr: FloatArray
    rot: FloatArray
    posed: tuple[FloatArray, ...]


def frame_terms(data: DigitMarkers, structure: Structure, point: Point) -> FrameTerms:
    """Each frame's part of the normal equations at ``point``."""
    M, L, n = len(data.labels), structure.levels, data.frames
    H, slide = data.hand.shape[0], point.slide
    res = marker_residuals(data, structure, point, levels=True)
    y, yh, pivot, r, rh = res.y, res.yh, res.pivot, res.r, res.rh
    p, rot, axes, centres, prox = res.posed
    # d p_i / d q_k = a_k x (p_i - c_k) where axis k moves marker i's segment.
    d = p[:, None] - centres[None]  # (M, L, 3, n)
    jq = cross_rows(axes, d)  # (M, L, 3, n)
    jq *= (np.arange(L)[None, :] < structure.depth[data.segment][:, None])[..., None, None]
    if slide is not None:  # the slide moves with the angle it follows
        jq[np.arange(M), structure.flexion[data.segment]] += matvec_rows(rot, slide[..., None])
    jf = np.empty((n, M, 3, L + 6))
    jf[..., :L] = jq.transpose(3, 0, 2, 1)
    jf[..., L:] = frame_columns(y, pivot)
    jf *= data.present.T[:, :, None, None]
    jf = jf.reshape(n, 3 * M, L + 6)
    jh = frame_columns(yh, pivot) * data.hand_present.T[:, :, None, None]
    jh = jh.reshape(n, 3 * H, 6)
    rr = r.transpose(2, 0, 1).reshape(n, 3 * M)
    rrh = rh.transpose(2, 0, 1).reshape(n, 3 * H)
    jft, jht = jf.transpose(0, 2, 1), jh.transpose(0, 2, 1)
    qq = jft @ jf
    qq[:, L:, L:] += jht @ jh
    bq = (jft @ rr[..., None])[..., 0]
    bq[:, L:] += (jht @ rrh[..., None])[..., 0]
    cost = (rr * rr).sum(axis=1) + (rrh * rrh).sum(axis=1)
    return FrameTerms(qq, bq, cost, jf, rr, rot, (p, point.q, prox, axes, centres))


def _global_products(
    structure: Structure,
    lines: Lines,
    data: DigitMarkers,
    posed: tuple[FloatArray, ...],
    rot: FloatArray,
    jf: FloatArray,
    rr: FloatArray,
    slide: FloatArray | None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``J_f^T J_g (n, K, G)``, ``J_g^T J_g (G, G)`` and each frame's ``J_g^T r (n, G)``
    over every global unknown (lines, places, with ``slide`` slides). ``posed``: ``p, q, proximal, axes, centres`` of
    :func:`line_columns`; ``rot (M, 3, 3, n)`` the segments' rotations, 0 where a marker
    is unseen; ``jf (n, 3 M, K)`` and ``rr (n, 3 M)`` the frames' columns and residuals
    (unseen rows 0)."""
    M, L, n = len(data.labels), structure.levels, data.frames
    K = jf.shape[2]
    q = posed[1]
    rows = _line_rows(structure, lines, data.segment, posed)
    rows *= data.present[None, :, None, :]
    jl = np.ascontiguousarray(rows.transpose(3, 1, 2, 0)).reshape(n, 3 * M, 4 * L)
    # The places' columns: marker i's three rows are its segment's rotation (the other
    # rows 0); with slides a second block, the rotation times the angle it follows.
    weights = [np.ones((M, n))]
    if slide is not None:
        weights.append(q[structure.flexion[data.segment]])  # (M, n)
    rotn = np.ascontiguousarray(rot.transpose(3, 0, 1, 2))  # (n, M, 3, 3)
    G = 4 * L + 3 * M * len(weights)
    sg = np.empty((n, G))
    sg[:, : 4 * L] = (rr[:, None] @ jl)[:, 0]
    ru = (rotn.transpose(0, 1, 3, 2) @ rr.reshape(n, M, 3, 1))[..., 0]  # (n, M, 3)
    for s, ws in enumerate(weights):
        sg[:, 4 * L + 3 * M * s : 4 * L + 3 * M * (s + 1)] = (ru * ws.T[..., None]).reshape(n, -1)
    jft = jf.reshape(n, M, 3, K).transpose(0, 1, 3, 2)  # (n, M, K, 3)
    qg = np.empty((n, K, G))
    gg = np.zeros((G, G))
    qg[..., : 4 * L] = jf.transpose(0, 2, 1) @ jl
    flat = jl.reshape(n * 3 * M, 4 * L)
    gg[: 4 * L, : 4 * L] = flat.T @ flat
    seen = data.present.T.astype(float)  # (n, M): R^T R = I where seen
    for s, ws in enumerate(weights):
        cols = slice(4 * L + 3 * M * s, 4 * L + 3 * M * (s + 1))
        ju = rotn * ws.T[:, :, None, None]  # (n, M, 3, 3)
        np.matmul(jft, ju, out=qg[..., cols].reshape(n, K, M, 3).transpose(0, 2, 1, 3))
        for i in range(M):  # the lines' rows of marker i times its columns, over all frames
            li = jl.reshape(n, M, 3, 4 * L)[:, i].reshape(3 * n, 4 * L)
            gg[: 4 * L, cols][:, 3 * i : 3 * i + 3] = li.T @ ju[:, i].reshape(3 * n, 3)
        for t, wt in enumerate(weights[: s + 1]):
            block = np.zeros((M, 3, M, 3))
            count = np.einsum("ni,ni,ni->i", seen, ws.T, wt.T)  # (M,)
            block[np.arange(M), :, np.arange(M), :] = count[:, None, None] * np.eye(3)
            gg[4 * L + 3 * M * t : 4 * L + 3 * M * (t + 1), cols] = block.reshape(3 * M, 3 * M)
    gg = np.triu(gg) + np.triu(gg, 1).T
    return qg, gg, sg


def schur_step(
    nq: Normal, lam: float, pool: Executor | None = None
) -> tuple[FloatArray, FloatArray]:
    """The damped step ``(dq (n, K), dg (G,))`` of the normal equations: the frames'
    blocks eliminated by the Schur complement, then back-substituted; the frames by
    blocks (:func:`.chain.over_blocks`, with ``pool`` side by side)."""
    n, K, G = nq.qg.shape
    wqg, wbq = np.empty((n, K, G)), np.empty((n, K))

    def eliminate(frames: slice) -> tuple[FloatArray, FloatArray]:
        qq = nq.qq[frames].copy()
        diag = np.einsum("nll->nl", qq)
        diag *= 1.0 + lam
        diag += RIDGE
        w = np.linalg.inv(qq)  # (b, K, K)
        wqg[frames] = w @ nq.qg[frames]
        wbq[frames] = (w @ nq.bq[frames, :, None])[..., 0]
        qg, wq = nq.qg[frames].reshape(-1, G), wqg[frames].reshape(-1, G)
        return qg.T @ wq, wq.T @ nq.bq[frames].reshape(-1)

    parts = over_blocks(eliminate, n, pool)
    s = nq.gg.copy()
    s[np.diag_indices_from(s)] *= 1.0 + lam
    s -= sum((p[0] for p in parts), start=np.zeros((G, G)))
    b = nq.bg - sum((p[1] for p in parts), start=np.zeros(G))
    dg = np.linalg.solve(s + 1e-12 * np.eye(G), b)
    return wbq - wqg @ dg, dg


def reduced(nq: Normal) -> tuple[FloatArray, FloatArray]:
    """The Schur complement ``S (G, G)`` of the undamped normal equations (the global
    unknowns' information, the frames' unknowns eliminated) and ``W Q_qg (n, K, G)``."""
    qq = nq.qq.copy()
    np.einsum("nll->nl", qq)[...] += RIDGE
    wqg = np.linalg.solve(qq, nq.qg)
    G, nk = nq.gg.shape[0], nq.bq.size
    s = nq.gg - nq.qg.reshape(nk, G).T @ wqg.reshape(nk, G)
    return s, wqg


def symmetric_pinv(s: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """The pseudo-inverse of a symmetric positive semi-definite ``s (G, G)`` (an
    information or a covariance matrix), inverted in its eigenvectors scaled to a unit
    diagonal (a direction below ``1e-12`` of the largest eigenvalue is dropped), and
    which unknowns (``(G,)`` bool) a dropped direction touches: of an information
    matrix, the unknowns whose variance is unbounded."""
    scale = np.sqrt(np.maximum(np.diag(s), 1e-300))
    w, v = np.linalg.eigh(s / np.outer(scale, scale))
    null = w <= 1e-12 * w.max()
    inv = (v[:, ~null] / w[~null]) @ v[:, ~null].T / np.outer(scale, scale)
    return inv, (np.abs(v[:, null]) > 1e-3).any(axis=1)
