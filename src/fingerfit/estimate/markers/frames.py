"""Each frame's angles with the model held: a Levenberg-Marquardt per frame.

With the lines, the markers' places and their slides held, the cost of
:mod:`.bundle` falls apart into one small problem per frame: its angles and its hand
frame's correction (``K = L + 6`` unknowns). :func:`solve_frames` solves them side by
side: every frame has its own damping, its own acceptance of a step and its own stopping
rule, and leaves the iteration when it has converged. The frames still iterating are
computed together (batched ``K x K`` solves; the loop is over iterations, never over
frames), so a frame's answer is the same whether it was solved alone, in a block of
frames or in the whole recording (to rounding). :func:`frames_step` is one damped step of
every frame, the adjustment's (:func:`.bundle.adjust`) correction of its trial points.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass, replace

import numpy as np

from ...transforms import FloatArray
from .chain import HandFrames, Point, Structure, marker_residuals, over_blocks
from .normal import LAM_START, RIDGE, damping, frame_terms
from .observe import DigitMarkers

#: A frame has converged when the undamped (Gauss-Newton) step from its point is below
#: this in every unknown (rad, mm): its angles then lie within about this of the minimum
#: (the steps shrink geometrically, in deep flexion by about 0.85 a step).
STEP = 1e-8
#: A frame that has taken this many steps (accepted or refused) without converging stops
#: there, unconverged (reported).
MAX_STEPS = 500
#: Below this fraction of its cost a change is rounding: a step whose cost lies within it
#: is taken, and judged by the linear model alone.
FLOOR = 1e-11
#: A frame whose damping (:func:`.normal.damping`) passes this has no step that lowers
#: its cost (its minimum to rounding): converged.
LAM_MAX = 1e8


@dataclass
class FrameSolution:
    """Every frame's solution.

    Attributes
    ----------
    q : ndarray, shape (L, n)
        Angles (rad).
    hand : HandFrames
        Each frame's correction of the hand's frame.
    cost : ndarray, shape (n,)
        Each frame's sum of squared residuals (mm^2): its digit's and hand's markers.
    steps : ndarray of int, shape (n,)
        Steps each frame took (accepted or refused).
    converged : ndarray of bool, shape (n,)
        False where a frame stopped at :data:`MAX_STEPS`.
    """

    q: FloatArray
    hand: HandFrames
    cost: FloatArray
    steps: np.ndarray
    converged: np.ndarray


def solve_frames(data: DigitMarkers, structure: Structure, start: Point) -> FrameSolution:
    """Every frame's angles and hand frame, the model held.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
    start : Point
        The model (its lines, places and slides: tracker coordinates at the reference
        posture, mm, mm/rad) and every frame's start (angles, rad; hand correction).

    Returns
    -------
    FrameSolution
    """
    n, L = data.frames, structure.levels
    lines, u, slide = start.lines, start.u, start.slide
    q, hand = start.q.copy(), start.hand.copy()
    lam = np.full(n, LAM_START)
    steps = np.zeros(n, dtype=int)
    converged = np.ones(n, dtype=bool)
    idx = np.arange(n)  # the frames still iterating
    f = frame_terms(data, structure, Point(lines, u, q, hand, slide))
    qq, bq, cost = f.qq, f.bq, f.cost
    while idx.size:
        # Converged: the undamped (Gauss-Newton) step from here is below STEP.
        far = np.abs(damped_step(qq, bq, np.zeros(len(idx)))).max(axis=1) > STEP
        idx, qq, bq = idx[far], qq[far], bq[far]
        d = damped_step(qq, bq, lam[idx])  # (m, K)
        q_try = q[:, idx] + d[:, :L].T
        now = hand.take(idx)
        h_try = now.moved(d[:, L : L + 3], d[:, L + 3 :])
        nt = frame_terms(data.take(idx), structure, Point(lines, u, q_try, h_try, slide))
        # Below the cost's rounding (FLOOR of it) a step is judged by the model alone.
        floor = FLOOR * cost[idx]
        ok = nt.cost <= cost[idx] + floor
        gain = cost[idx] - nt.cost
        # The gain against the one the linear model promised: a step that lowers the
        # cost by far less (across a curved valley) is taken, but the damping grows.
        promise = 2.0 * (d * bq).sum(axis=1) - np.einsum("nk,nkl,nl->n", d, qq, d)
        ratio = np.where(promise > floor, gain / np.maximum(promise, 1e-300), 0.5)
        lam[idx] = damping(lam[idx], ok, ratio)
        at = idx[ok]
        q[:, at] = q_try[:, ok]
        hand.rotation[at], hand.offset[at] = h_try.rotation[ok], h_try.offset[ok]
        cost[at] = nt.cost[ok]
        qq[ok], bq[ok] = nt.qq[ok], nt.bq[ok]
        steps[idx] += 1
        # No step lowers the cost (its minimum to rounding): converged; out of steps: not.
        stuck = lam[idx] > LAM_MAX
        out = ~stuck & (steps[idx] >= MAX_STEPS)
        converged[idx[out]] = False
        go = ~(stuck | out)
        idx, qq, bq = idx[go], qq[go], bq[go]
    return FrameSolution(q, hand, cost, steps, converged)


def damped_step(qq: FloatArray, bq: FloatArray, lam: FloatArray) -> FloatArray:
    """Each frame's damped Gauss-Newton step ``(m, K)`` from its normal equations ``qq
    (m, K, K)``, ``bq (m, K)``: the diagonal plus :data:`.normal.RIDGE`, times ``1 +
    lam`` (one damping per frame, ``(m,)``)."""
    a = qq.copy()
    diag = np.einsum("nkk->nk", a)
    diag += RIDGE
    diag *= 1.0 + lam[:, None]
    return np.linalg.solve(a, bq[..., None])[..., 0]


def frames_step(
    data: DigitMarkers,
    structure: Structure,
    point: Point,
    lam: float,
    pool: Executor | None = None,
) -> Point:
    """Every frame's angles and hand correction after one step of their own, the model
    held: a Gauss-Newton step damped by ``lam`` (:func:`damped_step`), kept in each
    frame whose cost it lowers.

    The adjustment's trial points (:func:`.bundle.adjust`) move the frames by the
    linear model of the whole problem; at the new model this step follows the cost's
    curvature in each frame's own unknowns (the embedded step of bundle adjustment).

    Parameters
    ----------
    data, structure, point
        As :func:`solve_frames` (``point`` its ``start``).
    lam : float
        The damping (Marquardt's: the diagonal times ``1 + lam``).
    pool : concurrent.futures.Executor, optional
        Threads for the frames' blocks (:func:`.chain.over_blocks`).

    Returns
    -------
    Point
        ``point`` with its frames moved (its lines, places and slides the same objects).
    """
    L = structure.levels

    def block(frames: slice) -> tuple[FloatArray, FloatArray, FloatArray]:
        part, here = data.take(frames), point.take(frames)
        terms = frame_terms(part, structure, here)
        d = damped_step(terms.qq, terms.bq, np.full(len(terms.bq), lam))
        q = here.q + d[:, :L].T
        hand = here.hand.moved(d[:, L : L + 3], d[:, L + 3 :])
        res = marker_residuals(part, structure, replace(here, q=q, hand=hand))
        cost = np.einsum("mcn,mcn->n", res.r, res.r) + np.einsum("hcn,hcn->n", res.rh, res.rh)
        better = cost < terms.cost
        return (
            np.where(better, q, here.q),
            np.where(better[:, None, None], hand.rotation, here.hand.rotation),
            np.where(better[:, None], hand.offset, here.hand.offset),
        )

    q, rotation, offset = zip(*over_blocks(block, data.frames, pool), strict=True)
    return replace(
        point,
        q=np.concatenate(q, axis=1),
        hand=HandFrames(np.concatenate(rotation), np.concatenate(offset)),
    )


def from_neighbours(data: DigitMarkers, structure: Structure, point: Point) -> tuple[Point, int]:
    """Each frame solved again from the angles of the frame before it and of the frame
    after it, kept where that reaches a lower minimum than its own angles do.

    A frame's angles can settle on a minimum of their own away from the motion's (a
    two-axis joint's angles have another branch that nearly fits its segment; a start
    that put a frame there leaves it there: a simulated thumb's frame ended with its CMC
    at -165 deg between frames at 31 deg, 8.6 mm from its markers). Its neighbours'
    angles start it on the motion's. Each start is solved to its minimum
    (:func:`solve_frames`) and the costs compared beyond rounding (:data:`FLOOR`): no
    threshold of ours decides.

    Parameters
    ----------
    data, structure
        As :func:`solve_frames`.
    point : Point
        The model and every frame's angles (rad) and hand correction.

    Returns
    -------
    point : Point
        The same, every frame's angles and hand correction changed where a neighbour's
        start reached a lower minimum.
    moved : int
        The frames changed.
    """
    own = solve_frames(data, structure, point)
    q, hand = point.q.copy(), point.hand.copy()
    cost = own.cost.copy()
    moved = np.zeros(data.frames, dtype=bool)
    for shift in (1, -1):  # the frame before, the frame after (wrapping at the ends)
        start = replace(point, q=np.roll(q, shift, axis=1))
        other = solve_frames(data, structure, start)
        better = other.cost < cost * (1.0 - FLOOR) - FLOOR
        q[:, better] = other.q[:, better]
        hand.rotation[better], hand.offset[better] = (
            other.hand.rotation[better],
            other.hand.offset[better],
        )
        cost[better] = other.cost[better]
        moved |= better
    return replace(point, q=q, hand=hand), int(moved.sum())
