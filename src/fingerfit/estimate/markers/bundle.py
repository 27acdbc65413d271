"""Bundle adjustment of one digit from its skin markers.

The unknowns are the digit's **lines** (each axis's direction and a point of it, the chain
of :mod:`fingerfit.track.chains`: a finger's MP with one or two axes, PIP, DIP; the thumb's
CMC two axes, MCP one or two, IP), each **marker's place** ``u_i`` on its segment at the
reference posture, and every frame's **angles** ``q_t``. Marker ``i`` on segment ``s`` is
predicted at ``A_s(q_t) u_i`` (the chain's motion of that segment, :meth:`Chains.pose`)
and measured at ``y_i(t)`` (the hand's motion removed, :mod:`.observe`); the reference
recording pins the angles' zero: there ``y_i = u_i`` (its mean, weighted by its frame
count). The cost is ``sum |y_i(t) - A_s(q_t) u_i|^2`` (mm^2, every marker seen in every
frame, isotropic noise).

Levenberg-Marquardt on the block structure: each frame's angles form a block of ``L``
unknowns coupled only to the global ones; the normal equations are reduced to the global
unknowns by the Schur complement, all frames at once (batched ``L x L`` inverses), and the
frames' steps follow by back-substitution. The Jacobian of a marker in its frame's angles
is analytic (``a_k x (p - c_k)`` with the axes where the chain puts them), in its place
``u_i`` the segment's rotation, in the lines :func:`line_columns`. Each frame's hand frame
(the rigid fit of the hand's markers) is corrected by six more unknowns of the frame's
block, the hand's markers observed about their reference shape (:class:`HandFrames`):
without them the hand markers' noise, carried to a fingertip 100 mm away, tilted the
DIP axis toward the direction that absorbs it.
A direction moves in the plane perpendicular to it (2 unknowns) and a point of a line
perpendicular to the line (2 unknowns; along the line it is no unknown).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ...track.chains import Chains, matvec_rows
from ...transforms import FloatArray, orthonormal_basis, unit
from .mixing import Mixer, information_weights
from .observe import DigitMarkers

#: SD of the prior on a marker's slide per radian of its joint (mm/rad): the slide is
#: estimated, when asked, against this prior (a weak one: skin moves a few mm over a
#: joint's range).
SLIDE_PRIOR = 3.0
#: Added to each frame's angle block (1/rad^2 in mm^2): an angle no marker of the frame
#: determines stays where it is.
RIDGE = 1e-9


@dataclass
class Lines:
    """A chain's lines (tracker coordinates at the reference posture).

    Attributes
    ----------
    axis : ndarray, shape (L, 3)
        Unit directions, proximal first.
    centre : ndarray, shape (L, 3)
        A point of each line (mm).
    """

    axis: FloatArray
    centre: FloatArray

    def copy(self) -> Lines:
        return Lines(self.axis.copy(), self.centre.copy())

    def moved(self, step: FloatArray) -> Lines:
        """The lines moved by ``step (4 L,)``: per level two direction and two point
        unknowns in the plane perpendicular to the axis (rad, mm)."""
        axis, centre = self.axis.copy(), self.centre.copy()
        for k in range(axis.shape[0]):
            b = orthonormal_basis(axis[k])[:2]  # (2, 3)
            axis[k] = unit(axis[k] + step[4 * k : 4 * k + 2] @ b)
            centre[k] = centre[k] + step[4 * k + 2 : 4 * k + 4] @ b
        return Lines(axis, centre)


@dataclass(frozen=True)
class Structure:
    """What moves what: ``depth (S,)`` axes moving each segment (segment ``s`` moves with
    the first ``depth[s]`` axes); ``flexion (S,)`` the level of each segment's proximal
    flexion axis, whose angle its markers slide with (needed to estimate the slide)."""

    depth: np.ndarray
    flexion: np.ndarray | None = None

    @property
    def levels(self) -> int:
        return int(self.depth[-1])


def predict(
    structure: Structure,
    lines: Lines,
    segment: np.ndarray,
    u: FloatArray,
    q: FloatArray,
    *,
    levels: bool = False,
) -> tuple[FloatArray, ...]:
    """Markers where the chain puts them.

    Parameters
    ----------
    structure : Structure
    lines : Lines
    segment : ndarray of int, shape (M,)
    u : ndarray, shape (M, 3) or (M, 3, n)
        Marker places at the reference posture (mm), or every frame's (sliding).
    q : ndarray, shape (L, n)
        Angles (rad).

    Returns
    -------
    p : ndarray, shape (M, 3, n)
        Predicted markers (mm).
    rotation : ndarray, shape (M, 3, 3, n)
        Each marker's segment rotation.
    axes, centres : ndarray, shape (L, 3, n)
        Each line where the proximal axes put it.
    proximal : ndarray, shape (L, 3, 3, n)
        With ``levels``: the rotation of the axes proximal to each level.
    """
    chains = Chains.from_lines(lines.axis[None], lines.centre[None], structure.depth[None])
    pose = chains.pose(q[None])
    level = structure.depth[segment]
    rot = pose.rotation[0, level]  # (M, 3, 3, n)
    p = matvec_rows(rot, u if u.ndim == 3 else u[..., None]) + pose.translation[0, level]
    if levels:
        return p, rot, pose.axes[0], pose.centres[0], pose.rotation[0, : structure.levels]
    return p, rot, pose.axes[0], pose.centres[0]


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


@dataclass
class HandFrames:
    """Each frame's correction of the hand's frame (the rigid fit of its markers): a
    marker carried back to ``y`` is at ``C (y - h) + h - d`` (``h`` the hand shape's
    centroid).

    Attributes
    ----------
    rotation : ndarray, shape (n, 3, 3)
    offset : ndarray, shape (n, 3)
        mm.
    """

    rotation: FloatArray
    offset: FloatArray

    @classmethod
    def identity(cls, n: int) -> HandFrames:
        return cls(np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), np.zeros((n, 3)))

    def apply(self, points: FloatArray, pivot: FloatArray) -> FloatArray:
        """``points (K, 3, n)`` corrected (mm)."""
        x = points - pivot[:, None]
        out = np.einsum("nij,kjn->kin", self.rotation, x)
        return out + (pivot[:, None] - self.offset.T)[None]

    def moved(self, omega: FloatArray, tau: FloatArray) -> HandFrames:
        """After a step ``omega (n, 3)`` rad, ``tau (n, 3)`` mm: ``y' = Rot(-omega) y - tau``
        about the pivot."""
        back = Rotation.from_rotvec(-omega).as_matrix()
        return HandFrames(back @ self.rotation, np.einsum("nij,nj->ni", back, self.offset) + tau)


def observed(data: DigitMarkers, hand: HandFrames) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The digit's and the hand's markers with the hand frames' correction, and the
    pivot ``(3,)``."""
    pivot = data.hand_shape.mean(axis=0)
    return hand.apply(data.position, pivot), hand.apply(data.hand, pivot), pivot


def residual(
    data: DigitMarkers,
    structure: Structure,
    lines: Lines,
    u: FloatArray,
    q: FloatArray,
    hand: HandFrames,
    slide: FloatArray | None = None,
) -> float:
    """The cost (mm^2): the digit's markers, the hand's markers about their shape, the
    reference term and (with ``slide``) the slide's prior."""
    y, yh, _ = observed(data, hand)
    r, rh, _ = _residuals(
        data,
        y,
        yh,
        predict(structure, lines, data.segment, places(structure, data, u, q, slide), q),
    )
    ref = _reference_residual(data, u)
    prior = 0.0 if slide is None else float((slide * slide).sum()) / SLIDE_PRIOR**2
    return float((r * r).sum() + (rh * rh).sum() + (ref * ref).sum()) + prior


def _residuals(
    data: DigitMarkers, y: FloatArray, yh: FloatArray, posed: tuple[FloatArray, ...]
) -> tuple[FloatArray, FloatArray, tuple[FloatArray, ...]]:
    """The digit's markers' residuals ``y - p`` ``(M, 3, n)`` (``p`` the first of
    :func:`predict`'s ``posed``) and the hand's about their shape ``(H, 3, n)``, 0 where
    unseen (mm), and ``posed`` itself."""
    r = (y - posed[0]) * data.present[:, None]
    rh = (yh - data.hand_shape[..., None]) * data.hand_present[:, None]
    return r, rh, posed


def places(
    structure: Structure, data: DigitMarkers, u: FloatArray, q: FloatArray, slide: FloatArray | None
) -> FloatArray:
    """The markers' places ``(M, 3)``, or with ``slide (M, 3)`` (mm/rad) every frame's
    ``u + slide theta`` ``(M, 3, n)``, ``theta`` the angle of the segment's proximal
    flexion axis (rad)."""
    if slide is None:
        return u
    assert structure.flexion is not None
    theta = q[structure.flexion[data.segment]]  # (M, n)
    return u[..., None] + slide[..., None] * theta[:, None, :]


def _reference_residual(data: DigitMarkers, u: FloatArray) -> FloatArray:
    """``sqrt(n_ref) (ybar - u)`` of each marker ``(M, 3)`` (0 where never seen)."""
    ok = data.reference_count > 0
    ref = np.where(ok[:, None], data.reference - u, 0.0)
    return ref * np.sqrt(data.reference_count)[:, None]


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
    lines: Lines,
    u: FloatArray,
    q: FloatArray,
    hand: HandFrames,
    free: np.ndarray,
    slide: FloatArray | None = None,
) -> tuple[Normal, FloatArray]:
    """The normal equations of every frame and of the global unknowns.

    Parameters
    ----------
    free : ndarray of bool, shape (4 L + 3 M,) or, with ``slide``, (4 L + 6 M,)
        Global unknowns that move (lines first, then the markers' places, then their
        slides).
    slide : ndarray, shape (M, 3), optional
        Each marker's slide (mm/rad, :func:`places`): then unknowns too, with the prior
        of :data:`SLIDE_PRIOR`.

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
    f = frame_terms(data, structure, lines, u, q, hand, slide)
    G = 4 * L + 3 * M * (1 if slide is None else 2)
    if free.any():
        masked = f.rot * data.present[:, None, None]
        qg, gg, sg = _global_products(structure, lines, data, f.posed, masked, f.jf, f.rr, slide)
        if not free.all():
            qg, gg, sg = qg[..., free], gg[np.ix_(free, free)], sg[:, free]
    else:  # the model held (the angles of a recording): no global column to build
        qg, gg, sg = np.zeros((n, L + 6, 0)), np.zeros((0, 0)), np.zeros((n, 0))
    bg = sg.sum(axis=0)
    ref = _reference_residual(data, u)
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
    cost = float(f.cost.sum() + (ref * ref).sum()) + prior
    count = 3 * int(data.present.sum() + data.hand_present.sum() + (data.reference_count > 0).sum())
    normal = Normal(f.qq, qg, gg, f.bq, bg, cost, count, f.cost)
    return normal, np.concatenate([f.bq, sg], axis=1)


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


def frame_terms(
    data: DigitMarkers,
    structure: Structure,
    lines: Lines,
    u: FloatArray,
    q: FloatArray,
    hand: HandFrames,
    slide: FloatArray | None = None,
) -> FrameTerms:
    """Each frame's part of the normal equations at ``q (L, n)`` (rad), ``hand``, the
    lines, places ``u (M, 3)`` (mm) and slides ``slide (M, 3)`` (mm/rad) as given."""
    M, L, n = len(data.labels), structure.levels, data.frames
    H = data.hand.shape[0]
    y, yh, pivot = observed(data, hand)
    ut = places(structure, data, u, q, slide)
    r, rh, posed = _residuals(
        data, y, yh, predict(structure, lines, data.segment, ut, q, levels=True)
    )
    p, rot, axes, centres, prox = posed
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
    return FrameTerms(qq, bq, cost, jf, rr, rot, (p, q, prox, axes, centres))


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


def schur_step(nq: Normal, lam: float) -> tuple[FloatArray, FloatArray]:
    """The damped step ``(dq (n, K), dg (G,))`` of the normal equations: the frames'
    blocks eliminated by the Schur complement, then back-substituted."""
    qq = nq.qq.copy()
    diag = np.einsum("nll->nl", qq)
    diag *= 1.0 + lam
    diag += RIDGE
    w = np.linalg.inv(qq)  # (n, L, L)
    wqg = w @ nq.qg  # (n, L, G)
    s = nq.gg.copy()
    s[np.diag_indices_from(s)] *= 1.0 + lam
    G, nk = s.shape[0], nq.bq.size
    s -= nq.qg.reshape(nk, G).T @ wqg.reshape(nk, G)
    b = nq.bg - wqg.reshape(nk, G).T @ nq.bq.reshape(nk)
    dg = np.linalg.solve(s + 1e-12 * np.eye(s.shape[0]), b)
    dq = (w @ nq.bq[..., None])[..., 0] - wqg @ dg
    return dq, dg


def reduced(nq: Normal) -> tuple[FloatArray, FloatArray]:
    """The Schur complement ``S (G, G)`` of the undamped normal equations (the global
    unknowns' information, the frames' unknowns eliminated) and ``W Q_qg (n, K, G)``."""
    qq = nq.qq.copy()
    np.einsum("nll->nl", qq)[...] += RIDGE
    wqg = np.linalg.solve(qq, nq.qg)
    G, nk = nq.gg.shape[0], nq.bq.size
    s = nq.gg - nq.qg.reshape(nk, G).T @ wqg.reshape(nk, G)
    return s, wqg


@dataclass
class BundleResult:
    """A converged bundle adjustment of one digit.

    Attributes
    ----------
    lines : Lines
    u : ndarray, shape (M, 3)
        Marker places at the reference posture (mm).
    q : ndarray, shape (L, n)
        Angles of every frame (rad).
    hand : HandFrames
        Each frame's correction of the hand's frame.
    slide : ndarray, shape (M, 3) or None
        Each marker's slide (mm/rad), when estimated.
    cost : float
        Sum of squared residuals (mm^2).
    rms_mm : float
        RMS residual per coordinate (mm).
    iterations : int
    normal : Normal
        At the solution.
    free : ndarray of bool, shape (4 L + 3 M,)
    """

    lines: Lines
    u: FloatArray
    q: FloatArray
    hand: HandFrames
    slide: FloatArray | None
    cost: float
    rms_mm: float
    iterations: int
    normal: Normal
    free: np.ndarray


def adjust(
    data: DigitMarkers,
    structure: Structure,
    lines: Lines,
    u: FloatArray,
    q: FloatArray,
    *,
    hand: HandFrames | None = None,
    slide: FloatArray | None = None,
    free: np.ndarray | None = None,
    max_iter: int = 100,
    tol: float = 1e-12,
    mix: bool = True,
) -> BundleResult:
    """Levenberg-Marquardt over the lines, the markers' places, every frame's angles and
    every frame's hand frame.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
    lines : Lines
        Start (tracker coordinates at the reference posture, mm).
    u : ndarray, shape (M, 3)
        Start of the markers' places (mm).
    q : ndarray, shape (L, n)
        Start of the angles (rad).
    hand : HandFrames, optional
        Start of the hand frames' correction (default none: the rigid fit's).
    slide : ndarray, shape (M, 3), optional
        Start of the markers' slides (mm/rad): estimated too (:func:`places`).
    free : ndarray of bool, shape (4 L + 3 M,) or with ``slide`` (4 L + 6 M,), optional
        Global unknowns that move (default all).
    max_iter : int
    tol : float
        Converged when an accepted step lowers the cost by less than ``tol`` of it.
    mix : bool
        Propose each step mixed with the last ones (:mod:`.mixing`), kept when it lowers
        the cost below the plain step's.

    Returns
    -------
    BundleResult
    """
    L, M = structure.levels, len(data.labels)
    G = 4 * L + 3 * M * (1 if slide is None else 2)
    free = np.ones(G, dtype=bool) if free is None else free
    lines_free = bool(free[: 4 * L].any())
    hand = HandFrames.identity(data.frames) if hand is None else hand
    lines, u, q = lines.copy(), u.copy(), q.copy()
    nq, _ = normal_equations(data, structure, lines, u, q, hand, free, slide)
    diagonal = np.zeros(G)
    diagonal[free] = np.diag(nq.gg)
    sizes = [(2, 3)] * 2 * L + [(1, 1)] * (G - 4 * L)
    mixer = Mixer(information_weights(diagonal, sizes)) if mix else None
    lam = 1e-4
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        done = False
        for _ in range(12):
            dq, dg = schur_step(nq, lam)
            step = np.zeros(G)
            step[free] = dg
            trial = (
                lines.moved(step[: 4 * L]) if lines_free else lines,
                u + step[4 * L : 4 * L + 3 * M].reshape(M, 3),
                q + dq[:, :L].T,
                hand.moved(dq[:, L : L + 3], dq[:, L + 3 :]),
                None if slide is None else slide + step[4 * L + 3 * M :].reshape(M, 3),
            )
            cost = residual(data, structure, *trial)
            if cost <= nq.cost:
                if mixer is not None:
                    here = _pack(lines, u, q, hand, slide)
                    there = _pack(*trial)
                    mixed = mixer.propose(here, (there[0] - here[0], there[1] - here[1]))
                    if mixed is not None:
                        candidate = _unpack(*mixed, L, M, slide is not None)
                        c = residual(data, structure, *candidate)
                        if c < cost:
                            trial, cost = candidate, c
                gain = nq.cost - cost
                lines, u, q, hand, slide = trial
                nq, _ = normal_equations(data, structure, lines, u, q, hand, free, slide)
                lam = max(lam / 3.0, 1e-9)
                done = gain <= tol * max(cost, 1e-300)
                break
            lam *= 4.0
            if mixer is not None:
                mixer.forget()
        else:
            done = True  # no step lowers the cost
        if done:
            break
    rms = float(np.sqrt(nq.cost / max(nq.count, 1)))
    return BundleResult(lines, u, q, hand, slide, nq.cost, rms, it, nq, free)


def _pack(
    lines: Lines, u: FloatArray, q: FloatArray, hand: HandFrames, slide: FloatArray | None
) -> tuple[FloatArray, FloatArray]:
    """A point's coordinates for :class:`.mixing.Mixer`: the global ones ``(6 L + 3 M,)``
    (each line's direction and point, the places, with ``slide`` the slides; mm, mm/rad)
    and each frame's ``(n, L + 6)`` (angles, the hand correction's rotation vector, rad,
    and offset, mm)."""
    parts = [np.concatenate([lines.axis, lines.centre], axis=1).ravel(), u.ravel()]
    if slide is not None:
        parts.append(slide.ravel())
    rotvec = Rotation.from_matrix(hand.rotation).as_rotvec()
    return np.concatenate(parts), np.concatenate([q.T, rotvec, hand.offset], axis=1)


def _unpack(
    g: FloatArray, f: FloatArray, L: int, M: int, sliding: bool
) -> tuple[Lines, FloatArray, FloatArray, HandFrames, FloatArray | None]:
    """The point of :func:`_pack`'s coordinates (each direction scaled to unit length)."""
    lines = g[: 6 * L].reshape(L, 6)
    places = g[6 * L :].reshape(-1, M, 3)
    hand = HandFrames(Rotation.from_rotvec(f[:, L : L + 3]).as_matrix(), f[:, L + 3 :].copy())
    return (
        Lines(unit(lines[:, :3]), lines[:, 3:].copy()),
        places[0].copy(),
        f[:, :L].T.copy(),
        hand,
        places[1].copy() if sliding else None,
    )


def line_covariance(result: BundleResult) -> FloatArray:
    """The covariance ``(L, 4, 4)`` of each line's unknowns (two direction, rad, and two
    point, mm, in the plane perpendicular to the axis: :meth:`Lines.moved`).

    ``sigma^2 S^-1``, with ``S`` the Schur complement of the frames' unknowns in the
    undamped normal matrix and ``sigma^2`` the residual variance per coordinate. ``S`` is
    inverted in its eigenvectors (scaled to a unit diagonal): a direction with no
    information (below ``1e-12`` of the largest) gives its unknowns an infinite variance;
    unknowns held fixed are NaN.
    """
    s, _ = reduced(result.normal)
    n, k = result.normal.qq.shape[:2]
    dof = max(result.normal.count - n * k - s.shape[0], 1)
    scale = np.sqrt(np.maximum(np.diag(s), 1e-300))
    w, v = np.linalg.eigh(s / np.outer(scale, scale))
    null = w <= 1e-12 * w.max()
    inv = (v[:, ~null] / w[~null]) @ v[:, ~null].T / np.outer(scale, scale)
    if null.any():
        touched = (np.abs(v[:, null]) > 1e-3).any(axis=1)
        inv[touched, :] = inv[:, touched] = np.inf
    full = np.full((result.free.size, result.free.size), np.nan)
    idx = np.flatnonzero(result.free)
    full[np.ix_(idx, idx)] = result.cost / dof * inv
    L = result.lines.axis.shape[0]
    return np.stack([full[4 * k : 4 * k + 4, 4 * k : 4 * k + 4] for k in range(L)])
