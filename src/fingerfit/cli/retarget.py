"""``fingerfit retarget``: drive a robot hand (Shadow, Allegro, any URDF/MJCF) from a recording."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import FingerfitError
from ._names import RETARGET_METHODS, RETARGET_ROBOTS
from .app import Quiet, app, notice, progress, say, user_errors

# --- Options shared with `fingerfit stream --retarget` ---------------------------------------

ROBOT_HELP = f"{' or '.join(RETARGET_ROBOTS)} (shipped maps), or a .urdf/.xml file (needs --map)."
MapOption = Annotated[
    Path | None, typer.Option("--map", help="Robot map TOML (docs/retargeting.md).")
]
MethodOption = Annotated[
    str,
    typer.Option(
        "--method",
        help=f"{' or '.join(RETARGET_METHODS)}. tip: fingertips (scaled, palm frame) + pinch + "
        "smoothness; joint: angles copied through the map.",
    ),
]
OrthogonalOption = Annotated[
    bool,
    typer.Option(
        "--orthogonal",
        help="Drive from the orthogonal model (axes perpendicular "
        "to the bones) instead of the fitted axes.",
    ),
]
#: No ``--contact-mm``: each pinch pair's contact distance comes from the model.
DEFAULT_CONTACT_MM = None
ContactOption = Annotated[
    float | None,
    typer.Option(
        "--contact-mm",
        help="Person's pad-point distance (mm) that counts as touching (pinch term) for "
        "every pair. Default: per pair, how close the person's pads came in their pinch "
        "holds (the model), else 8 mm.",
        show_default=False,
    ),
]


def check_robot_options(
    robot: str, map_path: Path | None, method: str, contact_mm: float | None
) -> list[Path]:
    """Check ``--method`` and ``--contact-mm``; return the robot's input files.

    Parameters
    ----------
    robot : str
        A built-in robot name or a ``.urdf``/``.xml`` file.
    map_path : Path, optional
    method : str
    contact_mm : float, optional
        mm; ``None``: from the model.

    Returns
    -------
    list of Path
        The map and the robot file when given (inputs no output may overwrite).

    Raises
    ------
    FingerfitError
        ``field '--method'`` or ``field '--contact-mm'``.
    """
    import math

    if method not in RETARGET_METHODS:
        raise FingerfitError(f"must be one of {', '.join(RETARGET_METHODS)}", field="--method")
    if contact_mm is not None and not (math.isfinite(contact_mm) and contact_mm >= 0):
        raise FingerfitError("must be a finite number >= 0", field="--contact-mm")
    inputs = [map_path] if map_path is not None else []
    if robot.lower().endswith((".urdf", ".xml")):
        inputs.append(Path(robot))
    return inputs


def check_orthogonal(model_path: Path, markers: bool, orthogonal: bool) -> None:
    """Refuse ``--orthogonal`` for a model fitted from markers (``markers``) in one line:
    it has its fitted axes only (``retarget``, ``view``, ``stream``)."""
    if markers and orthogonal:
        raise FingerfitError(
            "was fitted from markers: it has its fitted axes only, no --orthogonal variant",
            path=model_path,
        )


def resolve_robot(robot: str, map_path: Path | None, hand: str, option: str = "--robot"):
    """:func:`fingerfit.retarget.resolve`, its errors about the robot naming ``option``.

    Loads the robot file (MuJoCo or Pinocchio) and checks the map against it.

    Returns
    -------
    robot : fingerfit.retarget.robots.Robot
    rmap : fingerfit.retarget.maps.RobotMap
    """
    from ..retarget import resolve

    try:
        return resolve(robot, map_path, hand)
    except FingerfitError as exc:
        if exc.field == "--robot" and option != "--robot":
            raise FingerfitError(exc.reason, path=exc.path, line=exc.line, field=option) from None
        raise


@app.command()
@user_errors
def retarget(
    model_path: Annotated[
        Path, typer.Argument(metavar="MODEL", help="Model JSON from `fingerfit fit`.")
    ],
    recording: Annotated[
        Path,
        typer.Argument(
            help="Pose CSV (canonical format); with a model fitted from markers, a marker "
            "recording (.trc, .tsv, .c3d)."
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Joint CSV (time, one column per robot joint, rad; OUT.parquet: "
            "Parquet); the same arrays are written to OUT.npz.",
        ),
    ],
    robot: Annotated[str, typer.Option(help=ROBOT_HELP)] = "shadow",
    map_path: MapOption = None,
    method: MethodOption = "tip",
    orthogonal: OrthogonalOption = False,
    units: Annotated[
        str | None,
        typer.Option(
            help="Units of the recording (default: the model's session units; a marker "
            "recording's own)."
        ),
    ] = None,
    figure: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated frame numbers: draw the person and the robot side "
            "by side at them into OUT.png."
        ),
    ] = None,
    contact_mm: ContactOption = DEFAULT_CONTACT_MM,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace existing output files.")
    ] = False,
    quiet: Quiet = False,
) -> None:
    """Retarget a recording of the person's hand onto a robot hand's joints (radians)."""
    import warnings

    import numpy as np

    from ..estimate.plausibility import check_recording, enforce
    from ..io import read_pose_csv
    from ..io.atomic import check_target, refuse_writing_inputs, write_files
    from ..model import load_model
    from ..retarget import retarget as run
    from ..retarget.palm import palm_in_hand_sensor, person_palm
    from ..session import UNITS_TO_MM
    from .fit import is_marker_input, read_marker_input

    robot_files = check_robot_options(robot, map_path, method, contact_mm)
    if output.suffix.lower() not in (".csv", ".parquet"):
        raise FingerfitError(
            "must end in .csv or .parquet (OUT.npz is written beside it)", field="--output"
        )
    npz = output.with_suffix(".npz")
    png = output.with_suffix(".png")
    targets = [output, npz] + ([png] if figure is not None else [])
    inputs = [model_path, recording, *robot_files]
    refuse_writing_inputs(targets, inputs)
    for t in targets:
        check_target(t, overwrite=overwrite)
    model = load_model(model_path)
    markers = is_marker_input(model, model_path, recording)
    check_orthogonal(model_path, markers, orthogonal)
    units_given = units
    units = units or model.session_units
    if units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
    frames: list[int] = []
    if figure is not None:
        items = [v.strip() for v in figure.split(",") if v.strip()]
        if not items or not all(v.isdigit() for v in items):
            raise FingerfitError(
                "must be comma-separated frame numbers (0-based)", field="--figure"
            )
        frames = [int(v) for v in items]
    robot_model, rmap = resolve_robot(robot, map_path, model.hand)
    if markers:
        rec = read_marker_input(model, recording, units_given)
    else:
        rec = read_pose_csv(recording, units=units)
        for note in rec.notes:
            notice("note", note)
    bad = [f for f in frames if f >= rec.n_frames]
    if bad:
        raise FingerfitError(
            f"frame {bad[0]} is past the recording's {rec.n_frames} frames", field="--figure"
        )
    if not markers:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            enforce(check_recording(model, rec, units, recording), False)
        for w in caught:
            notice("warning", str(w.message))
    variant = "orthogonal" if orthogonal else "user_axis"
    with progress(quiet) as bar:
        task = bar.add_task(f"retargeting ({method})", total=2 if markers else 1)
        kin = None
        if markers:  # the angles of `fingerfit angles`, the hand's pose of its markers
            from ..kinematics.markers import with_hand
            from ..live.markers import marker_kinematics

            bar.update(task, description="angles of the markers")
            solved, unconverged = marker_kinematics(model, rec)
            if unconverged:
                notice(
                    "warning",
                    f"{unconverged} marker solves unconverged (a digit in a frame each; "
                    "their angles the last iterate's)",
                )
            rec, kin = with_hand(model, rec, solved)
            bar.update(task, advance=1, description=f"retargeting ({method})")
        res = run(model, rec, robot_model, rmap, method, variant, contact_mm=contact_mm, kin=kin)
        bar.advance(task)
    for note in res.notes:
        notice("note", note)
    palm = person_palm(model)
    angle, euler = palm_in_hand_sensor(model, palm)
    say(
        "palm frame {} deg from the hand sensor's (x-y-z angles {} deg); {}",
        f"{angle:.1f}",
        ", ".join(f"{v:.1f}" for v in euler),
        palm.evidence,
    )
    if res.violations:  # projection makes this impossible; never write a violating file
        raise FingerfitError(f"{res.violations} joint-limit violations", path=output)
    files: dict[Path, str | bytes] = {
        output: joints_file(output, res.time, res.joint_names, res.q),
        npz: npz_bytes(res.time, res.joint_names, res.q),
    }
    if frames:
        from ..retarget.figure import figure_png

        files[png] = figure_png(model, rec, res, robot_model, rmap, frames, variant, kin)
    write_files(files, overwrite=overwrite)
    err = np.linalg.norm(res.tips - res.targets, axis=2)
    say(
        "{} frames, {} robot joints ({}, {} method) -> {}; fingertip error in the palm frame "
        "median {} mm, limit violations 0",
        len(res.time),
        len(res.joint_names),
        rmap.name,
        method,
        ", ".join(str(p) for p in files),
        f"{np.nanmedian(err):.2f}" if np.isfinite(err).any() else "n/a",
    )


def joints_file(path: Path, time, names: tuple[str, ...], q) -> str | bytes:
    """The joint table's content for ``path``: :func:`csv_text`, or for a ``.parquet``
    path the same columns as a Parquet file's bytes (float64, radians in its metadata)."""
    import numpy as np

    from ..io.parquet import is_parquet, joints_meta, parquet_bytes

    if not is_parquet(path):
        return csv_text(time, names, q)
    q = np.asarray(q, dtype=float)
    cols = {"time": np.asarray(time, dtype=float)}
    cols.update({n: q[:, j] for j, n in enumerate(names)})
    return parquet_bytes(cols, joints_meta())


def csv_text(time, names: tuple[str, ...], q) -> str:
    """The joint CSV: ``time`` then one column per robot joint (rad), full precision."""
    import numpy as np
    import pandas as pd

    table = pd.DataFrame(np.column_stack([time, q]), columns=["time", *names])
    return table.to_csv(index=False, lineterminator="\n", float_format="%.17g")


def npz_bytes(time, names: tuple[str, ...], q) -> bytes:
    """``time (n,)`` s, ``q (n, nq)`` rad, ``joint_names (nq,)`` as an ``.npz`` file's bytes."""
    import io

    import numpy as np

    buf = io.BytesIO()
    np.savez(
        buf,
        time=np.asarray(time, float),
        q=np.asarray(q, float),
        joint_names=np.array(names, dtype=str),
    )
    return buf.getvalue()
