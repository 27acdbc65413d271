"""Marker recordings: optical markers' positions read into a
:class:`~fingerfit.session.Recording` (``markers`` filled, ``poses`` empty), and the
marker map that says which segment carries which markers.

One entry, :func:`read_marker_recording`, chooses the reader by suffix: ``.trc``
(OpenSim, :mod:`.trc`), ``.tsv`` (Qualisys QTM export, :mod:`.qtm`), ``.c3d`` (through
:func:`fingerfit.io.c3d.read_c3d_markers`, :mod:`.c3d`). Positions are millimetres in the
lab (tracker) frame, NaN where a marker was not seen; each marker's gaps are counted in
the recording's notes. :mod:`.text` holds the tab-separated text both text formats share,
:mod:`.frames` the checks every reader shares (duplicates, time grid, gaps, units),
:mod:`.markermap` the map (``fingerfit.markers/1`` TOML). See ``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

from ...errors import FingerfitError
from ...session import Recording

#: Suffixes of marker recordings, lower case.
MARKER_SUFFIXES = (".trc", ".tsv", ".c3d")


def is_marker_file(path: str | Path) -> bool:
    """Whether ``path`` names a marker recording (by its suffix, any case)."""
    return Path(path).suffix.lower() in MARKER_SUFFIXES


def read_marker_recording(path: str | Path, *, units: str | None = None) -> Recording:
    """Read a marker recording: TRC, Qualisys TSV or C3D, chosen by suffix.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Units of the file's coordinates (``mm``, ``cm``, ``m``, ``in``), overriding what
        it states (TRC ``Units``, C3D ``POINT:UNITS``; QTM exports millimetres).

    Returns
    -------
    Recording
        ``markers`` label -> positions ``(n_frames, 3)`` mm, lab (tracker) frame, NaN
        where unseen; ``time`` ``(n_frames,)`` s; ``poses`` empty; ``notes`` count
        every marker's gaps and anything dropped.

    Raises
    ------
    FingerfitError
        One line naming the file and the line or field at fault; an unknown suffix.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".trc":
        from .trc import read_trc

        return read_trc(path, units=units)
    if suffix == ".tsv":
        from .qtm import read_qtm_tsv

        return read_qtm_tsv(path, units=units)
    if suffix == ".c3d":
        from .c3d import read_c3d_marker_recording

        return read_c3d_marker_recording(path, units=units)
    raise FingerfitError(
        f"not a marker recording (suffix '{path.suffix}'; use {', '.join(MARKER_SUFFIXES)})",
        path=path,
    )


__all__ = ["MARKER_SUFFIXES", "is_marker_file", "read_marker_recording"]
