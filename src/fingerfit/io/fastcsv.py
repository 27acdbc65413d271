"""Vectorised CSV reading in batches and CSV writing, both through Apache Arrow.

Reading (:func:`csv_batches`): the file is read in blocks of whole lines into one reused
buffer, and each block is parsed by ``pyarrow.csv`` into typed columns (floats are
parsed correctly rounded, so the numbers are exactly those Python's ``float`` gives).
The fast path vouches only for plain input: anything unusual -- a parse error, a field
count that differs, a bare carriage return, a NaN or infinity spelled out in a numeric
field, a control character in a text field -- raises :class:`NotPlain`, and the caller
then reads the file with its exact, line-numbered reference parser, which gives the one
error message (or accepts the file the way it always has). So every validation and
message of the reference parser is kept, and valid files never pay for it.

Writing (:func:`write_table`): columns go to ``pyarrow.csv`` in batches of rows; floats
are written in their shortest round-trip form (read back bit for bit), NaN as an empty
field, and the file appears complete or not at all (:func:`fingerfit.io.atomic.atomic_path`).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..errors import FingerfitError
from ..memory import release_freed_memory
from ..transforms import matrix_from_quat_wxyz

#: Bytes of file parsed per batch.
CHUNK_BYTES = 1 << 22
#: Rows written per batch at most.
WRITE_ROWS = 1 << 18
#: Bytes of text per written batch, about (a wide table's batches have fewer rows): the
#: batches in flight, formatted but not yet written, stay a few of these.
WRITE_BYTES = 1 << 22


class NotPlain(Exception):
    """The fast path does not vouch for this input; use the reference parser."""


def _arrow():
    import pyarrow as pa
    import pyarrow.csv as pacsv

    return pa, pacsv


def read_header(path: Path) -> bytes:
    """The first line of ``path`` (without its line end), or a one-line error."""
    try:
        with open(path, "rb") as fh:
            return fh.readline()
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


def csv_batches(
    path: Path,
    names: Sequence[str],
    *,
    text: Sequence[str] = (),
    use: Sequence[str] | None = None,
    chunk_bytes: int | None = None,
) -> Iterator[tuple[int, int, dict]]:
    """Parse a comma-separated file after its header line, in batches of rows.

    Parameters
    ----------
    path : Path
    names : sequence of str
        Every column, in file order; each line must have exactly these fields.
    text : sequence of str
        Columns read as text (dictionary encoded); every other column is float64, an
        empty field giving NaN.
    use : sequence of str, optional
        The columns to convert and return (default all); the others are only counted.
    chunk_bytes : int, optional
        Bytes of file per batch (default :data:`CHUNK_BYTES`).

    Yields
    ------
    first_row : int
        0-based index (among data rows) of the batch's first row; its file line is
        ``first_row + 2``.
    n_bytes : int
        Bytes of file in the batch.
    columns : dict
        Float columns as ``(m,)`` float64 arrays (NaN = empty); a text column as a
        pair ``(codes (m,) int32, values list of str)``.

    Raises
    ------
    NotPlain
        The input is not plain (see the module notes); nothing about it is decided here.
    FingerfitError
        The file cannot be read.
    """
    parse = block_parser(names, text=text, use=use)
    first_row = 0
    chunk = CHUNK_BYTES if chunk_bytes is None else chunk_bytes
    for buf, cut in line_blocks(path, skip_header=True, chunk_bytes=chunk):
        if buf.find(b"\r", 0, cut) >= 0 and buf.count(b"\r", 0, cut) != buf.count(b"\r\n", 0, cut):
            raise NotPlain("carriage return inside a line")
        if buf.startswith(b"\xef\xbb\xbf"):  # Arrow would skip a byte-order mark here
            raise NotPlain("byte-order mark")
        n_rows, cols = parse(memoryview(buf)[:cut])
        # Arrow skips empty lines; the reference parser must judge them. (NumPy counts the
        # line ends 3x faster than bytearray.count.)
        ends = int(np.count_nonzero(np.frombuffer(buf, np.uint8, cut) == 10))
        if n_rows != ends + (buf[cut - 1 : cut] != b"\n"):
            raise NotPlain("empty line")
        yield first_row, cut, cols
        first_row += n_rows
        cols = None
    release_freed_memory()


def line_blocks(
    path: Path, *, skip_header: bool = False, chunk_bytes: int = CHUNK_BYTES
) -> Iterator[tuple[bytearray, int]]:
    """The file in blocks of whole lines (the last may lack its line end), read into one
    reused buffer: yields ``(buffer, n)``, the block being ``buffer[:n]``, valid only
    until the next block is requested.

    Raises
    ------
    FingerfitError
        The file cannot be read.
    """
    buf = bytearray(chunk_bytes)
    view = memoryview(buf)
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    with fh:
        if skip_header:
            fh.readline()
        carry = 0
        while True:
            if carry == len(buf):  # a line longer than the buffer: a larger buffer
                bigger = bytearray(2 * len(buf))
                bigger[:carry] = buf
                buf, view = bigger, memoryview(bigger)
            n = fh.readinto(view[carry:])
            end = carry + n
            cut = end if n == 0 else buf.rfind(b"\n", 0, end) + 1
            if cut == 0:
                if n == 0:
                    return
                carry = end
                continue
            yield buf, cut
            rest = end - cut
            buf[:rest] = buf[cut:end]
            carry = rest
            if n == 0:
                return


def block_parser(
    names: Sequence[str],
    *,
    text: Sequence[str] = (),
    use: Sequence[str] | None = None,
    delimiter: str = ",",
    missing: Sequence[str] = ("",),
) -> Callable[[object], tuple[int, dict]]:
    """A function parsing one block of lines (bytes-like) into ``(n_rows, columns)``.

    Columns as in :func:`csv_batches`; empty lines are skipped; a field spelled as one of
    ``missing`` is NaN; raises :class:`NotPlain` for a parse error, any other NaN or an
    infinity written out in a float column, or a control character in a text column.
    """
    pa, pacsv = _arrow()
    wanted = list(names) if use is None else list(use)
    types = {
        n: (pa.dictionary(pa.int32(), pa.string()) if n in text else pa.float64()) for n in names
    }
    read_opts = pacsv.ReadOptions(column_names=list(names), block_size=1 << 20, use_threads=True)
    parse_opts = pacsv.ParseOptions(delimiter=delimiter, quote_char=False, ignore_empty_lines=True)
    convert_opts = pacsv.ConvertOptions(
        column_types=types,
        include_columns=wanted,
        null_values=list(missing),
        strings_can_be_null=False,
        quoted_strings_can_be_null=False,
    )

    # The C library's allocator: memory of a parsed batch goes back to the system
    # when it is freed (Arrow's default pool keeps it for reuse, raising the peak).
    pool = pa.system_memory_pool()

    def parse(block: object) -> tuple[int, dict]:
        try:
            table = pacsv.read_csv(
                pa.py_buffer(block),
                read_options=read_opts,
                parse_options=parse_opts,
                convert_options=convert_opts,
                memory_pool=pool,
            )
        except (pa.ArrowException, ValueError) as exc:
            raise NotPlain(str(exc)) from None
        cols: dict[str, object] = {}
        for name in wanted:
            col = table.column(name)
            if name in text:
                col = col.unify_dictionaries().combine_chunks()
                values = col.dictionary.to_pylist()
                if any(_has_control(v) for v in values):
                    raise NotPlain("control character in a text field")
                cols[name] = (
                    col.indices.to_numpy(zero_copy_only=False).astype(np.int32),
                    values,
                )
            else:
                v = col.to_numpy()
                if v.dtype != np.float64:
                    v = v.astype(np.float64)
                if np.count_nonzero(~np.isfinite(v)) != col.null_count:
                    raise NotPlain("NaN or infinity written out")
                cols[name] = v
        return table.num_rows, cols

    return parse


def _has_control(s: str) -> bool:
    return any((ord(c) < 32 and c != "\t") or ord(c) == 127 for c in s)


class RowArrays:
    """Growable preallocated float64 storage of ``width`` values per row.

    The capacity is a generous estimate; untouched capacity costs no memory (pages are
    only committed when written).
    """

    def __init__(self, capacity: int, width: int) -> None:
        self.data = np.empty((max(capacity, 16), width))
        self.n = 0

    def reserve(self, extra: int) -> np.ndarray:
        """Room for ``extra`` more rows; returns the ``(extra, width)`` block to fill."""
        need = self.n + extra
        if need > self.data.shape[0]:
            grown = np.empty((max(need, int(self.data.shape[0] * 1.5)), self.data.shape[1]))
            grown[: self.n] = self.data[: self.n]
            self.data = grown
        block = self.data[self.n : need]
        self.n = need
        return block

    def array(self) -> np.ndarray:
        """The filled rows, ``(n, width)`` (a view)."""
        return self.data[: self.n]


def run_start(at: np.ndarray) -> int | None:
    """The first of ``at``'s rows when they are a run of consecutive rows, else None."""
    if at.size and at[-1] - at[0] == at.size - 1 and (at.size < 2 or (np.diff(at) == 1).all()):
        return int(at[0])
    return None


def put_rows(out: np.ndarray, at: np.ndarray, values: np.ndarray) -> None:
    """``out[at] = values``, as a slice copy when ``at`` is a run of consecutive rows.

    Parameters
    ----------
    out : ndarray, shape (n, ...)
    at : ndarray of int, shape (m,)
        Target rows.
    values : ndarray, shape (m, ...)
    """
    first = run_start(at)
    if first is not None:
        out[first : first + at.size] = values
    else:
        out[at] = values


def put_scaled_rows(out: np.ndarray, at: np.ndarray, values: np.ndarray, scale: float) -> None:
    """``out[at] = values * scale`` (positions to mm), without a temporary for a run.

    Parameters
    ----------
    out : ndarray, shape (n, 3)
        Positions (mm).
    at : ndarray of int, shape (m,)
        Target rows.
    values : ndarray, shape (m, 3)
        Positions in the file's units (any strides; float32 is taken as float64 first).
    scale : float
        Millimetres per file unit.
    """
    values = np.asarray(values, dtype=np.float64)
    first = run_start(at)
    if first is not None:
        np.multiply(values, scale, out=out[first : first + at.size])
    else:
        out[at] = values * scale


def put_quat_rows(out: np.ndarray, at: np.ndarray, quat: np.ndarray) -> None:
    """``out[at]`` = the rotation matrices of quaternions ``(w, x, y, z)``.

    Written in place for a run of rows (no ``(m, 3, 3)`` temporary); the same bits as
    :func:`~fingerfit.transforms.matrix_from_quat_wxyz`.

    Parameters
    ----------
    out : ndarray, shape (n, 3, 3)
        Rotations (sensor -> tracker).
    at : ndarray of int, shape (m,)
        Target rows.
    quat : ndarray, shape (m, 4)
        Scalar-first quaternions (any strides).
    """
    first = run_start(at)
    if first is not None:
        matrix_from_quat_wxyz(quat, out=out[first : first + at.size])
    else:
        out[at] = matrix_from_quat_wxyz(quat)


def rows_where(codes: np.ndarray, k: int) -> slice | np.ndarray:
    """The positions of ``k`` in ``codes (n,)``: a slice when they are evenly spaced (rows
    of sensors taking turns), else an index array. Either selects the same rows."""
    idx = np.flatnonzero(codes == k)
    if idx.size == 1:
        return slice(int(idx[0]), int(idx[0]) + 1)
    if idx.size > 1:
        step = int(idx[1] - idx[0])
        if idx[-1] - idx[0] == step * (idx.size - 1) and (np.diff(idx) == step).all():
            return slice(int(idx[0]), int(idx[-1]) + 1, step)
    return idx


def row_blocks(rows: slice | np.ndarray, size: int) -> Iterator[slice | np.ndarray]:
    """``rows`` (a slice with a step, or an index array) in pieces of ``size`` rows."""
    if isinstance(rows, slice):
        start, step = rows.start or 0, rows.step or 1
        count = len(range(start, rows.stop, step))
        for lo in range(0, count, size):
            hi = min(lo + size, count)
            yield slice(start + lo * step, start + (hi - 1) * step + 1, step)
    else:
        for lo in range(0, rows.size, size):
            yield rows[lo : lo + size]


def gap_rows(n: int, filled: Sequence[np.ndarray]) -> np.ndarray | None:
    """Rows of ``range(n)`` in none of the index arrays ``filled`` (None when there are none)."""
    mask = np.ones(n, dtype=bool)
    for f in filled:
        mask[f] = False
    rows = np.flatnonzero(mask)
    return rows if rows.size else None


def estimate_rows(path: Path, sample_rows: int, sample_bytes: int) -> int:
    """An upper estimate of the data rows of ``path`` from a first batch's size."""
    size = Path(path).stat().st_size
    if sample_rows == 0 or sample_bytes == 0:
        return 16
    return int(size / (sample_bytes / sample_rows) * 1.25) + 1024


def write_table(
    path: str | Path,
    table: object,
    *,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Write a table as CSV, atomically, floats in shortest round-trip form.

    Parameters
    ----------
    path : str or Path
        The file; it appears complete or not at all.
    table : pandas.DataFrame or mapping of str to ndarray
        Columns in order, each ``(n,)``: float (NaN is written as an empty field),
        integer, or text (object or string arrays, or a pair ``(codes, values)`` of
        int codes into a list of strings; text must not hold a comma, quote or line end).
    progress : callable, optional
        Called with the number of rows after each batch is written.

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        When the file cannot be written, or a text value needs quoting.
    """
    from .atomic import atomic_path

    pa, pacsv = _arrow()
    path = Path(path)
    columns: dict[str, np.ndarray] = {}
    text = {}
    items = table.items() if isinstance(table, Mapping) else ((k, table[k]) for k in table.columns)
    for key, v in items:
        name = str(key)
        if isinstance(v, tuple):  # (codes, values)
            codes, values = v
            text[name] = (np.asarray(codes, dtype=np.int32), pa.array(list(values), pa.string()))
            columns[name] = text[name][0]
            continue
        v = v.to_numpy() if hasattr(v, "to_numpy") else np.asarray(v)
        columns[name] = v
        if v.dtype.kind in "OUS":
            values, codes = np.unique(v.astype(str), return_inverse=True)
            text[name] = (codes.astype(np.int32), pa.array(values.tolist(), pa.string()))
    n = len(next(iter(columns.values()))) if columns else 0

    def batch(lo: int, hi: int):
        arrays = []
        for name, v in columns.items():
            if name in text:
                codes, values = text[name]
                arrays.append(pa.DictionaryArray.from_arrays(codes[lo:hi], values))
            elif v.dtype.kind == "f":
                arrays.append(pa.array(v[lo:hi], from_pandas=True))
            else:
                arrays.append(pa.array(v[lo:hi]))
        return pa.RecordBatch.from_arrays(arrays, names=list(columns))

    opts = pacsv.WriteOptions(quoting_style="none", quoting_header="none")
    rows_only = pacsv.WriteOptions(
        include_header=False, quoting_style="none", quoting_header="none"
    )

    def formatted(lo: int, hi: int) -> tuple[int, object]:
        # Arrow formats without the interpreter lock: batches format in parallel
        sink = pa.BufferOutputStream()
        pacsv.write_csv(batch(lo, hi), sink, write_options=rows_only)
        return hi - lo, sink.getvalue()

    with atomic_path(path) as tmp:
        try:
            with open(tmp, "wb") as fh, ThreadPoolExecutor(_WRITE_THREADS) as pool:
                header = pa.BufferOutputStream()
                pacsv.write_csv(batch(0, 0), header, write_options=opts)
                fh.write(header.getvalue())
                pending: deque = deque()
                # about 24 bytes of text per number
                step = min(WRITE_ROWS, max(1024, WRITE_BYTES // (24 * max(1, len(columns)))))
                for lo in range(0, n, step):
                    pending.append(pool.submit(formatted, lo, min(lo + step, n)))
                    if len(pending) > _WRITE_THREADS:  # at most one batch waiting
                        _write_next(fh, pending, progress)
                while pending:
                    _write_next(fh, pending, progress)
        except pa.ArrowInvalid as exc:
            raise FingerfitError(f"cannot write as CSV: {exc}", path=path) from None
    return path


#: Threads formatting batches of :func:`write_table` (written in order, one at a time).
_WRITE_THREADS = max(1, min(4, os.cpu_count() or 1))


def _write_next(fh, pending: deque, progress: Callable[[int], None] | None) -> None:
    """Write the oldest formatted batch (waiting for it) and report its rows."""
    rows, data = pending.popleft().result()
    fh.write(data)
    if progress is not None:
        progress(rows)
