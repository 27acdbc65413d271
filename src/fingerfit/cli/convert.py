"""``fingerfit convert``: real tracker files -> the canonical pose CSV of the session format,
a pose table from CSV to Parquet or back, and any of them -> OpenSim's orientation table
(``.sto``) or markers (``.trc``)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

if TYPE_CHECKING:
    from ..session import Recording
import typer
from rich.markup import escape

from ..errors import FingerfitError
from .app import Quiet, app, notice, out, progress, user_errors


class SourceFormat(StrEnum):
    """Input formats of ``fingerfit convert``."""

    pose_csv = "pose-csv"
    liberty = "liberty"
    liberty_binary = "liberty-binary"
    wide_csv = "wide-csv"
    c3d = "c3d"


def parse_map(spec: str | None, *, numeric: bool) -> dict | None:
    """Parse ``1=hand,2=index.proximal`` (or ``ArmR=hand,...`` for C3D).

    Parameters
    ----------
    spec : str or None
    numeric : bool
        Whether the keys are station numbers.

    Returns
    -------
    dict or None
        Station number (int) or channel name (str) -> sensor name.
    """
    from ..session import is_sensor_name

    if spec is None:
        return None
    out_map: dict = {}
    for part in spec.split(","):
        if not part.strip():
            continue
        key, sep, name = (s.strip() for s in part.partition("="))
        if not sep or not key or not name:
            raise FingerfitError(f"'{part.strip()}' is not KEY=SENSOR", field="--map")
        if numeric:
            if not key.isdigit():
                raise FingerfitError(f"station '{key}' is not a number", field="--map")
            key = int(key)
        if not is_sensor_name(name):
            raise FingerfitError(
                f"'{name}' is not a sensor name (hand, stylus or <finger>.<segment>, "
                "e.g. index.proximal)",
                field="--map",
            )
        if key in out_map:
            raise FingerfitError(f"'{key}' mapped twice", field="--map")
        if name in out_map.values():
            raise FingerfitError(f"sensor '{name}' given twice", field="--map")
        out_map[key] = name
    if not out_map:
        raise FingerfitError("empty map", field="--map")
    return out_map


def _write_residuals(path: Path, rec: Recording, fits: dict) -> None:
    import pandas as pd

    from ..io.atomic import atomic_write
    from ..io.parquet import RESIDUALS, TableMeta, is_parquet, write_table_file

    frames = []
    for name, fit in fits.items():
        frames.append(
            pd.DataFrame(
                {
                    "time": rec.time,
                    "segment": name,
                    "residual_mm": fit.residual,
                    "markers": fit.n_markers,
                }
            )
        )
    meta = TableMeta(RESIDUALS, units="mm")
    if not frames and not is_parquet(path):
        with atomic_write(path, newline="") as fh:
            pd.DataFrame().to_csv(fh, index=False, lineterminator="\n")
        return
    if not frames:
        frames = [
            pd.DataFrame(
                {
                    "time": pd.Series([], dtype=float),
                    "segment": pd.Series([], dtype=object),
                    "residual_mm": pd.Series([], dtype=float),
                    "markers": pd.Series([], dtype="int64"),
                }
            )
        ]
    write_table_file(path, pd.concat(frames, ignore_index=True), meta)


@app.command()
@user_errors
def convert(
    source: Annotated[Path, typer.Argument(help="Tracker file to convert.", show_default=False)],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Pose CSV to write (OUT.parquet: its Parquet form; OUT.sto: OpenSim "
            "orientations; OUT.trc: the sensor origins as OpenSim markers, m).",
            show_default=False,
        ),
    ],
    fmt: Annotated[
        SourceFormat | None,
        typer.Option(
            "--from",
            help="Input format (default: from the file: a pose CSV by its header, .parquet "
            "by its metadata, .c3d; Liberty files and wide CSV need it).",
            case_sensitive=False,
            show_default=False,
        ),
    ] = None,
    units: Annotated[
        str | None,
        typer.Option(
            help="Position units in the input (mm, cm, m, in). Default: in for liberty "
            "formats (the device default), POINT:UNITS for c3d, mm for a pose CSV, the "
            "file's own for .parquet; required for wide-csv."
        ),
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            min=0.001,
            help="Frame rate (Hz). Places frames on the 1/rate grid so lost frames show "
            "as NaN; needed when the input has no time.",
        ),
    ] = None,
    map_: Annotated[
        str | None,
        typer.Option(
            "--map",
            help="Station/channel -> sensor name, e.g. 1=hand,2=index.proximal "
            "(c3d: ArmR=hand,...).",
        ),
    ] = None,
    items: Annotated[
        str | None,
        typer.Option(
            help="liberty: output list, device codes or names (default 2,4,1 = position, "
            "Euler; 7 quaternion w,x,y,z; 8 timestamp ms; 9 frame count)."
        ),
    ] = None,
    columns: Annotated[
        str | None,
        typer.Option(
            help="wide-csv: column templates, e.g. 'time=Time;qw=w{n};qx=x{n};qy=y{n};"
            "qz=z{n};x=loc{n}_x;y=loc{n}_y;z=loc{n}_z' (the default)."
        ),
    ] = None,
    clusters: Annotated[
        str | None,
        typer.Option(
            help="c3d: marker clusters 'Seg=m1,m2,m3;...' (default: markers named "
            "<segment><number>, 3 or more)."
        ),
    ] = None,
    static: Annotated[
        Path | None,
        typer.Option(help="c3d: static trial defining each cluster's shape."),
    ] = None,
    residuals: Annotated[
        Path | None,
        typer.Option(help="c3d: also write the per-frame rigid-fit residuals (CSV, mm)."),
    ] = None,
    fill_gaps: Annotated[
        int,
        typer.Option(
            min=0,
            help="Interpolate gaps of at most this many frames (positions linear, "
            "orientations slerp); 0 = none.",
        ),
    ] = 0,
    max_speed: Annotated[
        float, typer.Option(min=0.0, help="Jump flag: position speed limit (mm/s).")
    ] = 3000.0,
    max_turn: Annotated[
        float, typer.Option(min=0.0, help="Jump flag: angular speed limit (deg/s).")
    ] = 3600.0,
    keep_repeats: Annotated[
        bool,
        typer.Option(
            "--keep-repeats",
            help="liberty without frame count: keep exactly repeated station cycles.",
        ),
    ] = False,
    unit_check: Annotated[
        bool,
        typer.Option(
            "--unit-check/--no-unit-check",
            help="Reject implausible distances between neighbouring hand sensors.",
        ),
    ] = True,
    out_units: Annotated[
        str | None,
        typer.Option(
            help="Units of x,y,z in the written pose CSV (default: mm; a pose table keeps its own)."
        ),
    ] = None,
    quiet: Quiet = False,
) -> None:
    """Convert Liberty/Patriot ASCII or binary, wide CSV or C3D to the pose CSV, or a
    pose table from CSV to Parquet and back (row for row, the numbers bit for bit); any of
    them to OpenSim's orientations (.sto) or markers (.trc)."""
    import numpy as np

    from ..io.atomic import check_target, refuse_writing_inputs
    from ..io.hygiene import check_recording
    from ..io.hygiene import fill_gaps as fill
    from ..io.opensim import write_markers, write_orientations
    from ..io.posewrite import read_pose_table, write_pose_csv, write_pose_rows
    from ..io.trackerfile import check_format_options, infer_format, read_tracker_file
    from ..session import UNITS_TO_MM, is_sensor_name

    if not source.is_file():
        raise FingerfitError("file not found", path=source)
    fmt = SourceFormat(infer_format(source)) if fmt is None else fmt
    check_format_options(
        fmt.value,
        units,
        items=items,
        columns=columns,
        clusters=clusters,
        static=static,
        residuals=residuals,
        rate=rate,
    )
    if out_units is not None and out_units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--out-units")
    # A pose table is copied row for row (the numbers bit for bit); with --fill-gaps its
    # recording is written, as a tracker file's is.
    opensim = {".sto": write_orientations, ".trc": write_markers}.get(output.suffix.lower())
    table_copy = fmt is SourceFormat.pose_csv and not fill_gaps and opensim is None
    if fmt is SourceFormat.pose_csv and map_ is not None:
        raise FingerfitError("does not apply to a pose table (it names its sensors)", field="--map")
    outputs = [output] if residuals is None else [output, residuals]
    refuse_writing_inputs(outputs, [source] if static is None else [source, static])
    for target in outputs:
        check_target(target)
    numeric = fmt is not SourceFormat.c3d
    sensors = parse_map(map_, numeric=numeric)
    with progress(quiet) as bar:
        task = bar.add_task(f"reading {source.name}", total=3)
        if table_copy:
            table = read_pose_table(source, units=units, rate_hz=rate)
            rec, fits, declared = table.recording, {}, table.units
        else:
            read = read_tracker_file(
                source,
                fmt.value,
                units=units,
                rate=rate,
                items=items,
                columns=columns,
                clusters=clusters,
                sensors=sensors,
                static=static,
                keep_repeats=keep_repeats,
            )
            rec, fits, declared = read.recording, read.fits, read.declared_units

        bad = [s for s in rec.sensors if not is_sensor_name(s)]
        if bad:
            raise FingerfitError(
                f"'{bad[0]}' is not a sensor name of the session format; name every "
                f"{'station' if numeric else 'segment'} with --map (found: {', '.join(rec.sensors)}; "
                f"e.g. --map {rec.sensors[0]}=hand)",
                path=source,
                field="--map",
            )
        bar.update(task, advance=1, description="checking the recording")
        if fill_gaps:
            rec = fill(rec, fill_gaps)
        check_recording(
            rec, source, units=unit_check, max_speed_mm_s=max_speed, max_turn_deg_s=max_turn
        )
        bar.update(task, advance=1, description=f"writing {output.name}")
        if out_units is None:
            out_units = declared if fmt is SourceFormat.pose_csv else "mm"
        if opensim is not None:
            opensim(output, rec)
        elif table_copy:
            write_pose_rows(output, table, out_units)
        else:
            write_pose_csv(output, rec, units=out_units)
        if residuals is not None:
            _write_residuals(residuals, rec, fits)
        bar.advance(task)
    n_valid = {s: int(p.valid.sum()) for s, p in rec.poses.items()}
    span = float(rec.time[-1] - rec.time[0]) if rec.n_frames else 0.0
    for note in rec.notes:
        notice("note", note)
    out.print(
        f"wrote [bold]{escape(str(output))}[/]: {rec.n_frames} frames ({span:.3f} s), sensors "
        + escape(", ".join(f"{s} ({n_valid[s]} samples)" for s in rec.sensors)),
        highlight=False,
        soft_wrap=True,
    )
    if residuals is not None:
        med = {n: float(np.nanmedian(f.residual)) for n, f in fits.items()}
        out.print(
            f"wrote [bold]{escape(str(residuals))}[/]: per-frame residuals of "
            + escape(", ".join(f"{n} (median {m:.2f} mm)" for n, m in med.items())),
            highlight=False,
            soft_wrap=True,
        )
