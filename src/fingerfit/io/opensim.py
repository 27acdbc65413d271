"""OpenSim's text tables: a motion (``.mot``), a recording's orientations (``.sto``) and
its markers (``.trc``: a marker recording's markers, or a 6-DOF one's sensor origins),
written atomically.

OpenSim works in metres and radians, its motions in degrees (``inDegrees=yes``), its
orientation tables in quaternions ``w,x,y,z`` (one cell per sensor, its four numbers
separated by commas), all in ground: here the tracker frame. Each sensor's column is
named after the frame that carries it in the exported model (:func:`frame_name`:
``index.proximal`` -> ``index_proximal_imu``, OpenSense's ``<body>_imu``), so
``IMUInverseKinematicsTool`` and ``InverseKinematicsSolver`` match them without a map.

A frame in which a value is missing is written ``NaN`` (the motion's coordinates, the
orientation's four numbers, the marker's three): OpenSim's readers take it as a missing
value. See ``docs/export.md``, *OpenSim*.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..session import UNITS_TO_MM, Recording
from ..transforms import quat_wxyz_columns
from .atomic import atomic_write

#: The OpenSim version the files are written for (the ``OpenSimVersion`` header).
OPENSIM_VERSION = "4.6"
#: Suffix of a sensor's frame in the exported model (OpenSense's ``<body>_imu``).
FRAME_SUFFIX = "_imu"


def frame_name(sensor: str) -> str:
    """The OpenSim frame (and marker) name of a sensor: ``index.proximal`` ->
    ``index_proximal_imu``, ``hand`` -> ``hand_imu`` (the body's name, then ``_imu``)."""
    return sensor.replace(".", "_") + FRAME_SUFFIX


def _text(values: np.ndarray) -> pd.Series:
    """Numbers ``(n,)`` as their shortest round-trip text, ``NaN`` where missing."""
    v = np.asarray(values, dtype=float)
    out = pd.Series(v.astype(str), dtype=object)
    out[~np.isfinite(v)] = "NaN"
    return out


def _rate_hz(time: np.ndarray) -> float:
    """The recording's frame rate (Hz): one over the median step (0 for one frame)."""
    steps = np.diff(np.asarray(time, dtype=float))
    return float(1.0 / np.median(steps)) if steps.size else 0.0


def _write(path: Path, header: str, table: pd.DataFrame) -> Path:
    with atomic_write(path, newline="") as fh:
        fh.write(header)
        table.to_csv(fh, sep="\t", index=False, lineterminator="\n", header=False)
    return path


def write_motion(path: str | Path, table: pd.DataFrame, *, name: str) -> Path:
    """Write an OpenSim motion file (``.mot``, STO version 1, ``inDegrees=yes``).

    Parameters
    ----------
    path : str or Path
    table : DataFrame
        ``time`` (s) first, then one column per coordinate: rotational ones in degrees,
        translational ones in metres; NaN where missing (written ``NaN``).
    name : str
        The motion's name (the file's first line).

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        When ``path`` cannot be written (nothing is left behind).
    """
    header = (
        f"{name}\nversion=1\nnRows={len(table)}\nnColumns={table.shape[1]}\n"
        "inDegrees=yes\nendheader\n" + "\t".join(table.columns) + "\n"
    )
    return _write(Path(path), header, table.apply(lambda c: _text(c.to_numpy())))


def write_orientations(path: str | Path, recording: Recording) -> Path:
    """Write a recording's sensor orientations as OpenSim's orientation table (``.sto``).

    Parameters
    ----------
    path : str or Path
    recording : Recording
        Rotations sensor -> tracker, ``(n_frames, 3, 3)`` per sensor.

    Returns
    -------
    Path
        Columns ``time`` (s) and one per sensor, named :func:`frame_name`, each cell
        ``w,x,y,z`` (the rotation sensor -> tracker: ground is the tracker frame);
        ``DataType=Quaternion``, ``DataRate`` the median frame rate (Hz).

    Raises
    ------
    FingerfitError
        When ``path`` cannot be written (nothing is left behind).
    """
    cols = {"time": _text(recording.time)}
    for s in recording.sensors:
        q = quat_wxyz_columns(recording.poses[s].rotation)  # (4, n), NaN where missing
        w, x, y, z = (_text(c) for c in q)
        cols[frame_name(s)] = w + "," + x + "," + y + "," + z
    table = pd.DataFrame(cols)
    header = (
        f"DataRate={_rate_hz(recording.time):.10g}\nDataType=Quaternion\nversion=3\n"
        f"OpenSimVersion={OPENSIM_VERSION}\nendheader\n" + "\t".join(table.columns) + "\n"
    )
    return _write(Path(path), header, table)


def write_markers(path: str | Path, recording: Recording, *, units: str = "m") -> Path:
    """Write a recording's markers as OpenSim's marker trajectories (``.trc``).

    Parameters
    ----------
    path : str or Path
    recording : Recording
        A marker recording (its ``markers``, label -> ``(n_frames, 3)`` mm) or a 6-DOF
        one (its sensor origins, ``(n_frames, 3)`` mm); tracker frame.
    units : str
        The file's ``Units`` (``mm``, ``cm``, ``m``, ``in``); OpenSim's is ``m``.

    Returns
    -------
    Path
        One marker per label of a marker recording, or per sensor, named
        :func:`frame_name` (the exported model has a marker of that name at each
        sensor's origin); tracker frame; ``DataRate`` the median frame rate (Hz); a
        missing sample ``NaN``. :func:`fingerfit.io.markers.read_marker_recording`
        reads it back.

    Raises
    ------
    FingerfitError
        When ``path`` cannot be written (nothing is left behind).
    """
    if recording.markers:
        points = recording.markers
    else:
        points = {frame_name(s): p.position for s, p in recording.poses.items()}
    scale = UNITS_TO_MM[units]
    rate = _rate_hz(recording.time)
    n = recording.n_frames
    names = list(points)
    cols = {"frame": pd.Series(np.arange(1, n + 1).astype(str)), "time": _text(recording.time)}
    for name, xyz in points.items():
        for k, axis in enumerate("XYZ"):
            cols[f"{name}.{axis}"] = _text(xyz[:, k] / scale)
    header = (
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames\n"
        f"{rate:.10g}\t{rate:.10g}\t{n}\t{len(names)}\t{units}\t{rate:.10g}\t1\t{n}\n"
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t\n"
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, len(names) + 1)) + "\n\n"
    )
    return _write(Path(path), header, pd.DataFrame(cols))
