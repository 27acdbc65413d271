"""Recordings written as the canonical pose table: a CSV, or its Parquet form for a
``.parquet`` path (one row per present sample, ordered by frame then sensor); and a pose
table copied row for row from one form to the other (``fingerfit convert``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..session import Recording
from ..transforms import quat_wxyz_columns
from .poserows import HEADER, PoseRows


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


@dataclass
class PoseTable:
    """A pose table read for conversion (:func:`read_pose_table`).

    Attributes
    ----------
    rows : PoseRows
        The rows as stored, in file order and file units.
    recording : Recording
        The same rows checked and placed per sensor (mm, tracker frame), as
        :func:`fingerfit.io.read_pose_csv` reads them.
    units : str
        The units of the rows' positions.
    """

    rows: PoseRows
    recording: Recording
    units: str


def read_pose_table(
    path: Path, *, units: str | None = None, rate_hz: float | None = None
) -> PoseTable:
    """Read a pose table (CSV, or Parquet by the extension) row for row, with every check
    of :func:`fingerfit.io.read_pose_csv`.

    Parameters
    ----------
    path : Path
    units : str, optional
        Units of the positions: a CSV's (default mm); a Parquet file states its own, which
        ``units`` must then agree with.
    rate_hz : float, optional
        Sampling rate (Hz) the frames must lie on (checked, as the reader does).

    Returns
    -------
    PoseTable

    Raises
    ------
    FingerfitError
        Anything the reader refuses, naming the file and the line (a Parquet file's row).
    """
    from ..session import UNITS_TO_MM
    from .parquet import is_parquet
    from .posecsv import read_pose_rows
    from .poseparquet import read_pose_parquet_rows
    from .poserows import assemble_rows

    if units is not None and units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
    if is_parquet(path):
        rows, stated = read_pose_parquet_rows(path)
        if units is not None and units != stated:
            raise FingerfitError(
                f"the file's positions are in {stated}, not {units} as stated for it (--units)",
                path=path,
                field="fingerfit.units",
            )
        units, first_line = stated, 1
    else:
        rows, units, first_line = read_pose_rows(path), units or "mm", 2
    recording = assemble_rows(rows, path, UNITS_TO_MM[units], rate_hz, first_line=first_line)
    return PoseTable(rows, recording, units)


def write_pose_rows(path: Path, table: PoseTable, units: str) -> Path:
    """Write the rows of a pose table as they are, as CSV or Parquet by the extension of
    ``path``, atomically: the same rows in the same order, the numbers bit for bit
    (positions converted when ``units`` differ from the table's, as the reader and the
    writer of a recording convert them: to mm, then to ``units``).

    Parameters
    ----------
    path : Path
    table : PoseTable
    units : str
        Units of the written positions (Parquet: stated in its metadata).

    Returns
    -------
    Path
    """
    from ..session import UNITS_TO_MM
    from .parquet import pose_meta, write_table_file

    rows = table.rows
    cols: dict[str, object] = {"time": rows.time, "sensor": (rows.sensor, list(rows.names))}
    for j, c in enumerate(HEADER[2:]):
        v = rows.pose[:, j]
        if j < 3 and units != table.units:
            v = np.divide(v * UNITS_TO_MM[table.units], UNITS_TO_MM[units])
        cols[c] = np.ascontiguousarray(v)
    return write_table_file(path, cols, pose_meta(units))
