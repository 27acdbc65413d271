"""Decoded marker frames made a :class:`~fingerfit.session.Recording`, with the checks
every marker reader shares.

The rules are those of the pose readers (:mod:`fingerfit.io.hygiene`): an exact repeat of
the previous frame is dropped and counted, time must increase, frames go on the
``1/rate`` grid so that lost frames become NaN rows, a coordinate beyond
:data:`~fingerfit.io.hygiene.MAX_COORDINATE_MM` is an error, and every marker's gaps are
counted in the recording's notes. A unit mistake is an error
(:func:`check_marker_units`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import FingerfitError, shown
from ...session import Recording
from ...transforms import row_norms
from ..hygiene import (
    WORKSPACE_MM,
    check_increasing,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
    repeated_rows,
)

#: Plausible spacing of markers (mm): the median, over the markers, of each marker's
#: median distance to its nearest neighbour. Measured: 32.4 mm on the real Qualisys glove
#: recording (``docs/formats.md``, 21 markers of a hand, arm, back and an object); skin
#: markers on a phalanx sit 5-30 mm apart. Metres or inches read as millimetres fall
#: below, millimetres read as metres far above; the marker map's hand span catches a
#: factor of 10 (:data:`fingerfit.io.markers.markermap.HAND_SPAN_MM`).
MARKER_SPACING_MM = (2.0, 300.0)
#: Frames the unit check looks at, at most (evenly spaced over the recording).
UNIT_CHECK_FRAMES = 1000


def check_labels(labels: list[str], path: Path, line: int | None, field: str) -> None:
    """Refuse an empty or repeated marker label.

    Raises
    ------
    FingerfitError
        Naming the file, the line and ``field`` and the label.
    """
    seen: set[str] = set()
    for i, label in enumerate(labels):
        if not label:
            raise FingerfitError(f"marker {i + 1} has no name", path=path, line=line, field=field)
        if label in seen:
            raise FingerfitError(
                f"marker name '{shown(label)}' given twice", path=path, line=line, field=field
            )
        seen.add(label)


def sample_frames(n: int, at_most: int = UNIT_CHECK_FRAMES) -> np.ndarray:
    """At most ``at_most`` frame indices spread evenly over ``n`` frames."""
    return (
        np.unique(np.linspace(0, n - 1, min(n, at_most)).astype(np.int64))
        if n
        else np.zeros(0, int)
    )


def median_pair_distances(points: np.ndarray) -> np.ndarray:
    """Median distance (mm) over frames between every two markers.

    Parameters
    ----------
    points : ndarray, shape (n_frames, m, 3)
        Marker positions (mm); NaN where unseen.

    Returns
    -------
    ndarray, shape (m, m)
        NaN on the diagonal and for pairs never seen together.
    """
    d = np.linalg.norm(points[:, :, None, :] - points[:, None, :, :], axis=-1)
    m = points.shape[1]
    d[:, np.arange(m), np.arange(m)] = np.nan
    seen = np.isfinite(d).any(axis=0)
    out = np.full((m, m), np.nan)
    if seen.any():
        out[seen] = np.nanmedian(d[:, seen], axis=0)
    return out


def check_marker_units(markers: dict[str, np.ndarray], path: Path | None = None) -> None:
    """Refuse marker positions a hand's markers cannot have (a unit mistake).

    Each marker's median distance from the origin must be at most
    :data:`~fingerfit.io.hygiene.WORKSPACE_MM`; with two or more markers, their typical
    spacing (:data:`MARKER_SPACING_MM`) must be a hand's.

    Parameters
    ----------
    markers : dict[str, ndarray]
        Label -> positions ``(n_frames, 3)`` mm, lab frame; NaN where unseen.
    path : Path, optional
        The file, for the message.

    Raises
    ------
    FingerfitError
        ``field 'units'``: naming the marker or the spacing found.
    """
    if not markers:
        return
    labels = list(markers)
    n = next(iter(markers.values())).shape[0]
    pts = np.stack([markers[k][sample_frames(n)] for k in labels], axis=1)
    for j, label in enumerate(labels):
        p = pts[:, j][np.isfinite(pts[:, j, 0])]
        if p.size and (r := float(np.median(row_norms(p)))) > WORKSPACE_MM:
            raise FingerfitError(
                f"marker '{label}' is {r / 1000:.4g} m from the origin (median): implausible, "
                "are the units the file states right?",
                path=path,
                field="units",
            )
    if len(labels) < 2:
        return
    nearest = np.fmin.reduce(median_pair_distances(pts), axis=1)  # NaN only if never paired
    nearest = nearest[np.isfinite(nearest)]
    if nearest.size:
        check_marker_length(
            float(np.median(nearest)),
            MARKER_SPACING_MM,
            "marker spacing",
            "each marker's median distance to its nearest neighbour, median over markers",
            path,
        )


def check_marker_length(
    value: float, bounds: tuple[float, float], what: str, how: str, path: str | Path | None
) -> None:
    """Refuse a length of a hand's markers outside ``bounds`` as a unit mistake.

    Parameters
    ----------
    value : float
        The length (mm).
    bounds : (float, float)
        Plausible range (mm).
    what, how : str
        The length's name and how it was measured, for the message.
    path : str or Path, optional

    Raises
    ------
    FingerfitError
        ``field 'units'``: ``<what> <value> mm (<how>; a hand's markers: lo-hi mm): are
        the units the file states right?``
    """
    lo, hi = bounds
    if not lo <= value <= hi:
        raise FingerfitError(
            f"{what} {value:.4g} mm ({how}; a hand's markers: {lo:g}-{hi:g} mm): are the "
            "units the file states right?",
            path=path,
            field="units",
        )


def marker_recording(
    path: Path,
    time: np.ndarray,
    lines: np.ndarray,
    labels: list[str],
    xyz: np.ndarray,
    *,
    scale_to_mm: float,
    rate_hz: float,
    notes: list[str] | None = None,
) -> Recording:
    """Frames of marker positions made a recording, checked and with its gaps counted.

    Parameters
    ----------
    path : Path
        The file (the recording's name is its file name).
    time : ndarray, shape (n,)
        Frame times (s), in file order.
    lines : ndarray of int, shape (n,)
        1-based file line (or frame number) of each frame, for messages.
    labels : list of str, length m
        Marker labels, distinct.
    xyz : ndarray, shape (n, m, 3)
        Positions in file units, lab frame; NaN where unseen (a sample with only some
        coordinates NaN is missing as a whole, and counted).
    scale_to_mm : float
        Millimetres per file unit.
    rate_hz : float
        Sampling rate: frames go on the ``1/rate_hz`` grid, lost frames as NaN rows.
    notes : list of str, optional
        The reader's own notes, first.

    Returns
    -------
    Recording
        ``poses`` empty, ``markers`` label -> ``(n_grid, 3)`` mm; ``notes`` count exact
        duplicate frames dropped, frames lost, partial samples and each marker's gaps.

    Raises
    ------
    FingerfitError
        No frames, a coordinate beyond 1000 km, time not increasing or off the grid, a
        unit mistake (:func:`check_marker_units`).
    """
    notes = list(notes or [])
    n, m = xyz.shape[:2]
    if n == 0:
        raise FingerfitError("no frames", path=path)
    flat = xyz.reshape(n, m * 3)
    big = implausible_rows(flat, scale_to_mm)
    if big.size:
        k = int(big[0])
        j = int(np.nanargmax(np.abs(flat[k])))
        raise FingerfitError(
            implausible_message(float(flat[k, j]) * scale_to_mm),
            path=path,
            line=int(lines[k]),
            field=f"{labels[j // 3]} {'XYZ'[j % 3]}",
        )
    repeat = repeated_rows(np.column_stack([time, flat]))
    if repeat.any():
        keep = ~repeat
        time, lines, xyz = time[keep], lines[keep], xyz[keep]
        notes.append(f"{int(repeat.sum())} exact duplicate rows dropped")
    check_increasing(time, lines, path)
    grid, index = place_on_grid(time, rate_hz, lines, path)
    notes += frames_missing_note(grid.size - time.size, "marker")
    unseen = np.isnan(xyz)
    partial = unseen.any(axis=2) & ~unseen.all(axis=2)
    if partial.any():
        notes.append(f"{int(partial.sum())} samples with empty fields treated as missing")
    points = np.full((grid.size, m, 3), np.nan)
    points[index] = np.where(unseen.any(axis=2)[..., None], np.nan, xyz * scale_to_mm)
    markers = {label: np.ascontiguousarray(points[:, j]) for j, label in enumerate(labels)}
    for label, p in markers.items():
        notes += missing_note(label, int(np.isnan(p[:, 0]).sum()), grid.size, "marker")
    check_marker_units(markers, path)
    return Recording(path.name, grid, {}, notes, markers)
