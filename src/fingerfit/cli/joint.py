"""``fingerfit joint``: the joint between two pose streams of any supported file."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

if TYPE_CHECKING:
    from ..session import Recording
import typer
from rich.markup import escape
from rich.table import Table

from ..errors import FingerfitError
from .app import QuietTable, app, notice, out, say, user_errors


class JointSource(StrEnum):
    """Input formats of ``fingerfit joint``."""

    pose_csv = "pose-csv"
    liberty = "liberty"
    liberty_binary = "liberty-binary"
    wide_csv = "wide-csv"
    c3d = "c3d"


class JointKind(StrEnum):
    """Joint models of ``fingerfit joint``."""

    auto = "auto"
    hinge = "hinge"
    two_axis = "two_axis"
    ball = "ball"


def read_any(
    source: Path,
    fmt: JointSource,
    *,
    units: str | None,
    rate: float | None,
    items: str | None,
    columns: str | None,
    clusters: str | None,
) -> tuple[Recording, str]:
    """Read ``source`` in ``fmt`` (positions mm, rotations sensor -> tracker) through
    :func:`fingerfit.io.trackerfile.read_tracker_file`, as ``fingerfit convert`` does.

    Sensors keep the file's names: pose CSV names, Liberty station numbers (``1``, ``2``,
    ...), wide-CSV sensor numbers, C3D cluster or ROTATION channel names.

    Returns
    -------
    recording : Recording
    declared : str
        The units the file's positions were read in: ``units``, else the format's default
        (pose CSV mm, Liberty inches), the wide Parquet file's or the C3D file's
        ``POINT:UNITS``.
    """
    from ..io.trackerfile import check_format_options, read_tracker_file

    check_format_options(
        fmt.value, units, items=items, columns=columns, clusters=clusters, rate=rate
    )
    read = read_tracker_file(
        source, fmt.value, units=units, rate=rate, items=items, columns=columns, clusters=clusters
    )
    return read.recording, read.declared_units


def _rate(rec: Recording) -> float | None:
    """Sampling rate (Hz) from the recording's time column, if regular enough to say."""
    import numpy as np

    t = np.asarray(rec.time, dtype=float)
    dt = np.diff(t[np.isfinite(t)])
    if dt.size < 2 or not (np.median(dt) > 0):
        return None
    return float(1.0 / np.median(dt))


def _table(fit) -> Table:
    """The printed summary of a :class:`~fingerfit.estimate.joint.JointFit`."""
    import numpy as np

    q = fit.quality

    def vec(v) -> str:
        return "-" if v is None else "(" + ", ".join(f"{x:.4g}" for x in v) + ")"

    table = Table(title=f"{fit.kind} joint ({fit.method}), {fit.units}", show_header=False)
    table.add_column("figure")
    table.add_column("value", justify="right")
    rows = [
        ("centre, parent frame", vec(fit.centre_parent)),
        ("centre, child frame", vec(fit.centre_child)),
        ("axis, parent frame", vec(fit.axis_parent)),
        ("axis, child frame", vec(fit.axis_child)),
        ("second axis, parent frame", vec(fit.second_axis_parent)),
        ("frames used (dropped)", f"{q.frames} ({q.dropped_frames})"),
        ("range of motion", f"{q.rom_deg:.1f} deg"),
        ("pivot residual", f"{q.pivot_residual_mm:.2f} mm RMS"),
        ("axis conditioning s5/s6", f"{q.axis_conditioning:.1f}"),
        ("axis spread (95 %)", "-" if np.isnan(q.axis_spread_deg) else f"{q.axis_spread_deg:.2f} deg"),
        ("centre spread (95 %)", "-" if np.isnan(q.centre_spread) else f"{q.centre_spread:.2f} {fit.units}"),
        ("movement cycles", str(q.cycles)),
    ]  # fmt: skip
    for name, value in rows:
        table.add_row(name, escape(value))
    return table


@app.command()
@user_errors
def joint(
    source: Annotated[Path, typer.Argument(help="Tracker file with both segments.", show_default=False)],
    parent: Annotated[str, typer.Option(help="Parent segment: sensor, station or cluster name.", show_default=False)],
    child: Annotated[str, typer.Option(help="Child segment: sensor, station or cluster name.", show_default=False)],
    kind: Annotated[JointKind, typer.Option(help="Joint model; auto chooses.", case_sensitive=False)] = JointKind.auto,
    method: Annotated[str, typer.Option(help="Hinge estimator: sara, robust or tang2018.")] = "sara",
    fmt: Annotated[
        JointSource | None,
        typer.Option("--from", help="Input format (default: from the file, as for convert).", case_sensitive=False),
    ] = None,
    units: Annotated[
        str | None,
        typer.Option(help="Position units in the file (mm, cm, m, in); defaults as for convert. Results are in these units."),
    ] = None,
    rate: Annotated[float | None, typer.Option(min=0.001, help="Frame rate (Hz).")] = None,
    items: Annotated[str | None, typer.Option(help="liberty: output list, e.g. 2,7,9,1.")] = None,
    columns: Annotated[str | None, typer.Option(help="wide-csv: column templates (see convert).")] = None,
    clusters: Annotated[str | None, typer.Option(help="c3d: marker clusters 'Seg=m1,m2,m3;...'.")] = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="Write the result as JSON.")] = None,
    convention_check: Annotated[
        bool,
        typer.Option("--convention-check/--no-convention-check", help="Refuse a wrong quaternion order or handedness."),
    ] = True,
    quiet: QuietTable = False,
) -> None:  # fmt: skip
    """Find the joint (hinge, two-axis or ball) between two segments of one recording."""
    from ..estimate.joint import fit_joint
    from ..io.atomic import atomic_write, refuse_writing_inputs
    from ..session import UNITS_TO_MM
    from ..transforms import transform_from_pr

    if not source.is_file():
        raise FingerfitError("file not found", path=source)
    if output is not None:
        refuse_writing_inputs([output], [source])
        if output.is_dir():
            raise FingerfitError("is a directory; give a file name", path=output)
    if fmt is None:
        from ..io.trackerfile import infer_format

        fmt = JointSource(infer_format(source))
    rec, declared = read_any(
        source, fmt, units=units, rate=rate, items=items, columns=columns, clusters=clusters
    )
    for note in rec.notes:
        notice("note", f"{source.name}: {note}")
    from ..io.hygiene import MAX_SPEED_MM_S, MAX_TURN_DEG_S, find_jumps, jump_notes

    jumps = [j for j in find_jumps(rec) if j.sensor in (parent, child)]
    for note in jump_notes(jumps, max_speed_mm_s=MAX_SPEED_MM_S, max_turn_deg_s=MAX_TURN_DEG_S):
        notice("warning", f"{source.name}: {note}")
    names = {"--parent": parent, "--child": child}
    for opt, name in names.items():
        if name not in rec.poses:
            raise FingerfitError(
                f"no segment '{name}' in the file (have: {', '.join(rec.sensors)})",
                path=source,
                field=opt,
            )
    if parent == child:
        raise FingerfitError("parent and child are the same segment", field="--child")
    p, c = rec.poses[parent], rec.poses[child]
    # Fit in the file's own units: the result is in them, and the units check (the joint's
    # distance from the segment origins) names the declared units when they are wrong.
    scale = UNITS_TO_MM[declared]
    try:
        fit = fit_joint(
            transform_from_pr(p.position / scale, p.rotation),
            transform_from_pr(c.position / scale, c.rotation),
            kind.value,
            units=declared,
            method=method,
            rate_hz=rate or _rate(rec),
            check_convention=convention_check,
        )
    except FingerfitError as exc:
        units_field = "--units" if exc.field == "units" else None
        raise FingerfitError(
            f"{parent} -> {child}: {exc.reason}", path=source, field=units_field
        ) from None
    if fit.quality.dropped_frames:
        notice("note", f"{fit.quality.dropped_frames} frame(s) without both poses dropped")
    for note in fit.quality.notes:
        notice("note", note)
    if not quiet:
        out.print(_table(fit))
    if output is not None:
        doc = {"file": str(source), "parent": parent, "child": child, **fit.summary()}
        with atomic_write(output) as fh:
            json.dump(doc, fh, indent=2)
            fh.write("\n")
        say("joint written to [bold]{}[/]", output)
