"""Liberty/Patriot ASCII streams: parse into :class:`~.records.LibertyRecords`, format
and write.

One CR/LF line per station, whitespace-separated: the station number (one or two digits,
optionally followed by one indicator character, e.g. ``01`` or ``01D``), then the items
of the output list in order. Numbers glued together by a sign (fixed-width fields
overflowing, ``12.345-6.789``) are split. Plain streams are read in batches by
:func:`_parse_ascii_fast`; anything else is judged line by line.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import FingerfitError, shown
from ...memory import release_freed_memory
from ..atomic import atomic_write
from .records import (
    _INT_ITEMS,
    ITEM_SIZE,
    LibertyRecords,
    _check_records,
    _field_name,
    parse_items,
)

#: Decimals the ASCII writer uses per item (the device's standard precision).
ASCII_DECIMALS = {"position": 3, "euler": 3, "quaternion": 4}


def _read_bytes(path: str | Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


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
        from ..fastcsv import NotPlain

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
    from ..fastcsv import (
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


def _split_values(nums: np.ndarray, items: Sequence[str]) -> dict[str, np.ndarray]:
    out, k = {}, 0
    for item in items:
        size = ITEM_SIZE[item]
        v = nums[:, k : k + size]
        out[item] = v[:, 0].copy() if size == 1 else v.copy()
        k += size
    return out


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
