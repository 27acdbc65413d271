"""Jumps in tracker recordings: position or orientation steps both faster than a body
moves and much faster than the movement around them (magnetic hemisphere flips, marker
swaps), found with their frame and never altered (:func:`find_jumps`), and the notes
that report them (:func:`jump_notes`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..session import Recording
from ..transforms import row_norms

#: Default thresholds of :func:`find_jumps`: faster than any finger moves.
MAX_SPEED_MM_S = 3000.0
MAX_TURN_DEG_S = 3600.0
#: A jump is also this many times faster than the median of the steps around it ...
JUMP_RELATIVE = 5.0
#: ... taken over a centred window of this many steps.
JUMP_WINDOW = 21

_LIST_MAX = 8


@dataclass(frozen=True)
class Jump:
    """A step of one sensor faster than a body can move.

    Attributes
    ----------
    sensor : str
    kind : {"position", "orientation"}
    frame : int
        0-based frame index of the first sample after the jump.
    end_frame : int
        Last frame of the jump (steps within a few frames are merged into one jump).
    time : float
        Time of ``frame`` (s).
    peak : float
        Largest speed in the jump: mm/s for position, deg/s for orientation.
    hemisphere : bool
        Whether the position after the jump is the mirror image through the tracker
        origin of the position before it (a magnetic tracker's hemisphere ambiguity).
    """

    sensor: str
    kind: str
    frame: int
    end_frame: int
    time: float
    peak: float
    hemisphere: bool = False


#: Candidate steps whose local medians are taken at a time (bounds the windows' memory).
_MEDIAN_BLOCK = 1 << 15


def centred_median(values: np.ndarray, at: np.ndarray, window: int) -> np.ndarray:
    """Median of the ``window`` values centred on each index of ``at``, NaN ignored.

    The window of index ``i`` is ``values[i - window // 2 : i - window // 2 + window]``,
    cut at the ends (pandas' ``rolling(window, center=True, min_periods=1).median()``,
    value for value), but only at ``at``: a recording's few fast steps, not its every step.

    Parameters
    ----------
    values : ndarray, shape (n,)
    at : ndarray of int, shape (k,)
        Indices into ``values`` whose values are finite.
    window : int
        Values per window (at least 1).

    Returns
    -------
    ndarray, shape (k,)
    """
    lo = window // 2
    padded = np.concatenate([np.full(lo, np.nan), values, np.full(window - 1 - lo, np.nan)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, window)
    out = np.empty(at.size)
    for s in range(0, at.size, _MEDIAN_BLOCK):  # blocks of windows, not frames
        out[s : s + _MEDIAN_BLOCK] = np.nanmedian(windows[at[s : s + _MEDIAN_BLOCK]], axis=1)
    return out


def find_jumps(
    recording: Recording,
    *,
    max_speed_mm_s: float = MAX_SPEED_MM_S,
    max_turn_deg_s: float = MAX_TURN_DEG_S,
    relative: float = JUMP_RELATIVE,
    window: int = JUMP_WINDOW,
    merge_frames: int = 5,
    valid: dict[str, np.ndarray] | None = None,
) -> list[Jump]:
    """Flag position and orientation jumps between consecutive valid samples.

    A step is a jump when its speed exceeds the absolute limit **and** ``relative``
    times the median speed of the ``window`` steps around it, so fast but smooth
    movement (e.g. a whole arm in a lab) is not flagged while a sudden step is.

    Parameters
    ----------
    recording : Recording
        Positions mm, rotations sensor -> tracker, time s.
    max_speed_mm_s : float
        Position speed (mm/s) above which a step may be a jump.
    max_turn_deg_s : float
        Angular speed (deg/s) above which a step may be a jump.
    relative : float
        How many times faster than the local median speed a jump must be.
    window : int
        Steps in the centred window of the local median.
    merge_frames : int
        Flagged steps at most this many frames apart form one jump.
    valid : dict of str to ndarray, shape (n_frames,), optional
        Each sensor's :attr:`~fingerfit.session.PoseSeries.valid` mask, when the caller
        has it already (:func:`check_recording`).

    Returns
    -------
    list of Jump
        In order of sensor, kind and frame. Nothing is changed in the data.
    """
    out: list[Jump] = []
    t = recording.time
    for name, pose in recording.poses.items():
        ok = pose.valid if valid is None else valid[name]
        idx = np.flatnonzero(ok)
        if idx.size < 2:
            continue
        sel = slice(None) if idx.size == ok.size else idx  # no gap: views, not copies
        dt = np.diff(t[sel])
        pos = pose.position[sel]
        speed = row_norms(pos[1:] - pos[:-1])
        speed /= dt
        r = pose.rotation[sel]
        cos = np.einsum("nij,nij->n", r[:-1], r[1:])
        cos -= 1.0
        cos /= 2.0
        turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0, out=cos), out=cos), out=cos)
        turn /= dt
        for kind, rate, limit in (
            ("position", speed, max_speed_mm_s),
            ("orientation", turn, max_turn_deg_s),
        ):
            fast = np.flatnonzero(rate > limit)
            steps = fast[rate[fast] > relative * centred_median(rate, fast, window)]
            if not steps.size:
                continue
            after = idx[steps + 1]
            group = np.cumsum(np.concatenate([[True], np.diff(after) > merge_frames]))
            for g in np.unique(group):
                s = steps[group == g]
                before_p = pos[s[0]]
                after_p = pos[s[-1] + 1]
                norm = np.linalg.norm(before_p)
                mirror = bool(
                    kind == "position"
                    and norm > 0
                    and np.linalg.norm(after_p + before_p) < 0.25 * norm
                )
                out.append(
                    Jump(
                        name,
                        kind,
                        int(idx[s[0] + 1]),
                        int(idx[s[-1] + 1]),
                        float(t[idx[s[0] + 1]]),
                        float(rate[s].max()),
                        mirror,
                    )
                )
    return out


def jump_notes(jumps: Sequence[Jump], *, max_speed_mm_s: float, max_turn_deg_s: float) -> list[str]:
    """One note per sensor and kind listing the jumps' frames (at most eight).

    Parameters
    ----------
    jumps : sequence of Jump
    max_speed_mm_s, max_turn_deg_s : float
        The thresholds used, stated in the notes.

    Returns
    -------
    list of str
    """
    notes = []
    keys = list(dict.fromkeys((j.sensor, j.kind) for j in jumps))
    for sensor, kind in keys:
        js = [j for j in jumps if j.sensor == sensor and j.kind == kind]
        limit = (
            f"> {max_speed_mm_s:g} mm/s" if kind == "position" else f"> {max_turn_deg_s:g} deg/s"
        )
        where = ", ".join(
            f"{j.frame} ({j.time:.3f} s{', hemisphere flip' if j.hemisphere else ''})"
            for j in js[:_LIST_MAX]
        )
        more = f" and {len(js) - _LIST_MAX} more" if len(js) > _LIST_MAX else ""
        notes.append(
            f"sensor '{sensor}': {len(js)} {kind} jumps ({limit}) flagged at frames {where}{more}"
        )
    return notes
