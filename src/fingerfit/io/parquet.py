"""Parquet tables: the schema, the metadata, atomic writes and validated reads.

Every table fingerfit writes as CSV can be written as Parquet instead, chosen by the
file's extension ``.parquet`` (:func:`is_parquet`): the same column names as the CSV,
every numeric column ``float64`` (text columns such as ``sensor`` UTF-8 strings), NaN
kept as NaN (not null), zstd compression, and the file's key-value metadata stating what
the numbers mean (:class:`TableMeta`: ``fingerfit.format``, ``fingerfit.units``,
``fingerfit.frame``, ``fingerfit.quaternion_order``, ...). Floats are stored as their
64 bits, so write -> read gives the same numbers bit for bit (``-0.0``, subnormals).

Writing: :class:`ParquetSink` appends row groups to a temporary file beside the target
and renames it into place only when closed after success
(:func:`fingerfit.io.atomic.atomic_path`), so a failure never leaves a half-written
file; :func:`write_parquet` writes a whole table through it, :func:`parquet_bytes`
gives a file's bytes (for :func:`fingerfit.io.atomic.write_files`), and
:func:`write_table_file` writes CSV or Parquet by the extension.

Reading: :func:`read_parquet` checks the file before trusting it -- that it is a
readable Parquet file at all (a truncated or corrupted file is one line, never a
traceback), that its metadata names the expected format, that the columns are exactly
those of the format, each of the right type, and that no float column holds an
infinity -- and returns plain NumPy columns. Every refusal is a one-line
:class:`~fingerfit.errors.FingerfitError` naming the file and the column (or metadata
key); a row is named by its 1-based index where a CSV error names a line
(``docs/errors.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown

#: The file extension that selects Parquet (case-insensitive).
SUFFIX = ".parquet"
#: Compression of every Parquet file fingerfit writes.
COMPRESSION = "zstd"
#: Rows per row group of :func:`write_parquet` (a few tens of MB of float64 columns).
ROW_GROUP_ROWS = 1 << 20

#: Metadata keys (every one a UTF-8 string value).
FORMAT_KEY = "fingerfit.format"
UNITS_KEY = "fingerfit.units"
TIME_UNITS_KEY = "fingerfit.time_units"
ANGLE_UNITS_KEY = "fingerfit.angle_units"
FRAME_KEY = "fingerfit.frame"
QUAT_KEY = "fingerfit.quaternion_order"
TABLE_KEY = "fingerfit.table"

#: Formats (values of ``fingerfit.format``).
POSE = "fingerfit.pose/1"
WIDE = "fingerfit.wide/1"
ANGLES = "fingerfit.angles/1"
JOINTS = "fingerfit.joints/1"
RESIDUALS = "fingerfit.residuals/1"
STUDY_TABLE = "fingerfit.study_table/1"

#: Quaternion order of every fingerfit file: scalar first.
QUAT_ORDER = "w,x,y,z"
#: The frame of positions and rotations in recordings and fingertip columns.
TRACKER_FRAME = "tracker"


def is_parquet(path: str | Path) -> bool:
    """Whether ``path`` names a Parquet file (its extension is ``.parquet``)."""
    return Path(path).suffix.lower() == SUFFIX


@dataclass(frozen=True)
class TableMeta:
    """What a table's numbers mean, stored in the Parquet file's key-value metadata.

    Attributes
    ----------
    format : str
        ``fingerfit.format``: :data:`POSE`, :data:`WIDE`, :data:`ANGLES`, ...
    units : str, optional
        ``fingerfit.units``: length units of the positions (``mm``, ``cm``, ``m``, ``in``).
    frame : str, optional
        ``fingerfit.frame``: the frame of positions and rotations (``tracker``).
    quaternion_order : str, optional
        ``fingerfit.quaternion_order``: ``w,x,y,z`` (scalar first).
    time_units : str, optional
        ``fingerfit.time_units``: ``s``.
    angle_units : str, optional
        ``fingerfit.angle_units``: ``deg`` or ``rad``.
    extra : dict of str to str
        Further ``fingerfit.*`` keys (e.g. ``fingerfit.table`` of a study table).
    """

    format: str
    units: str | None = None
    frame: str | None = None
    quaternion_order: str | None = None
    time_units: str | None = "s"
    angle_units: str | None = None
    extra: dict[str, str] = field(default_factory=dict)

    def items(self) -> dict[str, str]:
        """The metadata as written: key -> value, absent values left out."""
        pairs = {
            FORMAT_KEY: self.format,
            UNITS_KEY: self.units,
            TIME_UNITS_KEY: self.time_units,
            ANGLE_UNITS_KEY: self.angle_units,
            FRAME_KEY: self.frame,
            QUAT_KEY: self.quaternion_order,
            **self.extra,
        }
        return {k: v for k, v in pairs.items() if v is not None}


def pose_meta(units: str) -> TableMeta:
    """Metadata of a pose recording (long or wide): positions in ``units``, tracker frame,
    rotations sensor -> tracker as quaternions ``w,x,y,z``."""
    return TableMeta(POSE, units=units, frame=TRACKER_FRAME, quaternion_order=QUAT_ORDER)


def angles_meta(units: str) -> TableMeta:
    """Metadata of an angles table (``fingerfit angles``, ``stream --record``): angles in
    degrees, fingertip and pad points in ``units``, tracker frame."""
    return TableMeta(ANGLES, units=units, frame=TRACKER_FRAME, angle_units="deg")


def joints_meta() -> TableMeta:
    """Metadata of a joint trajectory (``retarget -o``, ``angles --urdf-names``): joint
    positions in radians."""
    return TableMeta(JOINTS, angle_units="rad")


def _pa():
    import pyarrow as pa
    import pyarrow.parquet as pq

    return pa, pq


#: A column as handed to the writers: ``(n,)`` float/int/bool/text array, or a pair
#: ``(codes (n,) int, names list of str)`` of a text column.
Column = np.ndarray | tuple[np.ndarray, Sequence[str]]


def _arrow_column(pa, v: object, lo: int, hi: int):
    """Rows ``lo:hi`` of a column as an Arrow array (floats as float64, NaN kept)."""
    if isinstance(v, tuple):
        codes, names = v
        dictionary = pa.array([str(n) for n in names], pa.string())
        codes = np.asarray(codes)[lo:hi].astype(np.int32, copy=False)
        return pa.DictionaryArray.from_arrays(codes, dictionary)
    if hasattr(v, "dtype") and str(getattr(v, "dtype", "")) == "category":
        cat = v.iloc[lo:hi] if hasattr(v, "iloc") else v[lo:hi]
        return pa.array(cat.astype(object).to_numpy(), pa.string(), from_pandas=True)
    a = v.to_numpy() if hasattr(v, "to_numpy") else np.asarray(v)
    a = a[lo:hi]
    if a.dtype.kind == "f":
        return pa.array(a.astype(np.float64, copy=False), pa.float64())
    if a.dtype.kind in "iu":
        return pa.array(a.astype(np.int64, copy=False), pa.int64())
    if a.dtype.kind == "b":
        return pa.array(a, pa.bool_())
    return pa.array(a.astype(object), pa.string(), from_pandas=True)


def _items(table: object) -> list[tuple[str, object]]:
    if isinstance(table, Mapping):
        return [(str(k), v) for k, v in table.items()]
    return [(str(k), table[k]) for k in table.columns]  # a DataFrame


def _n_rows(columns: list[tuple[str, object]]) -> int:
    if not columns:
        return 0
    v = columns[0][1]
    return len(v[0]) if isinstance(v, tuple) else len(v)


def _batch(pa, columns: list[tuple[str, object]], lo: int, hi: int, schema=None):
    arrays = [_arrow_column(pa, v, lo, hi) for _, v in columns]
    if schema is not None:
        arrays = [
            a if a.type == f.type else a.cast(f.type) for a, f in zip(arrays, schema, strict=True)
        ]
        return pa.RecordBatch.from_arrays(arrays, schema=schema)
    return pa.RecordBatch.from_arrays(arrays, names=[n for n, _ in columns])


class ParquetSink:
    """A Parquet file written a block of rows at a time that appears complete or not at all.

    Rows go to a temporary file beside ``path`` through a ``pyarrow.parquet.ParquetWriter``
    (zstd), each :meth:`write` one or more row groups; :meth:`close` finishes the file
    (footer, metadata) and renames it over ``path``, or with ``ok=False`` removes it. Also
    a context manager (closed with ``ok`` = no exception).

    Parameters
    ----------
    path : str or Path
        The file to write (checked with :func:`fingerfit.io.atomic.check_target`).
    meta : TableMeta
        Stored in the file's key-value metadata.
    schema : pyarrow.Schema, optional
        The columns' names and types; default: those of the first block (floats
        float64, integers int64, text strings). Later blocks are cast to it.
    row_group_rows : int
        Largest row group written.
    """

    def __init__(
        self,
        path: str | Path,
        meta: TableMeta,
        *,
        schema=None,
        row_group_rows: int = ROW_GROUP_ROWS,
    ) -> None:
        from .atomic import atomic_path

        self.path = Path(path)
        self.meta = meta
        self.rows = 0
        self._schema = schema
        self._writer = None
        self._group = row_group_rows
        self._ctx = atomic_path(self.path)
        self._tmp = self._ctx.__enter__()
        self._open = True

    def _start(self, pa, pq, schema) -> None:
        schema = schema.with_metadata(self.meta.items())
        self._schema = schema
        try:
            self._writer = pq.ParquetWriter(
                str(self._tmp), schema, compression=COMPRESSION, write_statistics=False
            )
        except (OSError, pa.ArrowException) as exc:
            raise FingerfitError(f"cannot write ({_reason(exc)})", path=self.path) from None

    def write(self, table: object) -> None:
        """Append rows: a DataFrame or a mapping name -> column (``(m,)`` arrays, or
        ``(codes, names)`` pairs for text), the same columns in the same order each time."""
        pa, pq = _pa()
        columns = _items(table)
        n = _n_rows(columns)
        for lo in range(0, max(n, 1), self._group):
            hi = min(lo + self._group, n)
            batch = _batch(pa, columns, lo, hi, self._schema)
            if self._writer is None:
                self._start(pa, pq, batch.schema)
            if hi > lo:
                try:
                    self._writer.write_batch(batch, row_group_size=self._group)
                except (OSError, pa.ArrowException) as exc:
                    raise FingerfitError(f"cannot write ({_reason(exc)})", path=self.path) from None
        self.rows += n

    def close(self, ok: bool = True) -> None:
        """Finish the file and rename it into place (``ok``), or remove it."""
        if not self._open:
            return
        self._open = False
        if ok:
            try:
                if self._writer is None:
                    raise FingerfitError("no columns to write", path=self.path)
                self._writer.close()
            except BaseException as exc:
                self._ctx.__exit__(type(exc), exc, exc.__traceback__)
                raise
            self._ctx.__exit__(None, None, None)
        else:
            if self._writer is not None:
                try:
                    self._writer.close()
                except Exception:  # the file is being discarded
                    pass
            err = FingerfitError("discarded", path=self.path)
            try:
                self._ctx.__exit__(FingerfitError, err, None)
            except FingerfitError:
                pass

    def __enter__(self) -> ParquetSink:
        return self

    def __exit__(self, kind, exc, tb) -> None:
        self.close(ok=kind is None)


def write_parquet(
    path: str | Path,
    table: object,
    meta: TableMeta,
    *,
    progress: Callable[[int], None] | None = None,
    row_group_rows: int = ROW_GROUP_ROWS,
) -> Path:
    """Write a whole table as one Parquet file, atomically.

    Parameters
    ----------
    path : str or Path
    table : DataFrame or mapping of str to column
        Columns in order, each ``(n,)``: float (stored float64, NaN kept), integer,
        text, or a pair ``(codes (n,) int, names)`` of a text column.
    meta : TableMeta
    progress : callable, optional
        Called with the number of rows after each row group.
    row_group_rows : int

    Returns
    -------
    Path
    """
    columns = _items(table)
    n = _n_rows(columns)
    with ParquetSink(path, meta, row_group_rows=row_group_rows) as sink:
        if n == 0:
            sink.write(dict(columns))
        for lo in range(0, n, row_group_rows):
            hi = min(lo + row_group_rows, n)
            sink.write({k: _rows(v, lo, hi) for k, v in columns})
            if progress is not None:
                progress(hi - lo)
    return Path(path)


def _rows(v: object, lo: int, hi: int) -> object:
    if isinstance(v, tuple):
        return (np.asarray(v[0])[lo:hi], v[1])
    if hasattr(v, "iloc"):
        return v.iloc[lo:hi]
    return np.asarray(v)[lo:hi]


def parquet_bytes(table: object, meta: TableMeta) -> bytes:
    """A whole table as the bytes of a Parquet file (for
    :func:`fingerfit.io.atomic.write_files`, which writes several files all-or-nothing)."""
    pa, pq = _pa()
    columns = _items(table)
    batch = _batch(pa, columns, 0, _n_rows(columns))
    sink = pa.BufferOutputStream()
    pq.write_table(
        pa.Table.from_batches([batch]).replace_schema_metadata(meta.items()),
        sink,
        compression=COMPRESSION,
        write_statistics=False,
    )
    return sink.getvalue().to_pybytes()


def write_table_file(
    path: str | Path,
    table: object,
    meta: TableMeta,
    *,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Write a table as CSV or Parquet, chosen by the extension of ``path``, atomically.

    CSV: :func:`fingerfit.io.fastcsv.write_table` (``meta`` is not written: the format's
    documentation states it); Parquet: :func:`write_parquet`.
    """
    if is_parquet(path):
        return write_parquet(path, table, meta, progress=progress)
    from .fastcsv import write_table

    return write_table(path, table, progress=progress)


def write_partitioned(
    folder: str | Path,
    chunks: Iterable[object],
    schema,
    meta: TableMeta,
    *,
    by: str = "subject",
) -> Path:
    """Write a table as a hive-partitioned Parquet dataset, one file per value of ``by``.

    ``folder/<by>=<value>/part-<k>.parquet`` holds the rows of one value (``k`` counts the
    pieces of a value met in several chunks), without the column ``by`` (its value is in
    the folder name); ``pandas.read_parquet(folder)``, ``pyarrow.dataset`` and
    ``dask.dataframe.read_parquet`` give it back as a column. Chunks are written as they
    come, so the whole table is never in memory; each file is written atomically
    (:func:`write_parquet`). A table without rows is one file ``folder/empty.parquet``
    holding the schema (``by`` included).

    Parameters
    ----------
    folder : str or Path
        The dataset's folder (created).
    chunks : iterable of DataFrame
        The table in pieces, each with the columns of ``schema``; the values of ``by``
        must name folders (no ``/``; a study's subject IDs do).
    schema : pyarrow.Schema
        Every column's type, ``by`` included; text columns string.
    meta : TableMeta
    by : str
        The partition column.

    Returns
    -------
    Path
        ``folder``.
    """
    pa, _ = _pa()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rest = pa.schema([f for f in schema if f.name != by])
    pieces: dict[str, int] = {}
    for chunk in chunks:
        if not len(chunk):
            continue
        keys = chunk[by].astype(str).to_numpy()
        # the rows of each value, in the order the values come (rows of a value stay in order)
        values, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(values.size + 1))
        for v in np.argsort(first, kind="stable"):
            rows = order[bounds[v] : bounds[v + 1]]
            value = str(values[v])
            if "/" in value or value in ("", ".", ".."):
                raise FingerfitError(f"'{shown(value)}' cannot name a folder", field=by)
            k = pieces.get(value, 0)
            pieces[value] = k + 1
            part = chunk.iloc[rows].drop(columns=[by])
            with ParquetSink(
                folder / f"{by}={value}" / f"part-{k}.parquet", meta, schema=rest
            ) as sink:
                sink.write(_typed(part, rest))
    if not pieces:
        with ParquetSink(folder / "empty.parquet", meta, schema=schema) as sink:
            sink.write(
                {
                    f.name: np.zeros(0) if f.type != pa.string() else np.zeros(0, object)
                    for f in schema
                }
            )
    return folder


def table_schema(frames: Iterable[object], empty: object | None = None):
    """The Parquet schema of a table given in pieces (DataFrames): text columns (text or
    categorical in any piece) string, columns integer in every piece int64, booleans bool,
    the rest float64. ``empty``: the table without rows, whose types count only for a
    column no piece with rows has."""
    import pandas as pd

    pa, _ = _pa()
    kinds: dict[str, set[str]] = {}
    for chunk in [*([] if empty is None else [empty]), *frames]:
        for c, t in chunk.dtypes.items():
            kind = "text" if isinstance(t, pd.CategoricalDtype) or t.kind in "OSU" else t.kind
            if isinstance(t, pd.StringDtype):
                kind = "text"
            if len(chunk) or not kinds.get(str(c)):
                kinds.setdefault(str(c), set()).add(kind)
    types = []
    for c, k in kinds.items():
        if "text" in k:
            types.append((c, pa.string()))
        elif k <= {"i", "u"}:
            types.append((c, pa.int64()))
        elif k == {"b"}:
            types.append((c, pa.bool_()))
        else:
            types.append((c, pa.float64()))
    return pa.schema(types)


def _typed(table, schema) -> dict[str, object]:
    """The columns of a DataFrame as ``schema`` types them: a text column that is all
    missing in this piece (pandas made it float) becomes nulls."""
    pa, _ = _pa()
    out: dict[str, object] = {}
    for f in schema:
        col = table[f.name]
        if f.type == pa.string() and col.dtype.kind == "f":
            col = col.astype(object).where(col.notna(), None)
        out[f.name] = col
    return out


# --------------------------------------------------------------------------- reading


@dataclass
class ParquetTable:
    """The checked columns of a Parquet file.

    Attributes
    ----------
    columns : dict of str to ndarray or tuple
        Float columns as ``(n,)`` float64 arrays (a null read as NaN); text columns as
        ``(codes (n,) int32, names list of str)`` (a null as the name ``""``).
    meta : dict of str to str
        The file's ``fingerfit.*`` metadata.
    n_rows : int
    names : list of str
        The column names, in file order.
    """

    columns: dict[str, object]
    meta: dict[str, str]
    n_rows: int
    names: list[str]


def _reason(exc: BaseException) -> str:
    """An exception's message on one line, shortened."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return shown(text, 160)


def _corrupt(path: Path, exc: BaseException) -> FingerfitError:
    return FingerfitError(
        f"not a readable Parquet file (truncated or corrupted?): {_reason(exc)}", path=path
    )


def _open(path: Path):
    """The ``pyarrow.parquet.ParquetFile`` of ``path``, or a one-line error."""
    _, pq = _pa()
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    try:
        return pq.ParquetFile(fh), fh
    except Exception as exc:  # any failure of a damaged file is one line
        fh.close()
        raise _corrupt(path, exc) from None


def parquet_schema(path: str | Path) -> tuple[list[str], dict[str, str]]:
    """The column names and the ``fingerfit.*`` metadata of a Parquet file (no data read).

    Raises
    ------
    FingerfitError
        The file cannot be read or is not Parquet.
    """
    path = Path(path)
    pf, fh = _open(path)
    with fh:
        try:
            schema = pf.schema_arrow
        except Exception as exc:
            raise _corrupt(path, exc) from None
    return list(schema.names), _metadata(schema)


def _metadata(schema) -> dict[str, str]:
    raw = schema.metadata or {}
    out = {}
    for k, v in raw.items():
        try:
            key, value = k.decode("utf-8"), v.decode("utf-8")
        except UnicodeDecodeError:
            continue
        if key.startswith("fingerfit."):
            out[key] = value
    return out


def check_meta(meta: Mapping[str, str], path: Path, fmt: str, **expected: str | None) -> None:
    """Refuse a file whose metadata is not that of format ``fmt``.

    ``expected``: further keys without their ``fingerfit.`` prefix (``units="mm"``,
    ``quaternion_order="w,x,y,z"``): each must be present with that value (a value of
    None: present with any value).
    """
    have = meta.get(FORMAT_KEY)
    if have is None:
        raise FingerfitError(
            f"no '{FORMAT_KEY}' metadata: not a table fingerfit wrote (expected {fmt})",
            path=path,
            field=FORMAT_KEY,
        )
    if have != fmt:
        raise FingerfitError(
            f"holds a '{shown(have)}' table, not {fmt}", path=path, field=FORMAT_KEY
        )
    for short, value in expected.items():
        key = f"fingerfit.{short}"
        got = meta.get(key)
        if got is None:
            raise FingerfitError(f"metadata '{key}' missing", path=path, field=key)
        if value is not None and got != value:
            raise FingerfitError(
                f"metadata says '{shown(got)}', expected '{value}'", path=path, field=key
            )


def open_checked(
    path: Path,
    fmt: str,
    *,
    columns: Sequence[str] | Callable[[list[str]], None] | None = None,
    text: Sequence[str] = (),
    expect: Mapping[str, str | None] | None = None,
):
    """Open a Parquet table of format ``fmt`` and check everything its schema tells (the
    checks of :func:`read_parquet` before any data is read).

    Returns
    -------
    tuple
        ``(pyarrow.parquet.ParquetFile, open file, pyarrow.Schema)``; the caller closes
        the file (``with fh:``).
    """
    pa, _ = _pa()
    pf, fh = _open(path)
    try:
        try:
            schema = pf.schema_arrow
        except Exception as exc:
            raise _corrupt(path, exc) from None
        check_meta(_metadata(schema), path, fmt, **(expect or {}))
        names = list(schema.names)
        dup = [n for n in names if names.count(n) > 1]
        if dup:
            raise FingerfitError("column appears twice", path=path, field=shown(dup[0]))
        if callable(columns):
            columns(names)
        elif columns is not None:
            for c in columns:
                if c not in names:
                    raise FingerfitError(
                        f"column missing (expected {', '.join(columns)})", path=path, field=c
                    )
            for c in names:
                if c not in columns:
                    raise FingerfitError(
                        f"unexpected column (expected {', '.join(columns)})",
                        path=path,
                        field=shown(c),
                    )
        for f in schema:
            t = f.type
            if f.name in text:
                if pa.types.is_dictionary(t):
                    t = t.value_type
                if not (pa.types.is_string(t) or pa.types.is_large_string(t)):
                    raise FingerfitError(
                        f"column type {t}, not string", path=path, field=shown(f.name)
                    )
            elif t != pa.float64():
                raise FingerfitError(
                    f"column type {t}, not float64 (double)", path=path, field=shown(f.name)
                )
    except BaseException:
        fh.close()
        raise
    return pf, fh, schema


def read_parquet(
    path: str | Path,
    fmt: str,
    *,
    columns: Sequence[str] | Callable[[list[str]], None] | None = None,
    text: Sequence[str] = (),
    expect: Mapping[str, str | None] | None = None,
) -> ParquetTable:
    """Read and check a Parquet table of format ``fmt``.

    Parameters
    ----------
    path : str or Path
    fmt : str
        The required ``fingerfit.format`` (:data:`POSE`, :data:`WIDE`, ...).
    columns : sequence of str or callable, optional
        The exact columns (in any order; a missing or an extra column is an error), or a
        function checking the list of names (raising :class:`FingerfitError`).
    text : sequence of str
        Columns that hold text (strings, or dictionary-encoded strings); every other
        column must be float64.
    expect : mapping, optional
        Further metadata (:func:`check_meta`).

    Returns
    -------
    ParquetTable

    Raises
    ------
    FingerfitError
        One line naming the file and the column or metadata key: not readable
        (truncated, corrupted, not Parquet), metadata missing or of another format,
        a column missing, extra, repeated or of another type, an infinite value (named
        by its 1-based row).
    """
    pa, _ = _pa()
    path = Path(path)
    pf, fh, schema = open_checked(path, fmt, columns=columns, text=text, expect=expect)
    names = list(schema.names)
    floats = [c for c in names if c not in text]
    with fh:
        try:
            n_rows = pf.metadata.num_rows
            # float columns straight into their final arrays, a row group at a time (no
            # whole Arrow table beside them)
            # (one row group: its decoded columns are the arrays, no copy at all)
            single = pf.num_row_groups == 1
            out: dict[str, object] = {} if single else {c: np.empty(n_rows) for c in floats}
            filled = 0
            for lo, block in float_blocks(pf, floats, n_rows):
                for c, v in zip(floats, block, strict=True):
                    if single:
                        out[c] = v
                    else:
                        out[c][lo : lo + v.size] = v
                filled = lo + (block[0].size if block else 0)
            if floats and filled != n_rows:
                raise ValueError(f"{filled} rows read of {n_rows}")
            texts = pf.read(columns=[c for c in names if c in text], use_threads=True)
        except Exception as exc:  # a damaged data page
            raise _corrupt(path, exc) from None
    try:
        for name in names:
            if name in text:
                out[name] = _text_codes(pa, texts.column(name))
                continue
            v = out[name]
            bad = np.flatnonzero(np.isinf(v))
            if bad.size:
                raise FingerfitError(
                    f"not a finite number: {float(v[bad[0]])!r}",
                    path=path,
                    line=int(bad[0]) + 1,
                    field=shown(name),
                )
    except FingerfitError:
        raise
    except Exception as exc:  # inconsistent pages of a damaged file
        raise _corrupt(path, exc) from None
    return ParquetTable({c: out[c] for c in names}, _metadata(schema), n_rows, names)


def float_blocks(
    pf, columns: Sequence[str], n_rows: int, batch_rows: int | None = None, ahead: bool = False
):
    """The float64 columns ``columns`` of an open Parquet file, a block of rows at a time.

    Yields ``(first row, [one (m,) float64 array per column])``: a row group at a time, or
    batches of ``batch_rows`` rows (a null read as NaN). The arrays are the decoded
    buffers where Arrow allows (no copy). ``ahead``: the next block is decoded in a
    thread of its own while the caller works on this one (Arrow decodes without the
    GIL, so decoding and NumPy's work share the cores).
    """
    blocks = _float_blocks(pf, columns, n_rows, batch_rows)
    if ahead:
        blocks = _ahead(blocks)
    yield from blocks


def _ahead(items):
    """``items`` produced one ahead in a thread of its own; its exception re-raised here.
    Stopped when the consumer stops (closes this generator)."""
    import queue
    import threading

    box: queue.Queue = queue.Queue(maxsize=1)
    stop = threading.Event()
    done = object()

    def produce() -> None:
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        box.put((item, None), timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            box.put((done, None))
        except BaseException as exc:  # handed to the consumer
            box.put((done, exc))

    worker = threading.Thread(target=produce, name="fingerfit-parquet-ahead", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = box.get()
            if exc is not None:
                raise exc
            if item is done:
                return
            yield item
    finally:
        stop.set()
        while worker.is_alive():
            try:
                box.get(timeout=0.1)
            except queue.Empty:
                pass
        worker.join()


def _float_blocks(pf, columns: Sequence[str], n_rows: int, batch_rows: int | None):
    if not columns:
        return
    lo = 0
    if batch_rows is None:
        parts = (pf.read_row_group(g, columns=list(columns)) for g in range(pf.num_row_groups))
    else:
        parts = pf.iter_batches(batch_size=batch_rows, columns=list(columns), use_threads=True)
    for part in parts:
        m = part.num_rows
        if lo + m > n_rows:
            raise ValueError(f"more rows than the {n_rows} the file states")
        block = []
        for j in range(len(columns)):
            col = part.column(j)
            chunks = col.chunks if hasattr(col, "chunks") else [col]
            if len(chunks) == 1:
                v = chunks[0].to_numpy(zero_copy_only=False)
            else:
                v = np.empty(m)
                at = 0
                for ch in chunks:
                    v[at : at + len(ch)] = ch.to_numpy(zero_copy_only=False)
                    at += len(ch)
            if v.dtype != np.float64:  # pragma: no cover - the schema was checked
                v = v.astype(np.float64)
            block.append(v)
        yield lo, block
        lo += m


def _text_codes(pa, col) -> tuple[np.ndarray, list[str]]:
    """A text column as ``(codes (n,) int32, names)``; nulls become ``""``."""
    if not pa.types.is_dictionary(col.type):
        col = col.dictionary_encode()
    col = col.unify_dictionaries().combine_chunks() if col.num_chunks > 1 else col.combine_chunks()
    names = [("" if s is None else s) for s in col.dictionary.to_pylist()]
    codes = col.indices
    if codes.null_count:
        names.append("")
        codes = codes.fill_null(len(names) - 1)
    return codes.to_numpy(zero_copy_only=False).astype(np.int32, copy=False), names
