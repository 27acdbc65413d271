"""``fingerfit stylus``: the stylus's tip offset, by pivot calibration or from its maker."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import FingerfitError, shown
from .app import Quiet, app, notice, say, user_errors
from .joint import JointSource


def _tip_offset(text: str) -> list[float]:
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 3 or not all(abs(v) < float("inf") for v in values):
        raise FingerfitError(
            f"must be three numbers x,y,z (mm), not '{shown(text)}'", field="--tip-offset"
        )
    return values


@app.command()
@user_errors
def stylus(
    pivot: Annotated[
        Path | None,
        typer.Argument(
            metavar="PIVOT",
            help="Pose recording of the stylus turned about its tip resting in a divot.",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Path, typer.Option("-o", "--output", help="The stylus file to write (stylus.json).")
    ] = Path("stylus.json"),
    sensor: Annotated[str, typer.Option(help="The stylus sensor's name in the recording.")] = "stylus",
    tip_offset: Annotated[
        str | None,
        typer.Option(
            "--tip-offset",
            metavar="X,Y,Z",
            help="A maker's tip offset in the sensor frame (mm) instead of a pivot recording.",
        ),
    ] = None,
    fmt: Annotated[
        JointSource | None,
        typer.Option("--from", help="Input format (default: from the file, as for convert).", case_sensitive=False),
    ] = None,
    units: Annotated[
        str | None, typer.Option(help="Position units in the file (mm, cm, m, in); defaults as for convert.")
    ] = None,
    rate: Annotated[float | None, typer.Option(min=0.001, help="Frame rate (Hz).")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace OUTPUT if it exists.")] = False,
    quiet: Quiet = False,
) -> None:  # fmt: skip
    """Calibrate the stylus tip by pivoting (least squares, with its RMS residual and the
    tip's uncertainty; a recording that does not determine the tip is refused), or store
    a maker's tip offset. Writes stylus.json for `capture --protocol landmarks`."""
    import numpy as np

    from ..io.atomic import check_target, refuse_writing_inputs
    from ..stylus import StylusCalibration, fit_pivot, write_stylus
    from ..stylus.file import check_tip_offset

    if (pivot is None) == (tip_offset is None):
        raise FingerfitError(
            "give a pivot recording or --tip-offset X,Y,Z (one of them)", field="PIVOT"
        )
    if output.is_dir():
        raise FingerfitError("is a directory; give a file name", path=output)
    if pivot is not None:
        refuse_writing_inputs([output], [pivot])
    check_target(output, overwrite=overwrite)
    if tip_offset is not None:
        tip = np.array(_tip_offset(tip_offset))
        check_tip_offset(tip, field="--tip-offset")
        cal = StylusCalibration(sensor, tip)
        write_stylus(output, cal)
        say("maker's tip offset ({}) mm -> [bold]{}[/]", ", ".join(f"{v:g}" for v in tip), output)
        return
    assert pivot is not None
    if not pivot.is_file():
        raise FingerfitError("no such file", path=pivot)
    from ..io.trackerfile import infer_format
    from .joint import read_any

    fmt = fmt or JointSource(infer_format(pivot))
    rec, _ = read_any(pivot, fmt, units=units, rate=rate, items=None, columns=None, clusters=None)
    for note in rec.notes:
        notice("note", f"{pivot.name}: {note}")
    if sensor not in rec.poses:
        raise FingerfitError(
            f"no sensor '{shown(sensor)}' (has: {', '.join(rec.sensors)})",
            path=pivot,
            field="--sensor",
        )
    pose = rec.poses[sensor]
    try:
        fit = fit_pivot(pose.position, pose.rotation)
    except FingerfitError as exc:
        raise FingerfitError(exc.reason, path=pivot) from None
    check_tip_offset(fit.tip_offset_mm, path=pivot, field=sensor)
    cal = StylusCalibration(
        sensor,
        fit.tip_offset_mm,
        fit.pivot_mm,
        fit.rms_mm,
        fit.rotation_span_deg,
        fit.n_frames,
        fit.tip_ci_mm,
    )
    write_stylus(output, cal)
    if fit.downweighted:
        notice(
            "note",
            f"{fit.downweighted} frame(s) of {fit.n_frames} down-weighted (Huber) as outliers",
        )
    if not quiet:
        say(
            "tip ({}) mm in the sensor frame, +/-{} mm (95 %); pivot ({}) mm; RMS {} mm over "
            "{} frames, turned through {} deg -> [bold]{}[/]",
            ", ".join(f"{v:.2f}" for v in fit.tip_offset_mm),
            f"{fit.tip_ci_mm:.2f}",
            ", ".join(f"{v:.2f}" for v in fit.pivot_mm),
            f"{fit.rms_mm:.2f}",
            fit.n_frames,
            f"{fit.rotation_span_deg:.0f}",
            output,
        )
