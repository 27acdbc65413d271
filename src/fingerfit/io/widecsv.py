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
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError, shown
from ..session import UNITS_TO_MM, Recording
from ..transforms import quat_wxyz_from_matrix
from .fastcsv import NotPlain, read_header
from .posecsv import check_field_counts
from .wideframes import QUAT_NORM_TOLERANCE as QUAT_NORM_TOLERANCE
from .wideframes import RATE_TOLERANCE as RATE_TOLERANCE
from .wideframes import _assemble
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
        vals, tcol, stations, names, notes = _decode_parquet(path, lay, sensors)
        return _assemble(path, vals, tcol, stations, names, notes, lay, units, rate_hz, check, 1)
    first = read_header(path).split(b"\n", 1)[0].decode("utf-8", "replace").strip().lstrip("\ufeff")
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


def _decode_parquet(
    path: Path, lay: WideLayout, sensors: Mapping[int, str] | None
) -> tuple[np.ndarray, np.ndarray | None, list[int], list[str], list[str]]:
    """Values ``(n_rows, n_stations, n_keys)``, time ``(n_rows,)`` (or None), stations,
    sensor names and notes of a wide Parquet file: exactly the layout's columns of its
    stations, float64."""
    from .parquet import WIDE, read_parquet

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
    table = read_parquet(path, WIDE, columns=check_columns, expect={key: value, "frame": "tracker"})
    stations, names, notes = plan
    cols = table.columns
    if table.n_rows == 0:
        raise FingerfitError("no data rows", path=path)
    vals = np.empty((table.n_rows, len(stations), len(lay.keys)))
    for j, s in enumerate(stations):
        for m, key in enumerate(lay.keys):
            vals[:, j, m] = cols.pop(_column(lay.columns[key], s))
    tcol = None if lay.time is None else cols.pop(lay.time)
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
    data: dict[str, np.ndarray] = {}
    if lay.time is not None:
        data[lay.time] = recording.time
    for s, name in enumerate(recording.sensors, start=1):
        pose = recording.poses[name]
        if lay.orientation == _QUAT:
            ori = quat_wxyz_from_matrix(pose.rotation)
        else:
            ori = np.full((recording.n_frames, 3), np.nan)
            ok = pose.valid
            ori[ok] = Rotation.from_matrix(pose.rotation[ok]).as_euler("ZYX", degrees=True)
        for m, key in enumerate(lay.orientation):
            data[_column(lay.columns[key], s)] = ori[:, m]
        for m, key in enumerate(_POS):
            data[_column(lay.columns[key], s)] = pose.position[:, m] / UNITS_TO_MM[units]
    return pd.DataFrame(data)


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
    from .parquet import write_table_file

    lay = layout or DEFAULT_LAYOUT
    table = wide_table(recording, units=units, layout=lay)
    return write_table_file(Path(path), table, _wide_meta(units, lay))
