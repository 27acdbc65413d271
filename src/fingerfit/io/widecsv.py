"""Wide CSV pose logs: one row per sample, one group of columns per station.

The default layout is that of common Liberty logging scripts::

    Time,w1,x1,y1,z1,w2,x2,y2,z2,loc1_x,loc1_y,loc1_z,loc2_x,loc2_y,loc2_z

with quaternions **scalar first** ``(w, x, y, z)`` and positions ``loc<n>_x|y|z``.
Other layouts are given as a small mapping of column templates in which ``{n}``
stands for the station number, e.g. ``time=t;x=X{n};y=Y{n};z=Z{n};az=A{n};el=E{n};
roll=R{n}`` (keys ``time``, ``x y z``, and ``qw qx qy qz`` or ``az el roll`` in
degrees with ``R = Rz(az) Ry(el) Rx(roll)``).

Hygiene (see :mod:`fingerfit.io.hygiene`): rows repeating the previous row exactly
are dropped and counted. When most rows update only some stations (a logger that
writes a row whenever any one sensor reports, holding the others' last values),
frames are assembled by station cycle from the updates, so held values never count
as samples. Positions come out in mm (tracker frame), rotations sensor -> tracker.

The layouts are in :mod:`.widelayout`, the checks and repairs from decoded rows to a
recording in :mod:`.wideframes`; their names are importable from here too.
"""

from __future__ import annotations

import csv
import io
import threading
from collections import deque
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError, shown
from ..session import UNITS_TO_MM, PoseSeries, Recording
from ..transforms import row_norms
from .fastcsv import NotPlain, put_quat_rows, put_rows, put_scaled_rows
from .hygiene import check_recording, implausible_rows, missing_note, plain_block
from .posecsv import check_field_counts, header_line
from .posewrite import sensor_quats
from .wideframes import QUAT_NORM_TOLERANCE as QUAT_NORM_TOLERANCE
from .wideframes import RATE_TOLERANCE as RATE_TOLERANCE
from .wideframes import _assemble, _frame_grid
from .wideframes import _repeats as _repeats
from .widelayout import (
    _EULER,
    _POS,
    _QUAT,
    DEFAULT_LAYOUT,
    WideLayout,
    _column,
    _header_plan,
    parse_layout,
)


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


def _decode_fast(
    path: Path, header: list[str], keys: list[list[str]], time: str | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Values ``(n_rows, n_stations, n_keys)`` and time ``(n_rows,)`` (or None) in batches
    into preallocated arrays; :class:`~fingerfit.io.fastcsv.NotPlain` for anything else."""
    from .fastcsv import RowArrays, csv_batches, estimate_rows

    flat = [c for cols in keys for c in cols]
    use = flat + ([time] if time is not None else [])
    rows: RowArrays | None = None
    for _, n_bytes, cols in csv_batches(path, header, use=use):
        m = cols[use[0]].size
        if rows is None:
            rows = RowArrays(estimate_rows(path, m, n_bytes), len(use))
        block = rows.reserve(m)
        for j, c in enumerate(use):
            block[:, j] = cols[c]
    if rows is None or rows.n == 0:
        raise FingerfitError("no data rows", path=path)
    data = rows.array()
    vals = data[:, : len(flat)].reshape(rows.n, len(keys), len(keys[0]))
    return vals, (data[:, -1] if time is not None else None)


def _decode_exact(
    path: Path, header: list[str], keys: list[list[str]], lay: WideLayout, units: str
):
    """The reference decoder (every error with its line); the time column is converted
    when the returned callable is called (after the coordinate check, as always)."""
    raw = _read_bytes(path)
    check_field_counts(raw, path, len(header))
    df = pd.read_csv(
        io.BytesIO(raw),
        dtype=str,
        keep_default_na=False,
        skip_blank_lines=True,
        quoting=csv.QUOTE_NONE,
        encoding="utf-8",
    )
    del raw
    df.columns = header
    n_rows = df.shape[0]
    if n_rows == 0:
        raise FingerfitError("no data rows", path=path)
    lines = np.arange(n_rows) + 2

    def numeric(col: str) -> np.ndarray:
        s = df[col].str.strip()
        v = pd.to_numeric(s, errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(v) & (s != "").to_numpy() & (s.str.lower() != "nan").to_numpy()
        bad |= np.isinf(v)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise FingerfitError(
                f"not a finite number: '{shown(df[col].iat[i])}'",
                path=path,
                line=int(lines[i]),
                field=col,
            )
        return v

    vals = np.empty((n_rows, len(keys), len(keys[0])))
    for j, cols in enumerate(keys):
        for m, c in enumerate(cols):
            vals[:, j, m] = numeric(c)
    return vals, (lambda: numeric(lay.time)) if lay.time is not None else None


def read_wide_csv(
    path: str | Path,
    *,
    units: str | None,
    layout: WideLayout | str | None = None,
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    check: bool = True,
) -> Recording:
    """Read a wide pose CSV (or its Parquet form) into a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
        ``*.parquet``: exactly the layout's columns of its stations, float64, with the
        metadata :func:`write_wide_csv` writes; rows are named by their 1-based index.
    units : str
        Position units of the file (``mm``, ``cm``, ``m``, ``in``). Required for a CSV:
        the format does not state them; a Parquet file states them (``units`` may be
        None, or must agree).
    layout : WideLayout or str, optional
        Column templates (see :func:`parse_layout`); default :data:`DEFAULT_LAYOUT`.
    rate_hz : float, optional
        Tracker frame rate. Frames are placed on the ``1/rate_hz`` grid by their
        times (missing frames become NaN rows); if the time column is a logger's
        clock too irregular for the grid, frames are timed by their count instead,
        which must agree with the time column's span within 5 %.
    sensors : mapping int -> str, optional
        Station -> sensor name; a station in the file but not in the mapping is an
        error. Default: station numbers as names.
    check : bool
        Run unit plausibility and jump checks (:func:`~fingerfit.io.hygiene.check_recording`).

    Returns
    -------
    Recording
        Time s; positions mm (tracker frame); rotations sensor -> tracker.

    Raises
    ------
    FingerfitError
        One line naming the file and line or column.
    """
    from .parquet import is_parquet

    path = Path(path)
    parquet = is_parquet(path)
    if parquet:
        units = wide_parquet_units(path, units)
    if units is None:
        raise FingerfitError(
            "the wide CSV does not state its units: give them (--units mm|cm|m|in)",
            path=path,
            field="units",
        )
    if units not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{units}' (use {', '.join(UNITS_TO_MM)})", path=path, field="units"
        )
    if rate_hz is not None and not rate_hz > 0:
        raise FingerfitError("the rate must be positive (Hz)", path=path, field="rate")
    lay = parse_layout(layout) if not isinstance(layout, WideLayout) else layout
    if parquet:
        try:
            return _read_parquet_fast(path, lay, sensors, units, rate_hz, check)
        except Exception:  # _Irregular, a FingerfitError, a damaged page Arrow reports
            pass  # the reference path below says what is wrong, or reads what is unusual
        vals, tcol, stations, names, notes = _decode_parquet(path, lay, sensors)
        return _assemble(path, vals, tcol, stations, names, notes, lay, units, rate_hz, check, 1)
    first = header_line(path)
    header = [h.strip() for h in first.split(",")]
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise FingerfitError(f"column '{shown(dup)}' appears twice", path=path, line=1)
    try:
        stations, names, notes = _header_plan(header, lay, sensors, path)
    except FingerfitError:
        check_field_counts(_read_bytes(path), path, len(header))  # that error comes first
        raise
    keys = [[_column(lay.columns[key], s) for key in lay.keys] for s in stations]
    try:
        vals, tcol = _decode_fast(path, header, keys, lay.time)
    except NotPlain:
        vals, tcol = _decode_exact(path, header, keys, lay, units)
    return _assemble(path, vals, tcol, stations, names, notes, lay, units, rate_hz, check, 2)


def wide_parquet_units(path: Path, units: str | None) -> str:
    """The units a wide Parquet file states (``fingerfit.units``); ``units``, when given,
    must agree."""
    from .parquet import WIDE, check_meta, parquet_schema

    _, meta = parquet_schema(path)
    check_meta(meta, path, WIDE, units=None)
    stated = meta["fingerfit.units"]
    if stated not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{shown(stated)}' (use {', '.join(UNITS_TO_MM)})",
            path=path,
            field="fingerfit.units",
        )
    if units is not None and units != stated:
        raise FingerfitError(
            f"the file's positions are in {stated}, not {units} as given (--units)",
            path=path,
            field="fingerfit.units",
        )
    return stated


#: Metadata of a wide table's orientation columns: quaternion order or Euler sequence.
_ORIENTATION_META = {_QUAT: ("quaternion_order", "w,x,y,z"), _EULER: ("euler_order", "ZYX,deg")}


def _wide_meta(units: str, lay: WideLayout):
    """The Parquet metadata of a wide table in ``units`` with layout ``lay``."""
    from .parquet import WIDE, TableMeta

    key, value = _ORIENTATION_META[lay.orientation]
    return TableMeta(WIDE, units=units, frame="tracker", extra={f"fingerfit.{key}": value})


class _Irregular(Exception):
    """A wide Parquet file the streaming reader does not vouch for (an error somewhere,
    repeated rows, stations updated one at a time, no time column, Euler angles): read
    again by the reference path, which names the error or repairs the rows."""


#: Rows of a wide Parquet file placed at a time by the streaming reader, and its threads.
_PARQUET_BLOCK = 1 << 15
_THREADS = 2


def _read_parquet_fast(
    path: Path,
    lay: WideLayout,
    sensors: Mapping[int, str] | None,
    units: str,
    rate_hz: float | None,
    check: bool,
) -> Recording:
    """The common case of a wide Parquet file, streamed into the recording's arrays.

    The time column first (the frames on the grid, :func:`_frame_grid`), then the values
    :data:`_PARQUET_BLOCK` rows at a time straight into each station's positions and
    rotation matrices: no ``(n, stations, keys)`` copy of the table. The arithmetic of
    :func:`_assemble` (the same bits); whatever :func:`_assemble` would refuse or repair
    raises, and the caller reads the file by the reference path.
    """
    from .parquet import WIDE, float_blocks, open_checked

    if lay.orientation != _QUAT or lay.time is None:
        raise _Irregular
    plan: list = []

    def check_columns(header: list[str]) -> None:
        plan.extend(_header_plan(header, lay, sensors, path))
        if plan[2]:
            raise _Irregular

    key, value = _ORIENTATION_META[lay.orientation]
    pf, fh, _ = open_checked(
        path, WIDE, columns=check_columns, expect={key: value, "frame": "tracker"}
    )
    stations, names, notes = plan
    n_st, k = len(stations), len(lay.keys)
    columns = [_column(lay.columns[key], s) for s in stations for key in lay.keys]
    scale = UNITS_TO_MM[units]
    with fh:
        n_rows = pf.metadata.num_rows
        if n_rows == 0:
            raise _Irregular
        tcol = np.empty(n_rows)
        read = 0
        for lo, (t,) in float_blocks(pf, [lay.time], n_rows):
            tcol[lo : lo + t.size] = t
            read = lo + t.size
        if read != n_rows or not np.isfinite(tcol).all():
            raise _Irregular
        lines = np.arange(n_rows) + 1
        notes.insert(0, f"{n_rows} rows of {n_st} stations read")
        time, grid_idx = _frame_grid(tcol, lines, n_rows, n_rows, rate_hz, path, notes)
        del tcol, lines
        n = int(grid_idx[-1]) + 1
        pos = [np.empty((n, 3)) for _ in stations]
        rot = [np.empty((n, 3, 3)) for _ in stations]
        filled = [np.zeros(n, dtype=bool) for _ in stations]
        buffers = threading.local()

        def place(lo: int, block: list[np.ndarray], before: np.ndarray | None) -> tuple[int, int]:
            """Check and place rows ``lo:lo + m`` (``before``: the row before them, for
            the repeats); their rows with held values and samples with empty fields."""
            m = block[0].size
            ext = getattr(buffers, "ext", None)
            if ext is None or ext.shape[0] < m + 1:
                # (rows, stations, keys) with each field's rows contiguous: the columns
                # are copied as they are, and the checks' reductions over stations and
                # keys go across contiguous rows
                rows = max(m, _PARQUET_BLOCK) + 1
                buffers.fields = np.empty((n_st, k, rows))
                buffers.ext = ext = buffers.fields.transpose(2, 0, 1)
                buffers.sums = np.empty(rows)
            fields = buffers.fields[:, :, : m + 1]  # (stations, keys, 1 + m), rows contiguous
            if before is not None:
                ext[0] = before
            v = ext[1 : m + 1]
            for c, col in enumerate(block):
                v[:, c // k, c % k] = col
            del block
            total = buffers.sums[:m]
            with np.errstate(over="ignore", invalid="ignore"):
                np.add.reduce(fields[:, :, 1:].reshape(n_st * k, m), axis=0, out=total)
            if np.isfinite(total).all():
                held, complete = _finite_block(fields, before is not None, scale)
                empty = 0
            else:
                held, complete, empty = _block_with_gaps(ext, m, before is not None, scale)
            at_all = grid_idx[lo : lo + m]
            for j in range(n_st):
                ok_j = complete if complete is True else complete[:, j]
                rows = slice(0, m) if ok_j is True or ok_j.all() else np.flatnonzero(ok_j)
                fv = v[rows, j]
                at = at_all[rows]
                put_scaled_rows(pos[j], at, fv[:, :3], scale)
                if complete is not True:
                    with np.errstate(over="ignore"):
                        norm = row_norms(fv[:, 3:])
                    if (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE).any():
                        raise _Irregular
                put_quat_rows(rot[j], at, fv[:, 3:])
                put_rows(filled[j], at, True)
            return held, empty

        # Blocks placed by two threads (NumPy works without the GIL; each block's rows go
        # to frames of their own) while Arrow decodes the next ones.
        n_partial_rows = n_partial_samples = 0
        read = 0
        before = None
        pending: deque = deque()
        blocks = float_blocks(pf, columns, n_rows, batch_rows=_PARQUET_BLOCK, ahead=True)
        with ThreadPoolExecutor(max_workers=_THREADS) as pool:
            try:
                for lo, block in blocks:
                    if len(pending) >= _THREADS:
                        held, empty = pending.popleft().result()
                        n_partial_rows += held
                        n_partial_samples += empty
                    pending.append(pool.submit(place, lo, block, before))
                    before = np.array([col[-1] for col in block]).reshape(n_st, k)
                    read = lo + block[0].size
                    del block
                while pending:
                    held, empty = pending.popleft().result()
                    n_partial_rows += held
                    n_partial_samples += empty
            finally:
                blocks.close()
                for fut in pending:
                    fut.cancel()
        if read != n_rows or (n_st > 1 and n_partial_rows / n_rows > 0.5):
            raise _Irregular
    if n_partial_samples:
        notes.append(f"{n_partial_samples} samples with empty fields treated as missing")
    poses: dict[str, PoseSeries] = {}
    missing: list[str] = []
    for j, name in enumerate(names):
        gap = np.flatnonzero(~filled[j])
        if gap.size:
            pos[j][gap] = np.nan
            rot[j][gap] = np.nan
        missing += missing_note(name, gap.size, n)
        poses[name] = PoseSeries(pos[j], rot[j])
    rec = Recording(path.name, np.asarray(time, dtype=float), poses, notes + missing)
    if check:
        check_recording(rec, path)
    return rec


def _finite_block(fields: np.ndarray, with_before: bool, scale: float) -> tuple[int, bool]:
    """The checks of a block of rows whose fields all hold finite numbers, by whole-block
    reductions: coordinates plausible and quaternion norms within the tolerance
    (:func:`~fingerfit.io.hygiene.plain_block`), no repeated row.

    ``fields (stations, keys, 1 + rows)``: the row before the block (when
    ``with_before``; else not looked at), then the block's rows. Returns the rows with
    held values and ``True`` (every sample complete); raises :class:`_Irregular` for
    anything the reference path must decide.
    """
    q = fields[:, 3:, 1:]
    if not plain_block(fields[:, :3, 1:], np.einsum("skm,skm->sm", q, q), scale):
        raise _Irregular
    # same[j, i]: station j's fields of row i equal those of the row before it
    same = fields[:, 0, 1:] == fields[:, 0, :-1]
    for key in range(1, fields.shape[1]):
        same &= fields[:, key, 1:] == fields[:, key, :-1]
    if not with_before:  # the file's first row: no row before it
        same[:, 0] = False
    if same.all(axis=0).any():  # a repeated row
        raise _Irregular
    return int(np.count_nonzero(same.any(axis=0))), True


def _block_with_gaps(
    ext: np.ndarray, m: int, with_before: bool, scale: float
) -> tuple[int, np.ndarray, int]:
    """The checks of a block of rows with empty fields (NaN), row by row: ``ext (1 + m,
    stations, keys)`` the row before and the block. Returns the rows with held values,
    complete samples ``(m, stations)`` and samples with empty fields."""
    v = ext[1 : m + 1]
    if np.isinf(v).any() or implausible_rows(v[:, :, :3], scale).size:
        raise _Irregular
    rep, same = _repeats(ext[: m + 1] if with_before else v)
    if with_before:
        rep, same = rep[1:], same[1:]
    if rep.any():
        raise _Irregular
    some, every = same[:, 0].copy(), same[:, 0].copy()
    for j in range(1, same.shape[1]):
        some |= same[:, j]
        every &= same[:, j]
    held = int(np.count_nonzero(some & ~every))
    del rep, same, some, every
    finite = np.isfinite(v)
    complete = finite.all(axis=2)
    empty = int(np.count_nonzero(~complete & finite.any(axis=2)))
    return held, complete, empty


def _decode_parquet(
    path: Path, lay: WideLayout, sensors: Mapping[int, str] | None
) -> tuple[np.ndarray, np.ndarray | None, list[int], list[str], list[str]]:
    """Values ``(n_rows, n_stations, n_keys)``, time ``(n_rows,)`` (or None), stations,
    sensor names and notes of a wide Parquet file: exactly the layout's columns of its
    stations, float64."""
    from .parquet import WIDE, float_blocks, open_checked
    from .parquet import _corrupt as parquet_corrupt
    from .parquet_read import refuse_infinite

    plan: list = []

    def check_columns(header: list[str]) -> None:
        try:
            plan.extend(_header_plan(header, lay, sensors, path))
        except FingerfitError as exc:  # no line: a Parquet file's header is its schema
            raise FingerfitError(exc.reason, path=path, field=exc.field) from None
        if plan[2]:  # columns not used: not a column of the layout
            used = {lay.time} | {_column(lay.columns[key], s) for s in plan[0] for key in lay.keys}
            extra = next(h for h in header if h not in used)
            raise FingerfitError(
                "unexpected column (not one of the layout's)", path=path, field=shown(extra)
            )

    key, value = _ORIENTATION_META[lay.orientation]
    pf, fh, schema = open_checked(
        path, WIDE, columns=check_columns, expect={key: value, "frame": "tracker"}
    )
    stations, names, notes = plan
    n_rows = pf.metadata.num_rows
    # every column straight into its place in the values (and the time), a row group at
    # a time: no whole Arrow table, no second copy
    vals = np.empty((n_rows, len(stations), len(lay.keys)))
    tcol = None if lay.time is None else np.empty(n_rows)
    targets = [vals[:, j, m] for j in range(len(stations)) for m in range(len(lay.keys))]
    columns = [_column(lay.columns[key], s) for s in stations for key in lay.keys]
    if tcol is not None:
        targets.append(tcol)
        columns.append(lay.time)
    with fh:
        try:
            read = 0
            for lo, block in float_blocks(pf, columns, n_rows):
                for out, v in zip(targets, block, strict=True):
                    out[lo : lo + v.size] = v
                read = lo + block[0].size
            if read != n_rows:
                raise ValueError(f"{read} rows read of {n_rows}")
        except Exception as exc:  # a damaged data page
            raise parquet_corrupt(path, exc) from None
    # an infinity is refused as read_parquet refuses it: the first column (in the file's
    # order) holding one, its first row
    if np.isinf(vals).any() or (tcol is not None and np.isinf(tcol).any()):
        where = dict(zip(columns, targets, strict=True))
        for c in schema.names:
            refuse_infinite(where[c], c, path)
    if n_rows == 0:
        raise FingerfitError("no data rows", path=path)
    return vals, tcol, stations, names, notes


def wide_table(
    recording: Recording, *, units: str = "mm", layout: WideLayout | None = None
) -> pd.DataFrame:
    """A recording as a wide table (one row per frame; stations numbered 1, 2, ...
    in sensor order).

    Parameters
    ----------
    recording : Recording
        Positions mm.
    units : str
        Units of the written positions.
    layout : WideLayout, optional
        Column templates; default :data:`DEFAULT_LAYOUT` (quaternions ``w, x, y, z``).

    Returns
    -------
    DataFrame
        Missing samples are NaN.
    """
    lay = layout or DEFAULT_LAYOUT
    return pd.DataFrame(_wide_block(recording, 0, recording.n_frames, units, lay))


def _wide_block(
    recording: Recording, lo: int, hi: int, units: str, lay: WideLayout
) -> dict[str, np.ndarray]:
    """The columns of :func:`wide_table` for frames ``lo:hi``, each ``(hi - lo,)``
    (positions in ``units``, orientations as ``lay`` states them; NaN where missing)."""
    data: dict[str, np.ndarray] = {}
    if lay.time is not None:
        data[lay.time] = recording.time[lo:hi]
    for s, name in enumerate(recording.sensors, start=1):
        pose = recording.poses[name]
        if lay.orientation == _QUAT:
            ori = sensor_quats(recording, name, lo, hi)
        else:
            ori = np.full((3, hi - lo), np.nan)
            ok = pose.valid[lo:hi]
            euler = Rotation.from_matrix(pose.rotation[lo:hi][ok]).as_euler("ZYX", degrees=True)
            ori[:, ok] = euler.T
        for m, key in enumerate(lay.orientation):
            data[_column(lay.columns[key], s)] = ori[m]
        for m, key in enumerate(_POS):
            data[_column(lay.columns[key], s)] = pose.position[lo:hi, m] / UNITS_TO_MM[units]
    return data


def write_wide_csv(
    path: str | Path,
    recording: Recording,
    *,
    units: str = "mm",
    layout: WideLayout | None = None,
) -> Path:
    """Write a recording as a wide CSV, atomically, floats in shortest round-trip form.

    Parameters
    ----------
    path : str or Path
        ``*.parquet``: the same columns as float64 in a Parquet file, the units, frame
        and quaternion order (or Euler sequence) in its metadata.
    recording : Recording
        Positions mm, rotations sensor -> tracker.
    units : str
        Units of the written positions.
    layout : WideLayout, optional
        Column templates; default :data:`DEFAULT_LAYOUT` (quaternions ``w, x, y, z``).

    Returns
    -------
    Path
    """
    from .parquet import is_parquet, write_table_file

    lay = layout or DEFAULT_LAYOUT
    if is_parquet(path) and lay.orientation == _QUAT:
        return _write_parquet(Path(path), recording, units, lay)
    table = wide_table(recording, units=units, layout=lay)
    return write_table_file(Path(path), table, _wide_meta(units, lay))


def _write_parquet(path: Path, recording: Recording, units: str, lay: WideLayout) -> Path:
    """The columns of :func:`wide_table` (quaternion layouts) written a row group of
    frames at a time, each made while the one before it is written: the same numbers,
    without the whole table in memory."""
    from .parquet import ROW_GROUP_ROWS, ParquetSink

    n = recording.n_frames
    with ParquetSink(
        path, _wide_meta(units, lay), statistics=(lay.time,) if lay.time else ()
    ) as sink:
        sink.write_blocks(
            _wide_block(recording, lo, min(lo + ROW_GROUP_ROWS, n), units, lay)
            for lo in range(0, max(n, 1), ROW_GROUP_ROWS)
        )
    return path
