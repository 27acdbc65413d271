"""Angles and fingertips of a whole recording, from whatever sensors each frame has.

A digit whose sensors are all present in a frame gets today's direct computation
(:func:`fingerfit.kinematics.compute_kinematics`, the same bits). Every other frame in which
the hand sensor and at least one of the digit's sensors are present is solved by the model
(:mod:`.solver`): each frame on its own first, then every frame of the recording near one
with the temporal prior between consecutive frames (offline, the prior looks both ways:
a joint its frame's sensors do not determine is carried between the frames around it).
Frames without the hand sensor, or without any sensor of the digit, are left empty.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import FingerfitError
from ..kinematics import FingerMotion, Kinematics, carry_by_hand, compute_kinematics
from ..model import VARIANTS, HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..transforms import FloatArray
from .chains import Chains
from .layout import DigitLayout, check_layout
from .smoother import smooth
from .solver import Observed, Weights, observe, solve_frames, uncertainty
from .statistics import chain_angles
from .weights import TrackOptions, chain_weights


@dataclass(frozen=True)
class DigitTrack:
    """How each frame of one digit was computed.

    Attributes
    ----------
    model : ndarray of bool, shape (n_frames,)
        Solved by the model (a sensor of the digit missing in the frame).
    carried : ndarray of bool, shape (n_frames,)
        Of those, the frames whose own sensors leave a joint undetermined (the digit's
        distal sensor missing in the frame): that joint comes from the frames around it.
    empty : ndarray of bool, shape (n_frames,)
        Not computed: the hand sensor missing, or every sensor of the digit.
    rms_mm : ndarray, shape (n_frames,)
        Where solved by the model: RMS over the frame's sensors of the position residual's
        length (mm); NaN elsewhere.
    sd : dict[str, ndarray]
        Angle name -> ``(n_frames,)`` standard deviation (rad, user-axis model when
        computed) from the frame's sensors alone where solved by the model (``inf`` where
        they do not determine it); NaN elsewhere.
    """

    model: np.ndarray
    carried: np.ndarray
    empty: np.ndarray
    rms_mm: FloatArray
    sd: dict[str, FloatArray]


@dataclass(frozen=True)
class Tracked:
    """A recording's kinematics with what the model solved.

    Attributes
    ----------
    kinematics : Kinematics
        As :func:`fingerfit.kinematics.compute_kinematics` gives it, the frames with a
        missing sensor solved by the model.
    layouts : dict[str, DigitLayout]
        Per digit, its sensors in the recording.
    digits : dict[str, DigitTrack]
        Per digit that needed the model in any frame.
    sensors : tuple of str
        The sensors used.
    iterations : int
        Solver iterations (both stages).
    can_solve : bool
        Whether the model carries the calibration statistics a frame needs to be solved.
    """

    kinematics: Kinematics
    layouts: dict[str, DigitLayout]
    digits: dict[str, DigitTrack] = field(default_factory=dict)
    sensors: tuple[str, ...] = ()
    iterations: int = 0
    can_solve: bool = True

    def frames_solved(self) -> int:
        """Frames in which any digit was solved by the model."""
        return _count_any(self.digits, "model")

    def frames_carried(self) -> int:
        """Frames in which a digit had a joint carried from the frames around it."""
        return _count_any(self.digits, "carried")

    def frames_empty(self) -> int:
        """Frames in which any digit could not be computed (left empty)."""
        return _count_any(self.digits, "empty")


def _count_any(digits: dict[str, DigitTrack], key: str) -> int:
    masks = [getattr(t, key) for t in digits.values()]
    return int(np.count_nonzero(np.logical_or.reduce(masks))) if masks else 0


def select_sensors(recording: Recording, sensors: list[str] | None) -> Recording:
    """``recording`` with only the named sensors (``--sensors``); all when ``None``.

    Raises
    ------
    FingerfitError
        A named sensor the recording does not have.
    """
    if sensors is None:
        return recording
    for s in sensors:
        if s not in recording.poses:
            raise FingerfitError(
                f"--sensors names '{s}', which the recording does not have "
                f"(has: {', '.join(recording.poses)})",
                path=recording.name,
            )
    keep = {s: recording.poses[s] for s in sensors}
    return Recording(recording.name, recording.time, keep, list(recording.notes))


def with_every_sensor(recording: Recording, names: list[str]) -> Recording:
    """The recording with a pose series of NaN for every sensor of ``names`` it lacks."""
    n = recording.n_frames
    poses = dict(recording.poses)
    for s in names:
        if s not in poses:
            poses[s] = PoseSeries(np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan))
    return Recording(recording.name, recording.time, poses, list(recording.notes))


def track_recording(
    model: HandModel,
    recording: Recording,
    variants: tuple[str, ...] = VARIANTS,
    fingers: list[str] | None = None,
    sensors: list[str] | None = None,
    options: TrackOptions | None = None,
    anchor: Kinematics | None = None,
) -> Tracked:
    """Joint angles and fingertips of every frame, the missing sensors solved by the model.

    Parameters
    ----------
    model : HandModel
        With calibration statistics (``model.tracking``) wherever a frame needs the model.
    recording : Recording
        Poses of any of the model's sensors (mm, tracker coordinates; NaN where missing).
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``: each solved with its own axes.
    fingers : list of str, optional
        Digits to compute (default: every digit of the model).
    sensors : list of str, optional
        Use only these sensors of the recording (``--sensors``).
    options : TrackOptions, optional
    anchor : Kinematics, optional
        The frame just before ``recording`` (one frame, as this function gave it: a live
        stream's previous batch): linked to the first frame by the temporal prior, so
        that batches solved one after the other join without a step.

    Returns
    -------
    Tracked
        Angles rad, tips and pads mm in tracker coordinates; frames with a complete digit
        exactly as :func:`~fingerfit.kinematics.compute_kinematics` gives them.

    Raises
    ------
    FingerfitError
        A layout that cannot determine a joint (:func:`~.layout.check_layout`), a
        ``--sensors`` name the recording lacks, or a model without calibration statistics
        when a frame needs them.
    """
    options = options or TrackOptions()
    fingers = list(fingers or model.fingers)
    rec = select_sensors(recording, sensors)
    layouts = check_layout(model, set(rec.poses), fingers, recording.name, skip="--fingers")
    needed = [HAND_SENSOR, *(s for d in fingers for s in layouts[d].sensors)]
    full = with_every_sensor(rec, needed)
    kin = compute_kinematics(model, full, variants, fingers)
    n = rec.n_frames
    valid = {s: full.poses[s].valid for s in needed}
    hand = valid[HAND_SENSOR]
    need: dict[str, np.ndarray] = {}
    empty: dict[str, np.ndarray] = {}
    for d in fingers:
        own = np.array([valid[s] for s in layouts[d].sensors])  # (3, n)
        complete = hand & own.all(axis=0)
        empty[d] = ~hand | ~own.any(axis=0)
        need[d] = ~complete & ~empty[d]
    digits = [d for d in fingers if need[d].any()]
    used = tuple(s for s in needed if s in rec.poses)
    if not digits:
        return Tracked(kin, layouts, {}, used, 0, model.tracking is not None)
    # Frames to solve: those that need the model and, for the temporal prior, their
    # neighbours within the margin.
    any_need = np.logical_or.reduce([need[d] for d in digits])
    rate = 1.0 / max(float(np.median(np.diff(rec.time))), 1e-9) if n > 1 else 1.0
    margin = round(options.margin_s * rate) if options.temporal else 0
    wide = _dilate(any_need, margin)
    frames = np.flatnonzero(wide)
    linked = np.zeros(frames.size, dtype=bool)
    linked[1:] = np.diff(frames) == 1
    h = full.poses[HAND_SENSOR]
    sub = {s: full.poses[s] for s in needed}
    motions = {v: dict(kin.motions[v]) for v in variants}
    tracks: dict[str, DigitTrack] = {}
    iterations = 0
    for iv, v in enumerate(variants):
        chains = Chains(model, (v,), digits)
        weights = chain_weights(model, chains, options)
        if iv == 0:
            obs = observe(
                chains,
                h.position[frames],
                h.rotation[frames],
                {s: p.position[frames] for s, p in sub.items()},
                {s: p.rotation[frames] for s, p in sub.items()},
            )
        angles = {v: {d: kin.motions[v][d].angles for d in digits}}
        direct = chain_angles(chains, angles)[..., frames]
        ends = None
        if anchor is not None and options.temporal and frames.size and frames[0] == 0:
            qa = chain_angles(chains, {v: {d: anchor.motions[v][d].angles for d in digits}})
            ends = (qa[..., -1], float(anchor.time[-1]))
        q0 = start(chains, weights, obs, direct, rec.time[frames], linked, coarse_step(rate), ends)
        if options.temporal and (frames.size > 1 or ends is not None):
            sol = smooth(chains, weights, obs, rec.time[frames], linked, q0, ends)
        else:
            sol = solve_frames(chains, weights, obs, q0)
        iterations += sol.iterations
        points = np.stack([chains.tip, chains.pad], axis=1)  # (D, 2, 3)
        tips = chains.points(chains.pose(sol.q), points)  # (D, 2, 3, m)
        sd = uncertainty(chains, sol.hessian) if iv == 0 else None
        for i, d in enumerate(digits):
            rows = need[d][frames]  # columns of `frames` this digit takes from the model
            at = frames[rows]
            m = kin.motions[v][d]
            new_angles = {k: a.copy() for k, a in m.angles.items()}
            for k, name in enumerate(chains.names[i]):
                new_angles[name][at] = sol.q[i, k, rows]
            tip, pad = m.tip.copy(), None if m.pad is None else m.pad.copy()
            world = _carry(model, h, at, tips[i][..., rows].transpose(2, 0, 1))
            tip[at] = world[:, 0]
            if pad is not None:
                pad[at] = world[:, 1]
            motions[v][d] = FingerMotion(new_angles, tip, pad)
            if iv == 0:
                rms = np.full(n, np.nan)
                rms[at] = sol.rms_mm[i, rows]
                sds = {}
                for k, name in enumerate(chains.names[i]):
                    x = np.full(n, np.nan)
                    x[at] = sd[i, k, rows]
                    sds[name] = x
                carried = need[d] & ~valid[layouts[d].sensors[-1]]
                tracks[d] = DigitTrack(need[d], carried, empty[d] & hand, rms, sds)
    for d in fingers:
        if d not in tracks and empty[d].any():
            none = np.zeros(n, dtype=bool)
            tracks[d] = DigitTrack(none, none, empty[d], np.full(n, np.nan), {})
    out = Kinematics(kin.time, {v: {d: motions[v][d] for d in fingers} for v in variants})
    return Tracked(out, layouts, tracks, used, iterations)


#: Frames per second solved on their own before the others start from them
#: (:func:`start`).
COARSE_RATE_HZ = 30.0


def coarse_step(rate: float) -> int:
    """Every how many frames :func:`start` solves one on its own (at least 1)."""
    return max(1, round(rate / COARSE_RATE_HZ))


def start(
    chains: Chains,
    weights: Weights,
    obs: Observed,
    direct: FloatArray,
    time: FloatArray,
    linked: np.ndarray,
    step: int,
    anchor: tuple[FloatArray, float] | None = None,
) -> FloatArray:
    """Where every frame's solution starts, ``(D, L, m)`` rad.

    Angles the frame's own sensors give directly (both sensors of the joint present) start
    there. The others: every ``step``-th frame of each run of consecutive frames (and its
    first and last) is solved on its own (Levenberg-Marquardt from mid-range: a chain
    started stretched sits between its two mirror solutions, a joint flexed one way or the
    other), and the frames between start from those, interpolated in time.
    """
    m = direct.shape[-1]
    mid = (0.5 * (weights.low + weights.high))[..., None]
    run_start = np.flatnonzero(~linked | (np.arange(m) == 0))
    run_end = np.append(run_start[1:], m) - 1
    pick = np.zeros(m, dtype=bool)
    pick[::step] = True
    pick[run_start] = True
    pick[run_end] = True
    cols = np.flatnonzero(pick)
    seed = direct[..., cols]
    sub = obs.take(cols)
    coarse = solve_frames(chains, weights, sub, np.where(np.isfinite(seed), seed, mid))
    q = repair(chains, weights, sub, coarse.q, coarse.cost, seed, run_of(linked)[cols])[0]
    # Interpolation within a run only: each run shifted far from the others in time.
    run = run_of(linked)
    span = float(time[-1] - time[0]) + 1.0 if m else 1.0
    t = time - time[0] + run * span
    flat = q.reshape(-1, cols.size)
    out = np.stack([np.interp(t, t[cols], x) for x in flat]).reshape(direct.shape)
    return np.where(np.isfinite(direct), direct, out)


def last_frame(kin: Kinematics) -> Kinematics:
    """The last frame of ``kin`` (the ``anchor`` of the next batch, :func:`track_recording`)."""
    return Kinematics(
        kin.time[-1:],
        {
            v: {
                d: FingerMotion(
                    {k: a[-1:] for k, a in m.angles.items()},
                    m.tip[-1:],
                    None if m.pad is None else m.pad[-1:],
                )
                for d, m in ms.items()
            }
            for v, ms in kin.motions.items()
        },
    )


def run_of(linked: np.ndarray) -> np.ndarray:
    """Each frame's run of consecutive frames (0, 1, ...), from ``linked`` (whether a frame
    follows the one before it)."""
    return np.cumsum(~linked | (np.arange(linked.size) == 0)) - 1


#: A frame whose cost exceeds this many times the median frame's (plus
#: :data:`SUSPECT_FLOOR`) is solved again from other starts (:func:`repair`).
SUSPECT_RATIO = 10.0
SUSPECT_FLOOR = 50.0
#: Passes of :func:`repair` at most (each lets a solution reach one more frame).
REPAIR_PASSES = 32


def repair(
    chains: Chains,
    weights: Weights,
    obs: Observed,
    q: FloatArray,
    cost: FloatArray,
    direct: FloatArray,
    run: np.ndarray,
) -> tuple[FloatArray, FloatArray]:
    """Frames left in a wrong minimum (a mirror solution: a joint flexed the wrong way
    where the sensors alone cannot tell) solved again from better starts.

    A frame whose cost stands out (:data:`SUSPECT_RATIO` times the median frame's of its
    chain) is solved again from the solutions of the frames before and after it in its run
    (a finger moves continuously) and from three points of the calibration's range; the
    cheapest solution is kept. Passes repeat while they improve a frame, so a good
    solution travels along a run of wrong ones.

    Parameters
    ----------
    chains, weights, obs
        As :func:`~.solver.solve_frames` (``m`` frames, in time order).
    q : ndarray, shape (D, L, m)
        Each frame's solution (rad).
    cost : ndarray, shape (D, m)
        Its cost.
    direct : ndarray, shape (D, L, m)
        The angles the frames' sensors give directly (NaN elsewhere): kept as starts.
    run : ndarray of int, shape (m,)
        Each frame's run of consecutive frames.

    Returns
    -------
    q, cost : ndarray
        Improved.
    """
    q, cost = q.copy(), cost.copy()
    m = q.shape[-1]
    lo, hi = weights.low[..., None], weights.high[..., None]
    fixed = [lo + f * (hi - lo) for f in (0.25, 0.5, 0.75)]
    tried = np.zeros(m, dtype=bool)
    for _ in range(REPAIR_PASSES):
        median = np.median(cost, axis=1, keepdims=True)
        suspect = (cost > SUSPECT_RATIO * median + SUSPECT_FLOOR).any(axis=0)
        cols = np.flatnonzero(suspect)
        if cols.size == 0:
            break
        prev = np.clip(cols - 1, 0, m - 1)
        nxt = np.clip(cols + 1, 0, m - 1)
        starts = [q[..., prev], q[..., nxt]]
        if not tried[cols].all():
            starts += [np.broadcast_to(f, q[..., cols].shape) for f in fixed]
            tried[cols] = True
        better = False
        sub = obs.take(cols)
        same = np.isfinite(direct[..., cols])
        oks = [run[prev] == run[cols], run[nxt] == run[cols]] + [None] * (len(starts) - 2)
        for start, ok in zip(starts, oks, strict=True):
            q0 = np.where(same, direct[..., cols], start)
            sol = solve_frames(chains, weights, sub, q0)
            gain = sol.cost < cost[..., cols] * (1.0 - 1e-9)
            if ok is not None:
                gain &= ok[None, :]
            if gain.any():
                better = True
                q[..., cols] = np.where(gain[:, None], sol.q, q[..., cols])
                cost[..., cols] = np.where(gain, sol.cost, cost[..., cols])
        if not better:
            break
    return q, cost


def _dilate(mask: np.ndarray, margin: int) -> np.ndarray:
    """``mask`` widened by ``margin`` frames on each side."""
    if margin <= 0 or not mask.any():
        return mask.copy()
    c = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    n = mask.size
    i = np.arange(n)
    lo = np.clip(i - margin, 0, n)
    hi = np.clip(i + margin + 1, 0, n)
    return (c[hi] - c[lo]) > 0


def _carry(model: HandModel, hand: PoseSeries, at: np.ndarray, points: FloatArray) -> FloatArray:
    """Points ``(m, k, 3)`` at the reference posture carried by the hand sensor's motion in
    frames ``at (m,)``: ``(m, k, 3)`` mm, tracker coordinates."""
    m, k, _ = points.shape
    rot = np.repeat(hand.rotation[at], k, axis=0)
    pos = np.repeat(hand.position[at], k, axis=0)
    return carry_by_hand(model, rot, pos, points.reshape(-1, 3)).reshape(m, k, 3)


__all__ = [
    "DigitTrack",
    "Observed",
    "TrackOptions",
    "Tracked",
    "last_frame",
    "select_sensors",
    "track_recording",
    "with_every_sensor",
]
