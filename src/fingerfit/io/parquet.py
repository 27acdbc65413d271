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

The metadata (:class:`TableMeta`, the format names) are in :mod:`.parquet_meta`, the
reading in :mod:`.parquet_read`; their names are importable from here too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from .parquet_meta import ANGLE_UNITS_KEY as ANGLE_UNITS_KEY
from .parquet_meta import ANGLES as ANGLES
from .parquet_meta import FORMAT_KEY as FORMAT_KEY
from .parquet_meta import FRAME_KEY as FRAME_KEY
from .parquet_meta import JOINTS as JOINTS
from .parquet_meta import POSE as POSE
from .parquet_meta import QUAT_KEY as QUAT_KEY
from .parquet_meta import QUAT_ORDER as QUAT_ORDER
from .parquet_meta import RESIDUALS as RESIDUALS
from .parquet_meta import STUDY_TABLE as STUDY_TABLE
from .parquet_meta import SUFFIX as SUFFIX
from .parquet_meta import TABLE_KEY as TABLE_KEY
from .parquet_meta import TIME_UNITS_KEY as TIME_UNITS_KEY
from .parquet_meta import TRACKER_FRAME as TRACKER_FRAME
from .parquet_meta import UNITS_KEY as UNITS_KEY
from .parquet_meta import WIDE as WIDE
from .parquet_meta import TableMeta, _pa, is_parquet
from .parquet_meta import angles_meta as angles_meta
from .parquet_meta import joints_meta as joints_meta
from .parquet_meta import pose_meta as pose_meta
from .parquet_read import ParquetTable as ParquetTable
from .parquet_read import _ahead, _reason
from .parquet_read import _corrupt as _corrupt
from .parquet_read import _metadata as _metadata
from .parquet_read import _text_codes as _text_codes
from .parquet_read import check_meta as check_meta
from .parquet_read import float_blocks as float_blocks
from .parquet_read import open_checked as open_checked
from .parquet_read import parquet_schema as parquet_schema
from .parquet_read import read_parquet as read_parquet

#: Compression of every Parquet file fingerfit writes, and its level (zstd's fastest
#: ordinary level: most of what zstd gains on float columns split into their bytes).
COMPRESSION = "zstd"
COMPRESSION_LEVEL = 1
#: Rows per row group of :func:`write_parquet` and the recording writers (a few MB to
#: tens of MB of float64 columns; small enough for a file of a few row groups to be
#: made and written at once, block by block).
ROW_GROUP_ROWS = 1 << 18
#: Columns given min/max statistics where a table has them (row groups can be skipped
#: by time in DuckDB, Dask, ``pyarrow.dataset``); no other column has any.
STATISTICS = ("time",)


def writer_options(schema, statistics: Sequence[str] = STATISTICS) -> dict[str, object]:
    """The options of pyarrow's Parquet writer for every file fingerfit writes.

    zstd at :data:`COMPRESSION_LEVEL`; float columns ``BYTE_STREAM_SPLIT``-encoded (each
    number's 8 bytes stored as 8 streams, which zstd compresses better and faster than
    the plain bytes; readers give back the same bits), text columns dictionary-encoded
    and no other (a dictionary of floats that are nearly all different is built and
    thrown away page after page); min/max statistics only for the columns of
    ``statistics`` the schema has. All standard Parquet: pyarrow, pandas, Dask, DuckDB
    and Polars read the files.

    Parameters
    ----------
    schema : pyarrow.Schema
        The file's columns.
    statistics : sequence of str
        Columns to give statistics, where present.

    Returns
    -------
    dict
        Keyword arguments of ``pyarrow.parquet.ParquetWriter`` and ``write_table``.
    """
    pa, _ = _pa()
    text = [
        f.name
        for f in schema
        if pa.types.is_dictionary(f.type)
        or pa.types.is_string(f.type)
        or pa.types.is_large_string(f.type)
    ]
    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    return {
        "compression": COMPRESSION,
        "compression_level": COMPRESSION_LEVEL,
        "use_dictionary": text,
        "column_encoding": dict.fromkeys(floats, "BYTE_STREAM_SPLIT") or None,
        "write_statistics": [c for c in statistics if c in schema.names] or False,
    }


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
    (:func:`writer_options`), each :meth:`write` one or more row groups; :meth:`close` finishes the file
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
    statistics : sequence of str
        Columns given min/max statistics where present (:func:`writer_options`).
    """

    def __init__(
        self,
        path: str | Path,
        meta: TableMeta,
        *,
        schema=None,
        row_group_rows: int = ROW_GROUP_ROWS,
        statistics: Sequence[str] = STATISTICS,
    ) -> None:
        from .atomic import atomic_path

        self.path = Path(path)
        self.meta = meta
        self.rows = 0
        self._schema = schema
        self._statistics = tuple(statistics)
        self._writer = None
        self._group = row_group_rows
        self._ctx = atomic_path(self.path)
        self._tmp = self._ctx.__enter__()
        self._open = True

    def _batches(self, table: object):
        """The rows of ``table`` as Arrow record batches of at most ``row_group_rows``
        rows (one, without rows, for a table without rows), cast to the file's schema
        (that of the first batch when none was given)."""
        pa, _ = _pa()
        columns = _items(table)
        n = _n_rows(columns)
        for lo in range(0, max(n, 1), self._group):
            batch = _batch(pa, columns, lo, min(lo + self._group, n), self._schema)
            if self._schema is None:
                self._schema = batch.schema
            yield batch

    def _write(self, batch) -> None:
        """Write a record batch as a row group (the first one opens the file)."""
        pa, pq = _pa()
        try:
            if self._writer is None:
                schema = self._schema.with_metadata(self.meta.items())
                self._writer = pq.ParquetWriter(
                    str(self._tmp), schema, **writer_options(schema, self._statistics)
                )
            if batch.num_rows:
                self._writer.write_batch(batch, row_group_size=self._group)
        except (OSError, pa.ArrowException) as exc:
            raise FingerfitError(f"cannot write ({_reason(exc)})", path=self.path) from None
        self.rows += batch.num_rows

    def write(self, table: object) -> None:
        """Append rows: a DataFrame or a mapping name -> column (``(m,)`` arrays, or
        ``(codes, names)`` pairs for text), the same columns in the same order each time."""
        for batch in self._batches(table):
            self._write(batch)

    def write_blocks(self, blocks: Iterable[object]) -> None:
        """Append each table of ``blocks`` (as :meth:`write` takes them), the next one
        made and turned into Arrow arrays in a thread of its own while this one is
        encoded, compressed and written (NumPy and Arrow both work without the GIL, so
        the two share the cores). An exception of ``blocks`` is raised here."""
        for batch in _ahead(b for table in blocks for b in self._batches(table)):
            self._write(batch)

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
        row_group_size=ROW_GROUP_ROWS,
        **writer_options(batch.schema),
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
