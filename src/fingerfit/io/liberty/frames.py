"""Liberty/Patriot station records -> frames -> :class:`~fingerfit.session.Recording`,
and the two file readers (parse, then frames, then the recording checks).

Frames: by the frame-count item when present; otherwise by station cycle (a record
whose station number is not above the previous one starts a new frame). Time: from
the timestamp item, else frame count / rate, else cycle index / rate. With a rate,
frames are placed on the ``1/rate`` grid and missing frames appear as NaN rows.
Returned positions are millimetres in tracker coordinates and rotation matrices map
sensor into tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ...errors import FingerfitError
from ...session import UNITS_TO_MM, PoseSeries, Recording
from ...transforms import row_norms
from ..fastcsv import (
    gap_rows,
    put_quat_rows,
    put_rows,
    put_scaled_rows,
    row_blocks,
    rows_where,
)
from ..hygiene import (
    QUAT_NORM_TOLERANCE,
    check_grid_size,
    check_recording,
    frames_missing_note,
    implausible_message,
    implausible_rows,
    missing_note,
    place_on_grid,
    repeated_rows,
)
from .ascii import parse_liberty_ascii
from .binary import parse_liberty_binary
from .records import MAX_STATION, LibertyRecords

#: Largest Euler angle magnitude accepted (deg); the device reports within +-180.
MAX_EULER_DEG = 360.0
#: Records converted to rotation matrices at a time (bounds the temporary memory).
_BLOCK = 1 << 16


def records_to_recording(
    records: LibertyRecords,
    path: str | Path,
    *,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
) -> Recording:
    """Group station records into frames and convert to a :class:`Recording`.

    Parameters
    ----------
    records : LibertyRecords
    path : str or Path
        Source file, for messages and the recording's name.
    units : str
        Units of the position item (``in`` device default, ``cm``, ``mm``, ``m``).
    rate_hz : float, optional
        Frame rate; needed when the output list has no timestamp. With it, frames go
        on the ``1/rate_hz`` grid and missing frames become NaN rows.
    sensors : mapping int -> str, optional
        Station number -> sensor name. Every station in the data must be mapped and
        every mapped station must have records. Default: the station numbers as names.
    keep_repeats : bool
        Without a frame-count item, a whole station cycle identical to the previous
        one (timestamp included, if any) is a repeated sample and is dropped and
        counted, unless this is True (a perfectly still set-up can repeat exactly at
        ASCII precision). With a frame count, a record repeating its frame count and
        values is always a repeat, and one with different values an error.

    Returns
    -------
    Recording
        Time (s), positions (mm, tracker frame), rotations (sensor -> tracker).
    """
    path = Path(path)
    if units not in UNITS_TO_MM:
        raise FingerfitError(
            f"unknown units '{units}' (use {', '.join(UNITS_TO_MM)})", path=path, field="units"
        )
    if rate_hz is not None and not rate_hz > 0:
        raise FingerfitError("the rate must be positive (Hz)", path=path, field="rate")
    scale = UNITS_TO_MM[units]
    notes = [f"{records.n_records} station records read"]
    station = records.station
    present = np.unique(station)
    if sensors is not None:
        unknown = np.flatnonzero(~np.isin(station, list(sensors)))
        if unknown.size:
            i = int(unknown[0])
            mapped = ", ".join(f"{k}={v}" for k, v in sensors.items())
            raise records.error(f"unknown station {station[i]} (not in the map {mapped})", i, path)
        absent = [k for k in sensors if k not in present]
        if absent:
            raise FingerfitError(
                f"mapped station {absent[0]} ('{sensors[absent[0]]}') has no records", path=path
            )
        stations = list(sensors)
        names = [sensors[s] for s in stations]
    else:
        stations = [int(s) for s in present]
        names = [str(s) for s in stations]
    lut = np.full(MAX_STATION + 1, -1, dtype=np.int16)
    lut[stations] = np.arange(len(stations))
    scol = lut[station]
    items = records.items

    if "frame" in items:
        fc = records.values["frame"]
        records.check_increasing(fc, range(station.size), path, what="frame count", strict=False)
        new_frame = np.empty(station.size, dtype=bool)
        new_frame[:1] = True
        np.not_equal(fc[1:], fc[:-1], out=new_frame[1:])
        if station.size < 2 or np.all(new_frame[1:] | (station[1:] > station[:-1])):
            # stations ascending within every frame (the device's order): no repeats,
            # frames in order, nothing to sort
            rec_idx = range(station.size)  # indexable like an array, no memory
            frame_of = np.cumsum(new_frame, dtype=np.int64)
            frame_of -= 1
            first_rec = np.flatnonzero(new_frame)
            frame_ids = fc[first_rec]
        else:
            values = records.matrix()
            key = fc.astype(np.int64) * (MAX_STATION + 1) + station
            _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
            orig = first[inverse]
            dup = orig != np.arange(station.size)
            keep = ~dup
            if dup.any():
                same = np.all(values == values[orig], axis=1)
                if not same.all():
                    i = int(np.flatnonzero(~same)[0])
                    raise records.error(
                        f"second, different record for station {station[i]} in frame {fc[i]:.0f}",
                        i,
                        path,
                    )
                notes.append(
                    f"{int(dup.sum())} exactly repeated records (same frame count) dropped"
                )
            del values
            rec_idx = np.flatnonzero(keep)
            fcs = fc[rec_idx]
            frame_ids, frame_of = np.unique(fcs, return_inverse=True)
            first_rec = rec_idx[np.unique(frame_of, return_index=True)[1]]
        del new_frame
        try:
            check_grid_size(
                frame_ids - frame_ids[0], np.arange(frame_ids.size), path, "frame count"
            )
        except FingerfitError as exc:  # name the record, not the frame index
            raise records.error(
                exc.reason, int(first_rec[exc.line or 0]), path, field=exc.field
            ) from None
        grid_idx = (frame_ids - frame_ids[0]).astype(np.int64)
        n = int(grid_idx[-1]) + 1
        if "timestamp" in items:
            ts = records.values["timestamp"][first_rec] / 1000.0
            records.check_increasing(ts, first_rec, path, what="timestamp", strict=True)
            time = np.interp(np.arange(n), grid_idx, ts)
            time[grid_idx] = ts
            notes.append("frames by frame count, time from the timestamp item")
        elif rate_hz is not None:
            time = (frame_ids[0] + np.arange(n)) / rate_hz
            notes.append(f"frames by frame count, time = frame count / {rate_hz:g} Hz")
        else:
            raise FingerfitError(
                "--rate is needed: the output list has a frame count but no timestamp",
                path=path,
                field="rate",
            )
        notes += frames_missing_note(n - frame_ids.size)
        frame_of_rec = np.take(grid_idx, frame_of, out=frame_of)  # in place
    else:
        new = np.concatenate([[True], station[1:] <= station[:-1]])
        cycle = np.cumsum(new) - 1
        n_cycles = int(cycle[-1]) + 1
        values = records.matrix()
        width = values.shape[1]
        block = np.full((n_cycles, len(stations), width), np.nan)
        block[cycle, scol] = values
        del values
        rep = repeated_rows(block.reshape(n_cycles, -1))
        del block
        if rep.any() and not keep_repeats:
            notes.append(
                f"{int(rep.sum())} exactly repeated frames ({int(np.isin(cycle, np.flatnonzero(rep)).sum())} "
                "records) dropped"
            )
            keep_rec = ~rep[cycle]
            rec_idx = np.flatnonzero(keep_rec)
            cyc_keep = np.flatnonzero(~rep)
            renum = np.full(n_cycles, -1)
            renum[cyc_keep] = np.arange(cyc_keep.size)
            frame_of = renum[cycle[rec_idx]]
        else:
            rec_idx = np.arange(station.size)
            frame_of = cycle
        n_frames = int(frame_of[-1]) + 1
        first_rec = rec_idx[np.unique(frame_of, return_index=True)[1]]
        if "timestamp" in items:
            ts = records.values["timestamp"][first_rec] / 1000.0
            records.check_increasing(ts, first_rec, path, what="timestamp", strict=True)
            if rate_hz is not None:
                try:
                    time, grid_idx = place_on_grid(ts, rate_hz, np.arange(ts.size), path)
                except FingerfitError as exc:
                    raise records.error(
                        exc.reason, int(first_rec[exc.line or 0]), path, field=exc.field
                    ) from None
                notes += frames_missing_note(time.size - n_frames)
                frame_of = grid_idx[frame_of]
                n = time.size
            else:
                time, n = ts, n_frames
                notes.append("no --rate: frames kept at their timestamps, not placed on a grid")
            notes.insert(1, "frames by station cycle, time from the timestamp item")
        elif rate_hz is not None:
            time = np.arange(n_frames) / rate_hz
            n = n_frames
            notes.append(
                f"frames by station cycle, time = cycle / {rate_hz:g} Hz (no timestamp or "
                "frame count item: lost frames cannot be detected)"
            )
        else:
            raise FingerfitError(
                "--rate is needed: the output list has no timestamp or frame count",
                path=path,
                field="rate",
            )
        frame_of_rec = frame_of
        del cycle
    del frame_of
    if n < 2**31:  # a frame index per record in half the memory while the arrays fill
        frame_of_rec = frame_of_rec.astype(np.int32)

    sel = rec_idx
    every = len(sel) == station.size  # no record dropped: use the arrays without a copy

    def taken(item: str) -> np.ndarray:
        return records.values[item] if every else records.values[item][sel]

    big = implausible_rows(taken("position"), scale)
    if big.size:
        i = int(sel[big[0]])
        v = records.values["position"][i]
        raise records.error(
            implausible_message(float(v[int(np.argmax(np.abs(v)))]) * scale),
            i,
            path,
            field="position",
        )
    if "quaternion" in items:
        q = taken("quaternion")
        for r in row_blocks(slice(0, q.shape[0]), _BLOCK):  # float64 a block at a time
            with np.errstate(over="ignore"):  # a huge component: norm inf, refused below
                norm = row_norms(np.asarray(q[r], dtype=float))
            bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOLERANCE)
            if bad.size:
                i = int(sel[r.start + bad[0]])
                raise records.error(
                    f"quaternion (w,x,y,z) has norm {norm[bad[0]]:.6g}, not 1 (wrong --items?)",
                    i,
                    path,
                )
        del q
        if "euler" in items:
            notes.append("orientation from the quaternion item (Euler angles not used)")
    else:
        e = np.asarray(taken("euler"), dtype=float)
        wild = np.flatnonzero((np.abs(e) > MAX_EULER_DEG).any(axis=1))
        if wild.size:
            i = int(sel[wild[0]])
            v = records.values["euler"][i]
            raise records.error(
                f"Euler angle {v[int(np.argmax(np.abs(v)))]:.6g} deg is outside "
                f"+-{MAX_EULER_DEG:g} deg (garbled record or wrong --items?)",
                i,
                path,
                field="euler",
            )
        del e
    # Per station, a block of records at a time (bounded temporary memory).
    poses: dict[str, PoseSeries] = {}
    missing: list[str] = []
    scol_sel = scol if every else scol[sel]
    for k, name in enumerate(names):
        # every frame is written once: by a record below or as a gap (NaN) at the end
        pos = np.empty((n, 3))
        rot = np.empty((n, 3, 3))
        rows_k = rows_where(scol_sel, k)  # a strided slice when stations take turns
        for r in row_blocks(rows_k, _BLOCK):
            at = frame_of_rec[r]
            src = r if every else sel[r]
            put_scaled_rows(pos, at, records.values["position"][src], scale)
            if "quaternion" in items:
                put_quat_rows(rot, at, records.values["quaternion"][src])
            else:
                put_rows(
                    rot,
                    at,
                    Rotation.from_euler(
                        "ZYX", np.asarray(records.values["euler"][src], dtype=float), degrees=True
                    ).as_matrix(),
                )
        gap = gap_rows(n, [frame_of_rec[rows_k]])
        if gap is not None:
            pos[gap] = np.nan
            rot[gap] = np.nan
        # every record placed is finite (refused otherwise): the gaps are what is missing
        missing += missing_note(name, 0 if gap is None else gap.size, n)
        poses[name] = PoseSeries(pos, rot)
    flagged = records.indicator if every else records.indicator[sel]
    flagged = flagged[flagged != ""]
    for ch in sorted(set(np.unique(flagged).tolist())):
        notes.append(
            f"{int((flagged == ch).sum())} records with indicator '{ch}' after the station number"
        )
    return Recording(path.name, np.asarray(time, dtype=float), poses, notes + missing)


def read_liberty_ascii(
    path: str | Path,
    *,
    items: str | Sequence[str] | None = None,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
    check: bool = True,
) -> Recording:
    """Read a Liberty/Patriot ASCII stream into a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
    items : str or sequence, optional
        Output list, device codes or names (default ``2,4,1``: position, Euler).
    units : str
        Position units in the file (device default ``in``).
    rate_hz : float, optional
        Frame rate (needed without a timestamp item).
    sensors : mapping int -> str, optional
        Station -> sensor name; unknown stations are an error.
    keep_repeats : bool
        Keep exactly repeated station cycles (see :func:`records_to_recording`).
    check : bool
        Run :func:`~fingerfit.io.hygiene.check_recording` (unit plausibility and
        jump flags).

    Returns
    -------
    Recording
        Time s, positions mm (tracker frame), rotations sensor -> tracker; ``notes``
        count everything dropped, missing or flagged.
    """
    recs = parse_liberty_ascii(path, items)
    rec = records_to_recording(
        recs, path, units=units, rate_hz=rate_hz, sensors=sensors, keep_repeats=keep_repeats
    )
    if check:
        check_recording(rec, path)
    return rec


def read_liberty_binary(
    path: str | Path,
    *,
    items: str | Sequence[str] | None = None,
    units: str = "in",
    rate_hz: float | None = None,
    sensors: Mapping[int, str] | None = None,
    keep_repeats: bool = False,
    check: bool = True,
) -> Recording:
    """Read binary ``LY``/``PA`` records into a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
    items, units, rate_hz, sensors, keep_repeats, check
        As for :func:`read_liberty_ascii` (default list position + Euler, inches).

    Returns
    -------
    Recording
        Time s, positions mm (tracker frame), rotations sensor -> tracker; ``notes``
        count everything dropped, missing or flagged (including non-zero error bytes).
    """
    recs = parse_liberty_binary(path, items)
    rec = records_to_recording(
        recs, path, units=units, rate_hz=rate_hz, sensors=sensors, keep_repeats=keep_repeats
    )
    if check:
        check_recording(rec, path)
    return rec
