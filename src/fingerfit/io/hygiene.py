"""Data hygiene for tracker recordings: reported, never silent.

Every reader of real tracker files passes its data through these checks:

* :func:`repeated_rows` -- exact repeats of the previous sample (a logger polling
  faster than the tracker updates); readers drop them and count them;
* :func:`check_increasing` and :func:`place_on_grid` -- time must increase; with a
  sampling rate, frames go on the ``1/rate`` grid and missing frames become NaN rows;
* :func:`find_jumps` (:mod:`.jumps`) -- position or orientation steps both faster than a finger moves
  and much faster than the movement around them (magnetic hemisphere flips, marker
  swaps) are flagged with their frame, never altered;
* :func:`check_units` -- implausible distances between neighbouring sensors of a hand
  (a unit mistake) are an error;
* :func:`fill_gaps` -- optional: short interior gaps interpolated (positions linear,
  orientations by spherical linear interpolation), longer ones left as NaN.

Counts of anything repaired or flagged go in :attr:`Recording.notes`.
Positions are millimetres in tracker coordinates; rotation matrices map sensor into
tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..digits import DIGIT_NAMES, DIGITS
from ..errors import FingerfitError
from ..session import PoseSeries, Recording, digit_sensors, true_runs
from ..transforms import row_norms
from .jumps import JUMP_RELATIVE as JUMP_RELATIVE
from .jumps import JUMP_WINDOW as JUMP_WINDOW
from .jumps import MAX_SPEED_MM_S, MAX_TURN_DEG_S, Jump, find_jumps, jump_notes
from .jumps import centred_median as centred_median

#: Plausible median distances (mm) between the origins of neighbouring hand sensors.
#: A unit mistake scales every distance by 2.54 (in/cm), 10 (cm/mm), 25.4 (in/mm) or
#: 1000 (m/mm); the ranges are wide enough for any adult hand and sensor placement and
#: catch the factors of 10 and more.
NEIGHBOUR_RANGE_MM = {
    ("hand", "proximal"): (15.0, 250.0),
    ("proximal", "middle"): (8.0, 150.0),
    ("middle", "distal"): (6.0, 120.0),
    # The thumb: its metacarpal sensor sits on the first metacarpal, radial and palmar of
    # the hand sensor; its phalanges are shorter than a finger's proximal one.
    ("hand", "metacarpal"): (15.0, 250.0),
    ("metacarpal", "proximal"): (8.0, 150.0),
    ("proximal", "distal"): (6.0, 120.0),
}
#: Largest plausible median distance (mm) of any sensor from the tracker origin.
WORKSPACE_MM = 10_000.0


#: Largest coordinate accepted from any file (mm): 1000 km, far beyond any tracker, far
#: below float trouble. Larger values (``1e308``, an overflowing unit conversion) are
#: garbled data and an error, never a sample.
MAX_COORDINATE_MM = 1e9
#: Largest departure of a quaternion's norm from 1 accepted from any file or device (a
#: sample of another layout or order, or garbled, is far off; a tracker's rounding is
#: far below).
QUAT_NORM_TOLERANCE = 1e-3
#: Largest sampling rate accepted from any file (Hz): far above any tracker, far below
#: float trouble.
MAX_RATE_HZ = 1e6
#: A sampling grid may hold at most this many times the frames read (plus
#: :data:`GRID_SLACK`): more means a garbled time or frame count, or a wrong rate.
MAX_GRID_RATIO = 10
GRID_SLACK = 1000


def plain_block(xyz: np.ndarray, squared_norms: np.ndarray, scale_to_mm: float) -> bool:
    """Whether a block of samples with every field a finite number passes the
    coordinate and quaternion checks, by whole-block reductions (a fast reader's common
    case; False: let the reference path decide, row by row).

    Parameters
    ----------
    xyz : ndarray
        The block's coordinates in file units, any shape and strides, no NaN.
    squared_norms : ndarray
        Each sample's squared quaternion norm ``w^2 + x^2 + y^2 + z^2``, any shape.
    scale_to_mm : float
        Millimetres per file unit.

    Returns
    -------
    bool
        No coordinate beyond :data:`MAX_COORDINATE_MM` and every ``|q|^2 - 1`` within
        :data:`QUAT_NORM_TOLERANCE`, which bounds ``|q| - 1`` by about half of it: a norm
        nearer the tolerance goes to the reference path, which decides it.
    """
    if max(-xyz.min(), xyz.max()) * abs(scale_to_mm) > MAX_COORDINATE_MM:
        return False
    return max(squared_norms.max() - 1.0, 1.0 - squared_norms.min()) <= QUAT_NORM_TOLERANCE


def implausible_rows(values: np.ndarray, scale_to_mm: float = 1.0) -> np.ndarray:
    """Rows holding a coordinate beyond :data:`MAX_COORDINATE_MM` (or infinite) in mm.

    Parameters
    ----------
    values : ndarray, shape (n, ...)
        Coordinates in file units; NaN (missing) is ignored.
    scale_to_mm : float
        Millimetres per file unit (an overflowing conversion counts as implausible).

    Returns
    -------
    ndarray of int
        Indices of the offending rows, in order.
    """
    v = np.asarray(values)
    if v.dtype not in (np.float32, np.float64):
        v = v.astype(float)
    if v.ndim == 1:
        v = v[:, None]
    columns = [(slice(None), *k) for k in np.ndindex(v.shape[1:])]
    if not columns:
        return np.zeros(0, dtype=np.int64)
    # Largest magnitude per row, NaN ignored, one column at a time (no (n, ...) copies);
    # exact in float32 too, which is scaled as float64 like the values will be.
    peak = np.abs(v[columns[0]])
    for k in columns[1:]:
        np.fmax(peak, np.abs(v[k]), out=peak)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.flatnonzero(peak.astype(float, copy=False) * abs(scale_to_mm) > MAX_COORDINATE_MM)


def implausible_message(value: float) -> str:
    """The message for a coordinate beyond :data:`MAX_COORDINATE_MM`."""
    return (
        f"coordinate {value:.6g} mm is implausible (more than {MAX_COORDINATE_MM / 1e6:g} km "
        "from the origin): a garbled value or wrong units"
    )


def check_grid_size(
    index: np.ndarray, lines: np.ndarray, path: str | Path, what: str = "time"
) -> None:
    """Refuse a sampling grid far larger than the frames read (garbled time or rate).

    Parameters
    ----------
    index : ndarray, shape (n,)
        Grid position of each frame read, relative to the first (float, may be huge).
    lines : ndarray of int, shape (n,)
        File line (or record) of each frame, for the message.
    path : str or Path
    what : str
        The quantity that sets the grid (``time``, ``frame count``).

    Raises
    ------
    FingerfitError
        Naming the line after the largest jump, when the grid would hold more than
        :data:`MAX_GRID_RATIO` times the frames read plus :data:`GRID_SLACK`.
    """
    idx = np.asarray(index, dtype=float)
    if idx.size < 2:
        return
    span = idx[-1] - idx[0]
    if np.isfinite(span) and span <= MAX_GRID_RATIO * idx.size + GRID_SLACK:
        return
    with np.errstate(invalid="ignore"):
        d = np.diff(idx)
    i = int(np.nanargmax(np.where(np.isfinite(d), d, np.inf))) + 1
    raise FingerfitError(
        f"{what} jumps by {d[i - 1]:.6g} frames: {span:.6g} frames for {idx.size} read "
        "(garbled value or wrong --rate?)",
        path=path,
        line=int(lines[i]),
        field=what,
    )


def repeated_rows(values: np.ndarray) -> np.ndarray:
    """Rows that repeat the previous row exactly.

    Parameters
    ----------
    values : ndarray, shape (n, m)
        One sample per row (any units); NaN equals NaN here.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where row ``i`` equals row ``i - 1`` in every column (never for row 0).
    """
    v = np.asarray(values, dtype=float)
    if v.shape[0] < 2:
        return np.zeros(v.shape[0], dtype=bool)
    a, b = v[1:], v[:-1]
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    return np.concatenate([[False], same.all(axis=1)])


def check_increasing(
    time: np.ndarray,
    lines: np.ndarray,
    path: str | Path,
    *,
    what: str = "time",
    strict: bool = True,
) -> None:
    """Raise if time does not increase from one frame to the next.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Frame times (s) or frame counts, in file order.
    lines : ndarray of int, shape (n,)
        1-based file line (or record number) of each frame, for the message.
    path : str or Path
        The file, for the message.
    what : str
        Name of the quantity in the message (``time``, ``frame count`` ...).
    strict : bool
        Whether equal consecutive values are an error too.

    Raises
    ------
    FingerfitError
        Naming the first line where the value goes backwards (or repeats).
    """
    t = np.asarray(time, dtype=float)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise FingerfitError(
            f"{what} is missing or not finite", path=path, line=int(lines[bad[0]]), field=what
        )
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0 if strict else d < 0)
    if bad.size:
        i = int(bad[0]) + 1
        verb = "goes backwards" if d[i - 1] < 0 else "does not increase"
        raise FingerfitError(
            f"{what} {verb} ({t[i]:.15g} after {t[i - 1]:.15g})",
            path=path,
            line=int(lines[i]),
            field=what,
        )


def place_on_grid(
    time: np.ndarray, rate_hz: float, lines: np.ndarray, path: str | Path
) -> tuple[np.ndarray, np.ndarray]:
    """Put frames on the ``1/rate_hz`` sampling grid, so missing frames become visible.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing frame times (s).
    rate_hz : float
        Sampling rate (frames per second).
    lines : ndarray of int, shape (n,)
        File line of each frame, for messages.
    path : str or Path

    Returns
    -------
    grid_time : ndarray, shape (n_grid,)
        Times of every grid frame: the measured time where a frame exists, the grid
        time ``t0 + k / rate_hz`` where it is missing.
    index : ndarray of int, shape (n,)
        Grid frame of each input frame.

    Raises
    ------
    FingerfitError
        If a frame is more than a quarter period off the grid, or two frames fall on
        the same grid frame (wrong ``rate_hz``).
    """
    t = np.asarray(time, dtype=float)
    if t.size == 0:
        return t.copy(), np.zeros(0, dtype=np.int64)
    check_grid_size((t - t[0]) * rate_hz, lines, path)
    idx = np.rint((t - t[0]) * rate_hz).astype(np.int64)
    off = np.abs(t - (t[0] + idx / rate_hz))
    bad = (off > 0.25 / rate_hz) | np.concatenate([[False], np.diff(idx) == 0])
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FingerfitError(
            f"time {t[i]:.6f} s is not on the {rate_hz:g} Hz sampling grid (wrong --rate?)",
            path=path,
            line=int(lines[i]),
            field="time",
        )
    n = int(idx[-1]) + 1
    grid = t[0] + np.arange(n) / rate_hz
    grid[idx] = t
    return grid, idx


def frames_missing_note(n_missing: int, what: str = "sensor") -> list[str]:
    """The note for frames missing for every sensor (or ``what``: ``marker``; empty when
    none)."""
    if n_missing <= 0:
        return []
    return [f"{n_missing} frames missing for every {what} (kept as NaN rows)"]


def sensor_missing_notes(recording: Recording) -> list[str]:
    """One note per sensor with missing frames: ``sensor 'x': k of n frames missing``."""
    out = []
    for name, pose in recording.poses.items():
        out += missing_note(name, recording.n_frames - int(pose.valid.sum()), recording.n_frames)
    return out


def missing_note(sensor: str, missing: int, n_frames: int, what: str = "sensor") -> list[str]:
    """The note of :func:`sensor_missing_notes` for one sensor (or ``what``: a
    ``marker``; none when nothing is missing), for a reader that counted the frames it
    left empty."""
    return [f"{what} '{sensor}': {missing} of {n_frames} frames missing"] if missing else []


def fill_gaps(recording: Recording, max_gap: int) -> Recording:
    """Interpolate short interior gaps; leave longer gaps and the ends as NaN.

    Positions are interpolated linearly in time; orientations by spherical linear
    interpolation (scipy ``Slerp``) between the valid samples on either side.

    Parameters
    ----------
    recording : Recording
        Positions in mm, rotations sensor -> tracker, ``time`` in s.
    max_gap : int
        Longest gap (in frames) to fill; ``0`` fills nothing.

    Returns
    -------
    Recording
        A new recording; ``notes`` gain, per sensor, the number of gaps and frames
        filled and the number of longer gaps kept as NaN.
    """
    if max_gap < 0:
        raise FingerfitError("the longest gap to fill must be 0 or more frames", field="max_gap")
    notes = list(recording.notes)
    poses: dict[str, PoseSeries] = {}
    t = recording.time
    for name, pose in recording.poses.items():
        valid = pose.valid
        starts, ends = true_runs(~valid).T
        interior = (starts > 0) & (ends < recording.n_frames)
        short = interior & (ends - starts <= max_gap)
        if not short.any():
            poses[name] = pose
            if interior.any():
                notes.append(
                    f"sensor '{name}': {int(interior.sum())} gaps longer than {max_gap} "
                    "frames kept as NaN"
                )
            continue
        marks = np.zeros(recording.n_frames + 1, dtype=np.int64)
        np.add.at(marks, starts[short], 1)
        np.add.at(marks, ends[short], -1)
        fill = np.cumsum(marks)[:-1] > 0
        pos = pose.position.copy()
        rot = pose.rotation.copy()
        tv = t[valid]
        for j in range(3):
            pos[fill, j] = np.interp(t[fill], tv, pose.position[valid, j])
        from scipy.spatial.transform import Rotation, Slerp  # on use (0.2-0.3 s to import)

        slerp = Slerp(tv, Rotation.from_matrix(pose.rotation[valid]))
        rot[fill] = slerp(t[fill]).as_matrix()
        poses[name] = PoseSeries(pos, rot)
        msg = (
            f"sensor '{name}': {int(short.sum())} gaps ({int(fill.sum())} frames) interpolated "
            f"(at most {max_gap} frames; positions linear, orientations slerp)"
        )
        longer = int((interior & ~short).sum())
        if longer:
            msg += f"; {longer} longer gaps kept as NaN"
        notes.append(msg)
    return Recording(recording.name, recording.time.copy(), poses, notes)


def check_units(
    recording: Recording,
    path: str | Path | None = None,
    *,
    valid: dict[str, np.ndarray] | None = None,
) -> None:
    """Raise if sensor distances are implausible for a hand (a unit mistake).

    Checks the median distance between neighbouring hand sensors (``hand`` ->
    ``<finger>.proximal`` -> ``.middle`` -> ``.distal``) against
    :data:`NEIGHBOUR_RANGE_MM`, and the median distance of every sensor from the
    tracker origin against :data:`WORKSPACE_MM`.

    Parameters
    ----------
    recording : Recording
        Positions in mm.
    path : str or Path, optional
        The source file, for the message.
    valid : dict of str to ndarray, shape (n_frames,), optional
        Each sensor's :attr:`~fingerfit.session.PoseSeries.valid` mask, when the caller
        has it already (:func:`check_recording`).

    Raises
    ------
    FingerfitError
        ``field 'units'``: naming the sensors and the distance found.
    """
    poses = recording.poses
    if valid is None:
        valid = {name: pose.valid for name, pose in poses.items()}

    def where(name: str, ok: np.ndarray) -> np.ndarray:  # a view when every frame is valid
        return poses[name].position if ok.all() else poses[name].position[ok]

    for name in poses:
        ok = valid[name]
        if ok.any():
            r = float(np.median(row_norms(where(name, ok))))
            if r > WORKSPACE_MM:
                raise FingerfitError(
                    f"sensor '{name}' is {r / 1000:.4g} m from the tracker origin (median): "
                    "implausible, are the units right (--units)?",
                    path=path,
                    field="units",
                )
    for digit in DIGIT_NAMES:
        kinds = ["hand", *DIGITS[digit].segments]
        chain = digit_sensors(digit)
        for i in range(3):
            a, b = chain[i], chain[i + 1]
            if a not in poses or b not in poses:
                continue
            ok = valid[a] & valid[b]
            if not ok.any():
                continue
            d = float(np.median(row_norms(where(a, ok) - where(b, ok))))
            lo, hi = NEIGHBOUR_RANGE_MM[(kinds[i], kinds[i + 1])]
            if not lo <= d <= hi:
                raise FingerfitError(
                    f"implausible distance {d:.4g} mm between sensors '{a}' and '{b}' "
                    f"(median over frames; expected {lo:g}-{hi:g} mm): are the units right "
                    "(--units)? (--no-unit-check if these are not hand sensors)",
                    path=path,
                    field="units",
                )


def check_recording(
    recording: Recording,
    path: str | Path | None = None,
    *,
    units: bool = True,
    max_speed_mm_s: float = MAX_SPEED_MM_S,
    max_turn_deg_s: float = MAX_TURN_DEG_S,
) -> list[Jump]:
    """Unit plausibility (an error) and jump flags (notes) in one call.

    Parameters
    ----------
    recording : Recording
        Positions mm; its ``notes`` gain one line per sensor and kind of jump.
    path : str or Path, optional
        The source file, for messages.
    units : bool
        Whether to run :func:`check_units`.
    max_speed_mm_s, max_turn_deg_s : float
        Jump thresholds, see :func:`find_jumps`.

    Returns
    -------
    list of Jump
    """
    valid = {name: pose.valid for name, pose in recording.poses.items()}  # once for both
    if units:
        check_units(recording, path, valid=valid)
    jumps = find_jumps(
        recording, max_speed_mm_s=max_speed_mm_s, max_turn_deg_s=max_turn_deg_s, valid=valid
    )
    recording.notes.extend(
        jump_notes(jumps, max_speed_mm_s=max_speed_mm_s, max_turn_deg_s=max_turn_deg_s)
    )
    return jumps
