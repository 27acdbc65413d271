"""Recordings written as the canonical pose table: a CSV, or its Parquet form for a
``.parquet`` path (one row per present sample, ordered by frame then sensor)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..session import Recording
from ..transforms import quat_wxyz_columns
from .poserows import HEADER


def pose_columns(recording: Recording, mm_per_unit: float) -> dict[str, object]:
    """Columns of the long table; ``sensor`` as ``(codes, names)``."""
    return pose_block(recording, 0, recording.n_frames, mm_per_unit)


def pose_block(recording: Recording, lo: int, hi: int, mm_per_unit: float) -> dict[str, object]:
    """The rows of frames ``lo:hi`` of the long table, one per present sample (a sample
    with a NaN or an infinity anywhere is left out), ordered by frame then sensor.

    Parameters
    ----------
    recording : Recording
        Positions in mm (tracker frame), rotations sensor -> tracker.
    lo, hi : int
        The frames.
    mm_per_unit : float
        Positions are divided by this (10 to write cm).

    Returns
    -------
    dict of str to ndarray
        ``time`` (s), ``sensor`` as ``(codes (m,) int32, names)``, ``x, y, z`` (file
        units) and ``qw, qx, qy, qz``, each ``(m,)``.
    """
    names = recording.sensors
    n_s = len(names)
    # x, y, z, qw, qx, qy, qz of each frame and sensor: each column's rows contiguous
    vals = np.empty((7, hi - lo, n_s))
    for j, s in enumerate(names):
        np.divide(recording.poses[s].position[lo:hi].T, mm_per_unit, out=vals[:3, :, j])
        vals[3:, :, j] = sensor_quats(recording, s, lo, hi)
    ok = np.isfinite(vals).all(axis=0)
    time = recording.time[lo:hi]
    if ok.all():
        flat = vals.reshape(7, -1)
        cols: dict[str, object] = {
            "time": np.repeat(time, n_s),
            "sensor": (np.tile(np.arange(n_s, dtype=np.int32), hi - lo), list(names)),
        }
    else:
        frame, sensor = np.nonzero(ok)
        flat = vals.reshape(7, -1)[:, ok.ravel()]
        cols = {"time": time[frame], "sensor": (sensor.astype(np.int32), list(names))}
    for j, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
        cols[c] = flat[j]
    return cols


def sensor_quats(recording: Recording, sensor: str, lo: int, hi: int) -> np.ndarray:
    """The quaternions of a sensor's rotations in frames ``lo:hi`` as rows ``(4, hi - lo)``
    (:func:`~fingerfit.transforms.quat_wxyz_columns`: ``w, x, y, z``). A matrix that is not
    a rotation raises the error of the whole recording's conversion: the first sensor, in
    order, with such a matrix, that matrix named by its frame."""
    try:
        return quat_wxyz_columns(recording.poses[sensor].rotation[lo:hi])
    except ValueError:
        for s in recording.sensors:
            quat_wxyz_columns(recording.poses[s].rotation)
        raise


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
    cols = pose_columns(recording, mm_per_unit)
    codes, names = cols["sensor"]
    cols["sensor"] = np.asarray(names, dtype=object)[codes]
    return pd.DataFrame(cols, columns=list(HEADER))


def write_pose_csv(path: str | Path, recording: Recording, *, units: str = "mm") -> Path:
    """Write a recording as a canonical pose CSV, or Parquet for a ``.parquet`` path, atomically.

    Parameters
    ----------
    path : str or Path
        ``*.parquet``: the same columns in a Parquet file
        (:func:`fingerfit.io.parquet.pose_meta`: units, tracker frame, quaternion order in
        its metadata; ``sensor`` dictionary-encoded text, the rest float64).
    recording : Recording
        Positions in mm (tracker frame); written in ``units``.
    units : str
        Units for ``x,y,z`` in the file.

    Returns
    -------
    Path
        The written file. Values are written in their shortest round-trip form
        (:func:`fingerfit.io.fastcsv.write_table`), so :func:`read_pose_csv` gives back
        the same numbers.
    """
    from ..session import UNITS_TO_MM
    from .parquet import is_parquet, pose_meta, write_table_file

    if is_parquet(path):
        return _write_parquet(Path(path), recording, UNITS_TO_MM[units], pose_meta(units))
    return write_table_file(
        Path(path), pose_columns(recording, UNITS_TO_MM[units]), pose_meta(units)
    )


def _write_parquet(path: Path, recording: Recording, mm_per_unit: float, meta) -> Path:
    """The long table of :func:`pose_columns` written a row group of frames at a time
    (about :data:`fingerfit.io.parquet.ROW_GROUP_ROWS` rows), each made while the one
    before it is written: the same rows and numbers, without the whole table in memory."""
    from .parquet import ROW_GROUP_ROWS, ParquetSink

    n = recording.n_frames
    step = max(1, ROW_GROUP_ROWS // max(len(recording.sensors), 1))
    with ParquetSink(path, meta) as sink:
        sink.write_blocks(
            pose_block(recording, lo, min(lo + step, n), mm_per_unit)
            for lo in range(0, max(n, 1), step)
        )
    return path
