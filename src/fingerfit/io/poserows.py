"""The rows of a pose table (the canonical pose CSV or its Parquet form) made a
:class:`~fingerfit.session.Recording`: every check of the format, then each sensor's
samples placed on the frame grid (mm, rotation matrices sensor -> tracker).

The table's columns are ``time,sensor,x,y,z,qw,qx,qy,qz`` (``docs/formats.md``): one row
per sensor per frame; time in seconds; ``x,y,z`` the sensor origin in tracker
coordinates (file units); ``(qw,qx,qy,qz)`` a unit quaternion, scalar first, rotating
sensor coordinates into tracker coordinates. The decoders (:mod:`.posecsv`,
:mod:`.poseparquet`) give :class:`PoseRows`; :func:`assemble_rows` checks and places them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from ..session import PoseSeries, Recording, is_sensor_name
from .fastcsv import put_quat_rows, put_rows, put_scaled_rows, rows_where
from .hygiene import (
    QUAT_NORM_TOLERANCE,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
)

HEADER = ("time", "sensor", "x", "y", "z", "qw", "qx", "qy", "qz")
#: The numeric columns, in the order of :attr:`PoseRows.pose` after ``time``.
NUMERIC = ("time", "x", "y", "z", "qw", "qx", "qy", "qz")
#: Rows converted to rotation matrices at a time (bounds the temporary memory).
_BLOCK = 1 << 16


@dataclass
class PoseRows:
    """The decoded data rows of a pose table, in file order (row ``i`` is file line ``i + 2``).

    ``time`` ``(n,)`` s; ``sensor`` ``(n,)`` int codes into ``names``; ``pose`` ``(n, 7)``
    ``x, y, z`` (file units) and ``qw, qx, qy, qz``; NaN where a field is empty.
    """

    time: np.ndarray
    sensor: np.ndarray
    names: list[str]
    pose: np.ndarray


def assemble_rows(
    rows: PoseRows, path: Path, scale_to_mm: float, rate_hz: float | None, first_line: int = 2
) -> Recording:
    """Check the decoded rows and place them per sensor on the frame grid.

    Errors name row ``i`` as line ``i + first_line``: the file line of a CSV (2: after
    the header), the 1-based row of a Parquet file (1).

    Every check and message of the format, in this order: no rows, time missing or going
    backwards, unknown sensor names, implausible coordinates, conflicting duplicates,
    quaternion norm, sampling grid.
    """
    time, code, pose = rows.time, rows.sensor, rows.pose
    n_rows = time.size
    notes: list[str] = []
    if n_rows == 0:
        raise FingerfitError("no data rows", path=path)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise FingerfitError(
            "time is missing or not finite", path=path, line=int(bad[0]) + first_line, field="time"
        )
    back = np.flatnonzero(time[1:] < time[:-1])
    if back.size:
        i = int(back[0]) + 1
        raise FingerfitError(
            f"time goes backwards ({time[i]:.6f} s after {time[i - 1]:.6f} s)",
            path=path,
            line=i + first_line,
            field="time",
        )
    n_codes = len(rows.names)
    # Rows grouped by sensor, in file order within each sensor (for the first row of
    # each name and for duplicates).
    order = np.argsort(code, kind="stable")
    starts = np.searchsorted(code[order], np.arange(n_codes))
    first_row = np.full(n_codes, n_rows, dtype=np.int64)
    present = starts < n_rows
    present[present] = code[order[starts[present]]] == np.flatnonzero(present)
    first_row[present] = order[starts[present]]
    for k in sorted(range(n_codes), key=lambda c: rows.names[c]):
        if first_row[k] < n_rows and not is_sensor_name(rows.names[k]):
            raise FingerfitError(
                f"unknown sensor name '{shown(rows.names[k])}' (expected hand, stylus or "
                "<finger>.<segment>)",
                path=path,
                line=int(first_row[k]) + first_line,
                field="sensor",
            )
    big = implausible_rows(pose[:, :3], scale_to_mm)
    if big.size:
        i = int(big[0])
        j = int(np.nanargmax(np.abs(pose[i, :3])))
        raise FingerfitError(
            implausible_message(float(pose[i, j]) * scale_to_mm),
            path=path,
            line=i + first_line,
            field="xyz"[j],
        )
    # Frames: rows of equal time (time does not decrease, so they are consecutive).
    new = np.empty(n_rows, dtype=bool)
    new[0] = True
    np.not_equal(time[1:], time[:-1], out=new[1:])
    frame_of_row = np.cumsum(new, dtype=np.int64) - 1
    # Exact duplicates (same time, sensor and values) are dropped and counted;
    # conflicting duplicates are an error.
    same_key = code[order[1:]] == code[order[:-1]]
    same_key &= frame_of_row[order[1:]] == frame_of_row[order[:-1]]
    if same_key.any():
        later, earlier = order[1:][same_key], order[:-1][same_key]
        a, b = pose[later], pose[earlier]
        same = np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=1)
        if not same.all():
            i = int(later[~same].min())
            raise FingerfitError(
                f"second, different sample for sensor '{rows.names[code[i]]}' at time "
                f"{time[i]:.6f} s",
                path=path,
                line=i + first_line,
            )
        notes.append(f"{later.size} exact duplicate rows dropped")
        keep = np.ones(n_rows, dtype=bool)
        keep[later] = False
        lines = np.flatnonzero(keep) + first_line
        time, code, pose = time[keep], code[keep], pose[keep]
        new = new[keep]
        new[0] = True
        new[1:] = time[1:] != time[:-1]
        del keep
    else:
        lines = None
    del order, same_key, frame_of_row  # a row's frame is cumsum(new) - 1, made again below

    def line_of(i: int) -> int:
        return int(lines[i]) if lines is not None else i + first_line

    finite = np.isfinite(pose)
    complete = finite.all(axis=1)
    n_partial = int(np.count_nonzero(~complete & finite.any(axis=1)))
    del finite
    if n_partial:
        notes.append(f"{n_partial} samples with empty fields treated as missing")
    q = pose[:, 3:]
    with np.errstate(over="ignore", invalid="ignore"):  # a huge component: norm inf, refused
        norm = np.sqrt(np.einsum("ij,ij->i", q, q))
    bad = np.flatnonzero(complete & (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE))
    if bad.size:
        i = int(bad[0])
        raise FingerfitError(
            f"quaternion (qw,qx,qy,qz) has norm {norm[i]:.6g}, not 1", path=path, line=line_of(i)
        )
    del norm

    row_of_frame = np.flatnonzero(new)
    frame_times = time[row_of_frame]
    grid = None  # frame -> grid index, when frames go on the sampling grid
    if rate_hz is not None and frame_times.size > 1:
        frame_lines = row_of_frame + first_line if lines is None else lines[row_of_frame]
        full_time, grid = place_on_grid(frame_times, rate_hz, frame_lines, path)
        notes += frames_missing_note(full_time.size - frame_times.size)
        frame_times = full_time
    n = frame_times.size
    del row_of_frame

    # Per sensor in order of first appearance: positions (mm) and rotation matrices,
    # converted a block of rows at a time.
    appear = [int(k) for k in np.argsort(first_row, kind="stable") if first_row[k] < n_rows]
    # np.empty, not np.full: each page is written once, then the frames without a
    # sample are set to NaN.
    pos = {k: np.empty((n, 3)) for k in appear}
    rot = {k: np.empty((n, 3, 3)) for k in appear}
    filled = {k: np.zeros(n, dtype=bool) for k in appear}
    frames_before = 0
    for lo in range(0, time.size, _BLOCK):
        hi = min(lo + _BLOCK, time.size)
        ok = complete[lo:hi]
        f = np.cumsum(new[lo:hi], dtype=np.int64)  # the rows' frames
        f += frames_before - 1
        frames_before = int(f[-1]) + 1
        if grid is not None:
            f = grid[f]
        c, p = code[lo:hi], pose[lo:hi]
        if not ok.all():
            c, f, p = c[ok], f[ok], p[ok]
        for k in np.flatnonzero(np.bincount(c, minlength=len(rows.names))):
            m = rows_where(c, k)  # a strided slice when sensors take turns regularly
            fk = f[m]
            put_scaled_rows(pos[int(k)], fk, p[m, :3], scale_to_mm)
            put_quat_rows(rot[int(k)], fk, p[m, 3:])
            put_rows(filled[int(k)], fk, True)
    poses = sensor_poses(appear, rows.names, filled, pos, rot, n, notes)
    return Recording(path.name, frame_times, poses, notes)


def sensor_poses(
    appear: list[int],
    names: list[str],
    filled: dict,
    pos: dict,
    rot: dict,
    n: int,
    notes: list[str],
) -> dict[str, PoseSeries]:
    """Each sensor's poses (in order of first appearance), NaN in the frames it has no
    sample in; a note per sensor with missing frames is added to ``notes``. The arrays of
    ``filled`` (frames with a sample), ``pos`` and ``rot`` are taken out of them."""
    poses: dict[str, PoseSeries] = {}
    for k in appear:
        name = names[k]
        gap = ~filled.pop(k)
        p_k, r_k = pos.pop(k), rot.pop(k)
        p_k[gap] = np.nan
        r_k[gap] = np.nan
        poses[name] = PoseSeries(p_k, r_k)
        notes += missing_note(name, int(np.count_nonzero(gap)), n)
    return poses
