"""The canonical pose CSV: ``time,sensor,x,y,z,qw,qx,qy,qz``.

One row per sensor per frame; time in seconds; ``x,y,z`` the sensor origin in
tracker coordinates (file units); ``(qw,qx,qy,qz)`` a unit quaternion, scalar
first, rotating sensor coordinates into tracker coordinates. Missing samples
may be absent rows or rows with empty/NaN fields. See ``docs/formats.md``.
"""

from __future__ import annotations

import csv
import io
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError, shown
from ..session import PoseSeries, Recording, is_sensor_name
from ..transforms import quat_wxyz_columns
from .fastcsv import put_quat_rows, put_rows, put_scaled_rows, rows_where
from .hygiene import (
    QUAT_NORM_TOLERANCE,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
    plain_block,
)

HEADER = ("time", "sensor", "x", "y", "z", "qw", "qx", "qy", "qz")
_NUMERIC = ("time", "x", "y", "z", "qw", "qx", "qy", "qz")


def check_field_counts(raw: bytes, path: Path, n_fields: int) -> int:
    """Check that every line of a CSV file has ``n_fields`` comma-separated fields.

    Parameters
    ----------
    raw : bytes
        The whole file.
    path : Path
        For error messages.
    n_fields : int

    Returns
    -------
    int
        Number of lines after the header (trailing blank lines are allowed).

    Raises
    ------
    FingerfitError
        Naming the first line that is not text (control bytes other than tab, CR and
        LF, or invalid UTF-8), is empty inside the data or has another field count (a
        truncated or garbled record).
    """
    b = np.frombuffer(raw, dtype=np.uint8)
    check_text(b, path)
    ends = np.flatnonzero(b == ord("\n"))
    if b.size and b[-1] != ord("\n"):
        ends = np.append(ends, b.size)
    starts = np.concatenate([[0], ends[:-1] + 1])
    lengths = ends - starts
    # A line holding only '\r' counts as empty.
    first = b[np.clip(starts, 0, max(b.size - 1, 0))] if b.size else np.zeros(0, np.uint8)
    empty = (lengths == 0) | ((lengths == 1) & (first == ord("\r")))
    commas = np.flatnonzero(b == ord(","))
    counts = np.bincount(np.searchsorted(ends, commas), minlength=ends.size)[: ends.size]
    last = ends.size
    while last > 0 and empty[last - 1]:
        last -= 1
    bad = np.flatnonzero((counts[:last] != n_fields - 1) | empty[:last])
    if bad.size:
        i = int(bad[0])
        if empty[i]:
            raise FingerfitError("empty line inside the data", path=path, line=i + 1)
        raise FingerfitError(
            f"expected {n_fields} comma-separated fields, found {counts[i] + 1} "
            "(truncated or garbled record)",
            path=path,
            line=i + 1,
        )
    return last - 1


def check_text(b: np.ndarray, path: Path) -> None:
    """Raise, naming the line, if the bytes ``b`` (``uint8``) are not UTF-8 text.

    Control bytes other than tab, CR and LF (a binary file, a corrupted transfer) and
    invalid UTF-8 sequences are refused.
    """
    ctrl = np.flatnonzero((b < 32) & (b != 9) & (b != 10) & (b != 13) | (b == 127))
    at = int(ctrl[0]) if ctrl.size else None
    if at is None and (b >= 128).any():
        try:
            b.tobytes().decode("utf-8")
        except UnicodeDecodeError as exc:
            at = exc.start
    if at is not None:
        line = int(np.count_nonzero(b[:at] == ord("\n"))) + 1
        raise FingerfitError(
            f"not text: byte 0x{int(b[at]):02x} at offset {at} (binary or corrupted file)",
            path=path,
            line=line,
        )


def _to_float(
    series: pd.Series, col: str, lines: np.ndarray, path: Path, underscores: bool = True
) -> np.ndarray:
    """Exact float conversion of a text column; empty fields become NaN.

    Infinite values (``inf``, ``-Infinity``, overflowing ``1e999`` ...) are an error,
    never a missing sample; so are digit-group underscores (``1_000``), which Python's
    parser would silently accept (looked for only when ``underscores`` is True).
    """
    text = series.to_numpy(dtype=object)
    try:
        values = text.astype(np.float64)
    except (ValueError, TypeError):
        for i, v in enumerate(text):
            try:
                float(v)
            except (ValueError, TypeError):
                raise FingerfitError(
                    f"not a number: '{shown(v)}'", path=path, line=int(lines[i]), field=col
                ) from None
        raise
    bad = np.isinf(values)
    if underscores:
        bad |= np.array([isinstance(v, str) and "_" in v for v in text], dtype=bool)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FingerfitError(
            f"not a finite number: '{shown(text[i])}'", path=path, line=int(lines[i]), field=col
        )
    return values


@dataclass
class _Rows:
    """The decoded data rows of a pose CSV, in file order (row ``i`` is file line ``i + 2``).

    ``time`` ``(n,)`` s; ``sensor`` ``(n,)`` int codes into ``names``; ``pose`` ``(n, 7)``
    ``x, y, z`` (file units) and ``qw, qx, qy, qz``; NaN where a field is empty.
    """

    time: np.ndarray
    sensor: np.ndarray
    names: list[str]
    pose: np.ndarray


def _decode_fast(path: Path) -> _Rows:
    """Batches through :func:`fingerfit.io.fastcsv.csv_batches` into preallocated rows.

    Raises :class:`~fingerfit.io.fastcsv.NotPlain` for anything the reference decoder
    must judge.
    """
    from .fastcsv import RowArrays, csv_batches, estimate_rows

    rows: RowArrays | None = None
    sensor = np.empty(0, dtype=np.int32)
    names: list[str] = []
    code_of: dict[str, int] = {}
    for first, n_bytes, cols in csv_batches(path, HEADER, text=("sensor",)):
        m = cols["time"].size
        if rows is None:
            capacity = estimate_rows(path, m, n_bytes)
            rows = RowArrays(capacity, 8)
            sensor = np.empty(max(capacity, 16), dtype=np.int32)
        block = rows.reserve(m)
        for j, c in enumerate(_NUMERIC):
            block[:, j] = cols[c]
        codes, values = cols["sensor"]
        lut = np.array([code_of.setdefault(v, len(code_of)) for v in values], dtype=np.int32)
        if sensor.size < rows.n:
            grown = np.empty(rows.data.shape[0], dtype=np.int32)
            grown[:first] = sensor[:first]
            sensor = grown
        sensor[first : first + m] = lut[codes] if lut.size else codes
    names = list(code_of)
    if rows is None:
        return _Rows(np.zeros(0), np.zeros(0, np.int32), [], np.zeros((0, 7)))
    data = rows.array()
    return _Rows(data[:, 0], sensor[: rows.n], names, data[:, 1:])


def _decode_exact(raw: bytes, path: Path) -> _Rows:
    """The reference decoder: Python's exact float parser, every error with its line."""
    check_field_counts(raw, path, len(HEADER))
    df = pd.read_csv(
        io.BytesIO(raw), dtype=str, skip_blank_lines=True, quoting=csv.QUOTE_NONE, encoding="utf-8"
    )
    lines = np.arange(df.shape[0]) + 2  # file line of each data row
    under = b"_" in raw
    values = {col: _to_float(df[col], col, lines, path, under) for col in _NUMERIC}
    sensors = df["sensor"].to_numpy(dtype=object)
    names, inverse = np.unique(
        np.where(pd.isna(sensors), "", sensors).astype(str), return_inverse=True
    )
    pose = np.column_stack([values[c] for c in _NUMERIC[1:]])
    return _Rows(values["time"], inverse.astype(np.int32), [str(n) for n in names], pose)


def read_pose_csv(
    path: str | Path,
    *,
    units: str = "mm",
    rate_hz: float | None = None,
    scale_to_mm: float | None = None,
) -> Recording:
    """Read a canonical pose CSV (or its Parquet form) into a :class:`Recording` (mm,
    tracker frame).

    A path ending in ``.parquet`` is read as the Parquet form
    (:func:`fingerfit.io.parquet.read_parquet`: the same columns, float64, the units in
    its metadata, which must agree with ``units``); then the same checks, rows named by
    their 1-based index instead of the line.

    Read in batches of about 4 MB into preallocated arrays with Arrow's CSV parser
    (correctly rounded floats); a file the fast path does not vouch for (any error, and
    rare spellings such as ``nan`` or blank trailing lines) is read by the reference
    decoder, which names the line of any error.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    units : str
        Units of ``x,y,z`` in the file (``mm``, ``cm``, ``m``, ``in``); converted to mm.
    rate_hz : float, optional
        Sampling rate. When given, frames are placed on the ``1/rate_hz`` grid so
        frames missing for every sensor appear as NaN rows (visible gaps).
    scale_to_mm : float, optional
        Overrides ``units`` with an explicit factor.

    Returns
    -------
    Recording
        ``time`` ``(n_frames,)`` s and, per sensor, positions ``(n_frames, 3)`` mm
        and rotation matrices ``(n_frames, 3, 3)`` (sensor -> tracker). ``notes``
        counts exact duplicate rows dropped and incomplete samples.

    Raises
    ------
    FingerfitError
        On any malformed content, naming the file and line.
    """
    from ..session import UNITS_TO_MM
    from .fastcsv import NotPlain, read_header
    from .parquet import is_parquet

    path = Path(path)
    if is_parquet(path):
        return _read_parquet(path, units, rate_hz, scale_to_mm)
    first = read_header(path).split(b"\n", 1)[0].decode("utf-8", "replace").strip()
    first = first.lstrip("\ufeff")
    if tuple(h.strip() for h in first.split(",")) != HEADER:
        raise FingerfitError(
            f"header must be exactly '{','.join(HEADER)}', found '{shown(first, 80)}'",
            path=path,
            line=1,
        )
    try:
        rows = _decode_fast(path)
    except NotPlain:
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
        rows = _decode_exact(raw, path)
        del raw
    if scale_to_mm is None:
        if units not in UNITS_TO_MM:
            raise FingerfitError(f"unknown units '{units}'", path=path, field="units")
        scale_to_mm = UNITS_TO_MM[units]
    return _assemble(rows, path, scale_to_mm, rate_hz)


def _read_parquet(
    path: Path, units: str, rate_hz: float | None, scale_to_mm: float | None
) -> Recording:
    """A pose Parquet file (:data:`fingerfit.io.parquet.POSE`): the columns of the CSV,
    its metadata stating the units (which must be ``units`` unless ``scale_to_mm`` is
    given), then every check of the CSV reader, rows named by their 1-based index."""
    from ..session import UNITS_TO_MM
    from .parquet import POSE, QUAT_ORDER, TRACKER_FRAME, read_parquet

    if scale_to_mm is None and units not in UNITS_TO_MM:
        raise FingerfitError(f"unknown units '{units}'", path=path, field="units")
    try:
        return _read_parquet_fast(path, units, rate_hz, scale_to_mm)
    except Exception:  # _Irregular, a FingerfitError, a damaged page Arrow reports
        pass  # the reference path below says what is wrong, or reads what is unusual
    table = read_parquet(
        path,
        POSE,
        columns=HEADER,
        text=("sensor",),
        expect={"units": None, "frame": TRACKER_FRAME, "quaternion_order": QUAT_ORDER},
    )
    stated = table.meta["fingerfit.units"]
    if stated not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{shown(stated)}' (use {', '.join(UNITS_TO_MM)})",
            path=path,
            field="fingerfit.units",
        )
    if scale_to_mm is None and stated != units:
        raise FingerfitError(
            f"the file's positions are in {stated}, not {units} as stated for it "
            "(session.toml units or --units)",
            path=path,
            field="fingerfit.units",
        )
    cols = table.columns
    codes, names = cols["sensor"]
    pose = np.empty((table.n_rows, 7))
    for j, c in enumerate(_NUMERIC[1:]):
        pose[:, j] = cols.pop(c)
    rows = _Rows(cols["time"], codes, list(names), pose)
    del table, cols
    scale = UNITS_TO_MM[stated] if scale_to_mm is None else scale_to_mm
    return _assemble(rows, path, scale, rate_hz, first_line=1)


#: Rows converted to rotation matrices at a time (bounds the temporary memory).
_BLOCK = 1 << 16
#: Threads placing the blocks of a pose Parquet file, and the rows of a block.
_THREADS = 2
_PARQUET_BLOCK = 1 << 15
#: Elements added to each row of a block buffer (see ``_read_parquet_fast``).
_PAD = 24


def _first(rows: slice | np.ndarray) -> int:
    """The first row of a :func:`~fingerfit.io.fastcsv.rows_where` selection."""
    return int(rows.start) if isinstance(rows, slice) else int(rows[0])


class _Irregular(Exception):
    """A pose Parquet file the streaming reader does not vouch for (an error somewhere,
    exact duplicates): read again by the reference path, which names the error."""


def _read_parquet_fast(
    path: Path, units: str, rate_hz: float | None, scale_to_mm: float | None
) -> Recording:
    """The common case of a pose Parquet file, streamed into the recording's arrays.

    The time and sensor columns first (the frames, the sampling grid, the sensors), then
    the numbers :data:`_BLOCK` rows at a time straight into each sensor's positions and
    rotation matrices: no whole table and no ``(n, 7)`` copy. The same arithmetic as
    :func:`_assemble` (the same bits); anything :func:`_assemble` would refuse or repair
    (exact duplicates) raises :class:`_Irregular` or :class:`FingerfitError`, and the
    caller reads the file by the reference path.
    """
    from ..memory import release_freed_memory
    from ..session import UNITS_TO_MM
    from .parquet import (
        POSE,
        QUAT_ORDER,
        TRACKER_FRAME,
        _metadata,
        _pa,
        _text_codes,
        float_blocks,
        open_checked,
    )

    pa, _ = _pa()
    pf, fh, schema = open_checked(
        path,
        POSE,
        columns=HEADER,
        text=("sensor",),
        expect={"units": None, "frame": TRACKER_FRAME, "quaternion_order": QUAT_ORDER},
    )
    with fh:
        stated = _metadata(schema)["fingerfit.units"]
        if stated not in UNITS_TO_MM or (scale_to_mm is None and stated != units):
            raise _Irregular
        scale = UNITS_TO_MM[stated] if scale_to_mm is None else scale_to_mm
        n_rows = pf.metadata.num_rows
        # time and sensor a row group at a time into their arrays (no whole column twice)
        time = np.empty(n_rows)
        code = np.empty(n_rows, dtype=np.int32)
        code_of: dict[str, int] = {}
        lo = 0
        for g in range(pf.num_row_groups):
            head = pf.read_row_group(g, columns=["time", "sensor"], use_threads=True)
            m = head.num_rows
            if lo + m > n_rows:
                raise _Irregular
            time[lo : lo + m] = head.column("time").to_numpy()  # a null becomes NaN
            c, group_names = _text_codes(pa, head.column("sensor"))
            lut = np.array([code_of.setdefault(v, len(code_of)) for v in group_names], np.int32)
            code[lo : lo + m] = lut[c] if lut.size else c
            lo += m
            del head, c
        if lo != n_rows:
            raise _Irregular
        names = list(code_of)
        if n_rows == 0 or not np.isfinite(time).all() or (time[1:] < time[:-1]).any():
            raise _Irregular
        n_codes = len(names)
        counts = np.bincount(code, minlength=n_codes)
        present = [int(k) for k in np.flatnonzero(counts)]
        if not all(is_sensor_name(names[k]) for k in present):
            raise _Irregular
        new = np.empty(n_rows, dtype=bool)
        new[0] = True
        np.not_equal(time[1:], time[:-1], out=new[1:])
        row_of_frame = np.flatnonzero(new)
        frame_of_row = np.cumsum(new, dtype=np.int64 if n_rows >= 1 << 31 else np.int32)
        # a sensor twice in a frame (a duplicate): its rows' frames do not increase
        first_row = {}
        for k in present:
            rows = rows_where(code, k)
            frames = frame_of_row[rows]
            first_row[k] = _first(rows)
            if (frames[1:] == frames[:-1]).any():
                raise _Irregular
            del rows, frames
        del frame_of_row
        frame_times = time[row_of_frame]
        grid = None
        frames_note: list[str] = []
        if rate_hz is not None and frame_times.size > 1:
            full_time, grid = place_on_grid(frame_times, rate_hz, row_of_frame + 1, path)
            frames_note = frames_missing_note(full_time.size - frame_times.size)
            frame_times = full_time
        n = frame_times.size
        del time
        # what the frames and the grid used goes back to the system before the
        # recording's arrays are allocated (else it counts in the peak beside them)
        release_freed_memory()

        appear = sorted(present, key=lambda k: first_row[k])
        pos = {k: np.empty((n, 3)) for k in appear}
        rot = {k: np.empty((n, 3, 3)) for k in appear}
        filled = {k: np.zeros(n, dtype=bool) for k in appear}
        buffers = threading.local()

        def place(lo: int, cols: list[np.ndarray]) -> int:
            """Check and place rows ``lo:lo + m``; their samples with empty fields."""
            m = cols[0].size
            hi = lo + m
            # the rows as (m, 7) with each column contiguous (a (7, m) buffer seen
            # transposed): copied column by column, checked column by column
            block = getattr(buffers, "block", None)
            if block is None or block.shape[1] < m:
                # rows a few cache lines longer than the block: columns a power of two
                # apart share cache sets, which makes strided work on rows several
                # times slower
                block = buffers.block = np.empty((7, max(m, _PARQUET_BLOCK) + _PAD))
                buffers.sums = np.empty(block.shape[1])
            for j, v in enumerate(cols):
                block[j, :m] = v
            del cols
            p, total = block[:, :m].T, buffers.sums[:m]
            partial = 0
            with np.errstate(over="ignore", invalid="ignore"):
                np.add.reduce(block[:, :m], axis=0, out=total)
            if np.isfinite(total).all():  # every field of every row a finite number
                ok = True
                np.multiply(block[3, :m], block[3, :m], out=total)  # squared norms
                for j in (4, 5, 6):
                    total += block[j, :m] * block[j, :m]
                if not plain_block(block[:3, :m], total, scale):
                    raise _Irregular
            else:
                finite = np.isfinite(p)
                ok = finite.all(axis=1)
                if np.isinf(p).any():
                    raise _Irregular
                partial = int(np.count_nonzero(~ok & finite.any(axis=1)))
                if implausible_rows(p[:, :3], scale).size:
                    raise _Irregular
                q = p[:, 3:]
                with np.errstate(over="ignore", invalid="ignore"):
                    norm = np.sqrt(np.einsum("ij,ij->i", q, q))
                if (ok & (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE)).any():
                    raise _Irregular
            f = np.cumsum(new[lo:hi], dtype=np.int64)  # the rows' frames
            f += int(np.searchsorted(row_of_frame, lo)) - 1  # frames begun before
            if grid is not None:
                f = grid[f]
            c = code[lo:hi]
            if ok is not True and not ok.all():
                c, f, p = c[ok], f[ok], p[ok]
            for k in np.flatnonzero(np.bincount(c, minlength=n_codes)):
                r = rows_where(c, k)
                fk = f[r]
                put_scaled_rows(pos[int(k)], fk, p[r, :3], scale)
                put_quat_rows(rot[int(k)], fk, p[r, 3:])
                put_rows(filled[int(k)], fk, True)
            return partial

        # Blocks are placed by two threads (NumPy works without the GIL; each block's
        # rows go to frames of their own) while Arrow decodes the next ones.
        n_partial = 0
        rows_read = 0
        pending: deque = deque()
        blocks = float_blocks(pf, _NUMERIC[1:], n_rows, batch_rows=_PARQUET_BLOCK, ahead=True)
        with ThreadPoolExecutor(max_workers=_THREADS) as pool:
            try:
                for lo, cols in blocks:
                    if len(pending) >= _THREADS:
                        n_partial += pending.popleft().result()
                    pending.append(pool.submit(place, lo, cols))
                    rows_read = lo + cols[0].size
                    del cols
                while pending:
                    n_partial += pending.popleft().result()
            finally:
                blocks.close()
                for fut in pending:
                    fut.cancel()
        if rows_read != n_rows:
            raise _Irregular
    notes: list[str] = []
    if n_partial:
        notes.append(f"{n_partial} samples with empty fields treated as missing")
    notes += frames_note
    poses = _poses(appear, names, filled, pos, rot, n, notes)
    return Recording(path.name, frame_times, poses, notes)


def _assemble(
    rows: _Rows, path: Path, scale_to_mm: float, rate_hz: float | None, first_line: int = 2
) -> Recording:
    """Check the decoded rows and place them per sensor on the frame grid.

    Errors name row ``i`` as line ``i + first_line``: the file line of a CSV (2: after
    the header), the 1-based row of a Parquet file (1).

    Every check and message of the format, in this order: no rows, time missing or going
    backwards, unknown sensor names, implausible coordinates, conflicting duplicates,
    quaternion norm, sampling grid.
    """
    time, code, pose = rows.time, rows.sensor, rows.pose
    n_rows = time.size
    notes: list[str] = []
    if n_rows == 0:
        raise FingerfitError("no data rows", path=path)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise FingerfitError(
            "time is missing or not finite", path=path, line=int(bad[0]) + first_line, field="time"
        )
    back = np.flatnonzero(time[1:] < time[:-1])
    if back.size:
        i = int(back[0]) + 1
        raise FingerfitError(
            f"time goes backwards ({time[i]:.6f} s after {time[i - 1]:.6f} s)",
            path=path,
            line=i + first_line,
            field="time",
        )
    n_codes = len(rows.names)
    # Rows grouped by sensor, in file order within each sensor (for the first row of
    # each name and for duplicates).
    order = np.argsort(code, kind="stable")
    starts = np.searchsorted(code[order], np.arange(n_codes))
    first_row = np.full(n_codes, n_rows, dtype=np.int64)
    present = starts < n_rows
    present[present] = code[order[starts[present]]] == np.flatnonzero(present)
    first_row[present] = order[starts[present]]
    for k in sorted(range(n_codes), key=lambda c: rows.names[c]):
        if first_row[k] < n_rows and not is_sensor_name(rows.names[k]):
            raise FingerfitError(
                f"unknown sensor name '{shown(rows.names[k])}' (expected hand, stylus or "
                "<finger>.<segment>)",
                path=path,
                line=int(first_row[k]) + first_line,
                field="sensor",
            )
    big = implausible_rows(pose[:, :3], scale_to_mm)
    if big.size:
        i = int(big[0])
        j = int(np.nanargmax(np.abs(pose[i, :3])))
        raise FingerfitError(
            implausible_message(float(pose[i, j]) * scale_to_mm),
            path=path,
            line=i + first_line,
            field="xyz"[j],
        )
    # Frames: rows of equal time (time does not decrease, so they are consecutive).
    new = np.empty(n_rows, dtype=bool)
    new[0] = True
    np.not_equal(time[1:], time[:-1], out=new[1:])
    frame_of_row = np.cumsum(new, dtype=np.int64) - 1
    # Exact duplicates (same time, sensor and values) are dropped and counted;
    # conflicting duplicates are an error.
    same_key = code[order[1:]] == code[order[:-1]]
    same_key &= frame_of_row[order[1:]] == frame_of_row[order[:-1]]
    if same_key.any():
        later, earlier = order[1:][same_key], order[:-1][same_key]
        a, b = pose[later], pose[earlier]
        same = np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=1)
        if not same.all():
            i = int(later[~same].min())
            raise FingerfitError(
                f"second, different sample for sensor '{rows.names[code[i]]}' at time "
                f"{time[i]:.6f} s",
                path=path,
                line=i + first_line,
            )
        notes.append(f"{later.size} exact duplicate rows dropped")
        keep = np.ones(n_rows, dtype=bool)
        keep[later] = False
        lines = np.flatnonzero(keep) + first_line
        time, code, pose = time[keep], code[keep], pose[keep]
        new = new[keep]
        new[0] = True
        new[1:] = time[1:] != time[:-1]
        del keep
    else:
        lines = None
    del order, same_key, frame_of_row  # a row's frame is cumsum(new) - 1, made again below

    def line_of(i: int) -> int:
        return int(lines[i]) if lines is not None else i + first_line

    finite = np.isfinite(pose)
    complete = finite.all(axis=1)
    n_partial = int(np.count_nonzero(~complete & finite.any(axis=1)))
    del finite
    if n_partial:
        notes.append(f"{n_partial} samples with empty fields treated as missing")
    q = pose[:, 3:]
    with np.errstate(over="ignore", invalid="ignore"):  # a huge component: norm inf, refused
        norm = np.sqrt(np.einsum("ij,ij->i", q, q))
    bad = np.flatnonzero(complete & (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE))
    if bad.size:
        i = int(bad[0])
        raise FingerfitError(
            f"quaternion (qw,qx,qy,qz) has norm {norm[i]:.6g}, not 1", path=path, line=line_of(i)
        )
    del norm

    row_of_frame = np.flatnonzero(new)
    frame_times = time[row_of_frame]
    grid = None  # frame -> grid index, when frames go on the sampling grid
    if rate_hz is not None and frame_times.size > 1:
        frame_lines = row_of_frame + first_line if lines is None else lines[row_of_frame]
        full_time, grid = place_on_grid(frame_times, rate_hz, frame_lines, path)
        notes += frames_missing_note(full_time.size - frame_times.size)
        frame_times = full_time
    n = frame_times.size
    del row_of_frame

    # Per sensor in order of first appearance: positions (mm) and rotation matrices,
    # converted a block of rows at a time.
    appear = [int(k) for k in np.argsort(first_row, kind="stable") if first_row[k] < n_rows]
    # np.empty, not np.full: each page is written once, then the frames without a
    # sample are set to NaN.
    pos = {k: np.empty((n, 3)) for k in appear}
    rot = {k: np.empty((n, 3, 3)) for k in appear}
    filled = {k: np.zeros(n, dtype=bool) for k in appear}
    frames_before = 0
    for lo in range(0, time.size, _BLOCK):
        hi = min(lo + _BLOCK, time.size)
        ok = complete[lo:hi]
        f = np.cumsum(new[lo:hi], dtype=np.int64)  # the rows' frames
        f += frames_before - 1
        frames_before = int(f[-1]) + 1
        if grid is not None:
            f = grid[f]
        c, p = code[lo:hi], pose[lo:hi]
        if not ok.all():
            c, f, p = c[ok], f[ok], p[ok]
        for k in np.flatnonzero(np.bincount(c, minlength=len(rows.names))):
            m = rows_where(c, k)  # a strided slice when sensors take turns regularly
            fk = f[m]
            put_scaled_rows(pos[int(k)], fk, p[m, :3], scale_to_mm)
            put_quat_rows(rot[int(k)], fk, p[m, 3:])
            put_rows(filled[int(k)], fk, True)
    poses = _poses(appear, rows.names, filled, pos, rot, n, notes)
    return Recording(path.name, frame_times, poses, notes)


def _pose_columns(recording: Recording, mm_per_unit: float) -> dict[str, object]:
    """Columns of the long table; ``sensor`` as ``(codes, names)``."""
    return _pose_block(recording, 0, recording.n_frames, mm_per_unit)


def _pose_block(recording: Recording, lo: int, hi: int, mm_per_unit: float) -> dict[str, object]:
    """The rows of frames ``lo:hi`` of the long table, one per present sample (a sample
    with a NaN or an infinity anywhere is left out), ordered by frame then sensor.

    Parameters
    ----------
    recording : Recording
        Positions in mm (tracker frame), rotations sensor -> tracker.
    lo, hi : int
        The frames.
    mm_per_unit : float
        Positions are divided by this (10 to write cm).

    Returns
    -------
    dict of str to ndarray
        ``time`` (s), ``sensor`` as ``(codes (m,) int32, names)``, ``x, y, z`` (file
        units) and ``qw, qx, qy, qz``, each ``(m,)``.
    """
    names = recording.sensors
    n_s = len(names)
    # x, y, z, qw, qx, qy, qz of each frame and sensor: each column's rows contiguous
    vals = np.empty((7, hi - lo, n_s))
    for j, s in enumerate(names):
        np.divide(recording.poses[s].position[lo:hi].T, mm_per_unit, out=vals[:3, :, j])
        vals[3:, :, j] = sensor_quats(recording, s, lo, hi)
    ok = np.isfinite(vals).all(axis=0)
    time = recording.time[lo:hi]
    if ok.all():
        flat = vals.reshape(7, -1)
        cols: dict[str, object] = {
            "time": np.repeat(time, n_s),
            "sensor": (np.tile(np.arange(n_s, dtype=np.int32), hi - lo), list(names)),
        }
    else:
        frame, sensor = np.nonzero(ok)
        flat = vals.reshape(7, -1)[:, ok.ravel()]
        cols = {"time": time[frame], "sensor": (sensor.astype(np.int32), list(names))}
    for j, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
        cols[c] = flat[j]
    return cols


def sensor_quats(recording: Recording, sensor: str, lo: int, hi: int) -> np.ndarray:
    """The quaternions of a sensor's rotations in frames ``lo:hi`` as rows ``(4, hi - lo)``
    (:func:`~fingerfit.transforms.quat_wxyz_columns`: ``w, x, y, z``). A matrix that is not
    a rotation raises the error of the whole recording's conversion: the first sensor, in
    order, with such a matrix, that matrix named by its frame."""
    try:
        return quat_wxyz_columns(recording.poses[sensor].rotation[lo:hi])
    except ValueError:
        for s in recording.sensors:
            quat_wxyz_columns(recording.poses[s].rotation)
        raise


def pose_table(recording: Recording, *, mm_per_unit: float = 1.0) -> pd.DataFrame:
    """The recording as the canonical long table (one row per present sample).

    Parameters
    ----------
    recording : Recording
    mm_per_unit : float
        Positions are divided by this (e.g. 10 to write cm).

    Returns
    -------
    DataFrame
        Columns ``time,sensor,x,y,z,qw,qx,qy,qz``, ordered by frame then sensor.
    """
    cols = _pose_columns(recording, mm_per_unit)
    codes, names = cols["sensor"]
    cols["sensor"] = np.asarray(names, dtype=object)[codes]
    return pd.DataFrame(cols, columns=list(HEADER))


def write_pose_csv(path: str | Path, recording: Recording, *, units: str = "mm") -> Path:
    """Write a recording as a canonical pose CSV, or Parquet for a ``.parquet`` path, atomically.

    Parameters
    ----------
    path : str or Path
        ``*.parquet``: the same columns in a Parquet file
        (:func:`fingerfit.io.parquet.pose_meta`: units, tracker frame, quaternion order in
        its metadata; ``sensor`` dictionary-encoded text, the rest float64).
    recording : Recording
        Positions in mm (tracker frame); written in ``units``.
    units : str
        Units for ``x,y,z`` in the file.

    Returns
    -------
    Path
        The written file. Values are written in their shortest round-trip form
        (:func:`fingerfit.io.fastcsv.write_table`), so :func:`read_pose_csv` gives back
        the same numbers.
    """
    from ..session import UNITS_TO_MM
    from .parquet import is_parquet, pose_meta, write_table_file

    if is_parquet(path):
        return _write_parquet(Path(path), recording, UNITS_TO_MM[units], pose_meta(units))
    return write_table_file(
        Path(path), _pose_columns(recording, UNITS_TO_MM[units]), pose_meta(units)
    )


def _write_parquet(path: Path, recording: Recording, mm_per_unit: float, meta) -> Path:
    """The long table of :func:`_pose_columns` written a row group of frames at a time
    (about :data:`fingerfit.io.parquet.ROW_GROUP_ROWS` rows), each made while the one
    before it is written: the same rows and numbers, without the whole table in memory."""
    from .parquet import ROW_GROUP_ROWS, ParquetSink

    n = recording.n_frames
    step = max(1, ROW_GROUP_ROWS // max(len(recording.sensors), 1))
    with ParquetSink(path, meta) as sink:
        sink.write_blocks(
            _pose_block(recording, lo, min(lo + step, n), mm_per_unit)
            for lo in range(0, max(n, 1), step)
        )
    return path


def _poses(
    appear: list[int],
    names: list[str],
    filled: dict,
    pos: dict,
    rot: dict,
    n: int,
    notes: list[str],
) -> dict[str, PoseSeries]:
    """Each sensor's poses (in order of first appearance), NaN in the frames it has no
    sample in; a note per sensor with missing frames is added to ``notes``. The arrays of
    ``filled`` (frames with a sample), ``pos`` and ``rot`` are taken out of them."""
    poses: dict[str, PoseSeries] = {}
    for k in appear:
        name = names[k]
        gap = ~filled.pop(k)
        p_k, r_k = pos.pop(k), rot.pop(k)
        p_k[gap] = np.nan
        r_k[gap] = np.nan
        poses[name] = PoseSeries(p_k, r_k)
        notes += missing_note(name, int(np.count_nonzero(gap)), n)
    return poses
