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
3. a joint that always has two axes (the thumb's CMC) starts from its child segment's
   pose each frame instead (:func:`saddle_start`): the rigid fit of its markers and the
   point whose distance to each stays most nearly constant, then the saddle fit of
   those poses (:mod:`fingerfit.estimate.saddle`, the 6-DOF pipeline's): a circle fit
   took its axes 56-86 deg off on simulated thumbs, whose CMC turns about both axes at
   once. A joint whose second axis is a model choice (a finger's MP, the thumb's MCP)
   gets it later, from the hinge fit (:func:`.fit.fit_chain`).

A segment whose markers all sit on one line through the joint (or a joint that did not
move) gives no plane: the fit reports it (:mod:`.determined`).
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

import numpy as np

from ...digits import FLEXION_FIRST
from ...errors import FingerfitError
from ...io.rigid import fit_cluster
from ...transforms import FloatArray
from ..saddle import fit_saddle
from .bundle import NEAR, BundleResult, adjust
from .chain import ChainLayout, HandFrames, Lines, Structure, predict
from .frames import from_neighbours
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


def sphere_centre(tracks: list[FloatArray]) -> FloatArray:
    """The point ``(3,)`` (mm) whose distance to each marker stays most nearly constant
    over its track: ``|p|^2 = 2 p . c + k_i``, linear in ``c`` and each marker's ``k_i``.

    Parameters
    ----------
    tracks : list of ndarray, shape (n_i, 3)
        Each marker's positions (mm) in the frame where the joint is fixed; no NaN.
    """
    m = len(tracks)
    rows = [
        np.column_stack([2 * t, np.repeat(np.eye(m)[i][None], len(t), axis=0)])
        for i, t in enumerate(tracks)
    ]
    rhs = np.concatenate([(t * t).sum(axis=1) for t in tracks])
    return np.linalg.lstsq(np.vstack(rows), rhs, rcond=None)[0][:3]


def saddle_start(
    tracks: FloatArray, reference: FloatArray, name: str
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A two-axis joint's start from its child markers: the segment's pose each frame from
    its markers and the joint's centre (:func:`sphere_centre`), then the saddle fit of
    those poses (:func:`fingerfit.estimate.saddle.fit_saddle`, the flexion axis proximal).

    Parameters
    ----------
    tracks : ndarray, shape (m, n, 3)
        The child segment's markers (mm) in the parent's frame; NaN where unseen.
    reference : ndarray, shape (m, 3)
        Their places at the reference posture (mm, the same frame).
    name : str
        The joint, for the error.

    Returns
    -------
    axis, centre : ndarray, shape (2, 3)
        The proximal (flexion) and distal (ab/adduction) lines at the reference posture.
    q : ndarray, shape (2, n)
        Their angles (rad; 0 where a marker is unseen).

    Raises
    ------
    FingerfitError
        Fewer than two markers on the segment: a marker's direction from the joint has
        two degrees of freedom, as many as the joint, and its pose has none to spare.
    """
    m, n = tracks.shape[:2]
    if m < 2:
        raise FingerfitError(
            f"{name}: one marker on its segment cannot start the joint's two axes "
            "(it needs two or more; docs/markers.md)"
        )
    seen = np.isfinite(tracks).all(axis=(0, 2))
    c = sphere_centre([t[seen] for t in tracks])
    points = np.concatenate([np.broadcast_to(c, (1, n, 3)), tracks]).transpose(1, 0, 2)
    pose = fit_cluster(points, np.vstack([c, reference]))
    ok = np.isfinite(pose.rotation).all(axis=(1, 2))
    try:
        fit = fit_saddle(
            pose.rotation[ok], pose.translation[ok], np.eye(3), order=FLEXION_FIRST,
            strict_order=False,
        )  # fmt: skip
    except FingerfitError as exc:
        raise FingerfitError(f"{name}: {exc.reason}") from None
    axis = np.stack([fit.flexion_axis, fit.abduction_axis])
    centre = np.stack([fit.flexion_point, fit.abduction_point])
    q = np.zeros((2, n))
    q[0, ok], q[1, ok] = fit.flexion_angle, fit.abduction_angle
    return axis, centre, q


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


def staged_start(data: DigitMarkers, layout: ChainLayout, threads: int = 1) -> BundleResult:
    """The staged solve of a digit's chain: each joint started from its child markers'
    arcs about it (a joint with two axes, the thumb's CMC: :func:`saddle_start`), then
    adjusted with every joint proximal to it. After a two-axis joint's stage and after
    the last, the frames are solved again from their neighbours' angles
    (:func:`.frames.from_neighbours`), and the stage adjusted again when one moved: a
    frame can be left on another branch of its angles (a two-axis joint's; a frame
    whose middle phalanx's markers are unseen reaches its nail marker two ways).

    Parameters
    ----------
    data : DigitMarkers
    layout : ChainLayout
        The whole chain (:func:`.chain.chain_layout`).
    threads : int
        :func:`.bundle.adjust`'s.

    Returns
    -------
    BundleResult
        The adjustment of the last stage (every marker, the whole chain), from which
        :func:`.bundle.adjust` goes on.
    """
    structure, first_levels, second = layout.structure, layout.first, layout.second
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
        if j in second:
            k = second[j]
            ax2, c2, q2 = saddle_start(tracks, u[child], f"{data.digit} {layout.names[level]}")
            axis[[level, k]], centre[[level, k]], q[[level, k]] = ax2, c2, q2
        else:
            usable = [t[np.isfinite(t).all(axis=1)] for t in tracks]
            a, c = circle_axis([t for t in usable if len(t) > 3])
            ang = np.stack([turn_about(t, u[i], a, c) for t, i in zip(tracks, child, strict=True)])
            seen = np.isfinite(ang)
            theta = np.where(seen, ang, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)
            axis[level], centre[level], q[level] = a, c, theta
        if flexion_sign(q[level]) < 0:
            axis[level], q[level] = -axis[level], -q[level]
        sub = Structure(structure.depth[: j + 1])
        part = subset(data, j)
        last = j == len(first_levels) - 1

        stage = partial(
            adjust, part, sub, max_iter=100 if last else 10, tol=1e-10 if last else 1e-6,
            near=NEAR if last else None, threads=threads,
        )  # fmt: skip
        result = stage(
            Lines(axis[:levels], centre[:levels]), u[: len(part.labels)], q[:levels], hand=hand
        )
        if j in second or last:  # frames left on the angles' other branch
            again, moved = from_neighbours(part, sub, result.point)
            if moved:
                result = stage(again.lines, again.u, again.q, hand=again.hand)
        axis[:levels], centre[:levels] = result.lines.axis, result.lines.centre
        u[: len(part.labels)], q[:levels], hand = result.u, result.q, result.hand
    assert result is not None
    return result
