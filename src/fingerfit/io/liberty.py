"""Polhemus Liberty / Patriot output: ASCII and binary streams -> :class:`Recording`.

**ASCII** (as captured from the device or saved by its host software): one CR/LF
line per station, whitespace-separated: the station number (one or two digits,
optionally followed by one indicator character, e.g. ``01`` or ``01D``), then the
items of the output list in order. Numbers glued together by a sign (fixed-width
fields overflowing, ``12.345-6.789``) are split.

**Binary**: records of an 8-byte header -- ``'LY'`` (Liberty) or ``'PA'`` (Patriot),
station byte, command byte, error byte, reserved byte, little-endian ``uint16`` body
size -- then the items as little-endian ``float32`` (timestamp and frame count as
``uint32``). The space and CR/LF items carry no data in binary records.

Output-list items (device codes of the ``O`` command): ``2``/``3`` position x, y, z;
``4``/``5`` Euler angles azimuth, elevation, roll in degrees, ``R = Rz(az) Ry(el)
Rx(roll)``; ``7`` quaternion **w, x, y, z**; ``8`` timestamp (ms); ``9`` frame count;
``0`` space and ``1`` CR/LF (ignored). The device default list is ``2,4,1`` and the
default units inches.

Frames: by the frame-count item when present; otherwise by station cycle (a record
whose station number is not above the previous one starts a new frame). Time: from
the timestamp item, else frame count / rate, else cycle index / rate. With a rate,
frames are placed on the ``1/rate`` grid and missing frames appear as NaN rows.
Returned positions are millimetres in tracker coordinates and rotation matrices map
sensor into tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

import csv
import io
import os
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError, shown
from ..memory import release_freed_memory
from ..session import UNITS_TO_MM, PoseSeries, Recording
from ..transforms import row_norms
from .atomic import atomic_write
from .fastcsv import (
    gap_rows,
    put_quat_rows,
    put_rows,
    put_scaled_rows,
    row_blocks,
    rows_where,
)
from .hygiene import (
    check_grid_size,
    check_recording,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
    repeated_rows,
)

#: Number of values of each data item.
ITEM_SIZE = {"position": 3, "euler": 3, "quaternion": 4, "timestamp": 1, "frame": 1}
#: Device item codes (``O`` command) and accepted names -> item; None = no data.
ITEM_ALIASES: dict[str, str | None] = {
    "0": None,
    "1": None,
    "2": "position",
    "3": "position",
    "4": "euler",
    "5": "euler",
    "7": "quaternion",
    "8": "timestamp",
    "9": "frame",
    "space": None,
    "crlf": None,
    "pos": "position",
    "position": "position",
    "euler": "euler",
    "quat": "quaternion",
    "quaternion": "quaternion",
    "time": "timestamp",
    "timestamp": "timestamp",
    "frame": "frame",
    "framecount": "frame",
}
#: The device's default output list ``O*,2,4,1``.
DEFAULT_ITEMS = ("position", "euler")
#: Decimals the ASCII writer uses per item (the device's standard precision).
ASCII_DECIMALS = {"position": 3, "euler": 3, "quaternion": 4}
MAX_STATION = 16
#: Largest Euler angle magnitude accepted (deg); the device reports within +-180.
MAX_EULER_DEG = 360.0
QUAT_NORM_TOLERANCE = 1e-3
_INT_ITEMS = ("timestamp", "frame")
#: Records converted to rotation matrices at a time (bounds the temporary memory).
_BLOCK = 1 << 16
_MAGIC = (b"LY", b"PA")


def parse_items(spec: str | Sequence[str] | None) -> tuple[str, ...]:
    """The data items of an output list.

    Parameters
    ----------
    spec : str or sequence of str or None
        Device codes or names, comma-separated (``"2,4,1"``, ``"pos,quat,time"``);
        ``None`` gives the device default (position, Euler angles).

    Returns
    -------
    tuple of str
        Item names in stream order, from ``position``, ``euler``, ``quaternion``,
        ``timestamp``, ``frame`` (space and CR/LF dropped).

    Raises
    ------
    FingerfitError
        ``field 'items'``: unknown or repeated item, or no position or orientation.
    """
    if spec is None:
        return DEFAULT_ITEMS
    parts = spec.split(",") if isinstance(spec, str) else list(spec)
    out: list[str] = []
    for raw in parts:
        key = str(raw).strip().lower()
        if key == "6":
            raise FingerfitError(
                "item 6 (direction cosines) is not supported; use 7 (quaternion) or 4 (Euler)",
                field="items",
            )
        if key not in ITEM_ALIASES:
            raise FingerfitError(
                f"unknown output item '{raw}' (use codes 0-5, 7-9 or names "
                "pos, euler, quat, time, frame)",
                field="items",
            )
        item = ITEM_ALIASES[key]
        if item is None:
            continue
        if item in out:
            raise FingerfitError(f"item '{item}' listed twice", field="items")
        out.append(item)
    if "position" not in out or not ({"euler", "quaternion"} & set(out)):
        raise FingerfitError(
            "the output list needs a position (2) and an orientation (4 or 7) item",
            field="items",
        )
    return tuple(out)


@dataclass
class LibertyRecords:
    """Raw station records of a Liberty/Patriot stream, in file order.

    Attributes
    ----------
    items : tuple of str
        Data items in stream order (see :func:`parse_items`).
    station : ndarray of int (int16 from the readers), shape (n_records,)
        Station numbers 1-16.
    values : dict[str, ndarray]
        Per item, in device units: ``position`` ``(n, 3)`` (file units),
        ``euler`` ``(n, 3)`` degrees (azimuth, elevation, roll), ``quaternion``
        ``(n, 4)`` scalar first ``(w, x, y, z)``, ``timestamp`` ``(n,)`` ms and
        ``frame`` ``(n,)`` counts (integer valued floats). float64, except position,
        Euler angles and quaternion from a binary stream: float32 as sent (exact; use
        them as float64, e.g. ``np.asarray(v, dtype=float)``, before any arithmetic).
    indicator : ndarray of str, shape (n_records,)
        Indicator character after the station number (ASCII) or the error byte
        (binary) as a character; ``""`` when none.
    where : ndarray of int, shape (n_records,)
        1-based file line (ASCII) or record number (binary) of each record.
    binary : bool
        Whether ``where`` counts binary records.
    record_size : int
        Bytes per binary record (0 for ASCII).
    """

    items: tuple[str, ...]
    station: np.ndarray
    values: dict[str, np.ndarray]
    indicator: np.ndarray
    where: np.ndarray
    binary: bool = False
    record_size: int = 0
    family: str = field(default="LY")

    @property
    def n_records(self) -> int:
        return int(self.station.shape[0])

    def matrix(self) -> np.ndarray:
        """All item values side by side, ``(n_records, n_values)`` float."""
        cols = [self.values[i].reshape(self.n_records, -1) for i in self.items]
        return np.concatenate(cols, axis=1).astype(float)

    def error(
        self, message: str, i: int | None, path: str | Path, field: str | None = None
    ) -> FingerfitError:
        """A one-line error about record ``i`` (file line or binary record)."""
        if i is None:
            return FingerfitError(message, path=path, field=field)
        if self.binary:
            k = int(self.where[i])
            where = f"record {k} (byte {(k - 1) * self.record_size}): "
            if field is not None:
                where += f"field '{field}': "
            return FingerfitError(where + message, path=path)
        return FingerfitError(message, path=path, line=int(self.where[i]), field=field)

    def check_increasing(
        self, values: np.ndarray, index: np.ndarray, path: str | Path, what: str, strict: bool
    ) -> None:
        """Raise at the first record (of ``index``) where ``values`` decrease (or repeat)."""
        d = np.diff(values)
        bad = np.flatnonzero(d <= 0 if strict else d < 0)
        if bad.size:
            j = int(bad[0]) + 1
            verb = "goes backwards" if d[j - 1] < 0 else "does not increase"
            raise self.error(
                f"{what} {verb} ({values[j]:.15g} after {values[j - 1]:.15g})",
                int(index[j]),
                path,
                field=what,
            )


# ----------------------------------------------------------------------------- ASCII


def _read_bytes(path: str | Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


#: Bytes of binary records converted per block.
_BINARY_BLOCK_BYTES = 1 << 20


@contextmanager
def _binary_source(
    path: str | Path, data: bytes | None
) -> Iterator[tuple[int, Callable[[np.ndarray, int], np.ndarray]]]:
    """The size of a file (or of ``data``) and a function that fills a uint8 buffer
    from a byte offset and returns it (a view of ``data`` when given)."""
    if data is not None:
        whole = np.frombuffer(data, dtype=np.uint8)

        def from_data(buf: np.ndarray, offset: int) -> np.ndarray:
            return whole[offset : offset + buf.size]

        yield whole.size, from_data
        return
    try:
        fh = open(path, "rb")  # closed by the with below
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    with fh:
        size = os.fstat(fh.fileno()).st_size

        def from_file(buf: np.ndarray, offset: int) -> np.ndarray:
            try:
                fh.seek(offset)
                got = fh.readinto(memoryview(buf))
            except OSError as exc:
                raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
            if got != buf.size:
                raise FingerfitError(
                    f"cannot read: the file changed while it was read (byte {offset + got})",
                    path=path,
                )
            return buf

        yield size, from_file


def _line_of(b: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """0-based line of each byte position (number of newlines before it)."""
    return np.searchsorted(np.flatnonzero(b == ord("\n")), positions)


def parse_liberty_ascii(
    path: str | Path, items: str | Sequence[str] | None = None, *, data: bytes | None = None
) -> LibertyRecords:
    """Parse a Liberty/Patriot ASCII stream into raw records.

    Parameters
    ----------
    path : str or Path
        The file (also used in messages).
    items : str or sequence, optional
        Output list (see :func:`parse_items`); default position + Euler angles.
    data : bytes, optional
        The file's content, if already in memory.

    Returns
    -------
    LibertyRecords
        Values in device units (positions in the file's units).

    Raises
    ------
    FingerfitError
        Naming the file and line: non-text bytes, a line with the wrong number of
        fields (truncated or garbled record), a non-numeric value, a bad station.
    """
    items_t = parse_items(items)
    if data is None:
        from .fastcsv import NotPlain

        try:
            recs = _parse_ascii_fast(Path(path), items_t)
        except NotPlain:
            pass
        else:
            _check_records(recs, path)
            return recs
    raw = _read_bytes(path) if data is None else data
    b = np.frombuffer(raw, dtype=np.uint8)
    ws = (b == 9) | (b == 10) | (b == 13)
    bad = np.flatnonzero(((b < 32) & ~ws) | (b > 126))
    if bad.size:
        line = int(_line_of(b, bad[:1])[0]) + 1
        raise FingerfitError(
            f"garbled record: byte 0x{int(b[bad[0]]):02x} is not ASCII text "
            "(binary output? use the liberty-binary format)",
            path=path,
            line=line,
        )
    # Split numbers glued by a sign: "12.345-6.789" -> "12.345 -6.789".
    text = re.sub(rb"(\.\d+)(?=[+-])", rb"\1 ", raw)
    b = np.frombuffer(text, dtype=np.uint8)
    expected = 1 + sum(ITEM_SIZE[i] for i in items_t)
    sep = (b == 32) | (b == 10) | (b == 13) | (b == 9)
    token_starts = np.flatnonzero(~sep & np.concatenate([[True], sep[:-1]]))
    n_lines = int((b == ord("\n")).sum()) + (1 if b.size and b[-1] != ord("\n") else 0)
    counts = np.bincount(_line_of(b, token_starts), minlength=n_lines)
    used = counts > 0
    wrong = np.flatnonzero(used & (counts != expected))
    if wrong.size:
        i = int(wrong[0])
        raise FingerfitError(
            f"expected {expected} fields (station + {', '.join(items_t)}), found "
            f"{counts[i]}: truncated or garbled record (or wrong --items)",
            path=path,
            line=i + 1,
        )
    lines = np.flatnonzero(used) + 1
    if lines.size == 0:
        raise FingerfitError("no records", path=path)
    table = pd.read_csv(
        io.BytesIO(text),
        sep=r"\s+",
        header=None,
        dtype={0: str},
        engine="c",
        skip_blank_lines=True,
        keep_default_na=False,
        na_values=[],
        quoting=csv.QUOTE_NONE,
    )
    # Station tokens: few distinct values, so parse each distinct token once.
    tokens, inverse = np.unique(table[0].to_numpy(dtype=str), return_inverse=True)
    parsed = [re.fullmatch(r"(\d{1,2})([^\d\s]?)", t) for t in tokens.tolist()]
    bad_tok = [k for k, m in enumerate(parsed) if m is None]
    if bad_tok:
        i = int(np.flatnonzero(np.isin(inverse, bad_tok))[0])
        raise FingerfitError(
            f"'{shown(table.iat[i, 0])}' is not a station number (1-2 digits and an optional "
            "indicator character)",
            path=path,
            line=int(lines[i]),
            field="station",
        )
    station = np.array([int(m.group(1)) for m in parsed], dtype=np.int16)[inverse]
    indicator = np.array([m.group(2) for m in parsed], dtype=str)[inverse]
    nums = np.empty((lines.size, expected - 1))
    raw_text: dict[int, pd.Series] = {}
    for j in range(1, expected):
        col = table[j]
        if col.dtype.kind not in "fi":  # something in it is not a number
            raw_text[j] = col.astype(str)
            col = pd.to_numeric(col, errors="coerce")
        nums[:, j - 1] = col.to_numpy(dtype=float)
    bad = ~np.isfinite(nums)
    if bad.any():
        i, j = (int(v[0]) for v in np.nonzero(bad))
        token = raw_text[j + 1].iat[i] if j + 1 in raw_text else table.iat[i, j + 1]
        raise FingerfitError(
            f"not a finite number: '{shown(token)}' (garbled record)",
            path=path,
            line=int(lines[i]),
            field=_field_name(items_t, j),
        )
    recs = LibertyRecords(items_t, station, _split_values(nums, items_t), indicator, lines)
    _check_records(recs, path)
    return recs


#: Bytes of an ASCII stream converted per batch (the conversion's temporaries are a few
#: times this).
_ASCII_CHUNK = 1 << 22
_STATION_TOKEN = re.compile(r"(\d{1,2})([^\d\s]?)")


def _ascii_to_csv(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One block of whitespace-separated lines as comma-separated lines.

    Parameters
    ----------
    b : ndarray of uint8, shape (n_bytes,)
        Whole lines of printable ASCII (checked by the caller).

    Returns
    -------
    csv : ndarray of uint8
        Tokens joined by single commas, one line per input line (blank lines empty).
    record_lines : ndarray of int
        0-based line (within the block) of each non-blank line, in order.
    """
    n = b.size
    nl = b == 10
    tok = ~((b == 32) | (b == 9) | (b == 13) | nl)
    # token starts and newlines in order: a token right after a newline (or first of
    # the block) begins its line, any other token gets a comma before it
    edge = np.empty(n, dtype=bool)
    edge[:1] = tok[:1]
    np.greater(tok[1:], tok[:-1], out=edge[1:])  # token starts
    events = np.flatnonzero(edge | nl)
    np.less(tok[1:], tok[:-1], out=edge[1:])  # token ends (exclusive)
    edge[:1] = False
    ends = np.flatnonzero(edge)
    if n and tok[-1]:
        ends = np.append(ends, n)
    del edge
    is_nl = nl[events]
    after_nl = np.concatenate([[True], is_nl[:-1]])
    starts = events[~is_nl]
    first = after_nl[~is_nl]
    nl_at = events[is_nl]
    del events, is_nl, after_nl
    # A token that is not first on its line follows a run of blanks: the run's first
    # byte (the end of the token before) becomes the comma, the other blanks go.
    keep = tok | nl
    comma = ends[np.flatnonzero(~first[1:])]  # token t (t >= 1) not first: end of t - 1
    keep[comma] = True
    b = b.copy()
    b[comma] = 44
    out = b[keep]
    del keep, comma
    heads = starts[first]
    if heads.size == nl_at.size + (1 if n and b[-1] != 10 else 0):
        return out, np.arange(heads.size)  # no blank line
    return out, np.searchsorted(nl_at, heads)


def _ascii_to_csv_quick(b: np.ndarray, n_lines: int) -> tuple[np.ndarray, bool] | None:
    """:func:`_ascii_to_csv` for blocks whose lines all end alike, without locating tokens.

    The first blank after every token becomes a comma and the other blanks go. When every
    line ends in blanks (a CR/LF stream: the CR is a blank) each line gets one empty
    last field (``trailing``); when none does, the text is that of :func:`_ascii_to_csv`.

    Parameters
    ----------
    b : ndarray of uint8, shape (n_bytes,)
        Whole lines of printable ASCII.
    n_lines : int
        Lines in the block.

    Returns
    -------
    (csv, trailing) or None
        None when some lines end in blanks and others do not (then use
        :func:`_ascii_to_csv`). Blank lines come out empty, as there.
    """
    nl = b == 10
    blank = (b == 32) | (b == 9) | (b == 13)
    tok = ~(blank | nl)
    sep = np.empty(b.size, dtype=bool)
    sep[:1] = False
    np.logical_and(blank[1:], tok[:-1], out=sep[1:])  # the first blank after a token
    # tokens ending at a line end (the others end at a blank): one per line, or none
    n_last = int(np.count_nonzero(tok[:-1] & nl[1:])) + int(b.size > 0 and bool(tok[-1]))
    if n_last == 0:
        trailing = True
    elif n_last == n_lines:
        trailing = False
    else:
        return None
    keep = tok | nl | sep
    out = np.where(sep, np.uint8(44), b)[keep]
    return out, trailing


def _parse_ascii_fast(path: Path, items: tuple[str, ...]) -> LibertyRecords:
    """Whole ASCII streams of plain records, in batches into preallocated arrays.

    Raises :class:`~fingerfit.io.fastcsv.NotPlain` for anything :func:`parse_liberty_ascii`
    must judge line by line: a byte that is not printable ASCII, a field count that
    differs, a token that is not a number or station, or no records at all.
    """
    from .fastcsv import (
        NotPlain,
        RowArrays,
        block_parser,
        estimate_rows,
        line_blocks,
    )

    width = sum(ITEM_SIZE[i] for i in items)
    names = [f"c{j}" for j in range(width + 1)]
    parse = block_parser(names, text=("c0",))
    parse_end = block_parser([*names, "end"], text=("c0",))  # lines ending in blanks
    rows: RowArrays | None = None
    station = np.empty(0, dtype=np.int16)  # 1-2 digits
    indicator = np.empty(0, dtype="<U1")
    where = np.empty(0, dtype=np.int32)  # file lines (below 2**31, else NotPlain)
    line0 = 0
    glued = re.compile(rb"(\.\d+)(?=[+-])")
    for buf, cut in line_blocks(path, chunk_bytes=_ASCII_CHUNK):
        b = np.frombuffer(buf, dtype=np.uint8, count=cut)
        if np.any(((b < 32) & (b != 9) & (b != 10) & (b != 13)) | (b > 126)):
            raise NotPlain("not printable ASCII")
        sign = (b[1:] == 43) | (b[1:] == 45)
        if np.any(sign & (b[:-1] >= 48) & (b[:-1] <= 57)):  # numbers glued by a sign
            b = np.frombuffer(glued.sub(rb"\1 ", bytes(b)), dtype=np.uint8)
        n_lines = int(np.count_nonzero(b == 10)) + (1 if b.size and b[-1] != 10 else 0)
        if line0 + n_lines >= 2**31:
            raise NotPlain("line numbers beyond int32")
        quick = _ascii_to_csv_quick(b, n_lines)
        rec_line = None  # every line a record
        if quick is not None:
            text, trailing = quick
            n, cols = (parse_end if trailing else parse)(memoryview(text))
            if trailing and n and not np.isnan(cols["end"]).all():
                raise NotPlain("field count")
            if n != n_lines:  # blank lines: find the records' lines
                quick = None
        if quick is None:
            text, rec_line = _ascii_to_csv(b)
            n, cols = parse(memoryview(text))
            if n != rec_line.size:
                raise NotPlain("field count")
        del b
        if rows is None:
            cap = estimate_rows(path, n, cut)
            rows = RowArrays(cap, width)
            station = np.empty(cap, dtype=np.int16)
            indicator = np.empty(cap, dtype="<U1")
            where = np.empty(cap, dtype=np.int32)
        at = rows.n
        block = rows.reserve(n)
        for j in range(width):
            block[:, j] = cols[f"c{j + 1}"]
        if station.size < rows.n:
            station = np.resize(station, rows.data.shape[0])
            indicator = np.resize(indicator, rows.data.shape[0])
            where = np.resize(where, rows.data.shape[0])
        codes, tokens = cols["c0"]
        parsed = [_STATION_TOKEN.fullmatch(t) for t in tokens]
        if any(m is None for m in parsed):
            raise NotPlain("station token")
        station[at : at + n] = np.array([int(m.group(1)) for m in parsed], dtype=np.int16)[codes]
        indicator[at : at + n] = np.array([m.group(2) for m in parsed], dtype="<U1")[codes]
        if rec_line is None:
            where[at : at + n] = np.arange(line0 + 1, line0 + 1 + n)
        else:
            where[at : at + n] = line0 + rec_line + 1
        line0 += n_lines
    if rows is None or rows.n == 0:
        raise NotPlain("no records")
    del cols, text, codes, tokens, parsed
    release_freed_memory()
    n = rows.n
    nums = rows.array()
    values, k = {}, 0
    for item in items:  # views into one array (no copy)
        size = ITEM_SIZE[item]
        values[item] = nums[:, k] if size == 1 else nums[:, k : k + size]
        k += size
    return LibertyRecords(items, station[:n], values, indicator[:n], where[:n])


def _field_name(items: Sequence[str], column: int) -> str:
    k = 0
    for item in items:
        if column < k + ITEM_SIZE[item]:
            return item if ITEM_SIZE[item] == 1 else f"{item}[{column - k}]"
        k += ITEM_SIZE[item]
    return "?"


def _split_values(nums: np.ndarray, items: Sequence[str]) -> dict[str, np.ndarray]:
    out, k = {}, 0
    for item in items:
        size = ITEM_SIZE[item]
        v = nums[:, k : k + size]
        out[item] = v[:, 0].copy() if size == 1 else v.copy()
        k += size
    return out


def _check_records(recs: LibertyRecords, path: str | Path) -> None:
    bad = np.flatnonzero((recs.station < 1) | (recs.station > MAX_STATION))
    if bad.size:
        i = int(bad[0])
        raise recs.error(
            f"unknown station {recs.station[i]} (stations are 1-{MAX_STATION})", i, path
        )
    for item in _INT_ITEMS:
        if item in recs.values:
            v = recs.values[item]
            bad = np.flatnonzero((v != np.floor(v)) | (v < 0))
            if bad.size:
                i = int(bad[0])
                raise recs.error(f"{item} must be a whole number >= 0, not {v[i]:g}", i, path)


def format_liberty_ascii(records: LibertyRecords, decimals: Mapping[str, int] | None = None) -> str:
    """Format records as a Liberty ASCII stream (CR/LF lines).

    Parameters
    ----------
    records : LibertyRecords
        Values in device units; quaternions ``(w, x, y, z)``.
    decimals : mapping, optional
        Decimals per item; default :data:`ASCII_DECIMALS` (position and Euler 3,
        quaternion 4). Timestamp and frame count are written as integers.

    Returns
    -------
    str
        ``"01 " + fields + "\\r\\n"`` per record; every field preceded by a space.
    """
    dec = dict(ASCII_DECIMALS)
    dec.update(decimals or {})
    n = records.n_records
    ind = np.where(records.indicator == "", " ", records.indicator).astype(str)
    cols = [np.char.add(np.char.mod("%02d", records.station), ind)]
    for item in records.items:
        v = records.values[item].reshape(n, -1)
        fmt = "%d" if item in _INT_ITEMS else f"%.{dec[item]}f"
        for j in range(v.shape[1]):
            vals = v[:, j].astype(np.int64) if item in _INT_ITEMS else v[:, j]
            cols.append(np.char.mod(" " + fmt, vals))
    lines = cols[0]
    for c in cols[1:]:
        lines = np.char.add(lines, c)
    return "".join(f"{ln}\r\n" for ln in lines.tolist())


def write_liberty_ascii(
    path: str | Path, records: LibertyRecords, decimals: Mapping[str, int] | None = None
) -> Path:
    """Write records as a Liberty ASCII stream, atomically.

    Parameters
    ----------
    path : str or Path
    records : LibertyRecords
        Values in device units; quaternions ``(w, x, y, z)``.
    decimals : mapping, optional
        Decimals per item (see :func:`format_liberty_ascii`).

    Returns
    -------
    Path
        The written file; it appears complete or not at all.
    """
    path = Path(path)
    with atomic_write(path, "w", newline="", encoding="ascii") as fh:
        fh.write(format_liberty_ascii(records, decimals))
    return path


# ---------------------------------------------------------------------------- binary


def _binary_dtype(items: Sequence[str]) -> np.dtype:
    fields: list[tuple] = [
        ("magic", "S2"),
        ("station", "u1"),
        ("command", "u1"),
        ("error", "u1"),
        ("reserved", "u1"),
        ("size", "<u2"),
    ]
    for item in items:
        if item in _INT_ITEMS:
            fields.append((item, "<u4"))
        else:
            fields.append((item, "<f4", (ITEM_SIZE[item],)))
    return np.dtype(fields)


def parse_liberty_binary(
    path: str | Path, items: str | Sequence[str] | None = None, *, data: bytes | None = None
) -> LibertyRecords:
    """Parse Liberty (``LY``) / Patriot (``PA``) binary records.

    Parameters
    ----------
    path : str or Path
    items : str or sequence, optional
        Output list (see :func:`parse_items`); default position + Euler angles.
    data : bytes, optional
        The file's content, if already in memory.

    Returns
    -------
    LibertyRecords
        ``where`` counts records from 1; messages give the byte offset too.

    Raises
    ------
    FingerfitError
        A header without ``LY``/``PA``, a body size that does not match the output
        list, a truncated last record, a bad station, a non-finite value.
    """
    items_t = parse_items(items)
    dt = _binary_dtype(items_t)
    body = dt.itemsize - 8
    with _binary_source(path, data) as (size, read_into):
        head_b = read_into(np.empty(min(size, 8), dtype=np.uint8), 0).tobytes()
        if size < 8:
            raise FingerfitError(
                f"record 1 (byte 0): truncated header ({size} of 8 bytes)", path=path
            )
        if head_b[:2] not in _MAGIC:
            raise FingerfitError(
                f"record 1 (byte 0): not a Liberty/Patriot binary record (header "
                f"{head_b[:2]!r}, expected 'LY' or 'PA'; ASCII output? use the liberty format)",
                path=path,
            )
        size0 = int.from_bytes(head_b[6:8], "little")
        if size0 != body:
            raise FingerfitError(
                f"record 1 (byte 0): body of {size0} bytes, but the output list "
                f"({', '.join(items_t)}) needs {body} (wrong --items?)",
                path=path,
            )
        n = size // dt.itemsize
        # read a block of records at a time into one reused buffer, converting into the
        # final arrays: no copy of the whole file in memory
        # float items stay float32 as sent (half the memory; converted to float64 a
        # block at a time where they are used); counts become float64
        values = {
            item: np.empty(
                (n, *dt[item].shape), dtype=np.float64 if item in _INT_ITEMS else np.float32
            )
            for item in items_t
        }
        station = np.empty(n, dtype=np.int16)
        err = np.empty(n, dtype=np.uint8)
        block = max(1, _BINARY_BLOCK_BYTES // dt.itemsize)
        buf = np.empty(min(n, block) * dt.itemsize, dtype=np.uint8)
        for lo in range(0, n, block):
            m = min(block, n - lo)
            recs = read_into(buf[: m * dt.itemsize], lo * dt.itemsize).view(dt)
            magic_bad = (recs["magic"] != head_b[:2]) | (recs["size"] != size0)
            if magic_bad.any():
                k = int(np.flatnonzero(magic_bad)[0])
                r = recs[k]
                what = (
                    f"header {bytes(r['magic'])!r} instead of {head_b[:2]!r}"
                    if r["magic"] != head_b[:2]
                    else f"body size {int(r['size'])} instead of {size0}"
                )
                k += lo
                raise FingerfitError(
                    f"record {k + 1} (byte {k * dt.itemsize}): {what} (garbled or misaligned "
                    "record)",
                    path=path,
                )
            for item in items_t:
                values[item][lo : lo + m] = recs[item]  # counts: exact uint32 -> float64
            station[lo : lo + m] = recs["station"]
            err[lo : lo + m] = recs["error"]
        del buf
    rest = size - n * dt.itemsize
    if rest:
        raise FingerfitError(
            f"record {n + 1} (byte {n * dt.itemsize}): truncated ({rest} of {dt.itemsize} bytes)",
            path=path,
        )
    chars = np.array([""] + [chr(c) for c in range(1, 256)])  # error byte 0: no indicator
    out = LibertyRecords(
        items_t,
        station,
        values,
        chars[err],
        np.arange(1, n + 1, dtype=np.int32 if n < 2**31 else np.int64),
        binary=True,
        record_size=dt.itemsize,
        family=head_b[:2].decode("ascii"),
    )
    first = _first_non_finite(out)
    if first is not None:
        i, j = first
        raise out.error(f"not a finite number in {_field_name(items_t, j)}", i, path)
    _check_records(out, path)
    return out


def _first_non_finite(records: LibertyRecords) -> tuple[int, int] | None:
    """(record, value column) of the first non-finite value in record order, or None.

    Column by column (no ``(n, n_values)`` copy of all values).
    """
    best: tuple[int, int] | None = None
    col = 0
    for item in records.items:
        v = records.values[item].reshape(records.n_records, -1)
        for j in range(v.shape[1]):
            bad = np.flatnonzero(~np.isfinite(v[:, j]))
            if bad.size and (best is None or int(bad[0]) < best[0]):
                best = (int(bad[0]), col + j)
        col += v.shape[1]
    return best


def liberty_binary_bytes(records: LibertyRecords, *, family: str | None = None) -> bytes:
    """Encode records as binary ``LY``/``PA`` records (float32 / uint32 little-endian).

    Parameters
    ----------
    records : LibertyRecords
        Values in device units.
    family : {"LY", "PA"}, optional
        Header letters; default ``records.family``.

    Returns
    -------
    bytes
    """
    dt = _binary_dtype(records.items)
    out = np.zeros(records.n_records, dtype=dt)
    out["magic"] = (family or records.family).encode("ascii")
    out["station"] = records.station
    out["command"] = ord("P")
    out["error"] = [ord(c) if c else 0 for c in records.indicator.tolist()]
    out["size"] = dt.itemsize - 8
    for item in records.items:
        out[item] = records.values[item]
    return out.tobytes()


def write_liberty_binary(path: str | Path, records: LibertyRecords) -> Path:
    """Write records as binary ``LY``/``PA`` records, atomically.

    Parameters
    ----------
    path : str or Path
    records : LibertyRecords
        Values in device units; quaternions ``(w, x, y, z)``; float items are stored
        as little-endian float32, timestamp and frame count as uint32.

    Returns
    -------
    Path
    """
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fh.write(liberty_binary_bytes(records))
    return path


# ------------------------------------------------------------------- records -> frames


def records_to_recording(
    records: LibertyRecords,
    path: str | Path,
    *,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
) -> Recording:
    """Group station records into frames and convert to a :class:`Recording`.

    Parameters
    ----------
    records : LibertyRecords
    path : str or Path
        Source file, for messages and the recording's name.
    units : str
        Units of the position item (``in`` device default, ``cm``, ``mm``, ``m``).
    rate_hz : float, optional
        Frame rate; needed when the output list has no timestamp. With it, frames go
        on the ``1/rate_hz`` grid and missing frames become NaN rows.
    sensors : mapping int -> str, optional
        Station number -> sensor name. Every station in the data must be mapped and
        every mapped station must have records. Default: the station numbers as names.
    keep_repeats : bool
        Without a frame-count item, a whole station cycle identical to the previous
        one (timestamp included, if any) is a repeated sample and is dropped and
        counted, unless this is True (a perfectly still set-up can repeat exactly at
        ASCII precision). With a frame count, a record repeating its frame count and
        values is always a repeat, and one with different values an error.

    Returns
    -------
    Recording
        Time (s), positions (mm, tracker frame), rotations (sensor -> tracker).
    """
    path = Path(path)
    if units not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{units}' (use {', '.join(UNITS_TO_MM)})", path=path, field="units"
        )
    if rate_hz is not None and not rate_hz > 0:
        raise FingerfitError("the rate must be positive (Hz)", path=path, field="rate")
    scale = UNITS_TO_MM[units]
    notes = [f"{records.n_records} station records read"]
    station = records.station
    present = np.unique(station)
    if sensors is not None:
        unknown = np.flatnonzero(~np.isin(station, list(sensors)))
        if unknown.size:
            i = int(unknown[0])
            mapped = ", ".join(f"{k}={v}" for k, v in sensors.items())
            raise records.error(f"unknown station {station[i]} (not in the map {mapped})", i, path)
        absent = [k for k in sensors if k not in present]
        if absent:
            raise FingerfitError(
                f"mapped station {absent[0]} ('{sensors[absent[0]]}') has no records", path=path
            )
        stations = list(sensors)
        names = [sensors[s] for s in stations]
    else:
        stations = [int(s) for s in present]
        names = [str(s) for s in stations]
    lut = np.full(MAX_STATION + 1, -1, dtype=np.int16)
    lut[stations] = np.arange(len(stations))
    scol = lut[station]
    items = records.items

    if "frame" in items:
        fc = records.values["frame"]
        records.check_increasing(fc, range(station.size), path, what="frame count", strict=False)
        new_frame = np.empty(station.size, dtype=bool)
        new_frame[:1] = True
        np.not_equal(fc[1:], fc[:-1], out=new_frame[1:])
        if station.size < 2 or np.all(new_frame[1:] | (station[1:] > station[:-1])):
            # stations ascending within every frame (the device's order): no repeats,
            # frames in order, nothing to sort
            rec_idx = range(station.size)  # indexable like an array, no memory
            frame_of = np.cumsum(new_frame, dtype=np.int64)
            frame_of -= 1
            first_rec = np.flatnonzero(new_frame)
            frame_ids = fc[first_rec]
        else:
            values = records.matrix()
            key = fc.astype(np.int64) * (MAX_STATION + 1) + station
            _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
            orig = first[inverse]
            dup = orig != np.arange(station.size)
            keep = ~dup
            if dup.any():
                same = np.all(values == values[orig], axis=1)
                if not same.all():
                    i = int(np.flatnonzero(~same)[0])
                    raise records.error(
                        f"second, different record for station {station[i]} in frame {fc[i]:.0f}",
                        i,
                        path,
                    )
                notes.append(
                    f"{int(dup.sum())} exactly repeated records (same frame count) dropped"
                )
            del values
            rec_idx = np.flatnonzero(keep)
            fcs = fc[rec_idx]
            frame_ids, frame_of = np.unique(fcs, return_inverse=True)
            first_rec = rec_idx[np.unique(frame_of, return_index=True)[1]]
        del new_frame
        try:
            check_grid_size(
                frame_ids - frame_ids[0], np.arange(frame_ids.size), path, "frame count"
            )
        except FingerfitError as exc:  # name the record, not the frame index
            raise records.error(
                exc.reason, int(first_rec[exc.line or 0]), path, field=exc.field
            ) from None
        grid_idx = (frame_ids - frame_ids[0]).astype(np.int64)
        n = int(grid_idx[-1]) + 1
        if "timestamp" in items:
            ts = records.values["timestamp"][first_rec] / 1000.0
            records.check_increasing(ts, first_rec, path, what="timestamp", strict=True)
            time = np.interp(np.arange(n), grid_idx, ts)
            time[grid_idx] = ts
            notes.append("frames by frame count, time from the timestamp item")
        elif rate_hz is not None:
            time = (frame_ids[0] + np.arange(n)) / rate_hz
            notes.append(f"frames by frame count, time = frame count / {rate_hz:g} Hz")
        else:
            raise FingerfitError(
                "--rate is needed: the output list has a frame count but no timestamp",
                path=path,
                field="rate",
            )
        notes += frames_missing_note(n - frame_ids.size)
        frame_of_rec = np.take(grid_idx, frame_of, out=frame_of)  # in place
    else:
        new = np.concatenate([[True], station[1:] <= station[:-1]])
        cycle = np.cumsum(new) - 1
        n_cycles = int(cycle[-1]) + 1
        values = records.matrix()
        width = values.shape[1]
        block = np.full((n_cycles, len(stations), width), np.nan)
        block[cycle, scol] = values
        del values
        rep = repeated_rows(block.reshape(n_cycles, -1))
        del block
        if rep.any() and not keep_repeats:
            notes.append(
                f"{int(rep.sum())} exactly repeated frames ({int(np.isin(cycle, np.flatnonzero(rep)).sum())} "
                "records) dropped"
            )
            keep_rec = ~rep[cycle]
            rec_idx = np.flatnonzero(keep_rec)
            cyc_keep = np.flatnonzero(~rep)
            renum = np.full(n_cycles, -1)
            renum[cyc_keep] = np.arange(cyc_keep.size)
            frame_of = renum[cycle[rec_idx]]
        else:
            rec_idx = np.arange(station.size)
            frame_of = cycle
        n_frames = int(frame_of[-1]) + 1
        first_rec = rec_idx[np.unique(frame_of, return_index=True)[1]]
        if "timestamp" in items:
            ts = records.values["timestamp"][first_rec] / 1000.0
            records.check_increasing(ts, first_rec, path, what="timestamp", strict=True)
            if rate_hz is not None:
                try:
                    time, grid_idx = place_on_grid(ts, rate_hz, np.arange(ts.size), path)
                except FingerfitError as exc:
                    raise records.error(
                        exc.reason, int(first_rec[exc.line or 0]), path, field=exc.field
                    ) from None
                notes += frames_missing_note(time.size - n_frames)
                frame_of = grid_idx[frame_of]
                n = time.size
            else:
                time, n = ts, n_frames
                notes.append("no --rate: frames kept at their timestamps, not placed on a grid")
            notes.insert(1, "frames by station cycle, time from the timestamp item")
        elif rate_hz is not None:
            time = np.arange(n_frames) / rate_hz
            n = n_frames
            notes.append(
                f"frames by station cycle, time = cycle / {rate_hz:g} Hz (no timestamp or "
                "frame count item: lost frames cannot be detected)"
            )
        else:
            raise FingerfitError(
                "--rate is needed: the output list has no timestamp or frame count",
                path=path,
                field="rate",
            )
        frame_of_rec = frame_of
        del cycle
    del frame_of
    if n < 2**31:  # a frame index per record in half the memory while the arrays fill
        frame_of_rec = frame_of_rec.astype(np.int32)

    sel = rec_idx
    every = len(sel) == station.size  # no record dropped: use the arrays without a copy

    def taken(item: str) -> np.ndarray:
        return records.values[item] if every else records.values[item][sel]

    big = implausible_rows(taken("position"), scale)
    if big.size:
        i = int(sel[big[0]])
        v = records.values["position"][i]
        raise records.error(
            implausible_message(float(v[int(np.argmax(np.abs(v)))]) * scale),
            i,
            path,
            field="position",
        )
    if "quaternion" in items:
        q = taken("quaternion")
        for r in row_blocks(slice(0, q.shape[0]), _BLOCK):  # float64 a block at a time
            with np.errstate(over="ignore"):  # a huge component: norm inf, refused below
                norm = row_norms(np.asarray(q[r], dtype=float))
            bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE)
            if bad.size:
                i = int(sel[r.start + bad[0]])
                raise records.error(
                    f"quaternion (w,x,y,z) has norm {norm[bad[0]]:.6g}, not 1 (wrong --items?)",
                    i,
                    path,
                )
        del q
        if "euler" in items:
            notes.append("orientation from the quaternion item (Euler angles not used)")
    else:
        e = np.asarray(taken("euler"), dtype=float)
        wild = np.flatnonzero((np.abs(e) > MAX_EULER_DEG).any(axis=1))
        if wild.size:
            i = int(sel[wild[0]])
            v = records.values["euler"][i]
            raise records.error(
                f"Euler angle {v[int(np.argmax(np.abs(v)))]:.6g} deg is outside "
                f"+-{MAX_EULER_DEG:g} deg (garbled record or wrong --items?)",
                i,
                path,
                field="euler",
            )
        del e
    # Per station, a block of records at a time (bounded temporary memory).
    poses: dict[str, PoseSeries] = {}
    missing: list[str] = []
    scol_sel = scol if every else scol[sel]
    for k, name in enumerate(names):
        # every frame is written once: by a record below or as a gap (NaN) at the end
        pos = np.empty((n, 3))
        rot = np.empty((n, 3, 3))
        rows_k = rows_where(scol_sel, k)  # a strided slice when stations take turns
        for r in row_blocks(rows_k, _BLOCK):
            at = frame_of_rec[r]
            src = r if every else sel[r]
            put_scaled_rows(pos, at, records.values["position"][src], scale)
            if "quaternion" in items:
                put_quat_rows(rot, at, records.values["quaternion"][src])
            else:
                put_rows(
                    rot,
                    at,
                    Rotation.from_euler(
                        "ZYX", np.asarray(records.values["euler"][src], dtype=float), degrees=True
                    ).as_matrix(),
                )
        gap = gap_rows(n, [frame_of_rec[rows_k]])
        if gap is not None:
            pos[gap] = np.nan
            rot[gap] = np.nan
        # every record placed is finite (refused otherwise): the gaps are what is missing
        missing += missing_note(name, 0 if gap is None else gap.size, n)
        poses[name] = PoseSeries(pos, rot)
    flagged = records.indicator if every else records.indicator[sel]
    flagged = flagged[flagged != ""]
    for ch in sorted(set(np.unique(flagged).tolist())):
        notes.append(
            f"{int((flagged == ch).sum())} records with indicator '{ch}' after the station number"
        )
    return Recording(path.name, np.asarray(time, dtype=float), poses, notes + missing)


def read_liberty_ascii(
    path: str | Path,
    *,
    items: str | Sequence[str] | None = None,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
    check: bool = True,
) -> Recording:
    """Read a Liberty/Patriot ASCII stream into a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
    items : str or sequence, optional
        Output list, device codes or names (default ``2,4,1``: position, Euler).
    units : str
        Position units in the file (device default ``in``).
    rate_hz : float, optional
        Frame rate (needed without a timestamp item).
    sensors : mapping int -> str, optional
        Station -> sensor name; unknown stations are an error.
    keep_repeats : bool
        Keep exactly repeated station cycles (see :func:`records_to_recording`).
    check : bool
        Run :func:`~fingerfit.io.hygiene.check_recording` (unit plausibility and
        jump flags).

    Returns
    -------
    Recording
        Time s, positions mm (tracker frame), rotations sensor -> tracker; ``notes``
        count everything dropped, missing or flagged.
    """
    recs = parse_liberty_ascii(path, items)
    rec = records_to_recording(
        recs, path, units=units, rate_hz=rate_hz, sensors=sensors, keep_repeats=keep_repeats
    )
    if check:
        check_recording(rec, path)
    return rec


def read_liberty_binary(
    path: str | Path,
    *,
    items: str | Sequence[str] | None = None,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
    check: bool = True,
) -> Recording:
    """Read binary ``LY``/``PA`` records into a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
    items, units, rate_hz, sensors, keep_repeats, check
        As for :func:`read_liberty_ascii` (default list position + Euler, inches).

    Returns
    -------
    Recording
        Time s, positions mm (tracker frame), rotations sensor -> tracker; ``notes``
        count everything dropped, missing or flagged (including non-zero error bytes).
    """
    recs = parse_liberty_binary(path, items)
    rec = records_to_recording(
        recs, path, units=units, rate_hz=rate_hz, sensors=sensors, keep_repeats=keep_repeats
    )
    if check:
        check_recording(rec, path)
    return rec
