"""C3D marker trajectories as a marker recording, read by
:func:`fingerfit.io.c3d.read_c3d_markers` (``ezc3d``, the ``c3d`` extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...session import Recording
from .frames import check_labels, marker_recording


def read_c3d_marker_recording(path: str | Path, *, units: str | None = None) -> Recording:
    """Read the marker trajectories of a C3D file as a marker recording.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Overrides ``POINT:UNITS``.

    Returns
    -------
    Recording
        ``markers`` label -> positions ``(n_frames, 3)`` mm, lab frame, NaN where
        unseen (a negative residual); ``time`` (s) ``(first_frame + k) / POINT:RATE``;
        ``poses`` empty; ``notes`` count gaps per marker.

    Raises
    ------
    FingerfitError
        Those of :func:`~fingerfit.io.c3d.read_c3d_markers`, a repeated label
        (``POINT:LABELS``), no frames, a unit mistake.
    """
    from ..c3d.markers import read_c3d_markers

    path = Path(path)
    c = read_c3d_markers(path, units=units)
    check_labels(c.labels, path, None, "POINT:LABELS")
    frames = np.arange(1, c.time.size + 1)
    return marker_recording(
        path, c.time, frames, c.labels, c.points, scale_to_mm=1.0, rate_hz=c.rate_hz
    )
