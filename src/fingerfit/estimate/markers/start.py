"""Where a digit's bundle adjustment starts: from its markers' arcs, joint by joint.

No generic hand and no truth: each joint's line comes from the arcs its child segment's
markers draw about it, proximal joint first (the staged start; a generic start fell into
wrong minima, DIP up to 50 deg off):

1. the child markers, in the parent segment's frame (the hand's for the first joint;
   further out, the proximal joints' motion undone with their start angles), each trace
   a circle about the joint's axis: the axis is the normal of the plane their pooled,
   centred positions span least (the smallest eigenvector of their scatter), and a point
   of it the mean of each marker's circle centre (an algebraic circle fit in that plane);
2. each frame's angle is the mean over the child markers of their turn about that line
   from their reference place; the axis is oriented so that the grasp's larger angles
   are positive (flexion);
3. a joint's second axis (a finger's MP ab/adduction, the thumb's CMC and MCP) starts
   perpendicular to the first axis and to the bone (the child markers' direction from the
   joint), through the same point, its angles at 0.

A segment whose markers all sit on one line through the joint (or a joint that did not
move) gives no plane: the fit reports it (:mod:`.determined`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...transforms import FloatArray, unit
from .bundle import NEAR, BundleResult, adjust
from .chain import HandFrames, Lines, Structure, predict
from .observe import DigitMarkers


def circle_axis(tracks: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """The common axis of points turning on circles about one line.

    Parameters
    ----------
    tracks : list of ndarray, shape (n_i, 3)
        Each marker's positions (mm) in the frame where the line is fixed; no NaN.

    Returns
    -------
    axis : ndarray, shape (3,)
        Unit normal of the circles' planes (sign arbitrary).
    point : ndarray, shape (3,)
        The mean of the circles' centres (mm).
    """
    scatter = sum(np.cov(t.T) * len(t) for t in tracks)
    _, vec = np.linalg.eigh(scatter)
    axis = vec[:, 0]
    basis = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]  # (3, 2)
    centres = []
    for t in tracks:
        xy = t @ basis
        # Kasa: x^2 + y^2 = 2 a x + 2 b y + c, linear in (a, b, c).
        a = np.column_stack([2 * xy, np.ones(len(xy))])
        sol = np.linalg.lstsq(a, (xy * xy).sum(axis=1), rcond=None)[0]
        along = (t @ axis).mean()
        centres.append(basis @ sol[:2] + along * axis)
    return axis, np.mean(centres, axis=0)


def turn_about(
    points: FloatArray, reference: FloatArray, axis: FloatArray, centre: FloatArray
) -> FloatArray:
    """The angle ``(n,)`` (rad) about the line ``(centre, axis)`` that takes ``reference
    (3,)`` toward each of ``points (n, 3)`` (right-hand rule; NaN where a point is)."""
    r = reference - centre
    r = r - (r @ axis) * axis
    p = points - centre
    p = p - (p @ axis)[:, None] * axis
    return np.arctan2(np.cross(r, p) @ axis, p @ r)


def flexion_sign(theta: FloatArray) -> float:
    """``1`` when an axis's angles ``(n,)`` (rad) are flexion (the larger tenth of them
    positive on average), else ``-1``: the axis then points the other way."""
    big = np.abs(theta) >= np.nanpercentile(np.abs(theta), 90)
    return -1.0 if np.nanmean(theta[big]) < 0 else 1.0


def subset(data: DigitMarkers, last: int) -> DigitMarkers:
    """The markers of the digit's segments up to ``last`` (0 the first)."""
    keep = np.flatnonzero(data.segment <= last)
    return replace(
        data,
        labels=[data.labels[i] for i in keep],
        segment=data.segment[keep],
        reference=data.reference[keep],
        reference_count=data.reference_count[keep],
        position=data.position[keep],
        present=data.present[keep],
    )


def staged_start(
    data: DigitMarkers,
    structure: Structure,
    first_levels: list[int],
    second: dict[int, int],
    threads: int = 1,
) -> BundleResult:
    """The staged solve of a digit's chain: each joint started from its child markers'
    arcs about it, then adjusted with every joint proximal to it.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
        The whole chain.
    first_levels : list of int
        The chain level of each joint's (flexion) axis, proximal joint first (3 entries).
    second : dict[int, int]
        Joint index -> the chain level of its second axis.
    threads : int
        :func:`.bundle.adjust`'s.

    Returns
    -------
    BundleResult
        The adjustment of the last stage (every marker, the whole chain), from which
        :func:`.bundle.adjust` goes on.
    """
    L, n = structure.levels, data.frames
    axis, centre = np.zeros((L, 3)), np.zeros((L, 3))
    q = np.zeros((L, n))
    u = np.where(np.isfinite(data.reference), data.reference, 0.0)
    result = None
    hand = HandFrames.identity(n)
    pivot = data.hand_shape.mean(axis=0)
    for j, level in enumerate(first_levels):
        levels = int(structure.depth[j])
        child = np.flatnonzero(data.segment == j)
        tracks = hand.apply(data.position[child], pivot)
        tracks = np.where(data.present[child, None], tracks, np.nan)
        if j > 0:  # the child markers in the parent segment's frame at its reference pose
            sub = Structure(structure.depth[:j])
            lines = Lines(axis[: sub.levels], centre[: sub.levels])
            seg, zero = np.full(len(child), j - 1), np.zeros((len(child), 3))
            p0, rot, _, _ = predict(sub, lines, seg, zero, q[: sub.levels])
            tracks = np.einsum("mjin,mjn->min", rot, tracks - p0)
        tracks = tracks.transpose(0, 2, 1)  # (m, n, 3)
        usable = [t[np.isfinite(t).all(axis=1)] for t in tracks]
        a, c = circle_axis([t for t in usable if len(t) > 3])
        ang = np.stack([turn_about(t, u[i], a, c) for t, i in zip(tracks, child, strict=True)])
        seen = np.isfinite(ang)
        theta = np.where(seen, ang, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)
        if flexion_sign(theta) < 0:
            a, theta = -a, -theta
        axis[level], centre[level], q[level] = a, c, theta
        if j in second:
            bone = unit(u[child].mean(axis=0) - c)
            axis[second[j]] = unit(np.cross(bone, a))
            centre[second[j]] = c
        sub = Structure(structure.depth[: j + 1])
        part = subset(data, j)
        result = adjust(
            part,
            sub,
            Lines(axis[:levels], centre[:levels]),
            u[: len(part.labels)],
            q[:levels],
            hand=hand,
            max_iter=10 if j < len(first_levels) - 1 else 100,
            tol=1e-6 if j < len(first_levels) - 1 else 1e-10,
            near=None if j < len(first_levels) - 1 else NEAR,
            threads=threads,
        )
        axis[:levels], centre[:levels] = result.lines.axis, result.lines.centre
        u[: len(part.labels)], q[:levels], hand = result.u, result.q, result.hand
    assert result is not None
    return result
