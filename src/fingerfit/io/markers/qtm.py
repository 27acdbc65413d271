"""Qualisys Track Manager's TSV export of 3D marker trajectories: read into a marker
recording.

The layout (tab-separated; QTM ends lines with a tab and writes ``\\r\\n``)::

    NO_OF_FRAMES   6000
    NO_OF_MARKERS  21
    FREQUENCY      100
    ...            (other KEY<TAB>value lines: cameras, time stamp, trajectory types)
    MARKER_NAMES   hand_top  hand_left ...
    Frame  Time  hand_top X  hand_top Y  hand_top Z  hand_left X ...
    1      0.00000  110.406 ...

Coordinates are millimetres (QTM's export unit); a missing sample is empty cells or
``nan``.
"""

from __future__ import annotations

import re
from pathlib import Path

from ...errors import FingerfitError, shown
from ...session import Recording
from ..hygiene import MAX_RATE_HZ
from .frames import check_labels, marker_recording
from .text import data_cells, numbers, read_lines, split_cells
from .trc import marker_scale

#: QTM's export unit.
QTM_UNITS = "mm"
_KEY = re.compile(r"^[A-Z][A-Z0-9_]*$")
#: Keys a 3D export must have.
REQUIRED = ("NO_OF_FRAMES", "NO_OF_MARKERS", "FREQUENCY", "MARKER_NAMES")


def read_qtm_tsv(path: str | Path, *, units: str | None = None) -> Recording:
    """Read a Qualisys QTM TSV export of 3D marker data.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Overrides QTM's millimetres (``mm``, ``cm``, ``m``, ``in``).

    Returns
    -------
    Recording
        ``markers`` label -> positions ``(n_frames, 3)`` mm, lab frame, NaN where
        unseen; ``time`` (s) from the ``Time`` column on the ``FREQUENCY`` grid (lost
        frames as NaN rows); ``poses`` empty; ``notes`` count gaps per marker.

    Raises
    ------
    FingerfitError
        One line naming the file and the line or field: a metadata key missing or not a
        number, ``DATA_INCLUDED`` not 3D, ``NO_OF_MARKERS`` or ``NO_OF_FRAMES`` not what
        the file holds, a repeated marker name, a header line that does not match
        ``MARKER_NAMES``, a wrong field count, a cell that is not a number, no frames,
        time not increasing or off the grid, a unit mistake.
    """
    path = Path(path)
    lines = read_lines(path)
    meta: dict[str, tuple[int, list[str]]] = {}
    header = None
    for i, line in enumerate(lines):
        cells = split_cells(line)
        while cells and not cells[-1]:
            cells.pop()
        if not cells:
            continue
        if cells[0] == "Frame":
            header = i
            break
        if not _KEY.match(cells[0]):
            raise FingerfitError(
                f"expected KEY<TAB>value metadata or the header line 'Frame<TAB>Time ...', found "
                f"'{shown(line, 40)}'",
                path=path,
                line=i + 1,
            )
        meta.setdefault(cells[0], (i + 1, cells[1:]))
    for key in REQUIRED:
        if key not in meta:
            raise FingerfitError("missing (not a QTM TSV export of 3D data?)", path=path, field=key)
    if "DATA_INCLUDED" in meta and meta["DATA_INCLUDED"][1] != ["3D"]:
        line_no, v = meta["DATA_INCLUDED"]
        raise FingerfitError(
            f"must be 3D, not '{shown(' '.join(v))}' (export 3D data)",
            path=path,
            line=line_no,
            field="DATA_INCLUDED",
        )

    def number(key: str) -> float:
        line_no, v = meta[key]
        try:
            return float(v[0])
        except (IndexError, ValueError):
            raise FingerfitError(
                f"must be a number, not '{shown(' '.join(v))}'", path=path, line=line_no, field=key
            ) from None

    rate = number("FREQUENCY")
    if not 0 < rate <= MAX_RATE_HZ:
        raise FingerfitError(
            f"must be positive and at most {MAX_RATE_HZ:g} Hz",
            path=path,
            line=meta["FREQUENCY"][0],
            field="FREQUENCY",
        )
    names_line, labels = meta["MARKER_NAMES"]
    check_labels(labels, path, names_line, "MARKER_NAMES")
    n_markers = number("NO_OF_MARKERS")
    if n_markers != len(labels):
        raise FingerfitError(
            f"NO_OF_MARKERS is {n_markers:g} but MARKER_NAMES names {len(labels)}",
            path=path,
            line=meta["NO_OF_MARKERS"][0],
            field="NO_OF_MARKERS",
        )
    if header is None:
        raise FingerfitError(
            "no header line 'Frame<TAB>Time<TAB><marker> X ...' (export with the time column)",
            path=path,
        )
    columns = ["Frame", "Time", *(f"{lb} {a}" for lb in labels for a in "XYZ")]
    found = split_cells(lines[header])
    while found and not found[-1]:
        found.pop()
    if found != columns:
        bad = next(
            (k for k, (a, b) in enumerate(zip(found, columns, strict=False)) if a != b),
            min(len(found), len(columns)),
        )
        expected = columns[bad] if bad < len(columns) else "nothing"
        got = found[bad] if bad < len(found) else "nothing"
        raise FingerfitError(
            f"header column {bad + 1} is '{shown(got)}', expected '{shown(expected)}' "
            "(from MARKER_NAMES)",
            path=path,
            line=header + 1,
        )
    cells, rows = data_cells(lines, header + 1, len(columns), path)
    n_frames = number("NO_OF_FRAMES")
    if n_frames != rows.size:
        raise FingerfitError(
            f"NO_OF_FRAMES is {n_frames:g} but the file holds {rows.size} frames",
            path=path,
            line=meta["NO_OF_FRAMES"][0],
            field="NO_OF_FRAMES",
        )
    values = numbers(cells, rows, columns, path)
    xyz = values[:, 2:].reshape(-1, len(labels), 3)
    scale = marker_scale(QTM_UNITS, units, path, "units")
    return marker_recording(
        path, values[:, 1], rows, list(labels), xyz, scale_to_mm=scale, rate_hz=rate
    )
