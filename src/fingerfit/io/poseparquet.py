"""The Parquet form of the pose table (:data:`fingerfit.io.parquet.POSE`) read into a
:class:`~fingerfit.session.Recording`: the common case streamed straight into the
recording's arrays, anything unusual by the reference path (:func:`fingerfit.io.parquet.
read_parquet`, then :func:`fingerfit.io.poserows.assemble_rows`), which names the error.
"""

from __future__ import annotations

import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from ..session import Recording, is_sensor_name
from .fastcsv import put_quat_rows, put_rows, put_scaled_rows, rows_where
from .hygiene import (
    QUAT_NORM_TOLERANCE,
    frames_missing_note,
    implausible_rows,
    place_on_grid,
    plain_block,
)
from .poserows import HEADER, NUMERIC, PoseRows, assemble_rows, sensor_poses


def read_pose_parquet(
    path: Path, units: str, rate_hz: float | None, scale_to_mm: float | None
) -> Recording:
    """A pose Parquet file (:data:`fingerfit.io.parquet.POSE`): the columns of the CSV,
    its metadata stating the units (which must be ``units`` unless ``scale_to_mm`` is
    given), then every check of the CSV reader, rows named by their 1-based index."""
    from ..session import UNITS_TO_MM

    if scale_to_mm is None and units not in UNITS_TO_MM:
        raise FingerfitError(f"unknown units '{units}'", path=path, field="units")
    try:
        return _read_parquet_fast(path, units, rate_hz, scale_to_mm)
    except Exception:  # _Irregular, a FingerfitError, a damaged page Arrow reports
        pass  # the reference path below says what is wrong, or reads what is unusual
    rows, stated = read_pose_parquet_rows(path)
    if scale_to_mm is None and stated != units:
        raise FingerfitError(
            f"the file's positions are in {stated}, not {units} as stated for it "
            "(session.toml units or --units)",
            path=path,
            field="fingerfit.units",
        )
    scale = UNITS_TO_MM[stated] if scale_to_mm is None else scale_to_mm
    return assemble_rows(rows, path, scale, rate_hz, first_line=1)


def read_pose_parquet_rows(path: Path) -> tuple[PoseRows, str]:
    """The rows of a pose Parquet file as stored, in file order and file units, with the
    units its metadata states; unchecked beyond the file, its metadata and its columns
    (:func:`read_pose_parquet` checks and places them).

    Parameters
    ----------
    path : Path

    Returns
    -------
    rows : PoseRows
        ``time`` ``(n,)`` s, ``sensor`` ``(n,)`` codes into ``names``, ``pose`` ``(n, 7)``
        ``x, y, z`` (file units) and ``qw, qx, qy, qz`` (a null read as NaN).
    units : str
        ``fingerfit.units``: ``mm``, ``cm``, ``m`` or ``in``.

    Raises
    ------
    FingerfitError
        Not a readable pose Parquet file, or units other than those.
    """
    from ..session import UNITS_TO_MM
    from .parquet import POSE, QUAT_ORDER, TRACKER_FRAME, read_parquet

    table = read_parquet(
        path,
        POSE,
        columns=HEADER,
        text=("sensor",),
        expect={"units": None, "frame": TRACKER_FRAME, "quaternion_order": QUAT_ORDER},
    )
    stated = table.meta["fingerfit.units"]
    if stated not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{shown(stated)}' (use {', '.join(UNITS_TO_MM)})",
            path=path,
            field="fingerfit.units",
        )
    cols = table.columns
    codes, names = cols["sensor"]
    pose = np.empty((table.n_rows, 7))
    for j, c in enumerate(NUMERIC[1:]):
        pose[:, j] = cols.pop(c)
    return PoseRows(cols["time"], codes, list(names), pose), stated


#: Threads placing the blocks of a pose Parquet file, and the rows of a block.
_THREADS = 2
_PARQUET_BLOCK = 1 << 15
#: Elements added to each row of a block buffer (see ``_read_parquet_fast``).
_PAD = 24


def _first(rows: slice | np.ndarray) -> int:
    """The first row of a :func:`~fingerfit.io.fastcsv.rows_where` selection."""
    return int(rows.start) if isinstance(rows, slice) else int(rows[0])


class _Irregular(Exception):
    """A pose Parquet file the streaming reader does not vouch for (an error somewhere,
    exact duplicates): read again by the reference path, which names the error."""


def _read_parquet_fast(
    path: Path, units: str, rate_hz: float | None, scale_to_mm: float | None
) -> Recording:
    """The common case of a pose Parquet file, streamed into the recording's arrays.

    The time and sensor columns first (the frames, the sampling grid, the sensors), then
    the numbers :data:`_PARQUET_BLOCK` rows at a time straight into each sensor's positions and
    rotation matrices: no whole table and no ``(n, 7)`` copy. The same arithmetic as
    :func:`assemble_rows` (the same bits); anything :func:`assemble_rows` would refuse or repair
    (exact duplicates) raises :class:`_Irregular` or :class:`FingerfitError`, and the
    caller reads the file by the reference path.
    """
    from ..memory import release_freed_memory
    from ..session import UNITS_TO_MM
    from .parquet import (
        POSE,
        QUAT_ORDER,
        TRACKER_FRAME,
        _metadata,
        _pa,
        _text_codes,
        float_blocks,
        open_checked,
    )

    pa, _ = _pa()
    pf, fh, schema = open_checked(
        path,
        POSE,
        columns=HEADER,
        text=("sensor",),
        expect={"units": None, "frame": TRACKER_FRAME, "quaternion_order": QUAT_ORDER},
    )
    with fh:
        stated = _metadata(schema)["fingerfit.units"]
        if stated not in UNITS_TO_MM or (scale_to_mm is None and stated != units):
            raise _Irregular
        scale = UNITS_TO_MM[stated] if scale_to_mm is None else scale_to_mm
        n_rows = pf.metadata.num_rows
        # time and sensor a row group at a time into their arrays (no whole column twice)
        time = np.empty(n_rows)
        code = np.empty(n_rows, dtype=np.int32)
        code_of: dict[str, int] = {}
        lo = 0
        for g in range(pf.num_row_groups):
            head = pf.read_row_group(g, columns=["time", "sensor"], use_threads=True)
            m = head.num_rows
            if lo + m > n_rows:
                raise _Irregular
            time[lo : lo + m] = head.column("time").to_numpy()  # a null becomes NaN
            c, group_names = _text_codes(pa, head.column("sensor"))
            lut = np.array([code_of.setdefault(v, len(code_of)) for v in group_names], np.int32)
            code[lo : lo + m] = lut[c] if lut.size else c
            lo += m
            del head, c
        if lo != n_rows:
            raise _Irregular
        names = list(code_of)
        if n_rows == 0 or not np.isfinite(time).all() or (time[1:] < time[:-1]).any():
            raise _Irregular
        n_codes = len(names)
        counts = np.bincount(code, minlength=n_codes)
        present = [int(k) for k in np.flatnonzero(counts)]
        if not all(is_sensor_name(names[k]) for k in present):
            raise _Irregular
        new = np.empty(n_rows, dtype=bool)
        new[0] = True
        np.not_equal(time[1:], time[:-1], out=new[1:])
        row_of_frame = np.flatnonzero(new)
        frame_of_row = np.cumsum(new, dtype=np.int64 if n_rows >= 1 << 31 else np.int32)
        # a sensor twice in a frame (a duplicate): its rows' frames do not increase
        first_row = {}
        for k in present:
            rows = rows_where(code, k)
            frames = frame_of_row[rows]
            first_row[k] = _first(rows)
            if (frames[1:] == frames[:-1]).any():
                raise _Irregular
            del rows, frames
        del frame_of_row
        frame_times = time[row_of_frame]
        grid = None
        frames_note: list[str] = []
        if rate_hz is not None and frame_times.size > 1:
            full_time, grid = place_on_grid(frame_times, rate_hz, row_of_frame + 1, path)
            frames_note = frames_missing_note(full_time.size - frame_times.size)
            frame_times = full_time
        n = frame_times.size
        del time
        # what the frames and the grid used goes back to the system before the
        # recording's arrays are allocated (else it counts in the peak beside them)
        release_freed_memory()

        appear = sorted(present, key=lambda k: first_row[k])
        pos = {k: np.empty((n, 3)) for k in appear}
        rot = {k: np.empty((n, 3, 3)) for k in appear}
        filled = {k: np.zeros(n, dtype=bool) for k in appear}
        buffers = threading.local()

        def place(lo: int, cols: list[np.ndarray]) -> int:
            """Check and place rows ``lo:lo + m``; their samples with empty fields."""
            m = cols[0].size
            hi = lo + m
            # the rows as (m, 7) with each column contiguous (a (7, m) buffer seen
            # transposed): copied column by column, checked column by column
            block = getattr(buffers, "block", None)
            if block is None or block.shape[1] < m:
                # rows a few cache lines longer than the block: columns a power of two
                # apart share cache sets, which makes strided work on rows several
                # times slower
                block = buffers.block = np.empty((7, max(m, _PARQUET_BLOCK) + _PAD))
                buffers.sums = np.empty(block.shape[1])
            for j, v in enumerate(cols):
                block[j, :m] = v
            del cols
            p, total = block[:, :m].T, buffers.sums[:m]
            partial = 0
            with np.errstate(over="ignore", invalid="ignore"):
                np.add.reduce(block[:, :m], axis=0, out=total)
            if np.isfinite(total).all():  # every field of every row a finite number
                ok = True
                np.multiply(block[3, :m], block[3, :m], out=total)  # squared norms
                for j in (4, 5, 6):
                    total += block[j, :m] * block[j, :m]
                if not plain_block(block[:3, :m], total, scale):
                    raise _Irregular
            else:
                finite = np.isfinite(p)
                ok = finite.all(axis=1)
                if np.isinf(p).any():
                    raise _Irregular
                partial = int(np.count_nonzero(~ok & finite.any(axis=1)))
                if implausible_rows(p[:, :3], scale).size:
                    raise _Irregular
                q = p[:, 3:]
                with np.errstate(over="ignore", invalid="ignore"):
                    norm = np.sqrt(np.einsum("ij,ij->i", q, q))
                if (ok & (np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE)).any():
                    raise _Irregular
            f = np.cumsum(new[lo:hi], dtype=np.int64)  # the rows' frames
            f += int(np.searchsorted(row_of_frame, lo)) - 1  # frames begun before
            if grid is not None:
                f = grid[f]
            c = code[lo:hi]
            if ok is not True and not ok.all():
                c, f, p = c[ok], f[ok], p[ok]
            for k in np.flatnonzero(np.bincount(c, minlength=n_codes)):
                r = rows_where(c, k)
                fk = f[r]
                put_scaled_rows(pos[int(k)], fk, p[r, :3], scale)
                put_quat_rows(rot[int(k)], fk, p[r, 3:])
                put_rows(filled[int(k)], fk, True)
            return partial

        # Blocks are placed by two threads (NumPy works without the GIL; each block's
        # rows go to frames of their own) while Arrow decodes the next ones.
        n_partial = 0
        rows_read = 0
        pending: deque = deque()
        blocks = float_blocks(pf, NUMERIC[1:], n_rows, batch_rows=_PARQUET_BLOCK, ahead=True)
        with ThreadPoolExecutor(max_workers=_THREADS) as pool:
            try:
                for lo, cols in blocks:
                    if len(pending) >= _THREADS:
                        n_partial += pending.popleft().result()
                    pending.append(pool.submit(place, lo, cols))
                    rows_read = lo + cols[0].size
                    del cols
                while pending:
                    n_partial += pending.popleft().result()
            finally:
                blocks.close()
                for fut in pending:
                    fut.cancel()
        if rows_read != n_rows:
            raise _Irregular
    notes: list[str] = []
    if n_partial:
        notes.append(f"{n_partial} samples with empty fields treated as missing")
    notes += frames_note
    poses = sensor_poses(appear, names, filled, pos, rot, n, notes)
    return Recording(path.name, frame_times, poses, notes)
