"""A digit's chain and its skin markers: the unknowns of the marker adjustment, where they
put the markers, and the cost.

The unknowns are the digit's **lines** (each axis's direction and a point of it, the chain
of :mod:`fingerfit.track.chains`: a finger's MP with one or two axes, PIP, DIP; the thumb's
CMC two axes, MCP one or two, IP), each **marker's place** ``u_i`` on its segment at the
reference posture, and every frame's **angles** ``q_t``. Marker ``i`` on segment ``s`` is
predicted at ``A_s(q_t) u_i`` (the chain's motion of that segment, :meth:`Chains.pose`)
and measured at ``y_i(t)`` (the hand's motion removed, :mod:`.observe`); the reference
recording pins the angles' zero: there ``y_i = u_i`` (its mean, weighted by its frame
count). The cost is ``sum |y_i(t) - A_s(q_t) u_i|^2`` (mm^2, every marker seen in every
frame, isotropic noise).

Each frame's hand frame (the rigid fit of the hand's markers) is corrected by six more
unknowns (:class:`HandFrames`), the hand's markers observed about their reference shape:
without them the hand markers' noise, carried to a fingertip 100 mm away, tilted the DIP
axis toward the direction that absorbs it. A direction moves in the plane perpendicular
to it (2 unknowns) and a point of a line perpendicular to the line (2 unknowns; along the
line it is no unknown): :meth:`Lines.moved`.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from ...digits import ABDUCTION_FIRST, DIGITS, FLEXION_FIRST, second_axis
from ...track.chains import Chains, matvec_rows
from ...transforms import FloatArray, orthonormal_basis, unit
from .observe import DigitMarkers

T = TypeVar("T")

#: Frames per block of the frame-wise work (:func:`over_blocks`): a block's intermediate
#: arrays then stay in the processor's caches. A speed setting only: the blocks' sums
#: are taken in their order, whatever ``pool`` runs them.
BLOCK_FRAMES = 1024

#: SD of the prior on a marker's slide per radian of its joint (mm/rad): the slide is
#: estimated, when asked, against this prior (a weak one: skin moves a few mm over a
#: joint's range).
SLIDE_PRIOR = 3.0


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


@dataclass(frozen=True)
class ChainLayout:
    """A digit's chain for the marker fit (:func:`chain_layout`).

    Attributes
    ----------
    names : list of str
        Each level's axis name, proximal first (``mp_abduction``, ``mp``, ``pip``, ...).
    structure : Structure
    first : list of int
        The level of each joint's flexion axis.
    second : dict[int, int]
        Joint index -> the level of its second axis.
    choice : int
        The joint whose second axis is the model's choice (a finger's MP, the thumb's
        MCP); the others' are fixed by the digit (the thumb's CMC always has two).
    """

    names: list[str]
    structure: Structure
    first: list[int]
    second: dict[int, int]
    choice: int = 0

    def order_of(self, joint: int) -> str:
        """A two-axis joint's order: ``abduction_first`` when its second axis is
        proximal."""
        return ABDUCTION_FIRST if self.second[joint] < self.first[joint] else FLEXION_FIRST

    @property
    def order(self) -> str:
        """The order of the choice joint (:data:`ABDUCTION_FIRST` for a hinge)."""
        return self.order_of(self.choice) if self.choice in self.second else ABDUCTION_FIRST


def chain_layout(digit: str, two_axis: bool, order: str = ABDUCTION_FIRST) -> ChainLayout:
    """The chain of ``digit``: the joint whose second axis is a choice (a finger's MP,
    the thumb's MCP) a hinge or, with ``two_axis``, two axes in ``order`` (the
    ab/adduction axis proximal, or the flexion axis); a joint that always has two (the
    thumb's CMC) in the digit's order (:data:`fingerfit.digits.DIGITS`)."""
    d = DIGITS[digit]
    choice = next(
        j for j, joint in enumerate(d.joints) if joint in d.second_axes
        and joint not in d.required_second
    )  # fmt: skip
    names: list[str] = []
    first: list[int] = []
    second: dict[int, int] = {}
    depth = []
    for j, joint in enumerate(d.joints):
        if joint in d.required_second or (two_axis and j == choice):
            pair = [joint, second_axis(joint)]
            if (order if j == choice else d.order[joint]) == ABDUCTION_FIRST:
                pair.reverse()
            second[j] = len(names) + pair.index(second_axis(joint))
            first.append(len(names) + pair.index(joint))
            names += pair
        else:
            first.append(len(names))
            names.append(joint)
        depth.append(len(names))
    return ChainLayout(names, Structure(np.array(depth), np.array(first)), first, second, choice)


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

    def copy(self) -> HandFrames:
        return HandFrames(self.rotation.copy(), self.offset.copy())

    def take(self, frames: slice | np.ndarray) -> HandFrames:
        """The corrections of ``frames`` only (a slice: views; indices: copies)."""
        return HandFrames(self.rotation[frames], self.offset[frames])

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


@dataclass
class Point:
    """A point of the adjustment's unknowns (tracker coordinates at the reference
    posture).

    Attributes
    ----------
    lines : Lines
    u : ndarray, shape (M, 3)
        The markers' places (mm).
    q : ndarray, shape (L, n)
        Every frame's angles (rad).
    hand : HandFrames
        Every frame's correction of the hand's frame.
    slide : ndarray, shape (M, 3) or None
        The markers' slides (mm/rad, :func:`places`), when estimated.
    """

    lines: Lines
    u: FloatArray
    q: FloatArray
    hand: HandFrames
    slide: FloatArray | None = None

    def take(self, frames: slice | np.ndarray) -> Point:
        """The same point over ``frames`` only (their angles and hand corrections)."""
        return Point(self.lines, self.u, self.q[:, frames], self.hand.take(frames), self.slide)


def observed(data: DigitMarkers, hand: HandFrames) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The digit's and the hand's markers with the hand frames' correction, and the
    pivot ``(3,)``."""
    pivot = data.hand_shape.mean(axis=0)
    return hand.apply(data.position, pivot), hand.apply(data.hand, pivot), pivot


def total_cost(
    data: DigitMarkers, structure: Structure, point: Point, pool: Executor | None = None
) -> float:
    """The cost (mm^2) at ``point``: the digit's markers, the hand's markers about their
    shape, the reference term and (with slides) the slide's prior; the frames by blocks
    (:func:`over_blocks`, with ``pool`` side by side)."""

    def block(frames: slice) -> float:
        res = marker_residuals(data.take(frames), structure, point.take(frames))
        return float((res.r * res.r).sum() + (res.rh * res.rh).sum())

    ref = reference_residual(data, point.u)
    slide = point.slide
    prior = 0.0 if slide is None else float((slide * slide).sum()) / SLIDE_PRIOR**2
    return sum(over_blocks(block, data.frames, pool)) + float((ref * ref).sum()) + prior


@dataclass
class MarkerResiduals:
    """The markers at a point of the unknowns (frames last, mm).

    Attributes
    ----------
    y, yh : ndarray, shape (M, 3, n) and (H, 3, n)
        The digit's and the hand's markers with the hand frames' correction
        (:func:`observed`).
    pivot : ndarray, shape (3,)
    r, rh : ndarray, shape (M, 3, n) and (H, 3, n)
        The digit's residuals ``y - p`` and the hand's about their shape, 0 where unseen.
    posed : tuple
        :func:`predict`'s result (``p`` first).
    """

    y: FloatArray
    yh: FloatArray
    pivot: FloatArray
    r: FloatArray
    rh: FloatArray
    posed: tuple[FloatArray, ...]


def marker_residuals(
    data: DigitMarkers, structure: Structure, point: Point, *, levels: bool = False
) -> MarkerResiduals:
    """The markers observed, where the chain puts them (:func:`predict`, with
    ``levels``) and their residuals, at ``point``."""
    y, yh, pivot = observed(data, point.hand)
    ut = places(structure, data, point.u, point.q, point.slide)
    posed = predict(structure, point.lines, data.segment, ut, point.q, levels=levels)
    r = (y - posed[0]) * data.present[:, None]
    rh = (yh - data.hand_shape[..., None]) * data.hand_present[:, None]
    return MarkerResiduals(y, yh, pivot, r, rh, posed)


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


def reference_residual(data: DigitMarkers, u: FloatArray) -> FloatArray:
    """``sqrt(n_ref) (ybar - u)`` of each marker ``(M, 3)`` (0 where never seen)."""
    ok = data.reference_count > 0
    ref = np.where(ok[:, None], data.reference - u, 0.0)
    return ref * np.sqrt(data.reference_count)[:, None]


def frame_blocks(n: int) -> list[slice]:
    """``n`` frames cut into consecutive blocks of about :data:`BLOCK_FRAMES`."""
    edges = np.linspace(0, n, max(1, round(n / BLOCK_FRAMES)) + 1).astype(int)
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(edges)]


def over_blocks(fn: Callable[[slice], T], n: int, pool: Executor | None = None) -> list[T]:
    """``fn`` of each block of :func:`frame_blocks` ``(n)``, in order; with ``pool`` (a
    thread pool: NumPy releases the interpreter's lock in its loops) side by side."""
    blocks = frame_blocks(n)
    if pool is None or len(blocks) == 1:
        return [fn(b) for b in blocks]
    return list(pool.map(fn, blocks))
