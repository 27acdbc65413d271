"""Liberty (``LY``) / Patriot (``PA``) binary records: parse into
:class:`~.records.LibertyRecords`, encode and write.

Records of an 8-byte header -- ``'LY'`` or ``'PA'``, station byte, command byte, error
byte, reserved byte, little-endian ``uint16`` body size -- then the items as
little-endian ``float32`` (timestamp and frame count as ``uint32``). The space and CR/LF
items carry no data in binary records.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ...errors import FingerfitError
from ..atomic import atomic_write
from .records import (
    _INT_ITEMS,
    ITEM_SIZE,
    LibertyRecords,
    _check_records,
    _field_name,
    parse_items,
)

_MAGIC = (b"LY", b"PA")

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
