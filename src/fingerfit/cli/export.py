"""``fingerfit export``: the individual hand model as URDF, MuJoCo MJCF and/or OpenSim."""

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
    osim: Annotated[
        Path | None,
        typer.Option("--osim", help="OpenSim model to write (.osim; metres, radians)."),
    ] = None,
    landmarks: Annotated[
        Path | None,
        typer.Option(
            "--landmarks",
            help="--osim: also the session's landmarks.csv (session units) as markers.",
        ),
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
    """Export the digit chains for robot and biomechanics software: root `hand` (hand sensor
    frame), joints <digit>_<joint>, tips <digit>_tip.

    Every file is written or none; an existing file is replaced only with --overwrite.
    """
    _export(
        model_path,
        {"--urdf": urdf, "--mjcf": mjcf, "--osim": osim},
        variant,
        margin_deg,
        fix_centres,
        overwrite,
        landmarks,
        quiet,
    )


def _export(
    model_path: Path,
    targets: dict[str, Path | None],
    variant: str,
    margin_deg: float,
    fix_centres: bool = False,
    overwrite: bool = False,
    landmarks: Path | None = None,
    quiet: bool = False,
) -> None:
    """Check the options, build every document, then write them all or none.

    ``targets``: option (``--urdf``, ``--mjcf``, ``--osim``) -> the file it names, or None;
    ``landmarks``: a landmarks CSV whose points the OpenSim model carries as markers.
    """
    from functools import partial

    from ..export import mjcf_string, osim_string, robot_hand, urdf_string
    from ..export import write_text as _write_text
    from ..export.osim import landmark_markers
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..io.sessiondir import read_landmarks
    from ..model import VARIANTS, load_model, with_fixed_centres

    given = {flag: p for flag, p in targets.items() if p is not None}
    if not given:
        raise FingerfitError("nothing to write: give --urdf, --mjcf and/or --osim")
    seen: dict[Path, str] = {}
    for flag, p in given.items():
        if p.resolve() in seen:
            raise FingerfitError(f"{seen[p.resolve()]} and {flag} name the same file", path=p)
        seen[p.resolve()] = flag
    if landmarks is not None and "--osim" not in given:
        raise FingerfitError("applies to --osim only", field="--landmarks")
    inputs = [model_path] if landmarks is None else [model_path, landmarks]
    refuse_writing_inputs(list(given.values()), inputs)
    for p in given.values():
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
    points = None if landmarks is None else read_landmarks(landmarks, units=model.session_units)
    hand = robot_hand(model, variant, margin_deg)
    if points:
        skipped = landmark_markers(model, hand, points)[1]
        if skipped:
            notice(
                "note",
                f"{len(skipped)} landmark(s) not made markers ({', '.join(skipped)}): a tip "
                "or pad is the model's <digit>_tip/<digit>_pad, or the digit is not modelled",
            )
    build = {
        "--urdf": urdf_string,
        "--mjcf": mjcf_string,
        "--osim": partial(osim_string, landmarks=points),
    }
    files = {p: build[flag](model, variant, margin_deg) for flag, p in given.items()}
    _write_text(files, overwrite=overwrite)  # all files or none
    if quiet:
        return
    out.print(
        f"{len(hand.fingers)} digit(s), {len(hand.joints)} joints ({variant} axes, limits = "
        f"observed range of motion ± {margin_deg:g}°; metres, radians) -> "
        + ", ".join(str(p) for p in files),
        markup=False,
        highlight=False,
    )
