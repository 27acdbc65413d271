"""A wide CSV's decoded rows made a :class:`~fingerfit.session.Recording`: the coordinate
check, repeated rows dropped, frames assembled by station cycle when rows update one
station at a time, the frames timed (on the ``--rate`` grid, at the time column's values,
or by count) and each station's samples placed, quaternion norms checked. Every check and
repair of the format after decoding; :mod:`.widecsv` decodes the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..session import UNITS_TO_MM, PoseSeries, Recording
from ..transforms import row_norms
from .fastcsv import gap_rows, put_quat_rows, put_rows, put_scaled_rows, row_blocks
from .hygiene import (
    QUAT_NORM_TOLERANCE,
    check_increasing,
    check_recording,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
)
from .widelayout import _POS, _QUAT, WideLayout, _column

#: Largest relative disagreement between ``--rate`` and the rate implied by the time
#: column when frames are timed by counting.
RATE_TOLERANCE = 0.05
#: Frames converted to rotation matrices at a time (bounds the temporary memory).
_BLOCK = 1 << 17


def _repeats(vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Repeated rows and held values of ``vals (n, stations, keys)``.

    Returns
    -------
    rep : ndarray of bool, shape (n,)
        Row ``i`` equals row ``i - 1`` in every field (NaN equal to NaN) and holds a
        number at all (as :func:`~fingerfit.io.hygiene.repeated_rows`, restricted).
    same : ndarray of bool, shape (n, stations)
        Station ``j``'s fields of row ``i`` equal those of row ``i - 1`` (NaN never
        equal); row 0 never.
    """
    n = vals.shape[0]
    same = np.zeros(vals.shape[:2], dtype=bool)
    rep = np.zeros(n, dtype=bool)
    if n < 2:
        return rep, same
    eq = vals[1:] == vals[:-1]
    same[1:] = eq.all(axis=2)
    del eq
    rep[1:] = same[1:].all(axis=1)
    # rows that differ only where both rows hold NaN are repeats too
    odd = ~np.isfinite(vals).all(axis=(1, 2))  # rows holding a NaN (or an infinity)
    cand = np.flatnonzero(~rep[1:] & odd[1:] & odd[:-1]) + 1
    if cand.size:
        rep[cand] = _pair_equal(vals[cand - 1], vals[cand])
    # a row holding no finite number at all is no sample, so no repeat
    empty = np.flatnonzero(rep & odd)
    if empty.size:
        rep[empty] = np.isfinite(vals[empty]).any(axis=(1, 2))
    return rep, same


def _pair_equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows of ``a`` and ``b (m, ...)`` equal in every field, NaN equal to NaN."""
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    return same.reshape(a.shape[0], -1).all(axis=1)


def _frame_grid(
    f_time: np.ndarray | None,
    f_lines: np.ndarray,
    n_frames: int,
    n_kept: int,
    rate_hz: float | None,
    path: Path,
    notes: list[str],
) -> tuple[np.ndarray, np.ndarray]:
    """The recording's time and each frame's place on it (``grid_idx``), from the frames'
    times ``f_time`` (None: no time column), noting in ``notes`` how they were timed."""
    if f_time is None:
        if rate_hz is None:
            raise FingerfitError(
                "--rate is needed: the layout has no time column", path=path, field="rate"
            )
        time = np.arange(n_frames) / rate_hz
        grid_idx = np.arange(n_frames)
        notes.append(f"time = frame / {rate_hz:g} Hz (no time column: lost frames undetectable)")
    elif rate_hz is None:
        check_increasing(f_time, f_lines, path, what="time")
        time, grid_idx = f_time.copy(), np.arange(n_frames)  # not a view of all values
        notes.append(
            "no --rate: frames kept at the time column's values, not on a grid"
            + (" (a logger's clock: give --rate for reliable timing)" if n_frames != n_kept else "")
        )
    else:
        check_increasing(f_time, f_lines, path, what="time")
        idx = np.rint((f_time - f_time[0]) * rate_hz)
        off = np.abs(f_time - (f_time[0] + idx / rate_hz))
        if n_frames < 2 or ((off <= 0.25 / rate_hz).all() and (np.diff(idx) > 0).all()):
            time, grid_idx = place_on_grid(f_time, rate_hz, f_lines, path)
            notes += frames_missing_note(time.size - n_frames)
        else:
            span = f_time[-1] - f_time[0]
            implied = (n_frames - 1) / span if span > 0 else np.inf
            if abs(implied / rate_hz - 1.0) > RATE_TOLERANCE:
                raise FingerfitError(
                    f"the time column spans {span:.4g} s for {n_frames} frames ({implied:.4g} Hz), "
                    f"not {rate_hz:g} Hz: frames lost or wrong --rate",
                    path=path,
                    field="rate",
                )
            time = f_time[0] + np.arange(n_frames) / rate_hz
            grid_idx = np.arange(n_frames)
            lag = f_time - time
            notes.append(
                f"time column too irregular for the {rate_hz:g} Hz grid (a logger's clock): "
                f"frames timed by count from its first value; its span implies "
                f"{implied:.4g} Hz and its delay varies by up to "
                f"{1000 * (lag.max() - lag.min()):.0f} ms"
            )
    return time, grid_idx


def _assemble(
    path: Path,
    vals: np.ndarray,
    tcol,
    stations: list[int],
    names: list[str],
    notes: list[str],
    lay: WideLayout,
    units: str,
    rate_hz: float | None,
    check: bool,
    first_line: int,
) -> Recording:
    """The recording from the decoded values: every check and repair of the format.

    ``vals (n_rows, n_stations, n_keys)`` in file units; ``tcol`` the time column
    ``(n_rows,)`` s, None, or a callable converting it (the reference decoder); row
    ``i`` is named as line ``i + first_line`` (a CSV's file line, a Parquet file's
    1-based row).
    """
    n_rows = vals.shape[0]
    lines = np.arange(n_rows) + first_line
    k = len(lay.keys)
    big = implausible_rows(vals[:, :, :3], UNITS_TO_MM[units])
    if big.size:
        i = int(big[0])
        j, m = np.unravel_index(int(np.nanargmax(np.abs(vals[i, :, :3]))), (len(stations), 3))
        raise FingerfitError(
            implausible_message(float(vals[i, j, m]) * UNITS_TO_MM[units]),
            path=path,
            line=int(lines[i]),
            field=_column(lay.columns[_POS[m]], stations[j]),
        )
    if callable(tcol):  # the reference decoder converts the time column only now
        tcol = tcol()
    if tcol is not None:
        check_increasing(tcol, lines, path, what="time", strict=False)
        # check_increasing names the column 'time'; the message says which line.
    notes.insert(0, f"{n_rows} rows of {len(stations)} stations read")

    # A row repeating the previous one is a repeat only if it holds a sample at all.
    rep, same_all = _repeats(vals)
    if rep.any():
        notes.append(
            f"{int(rep.sum())} exactly repeated rows dropped (a logger polling faster "
            "than the tracker)"
        )
    if rep.any():
        keep = np.flatnonzero(~rep)
        v = vals[keep]
        t_rows = None if tcol is None else tcol[keep]
        row_lines = lines[keep]
    else:  # no copy
        v, t_rows, row_lines = vals, tcol, lines
    del vals
    n_kept = v.shape[0]
    # a held (repeated) value; missing (NaN) is never "held". Between a kept row and the
    # kept row before it lie only exact repeats of the latter, so comparing with the
    # row just before (in the file) gives the same.
    same = same_all[keep] if rep.any() else same_all
    del same_all
    partial = same.any(axis=1) & ~same.all(axis=1)
    if len(stations) > 1 and partial.mean() > 0.5:
        rows_u, st_u = np.nonzero(~same)
        new = np.concatenate([[True], st_u[1:] <= st_u[:-1]])
        frame_of = np.cumsum(new) - 1
        n_frames = int(frame_of[-1]) + 1
        frame_vals = np.full((n_frames, len(stations), k), np.nan)
        frame_vals[frame_of, st_u] = v[rows_u, st_u]
        first_row = rows_u[np.flatnonzero(new)]
        held = int(same.sum())
        notes.append(
            f"rows update one station at a time (values held between updates): "
            f"{n_frames} frames assembled by station cycle, {held} held values not counted "
            "as samples"
        )
    else:
        frame_vals = v
        first_row = None  # every kept row is a frame
        n_frames = n_kept
    if first_row is None:  # no copies
        f_lines, f_time = row_lines, t_rows
    else:
        f_lines = row_lines[first_row]
        f_time = None if t_rows is None else t_rows[first_row]

    time, grid_idx = _frame_grid(f_time, f_lines, n_frames, n_kept, rate_hz, path, notes)
    n = int(grid_idx[-1]) + 1 if n_frames else 0

    scale = UNITS_TO_MM[units]
    poses: dict[str, PoseSeries] = {}
    missing: list[str] = []
    finite = np.isfinite(frame_vals)
    complete = finite.all(axis=2)
    partial_s = ~complete & finite.any(axis=2)
    del finite
    if partial_s.any():
        notes.append(f"{int(partial_s.sum())} samples with empty fields treated as missing")
    for j, name in enumerate(names):
        ok_j = complete[:, j]
        rows = slice(0, n_frames) if ok_j.all() else np.flatnonzero(ok_j)
        # every row is written once: by a sample below or as a gap (NaN) at the end
        pos = np.empty((n, 3))
        rot = np.empty((n, 3, 3))
        for r in row_blocks(rows, _BLOCK):  # blocks bound the temporary memory
            fv = frame_vals[r, j]
            at = grid_idx[r]
            put_scaled_rows(pos, at, fv[:, :3], scale)
            if lay.orientation == _QUAT:
                with np.errstate(over="ignore"):  # a huge component: norm inf, refused below
                    norm = row_norms(fv[:, 3:])
                bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE)
                if bad.size:
                    raise FingerfitError(
                        f"quaternion of station {stations[j]} has norm {norm[bad[0]]:.6g}, "
                        "not 1 (wrong --columns?)",
                        path=path,
                        line=int(f_lines[np.arange(n_frames)[r][bad[0]]]),
                        field=_column(lay.columns["qw"], stations[j]),
                    )
                put_quat_rows(rot, at, fv[:, 3:])
            else:
                put_rows(rot, at, Rotation.from_euler("ZYX", fv[:, 3:], degrees=True).as_matrix())
        gap = gap_rows(n, [grid_idx[rows]])
        if gap is not None:
            pos[gap] = np.nan
            rot[gap] = np.nan
        # only complete (finite) samples are placed: the gaps are what is missing
        missing += missing_note(name, 0 if gap is None else gap.size, n)
        poses[name] = PoseSeries(pos, rot)
    rec = Recording(path.name, np.asarray(time, dtype=float), poses, notes + missing)
    if check:
        check_recording(rec, path)
    return rec
