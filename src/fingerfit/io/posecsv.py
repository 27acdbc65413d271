"""The canonical pose CSV: ``time,sensor,x,y,z,qw,qx,qy,qz``, decoded.

One row per sensor per frame; time in seconds; ``x,y,z`` the sensor origin in
tracker coordinates (file units); ``(qw,qx,qy,qz)`` a unit quaternion, scalar
first, rotating sensor coordinates into tracker coordinates. Missing samples
may be absent rows or rows with empty/NaN fields. See ``docs/formats.md``.

:func:`read_pose_csv` reads it (and, by the extension, its Parquet form through
:mod:`.poseparquet`); the rows are checked and placed by :mod:`.poserows`; the writers
are in :mod:`.posewrite`. The text checks here (:func:`check_field_counts`,
:func:`check_text`) serve every CSV reader.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError, shown
from ..session import Recording
from .poserows import HEADER, NUMERIC, PoseRows, assemble_rows

#: The first bytes of a Parquet file.
PARQUET_MAGIC = b"PAR1"


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
    invalid UTF-8 sequences are refused; a Parquet file (its first bytes ``PAR1``) is
    named as one.
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
        if b[:4].tobytes() == PARQUET_MAGIC:
            raise FingerfitError(
                f"not text: a Parquet file (name it {Path(path).stem}.parquet to read it as one)",
                path=path,
                line=line,
            )
        raise FingerfitError(
            f"not text: byte 0x{int(b[at]):02x} at offset {at} (binary or corrupted file)",
            path=path,
            line=line,
        )


def read_magic(path: Path) -> bytes:
    """The first four bytes of a file (:data:`PARQUET_MAGIC` for a Parquet file)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(4)
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


def header_line(path: Path) -> str:
    """The first line of a CSV file as text (a byte-order mark and the line end removed).

    Raises
    ------
    FingerfitError
        The file cannot be read, or its first line is not text (:func:`check_text`: a
        binary file, a Parquet file named ``.csv``).
    """
    from .fastcsv import read_header

    head = read_header(path).split(b"\n", 1)[0]
    check_text(np.frombuffer(head, dtype=np.uint8), path)
    return head.decode("utf-8").strip().lstrip("\ufeff")


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


def _decode_fast(path: Path) -> PoseRows:
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
        for j, c in enumerate(NUMERIC):
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
        return PoseRows(np.zeros(0), np.zeros(0, np.int32), [], np.zeros((0, 7)))
    data = rows.array()
    return PoseRows(data[:, 0], sensor[: rows.n], names, data[:, 1:])


def _decode_exact(raw: bytes, path: Path) -> PoseRows:
    """The reference decoder: Python's exact float parser, every error with its line."""
    check_field_counts(raw, path, len(HEADER))
    df = pd.read_csv(
        io.BytesIO(raw), dtype=str, skip_blank_lines=True, quoting=csv.QUOTE_NONE, encoding="utf-8"
    )
    lines = np.arange(df.shape[0]) + 2  # file line of each data row
    under = b"_" in raw
    values = {col: _to_float(df[col], col, lines, path, under) for col in NUMERIC}
    sensors = df["sensor"].to_numpy(dtype=object)
    names, inverse = np.unique(
        np.where(pd.isna(sensors), "", sensors).astype(str), return_inverse=True
    )
    pose = np.column_stack([values[c] for c in NUMERIC[1:]])
    return PoseRows(values["time"], inverse.astype(np.int32), [str(n) for n in names], pose)


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
    from .parquet import is_parquet

    path = Path(path)
    if is_parquet(path):
        from .poseparquet import read_pose_parquet

        return read_pose_parquet(path, units, rate_hz, scale_to_mm)
    rows = read_pose_rows(path)
    if scale_to_mm is None:
        if units not in UNITS_TO_MM:
            raise FingerfitError(f"unknown units '{units}'", path=path, field="units")
        scale_to_mm = UNITS_TO_MM[units]
    return assemble_rows(rows, path, scale_to_mm, rate_hz)


def is_pose_header(line: str) -> bool:
    """Whether a CSV file's first line (:func:`header_line`) is the pose CSV's header."""
    return tuple(h.strip() for h in line.split(",")) == HEADER


def read_pose_rows(path: Path) -> PoseRows:
    """The data rows of a pose CSV as decoded, in file order and file units, unchecked
    beyond the header and the text (:func:`read_pose_csv` checks and places them).

    Parameters
    ----------
    path : Path

    Returns
    -------
    PoseRows
        ``time`` ``(n,)`` s, ``sensor`` ``(n,)`` codes into ``names``, ``pose`` ``(n, 7)``
        ``x, y, z`` (file units) and ``qw, qx, qy, qz``; NaN where a field is empty.

    Raises
    ------
    FingerfitError
        The header is not the pose CSV's, or a line is not text or not numbers.
    """
    from .fastcsv import NotPlain

    first = header_line(path)
    if not is_pose_header(first):
        raise FingerfitError(
            f"header must be exactly '{','.join(HEADER)}', found '{shown(first, 80)}'",
            path=path,
            line=1,
        )
    try:
        return _decode_fast(path)
    except NotPlain:
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
        return _decode_exact(raw, path)
