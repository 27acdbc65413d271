"""Parquet tables read and checked before they are trusted: a readable Parquet file at
all (a truncated or corrupted file is one line, never a traceback), metadata naming the
expected format, exactly the format's columns, each of the right type, and no infinity in
a float column; the columns come back as plain NumPy arrays. Every refusal is a one-line
:class:`~fingerfit.errors.FingerfitError` naming the file and the column (or metadata
key); a row is named by its 1-based index (``docs/errors.md``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from .parquet_meta import FORMAT_KEY, _pa

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
            # float columns straight into their final arrays, no whole Arrow table beside
            # them. One row group: its decoded columns are the arrays, no copy at all.
            # Several: a few columns of a row group at a time (Arrow decodes the whole
            # row group of the columns asked for, so the memory beside the arrays is a
            # few column chunks, not a row group of every column).
            # Each block is checked for infinities as it is placed (in cache), while
            # the next one is decoded in a thread of its own.
            out: dict[str, object] = {}
            if pf.num_row_groups == 1:
                for _, block in float_blocks(pf, floats, n_rows):
                    for c, v in zip(floats, block, strict=True):
                        refuse_infinite(v, c, path)
                        out[c] = v
                if floats and out[floats[0]].size != n_rows:
                    raise ValueError(f"{out[floats[0]].size} rows read of {n_rows}")
            else:
                groups = [
                    floats[i : i + _READ_COLUMNS] for i in range(0, len(floats), _READ_COLUMNS)
                ]
                for c in floats:
                    out[c] = np.empty(n_rows)
                filled = dict.fromkeys(range(len(groups)), 0)
                for (gi, few), (lo, block) in _column_groups(pf, groups, n_rows):
                    for c, v in zip(few, block, strict=True):
                        refuse_infinite(v, c, path, first=lo)
                        out[c][lo : lo + v.size] = v
                    filled[gi] = lo + block[0].size
                if any(f != n_rows for f in filled.values()):
                    raise ValueError(f"{min(filled.values())} rows read of {n_rows}")
            texts = pf.read(columns=[c for c in names if c in text], use_threads=True)
        except FingerfitError:
            raise
        except Exception as exc:  # a damaged data page
            raise _corrupt(path, exc) from None
    try:
        for name in names:
            if name in text:
                out[name] = _text_codes(pa, texts.column(name))
    except Exception as exc:  # inconsistent pages of a damaged file
        raise _corrupt(path, exc) from None
    return ParquetTable({c: out[c] for c in names}, _metadata(schema), n_rows, names)


#: Float columns of a file of several row groups decoded at a time by :func:`read_parquet`.
_READ_COLUMNS = 4


def _column_groups(pf, groups: list[list[str]], n_rows: int):
    """:func:`float_blocks` of each group of columns in turn, decoded one block ahead:
    yields ``((group index, columns), (first row, arrays))``."""

    def blocks():
        for gi, few in enumerate(groups):
            for item in _float_blocks(pf, few, n_rows, None):
                yield (gi, few), item

    return _ahead(blocks())


def float_blocks(
    pf, columns: Sequence[str], n_rows: int, batch_rows: int | None = None, ahead: bool = False
):
    """The float64 columns ``columns`` of an open Parquet file, a block of rows at a time.

    Yields ``(first row, [one (m,) float64 array per column])``: a row group at a time, or
    batches of at most ``batch_rows`` rows, none across row groups (a null read as NaN). The arrays are the decoded
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
        # a reader per row group: one reader over the whole file holds on to memory
        # growing with the bytes read (about the file's size for BYTE_STREAM_SPLIT or
        # plain columns) until it is done
        parts = (
            batch
            for g in range(pf.num_row_groups)
            for batch in pf.iter_batches(
                batch_size=batch_rows, row_groups=[g], columns=list(columns), use_threads=True
            )
        )
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


def refuse_infinite(values: np.ndarray, column: str, path: Path, first: int = 0) -> None:
    """Refuse a float column ``(n,)`` with an infinity: one line naming the file, the
    column and the 1-based row (NaN is a missing value, not an error). ``first``: the
    0-based row of ``values[0]`` in the file (a block of the column)."""
    # A finite sum has no infinity (nor NaN) in it: one reduction for the common case.
    # An infinity makes it infinite or NaN (inf - inf), and so may NaN or an overflow:
    # then the values are looked at one by one.
    with np.errstate(over="ignore", invalid="ignore"):
        total = values.sum()
    if np.isfinite(total) or not np.isinf(values).any():
        return
    bad = np.flatnonzero(np.isinf(values))
    raise FingerfitError(
        f"not a finite number: {float(values[bad[0]])!r}",
        path=path,
        line=int(bad[0]) + first + 1,
        field=shown(column),
    )
