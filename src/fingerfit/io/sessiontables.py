"""The session's small tables: ``landmarks.csv`` (``name,x,y,z[,sd]``) and ``events.csv``
(``recording,finger,target,start,end``), read and written (``docs/formats.md``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..digits import DIGIT_NAMES
from ..errors import FingerfitError, shown
from ..session import UNITS_TO_MM, TargetEvent, is_landmark_name
from ..transforms import FloatArray
from .atomic import atomic_write
from .hygiene import implausible_message, implausible_rows
from .posecsv import check_field_counts
from .textfile import read_bytes

LANDMARKS_FILE = "landmarks.csv"
EVENTS_FILE = "events.csv"
EVENTS_HEADER = ("recording", "finger", "target", "start", "end")
LANDMARKS_HEADER = ("name", "x", "y", "z")
#: With each digitised point's uncertainty (``fingerfit capture --protocol landmarks``).
LANDMARKS_SD_HEADER = ("name", "x", "y", "z", "sd")


def _read_small_csv(path: Path, header: tuple[str, ...]) -> pd.DataFrame:
    """A small text table with an exact header; every line has ``len(header)`` fields.

    Returns the table as strings; row ``i`` is file line ``i + 2``.
    """
    raw = read_bytes(path)
    first = raw.split(b"\n", 1)[0].decode("utf-8", "replace").strip().lstrip("\ufeff")
    cols = tuple(h.strip() for h in first.split(","))
    if cols != header:
        raise FingerfitError(
            f"header must be '{','.join(header)}', found '{shown(first, 80)}'", path=path, line=1
        )
    n = check_field_counts(raw, path, len(header))
    if n == 0:
        return pd.DataFrame(columns=list(header), dtype=str)
    df = pd.read_csv(
        io.BytesIO(raw),
        dtype=str,
        keep_default_na=False,
        quoting=csv.QUOTE_NONE,
        encoding="utf-8",
        skip_blank_lines=True,
    )
    df.columns = list(header)
    return df.apply(lambda c: c.str.strip())


def _number(text: str, path: Path, line: int, field: str, what: str) -> float:
    """A finite number from a field's text, else an error naming the line and field."""
    try:
        if "_" in text:
            raise ValueError
        v = float(text)
    except ValueError:
        raise FingerfitError(
            f"{what} must be a number, not '{shown(text)}'", path=path, line=line, field=field
        ) from None
    if not math.isfinite(v):
        raise FingerfitError(
            f"{what} must be a finite number, not '{shown(text)}'",
            path=path,
            line=line,
            field=field,
        )
    return v


def read_landmarks(path: str | Path, units: str = "mm") -> dict[str, np.ndarray]:
    """Read a landmarks CSV: :func:`read_landmark_table`'s positions."""
    return read_landmark_table(path, units)[0]


def read_landmark_table(
    path: str | Path, units: str = "mm"
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Read a ``name,x,y,z`` landmarks CSV, or ``name,x,y,z,sd`` (the digitised points'
    uncertainties, written by ``fingerfit capture --protocol landmarks``).

    Parameters
    ----------
    path : str or Path
    units : str
        Units of ``x,y,z`` (and ``sd``) in the file.

    Returns
    -------
    positions : dict[str, ndarray]
        Landmark name -> position ``(3,)`` in mm, tracker coordinates.
    sd : dict[str, float]
        Landmark name -> its uncertainty (mm, the standard error of its takes), for the
        rows whose ``sd`` is given (an empty cell: not known).

    Raises
    ------
    FingerfitError
        Naming the file and line: header, field count, unknown or repeated name,
        a coordinate that is not a finite number, a negative ``sd``.
    """
    path = Path(path)
    with_sd = _header(path) == LANDMARKS_SD_HEADER
    df = _read_small_csv(path, LANDMARKS_SD_HEADER if with_sd else LANDMARKS_HEADER)
    out: dict[str, np.ndarray] = {}
    sds: dict[str, float] = {}
    for i, row in enumerate(df.itertuples(index=False), start=2):
        name = str(row.name)
        if not is_landmark_name(name):
            raise FingerfitError(
                f"unknown landmark name '{shown(name)}'", path=path, line=i, field="name"
            )
        if name in out:
            raise FingerfitError(f"landmark '{name}' given twice", path=path, line=i, field="name")
        xyz = np.array(
            [_number(v, path, i, k, "coordinate") for k, v in zip("xyz", row[1:4], strict=True)]
        )
        if with_sd and row[4] != "":
            sd = _number(row[4], path, i, "sd", "sd")
            if sd < 0:
                raise FingerfitError("sd must not be negative", path=path, line=i, field="sd")
            sds[name] = sd * UNITS_TO_MM[units]
        if implausible_rows(xyz[None], UNITS_TO_MM[units]).size:
            big = float(xyz[np.argmax(np.abs(xyz))]) * UNITS_TO_MM[units]
            raise FingerfitError(implausible_message(big), path=path, line=i)
        out[name] = xyz * UNITS_TO_MM[units]
    return out, sds


def _header(path: Path) -> tuple[str, ...]:
    """A small CSV's header fields (empty when unreadable: the reader says why)."""
    try:
        with path.open("rb") as fh:
            first = fh.readline(4096)
    except OSError:
        return ()
    text = first.decode("utf-8", "replace").strip().lstrip("\ufeff")
    return tuple(h.strip() for h in text.split(","))


def read_events(path: str | Path) -> list[TargetEvent]:
    """Read ``recording,finger,target,start,end`` touch events.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of TargetEvent
        ``start`` and ``end`` in seconds (finite, ``start < end``).

    Raises
    ------
    FingerfitError
        Naming the file and line: header, field count, a time that is not a finite
        number, ``end <= start``, an unknown finger.
    """
    path = Path(path)
    df = _read_small_csv(path, EVENTS_HEADER)
    events = []
    for i, row in enumerate(df.itertuples(index=False), start=2):
        start = _number(row.start, path, i, "start", "start and end (s)")
        end = _number(row.end, path, i, "end", "start and end (s)")
        if not end > start:
            raise FingerfitError(
                f"need start < end, got {start:g} and {end:g} s", path=path, line=i
            )
        if row.finger not in DIGIT_NAMES:
            raise FingerfitError(
                f"unknown digit '{shown(row.finger)}' (expected one of {', '.join(DIGIT_NAMES)})",
                path=path,
                line=i,
                field="finger",
            )
        if row.target == row.finger:
            raise FingerfitError(
                f"digit '{row.finger}' cannot pinch itself", path=path, line=i, field="target"
            )
        events.append(TargetEvent(row.recording, row.finger, row.target, start, end))
    return events


def match_event_recordings(events: list[TargetEvent], names: list[str]) -> list[TargetEvent]:
    """Events naming a recording by another extension, renamed to the session's file.

    An event's ``recording`` that is no recording's name but has the stem of exactly
    one (``targets.csv`` for a session converted to ``targets.parquet``) names that
    recording; any other name is left for the session's check to refuse.

    Parameters
    ----------
    events : list of TargetEvent
    names : list of str
        The file names of the session's recordings.

    Returns
    -------
    list of TargetEvent
    """
    stems: dict[str, list[str]] = {}
    for n in names:
        stems.setdefault(Path(n).stem, []).append(n)
    out = []
    for ev in events:
        found = stems.get(Path(ev.recording).stem, [])
        if ev.recording not in names and len(found) == 1:
            ev = dataclasses.replace(ev, recording=found[0])
        out.append(ev)
    return out


def write_landmarks(
    path: str | Path,
    landmarks: dict[str, FloatArray],
    units: str = "mm",
    sd: dict[str, float] | None = None,
) -> Path:
    """Write ``name,x,y,z`` landmarks (``name,x,y,z,sd`` with ``sd``), atomically.

    Parameters
    ----------
    path : str or Path
    landmarks : dict[str, ndarray]
        Name -> position ``(3,)`` in mm, tracker coordinates.
    units : str
        Units of the written coordinates.
    sd : dict[str, float], optional
        Name -> uncertainty (mm); a landmark without one (or NaN) gets an empty cell.
    """
    scale = UNITS_TO_MM[units]
    rows = [(k, *(v / scale)) for k, v in landmarks.items()]
    if sd is not None:
        rows = [
            (*r, "" if not np.isfinite(sd.get(r[0], np.nan)) else sd[r[0]] / scale) for r in rows
        ]
    lm = pd.DataFrame(
        rows, columns=list(LANDMARKS_SD_HEADER if sd is not None else LANDMARKS_HEADER)
    )
    with atomic_write(path, newline="") as fh:
        lm.to_csv(fh, index=False, lineterminator="\n")
    return Path(path)


def write_events(path: str | Path, events: list[TargetEvent]) -> Path:
    """Write ``recording,finger,target,start,end`` touch events (s), atomically."""
    ev = pd.DataFrame([e.__dict__ for e in events], columns=list(EVENTS_HEADER))
    with atomic_write(path, newline="") as fh:
        ev.to_csv(fh, index=False, lineterminator="\n")
    return Path(path)
