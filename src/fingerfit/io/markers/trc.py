"""OpenSim's marker trajectories (``.trc``): read into a marker recording.

The layout (tab-separated)::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...
    100       100         300        12          mm     100           ...
    Frame#  Time  H1        H2 ...
                  X1 Y1 Z1  X2 Y2 Z2 ...
    1       0.00  ...

then one line per frame: the frame number, the time (s) and three coordinates per
marker. A missing sample is empty cells or ``NaN``. The writer is
:func:`fingerfit.io.opensim.write_markers`.
"""

from __future__ import annotations

from pathlib import Path

from ...errors import FingerfitError, shown
from ...session import UNITS_TO_MM, Recording
from ..hygiene import MAX_RATE_HZ
from .frames import check_labels, marker_recording
from .text import data_cells, numbers, read_lines, split_cells

#: Header lines before the data (the data may follow a blank line).
HEADER_LINES = 5


def marker_scale(stated: str, units: str | None, path: Path, field: str) -> float:
    """Millimetres per file unit: ``units`` when given, else the file's ``stated`` units.

    Raises
    ------
    FingerfitError
        Naming ``field`` (or ``units``): units not one of ``mm``, ``cm``, ``m``, ``in``.
    """
    if units is not None:
        if units not in UNITS_TO_MM:
            raise FingerfitError(
                f"unknown units '{shown(units)}' (use {', '.join(UNITS_TO_MM)})",
                path=path,
                field="units",
            )
        return UNITS_TO_MM[units]
    if stated not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{shown(stated)}' (use {', '.join(UNITS_TO_MM)}, or give --units)",
            path=path,
            field=field,
        )
    return UNITS_TO_MM[stated]


def _header_value(keys: list[str], values: list[str], key: str, path: Path) -> str:
    if key not in keys:
        raise FingerfitError(f"header line 2 has no '{key}'", path=path, line=2, field=key)
    i = keys.index(key)
    if i >= len(values) or not values[i]:
        raise FingerfitError("missing", path=path, line=3, field=key)
    return values[i]


def _count(text: str, path: Path, key: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise FingerfitError(
            f"must be a whole number, not '{shown(text)}'", path=path, line=3, field=key
        ) from None


def read_trc(path: str | Path, *, units: str | None = None) -> Recording:
    """Read an OpenSim ``.trc`` marker file.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Overrides the file's ``Units`` (``mm``, ``cm``, ``m``, ``in``).

    Returns
    -------
    Recording
        ``markers`` label -> positions ``(n_frames, 3)`` mm, lab frame, NaN where
        unseen; ``time`` (s) from the ``Time`` column on the ``DataRate`` grid (lost
        frames as NaN rows); ``poses`` empty; ``notes`` count gaps per marker.

    Raises
    ------
    FingerfitError
        One line naming the file and the line or field: not a TRC header, ``Units``
        unknown, ``DataRate`` not positive, ``NumMarkers`` or ``NumFrames`` not what the
        file holds, a repeated marker name, a wrong field count, a cell that is not a
        number, no frames, time not increasing or off the grid, a unit mistake.
    """
    path = Path(path)
    lines = read_lines(path)
    if not lines or not lines[0].startswith("PathFileType"):
        raise FingerfitError(
            "not a TRC file (line 1 must start with 'PathFileType')", path=path, line=1
        )
    if len(lines) < HEADER_LINES:
        raise FingerfitError(f"TRC header needs {HEADER_LINES} lines", path=path)
    keys, values = split_cells(lines[1]), split_cells(lines[2])
    stated = _header_value(keys, values, "Units", path)
    scale = marker_scale(stated, units, path, "Units")
    rate_text = _header_value(keys, values, "DataRate", path)
    try:
        rate = float(rate_text)
    except ValueError:
        rate = float("nan")
    if not 0 < rate <= MAX_RATE_HZ:
        raise FingerfitError(
            f"must be positive and at most {MAX_RATE_HZ:g} Hz, not '{shown(rate_text)}'",
            path=path,
            line=3,
            field="DataRate",
        )
    n_markers = _count(_header_value(keys, values, "NumMarkers", path), path, "NumMarkers")
    n_frames = _count(_header_value(keys, values, "NumFrames", path), path, "NumFrames")
    names = split_cells(lines[3])
    if names[:2] != ["Frame#", "Time"]:
        raise FingerfitError(
            f"line 4 must start with 'Frame#<TAB>Time', found '{shown(lines[3], 40)}'",
            path=path,
            line=4,
        )
    labels = [c for c in names[2:] if c]
    check_labels(labels, path, 4, "marker names")
    if len(labels) != n_markers:
        raise FingerfitError(
            f"NumMarkers is {n_markers} but line 4 names {len(labels)} markers",
            path=path,
            line=3,
            field="NumMarkers",
        )
    coords = [c for c in split_cells(lines[4]) if c]
    if len(coords) != 3 * n_markers:
        raise FingerfitError(
            f"{len(coords)} coordinate names (X1 Y1 Z1 ...), expected {3 * n_markers}",
            path=path,
            line=5,
        )
    columns = ["Frame#", "Time", *(f"{lb} {a}" for lb in labels for a in "XYZ")]
    cells, rows = data_cells(lines, HEADER_LINES, len(columns), path)
    if rows.size != n_frames:
        raise FingerfitError(
            f"NumFrames is {n_frames} but the file holds {rows.size} frames",
            path=path,
            line=3,
            field="NumFrames",
        )
    values_ = numbers(cells, rows, columns, path)
    xyz = values_[:, 2:].reshape(-1, n_markers, 3)
    return marker_recording(path, values_[:, 1], rows, labels, xyz, scale_to_mm=scale, rate_hz=rate)
