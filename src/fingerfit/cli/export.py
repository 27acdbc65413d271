"""``fingerfit export``: the individual finger model as URDF and/or MuJoCo MJCF."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import FingerfitError
from ._names import DEFAULT_MARGIN_DEG, VARIANTS
from .app import app, notice, out, user_errors


@app.command()
@user_errors
def export(
    model_path: Annotated[
        Path, typer.Argument(metavar="MODEL", help="Model JSON from `fingerfit fit`.")
    ],
    urdf: Annotated[
        Path | None, typer.Option("--urdf", help="URDF file to write (metres, radians).")
    ] = None,
    mjcf: Annotated[
        Path | None, typer.Option("--mjcf", help="MuJoCo MJCF file to write (metres, radians).")
    ] = None,
    variant: Annotated[
        str,
        typer.Option(help=f"Flexion axes: {' or '.join(VARIANTS)} (perpendicular to the bones)."),
    ] = "user_axis",
    margin_deg: Annotated[
        float,
        typer.Option(
            "--margin-deg",
            help="Joint limits: observed range of motion widened by this margin (deg).",
        ),
    ] = DEFAULT_MARGIN_DEG,
    fix_centres: Annotated[
        bool,
        typer.Option(
            "--fix-centres",
            help="Rolling-contact models: fix each migrating centre at its mid-range position.",
        ),
    ] = False,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace existing output files.")
    ] = False,
    quiet: Annotated[
        bool,
        typer.Option("--quiet", "-q", help="Print nothing but warnings (the files are named)."),
    ] = False,
) -> None:
    """Export the finger chains for robot software: root link `hand` (hand sensor frame),
    joints <finger>_mp|pip|dip, fingertip frame <finger>_tip.

    Both files are written or neither; an existing file is replaced only with --overwrite.
    """
    _export(model_path, urdf, mjcf, variant, margin_deg, fix_centres, overwrite, quiet)


def _export(
    model_path: Path,
    urdf: Path | None,
    mjcf: Path | None,
    variant: str,
    margin_deg: float,
    fix_centres: bool = False,
    overwrite: bool = False,
    quiet: bool = False,
) -> None:
    """Check the options, build every document, then write them all or none."""
    from ..export import mjcf_string, robot_hand, urdf_string
    from ..export import write_text as _write_text
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..model import VARIANTS, load_model, with_fixed_centres

    if urdf is None and mjcf is None:
        raise FingerfitError("nothing to write: give --urdf and/or --mjcf")
    if urdf is not None and mjcf is not None and urdf.resolve() == mjcf.resolve():
        raise FingerfitError("--urdf and --mjcf name the same file", path=urdf)
    targets = [p for p in (urdf, mjcf) if p is not None]
    refuse_writing_inputs(targets, [model_path])
    for p in targets:
        check_target(p, overwrite=overwrite)
    if variant not in VARIANTS:
        raise FingerfitError(f"must be one of {', '.join(VARIANTS)}", field="--variant")
    if not margin_deg >= 0:
        raise FingerfitError("must be >= 0", field="--margin-deg")
    model = load_model(model_path)
    if fix_centres:
        model, deviation = with_fixed_centres(model)
        for joint, mm in deviation.items():
            notice(
                "warning",
                f"{joint}: migrating centre fixed at mid-range; it differs from the fitted "
                f"one by up to {mm:.2f} mm over the observed range of motion",
            )
    files: dict[Path, str] = {}
    if urdf is not None:
        files[urdf] = urdf_string(model, variant, margin_deg)
    if mjcf is not None:
        files[mjcf] = mjcf_string(model, variant, margin_deg)
    _write_text(files, overwrite=overwrite)  # all files or none
    if quiet:
        return
    hand = robot_hand(model, variant, margin_deg)
    out.print(
        f"{len(hand.fingers)} digit(s), {len(hand.joints)} joints ({variant} axes, limits = "
        f"observed range of motion ± {margin_deg:g}°; metres, radians) -> "
        + ", ".join(str(p) for p in files),
        markup=False,
        highlight=False,
    )
