"""The canonical pose CSV: ``time,sensor,x,y,z,qw,qx,qy,qz``.

One row per sensor per frame; time in seconds; ``x,y,z`` the sensor origin in
tracker coordinates (file units); ``(qw,qx,qy,qz)`` a unit quaternion, scalar
first, rotating sensor coordinates into tracker coordinates. Missing samples
may be absent rows or rows with empty/NaN fields. See ``docs/formats.md``.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError, shown
from ..session import PoseSeries, Recording, is_sensor_name
from ..transforms import matrix_from_quat_wxyz, quat_wxyz_from_matrix
from .atomic import atomic_write
from .hygiene import check_grid_size, implausible_message, implausible_rows

HEADER = ("time", "sensor", "x", "y", "z", "qw", "qx", "qy", "qz")
_NUMERIC = ("time", "x", "y", "z", "qw", "qx", "qy", "qz")
QUAT_NORM_TOLERANCE = 1e-3


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
    invalid UTF-8 sequences are refused.
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
        raise FingerfitError(
            f"not text: byte 0x{int(b[at]):02x} at offset {at} (binary or corrupted file)",
            path=path,
            line=line,
        )


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


def read_pose_csv(
    path: str | Path,
    *,
    units: str = "mm",
    rate_hz: float | None = None,
    scale_to_mm: float | None = None,
) -> Recording:
    """Read a canonical pose CSV into a :class:`Recording` (mm, tracker frame).

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

    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    first = raw.split(b"\n", 1)[0].decode("utf-8", "replace").strip().lstrip("\ufeff")
    if tuple(h.strip() for h in first.split(",")) != HEADER:
        raise FingerfitError(
            f"header must be exactly '{','.join(HEADER)}', found '{shown(first, 80)}'",
            path=path,
            line=1,
        )
    check_field_counts(raw, path, len(HEADER))
    if scale_to_mm is None:
        if units not in UNITS_TO_MM:
            raise FingerfitError(f"unknown units '{units}'", path=path, field="units")
        scale_to_mm = UNITS_TO_MM[units]

    # Read text and convert with Python's exact float parser: round-trip exact (pandas'
    # fast C parser is not) and every bad value can be named with its line.
    df = pd.read_csv(
        io.BytesIO(raw), dtype=str, skip_blank_lines=True, quoting=csv.QUOTE_NONE, encoding="utf-8"
    )
    notes: list[str] = []
    lines = np.arange(df.shape[0]) + 2  # file line of each data row
    under = b"_" in raw
    values = {col: _to_float(df[col], col, lines, path, under) for col in _NUMERIC}
    time = values["time"]
    sensors = df["sensor"].to_numpy(dtype=object)
    if df.shape[0] == 0:
        raise FingerfitError("no data rows", path=path)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise FingerfitError(
            "time is missing or not finite", path=path, line=int(lines[bad[0]]), field="time"
        )
    back = np.flatnonzero(np.diff(time) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise FingerfitError(
            f"time goes backwards ({time[i]:.6f} s after {time[i - 1]:.6f} s)",
            path=path,
            line=int(lines[i]),
            field="time",
        )
    names, inverse = np.unique(
        np.where(pd.isna(sensors), "", sensors).astype(str), return_inverse=True
    )
    for k, name in enumerate(names):
        if not is_sensor_name(name):
            i = int(np.flatnonzero(inverse == k)[0])
            raise FingerfitError(
                f"unknown sensor name '{shown(name)}' (expected hand, stylus or <digit>.<segment>)",
                path=path,
                line=int(lines[i]),
                field="sensor",
            )

    pose = np.column_stack([values[c] for c in ("x", "y", "z", "qw", "qx", "qy", "qz")])
    big = implausible_rows(pose[:, :3], scale_to_mm)
    if big.size:
        i = int(big[0])
        j = int(np.nanargmax(np.abs(pose[i, :3])))
        raise FingerfitError(
            implausible_message(float(pose[i, j]) * scale_to_mm),
            path=path,
            line=int(lines[i]),
            field="xyz"[j],
        )
    # Exact duplicates (same time, sensor and values) are dropped and counted;
    # conflicting duplicates are an error.
    key = pd.DataFrame({"t": time, "s": inverse})
    dup = key.duplicated(keep="first").to_numpy()
    if dup.any():
        firsts = key.drop_duplicates(keep="first").reset_index().set_index(["t", "s"])["index"]
        orig = firsts.loc[list(zip(time[dup], inverse[dup], strict=True))].to_numpy()
        same = np.all(
            (pose[dup] == pose[orig]) | (np.isnan(pose[dup]) & np.isnan(pose[orig])), axis=1
        )
        if not same.all():
            i = int(np.flatnonzero(dup)[~same][0])
            raise FingerfitError(
                f"second, different sample for sensor '{names[inverse[i]]}' at time {time[i]:.6f} s",
                path=path,
                line=int(lines[i]),
            )
        notes.append(f"{int(dup.sum())} exact duplicate rows dropped")
        keep = ~dup
        time, inverse, pose, lines = time[keep], inverse[keep], pose[keep], lines[keep]

    complete = np.isfinite(pose).all(axis=1)
    partial = ~complete & np.isfinite(pose).any(axis=1)
    if partial.any():
        notes.append(f"{int(partial.sum())} samples with empty fields treated as missing")
    with np.errstate(over="ignore"):  # a huge component: norm inf, refused below
        norm = np.linalg.norm(pose[:, 3:], axis=1)
    bad = np.flatnonzero(complete & (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE))
    if bad.size:
        i = int(bad[0])
        raise FingerfitError(
            f"quaternion (qw,qx,qy,qz) has norm {norm[i]:.6g}, not 1", path=path, line=int(lines[i])
        )

    frame_times, frame_of_row = np.unique(time, return_inverse=True)
    if rate_hz is not None and frame_times.size > 1:
        t0 = frame_times[0]
        row_of_frame = np.unique(frame_of_row, return_index=True)[1]
        check_grid_size((frame_times - t0) * rate_hz, lines[row_of_frame], path)
        idx = np.rint((frame_times - t0) * rate_hz).astype(np.int64)
        off = np.abs(frame_times - (t0 + idx / rate_hz))
        if np.any(off > 0.25 / rate_hz) or np.any(np.diff(idx) == 0):
            i = int(np.flatnonzero((off > 0.25 / rate_hz) | np.r_[False, np.diff(idx) == 0])[0])
            row = int(row_of_frame[i])
            raise FingerfitError(
                f"time {frame_times[i]:.6f} s is not on the {rate_hz:g} Hz sampling grid",
                path=path,
                line=int(lines[row]),
                field="time",
            )
        n = int(idx[-1]) + 1
        full_time = t0 + np.arange(n) / rate_hz
        full_time[idx] = frame_times
        if n > frame_times.size:
            notes.append(f"{n - frame_times.size} frames missing for every sensor (kept as NaN)")
        frame_of_row = idx[frame_of_row]
        frame_times = full_time
    n = frame_times.size
    poses: dict[str, PoseSeries] = {}
    _, first = np.unique(inverse, return_index=True)
    for k in np.argsort(first):  # sensors in order of first appearance
        name = names[k]
        rows = inverse == k
        pos = np.full((n, 3), np.nan)
        quat = np.full((n, 4), np.nan)
        ok = rows & complete
        pos[frame_of_row[ok]] = pose[ok, :3] * scale_to_mm
        quat[frame_of_row[ok]] = pose[ok, 3:]
        poses[str(name)] = PoseSeries(pos, matrix_from_quat_wxyz(quat))
        missing = n - int(ok.sum())
        if missing:
            notes.append(f"sensor '{name}': {missing} of {n} frames missing")
    return Recording(path.name, frame_times, poses, notes)


def pose_table(recording: Recording, *, mm_per_unit: float = 1.0) -> pd.DataFrame:
    """The recording as the canonical long table (one row per present sample).

    Parameters
    ----------
    recording : Recording
    mm_per_unit : float
        Positions are divided by this (e.g. 10 to write cm).

    Returns
    -------
    DataFrame
        Columns ``time,sensor,x,y,z,qw,qx,qy,qz``, ordered by frame then sensor.
    """
    names = recording.sensors
    pos = np.stack([recording.poses[s].position for s in names], axis=1) / mm_per_unit
    quat = np.stack([quat_wxyz_from_matrix(recording.poses[s].rotation) for s in names], axis=1)
    ok = np.isfinite(pos).all(axis=2) & np.isfinite(quat).all(axis=2)
    frame, sensor = np.nonzero(ok)
    data = {
        "time": recording.time[frame],
        "sensor": np.asarray(names, dtype=object)[sensor],
    }
    for j, c in enumerate(("x", "y", "z")):
        data[c] = pos[frame, sensor, j]
    for j, c in enumerate(("qw", "qx", "qy", "qz")):
        data[c] = quat[frame, sensor, j]
    return pd.DataFrame(data, columns=list(HEADER))


def write_pose_csv(path: str | Path, recording: Recording, *, units: str = "mm") -> Path:
    """Write a recording as a canonical pose CSV, atomically.

    Parameters
    ----------
    path : str or Path
    recording : Recording
        Positions in mm (tracker frame); written in ``units``.
    units : str
        Units for ``x,y,z`` in the file.

    Returns
    -------
    Path
        The written file. Values are written with round-trip precision, so
        :func:`read_pose_csv` gives back the same numbers.
    """
    from ..session import UNITS_TO_MM

    table = pose_table(recording, mm_per_unit=UNITS_TO_MM[units])
    path = Path(path)
    with atomic_write(path, newline="") as fh:
        table.to_csv(fh, index=False, float_format=None, lineterminator="\n")
    return path
