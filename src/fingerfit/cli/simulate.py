"""``fingerfit simulate``: write simulated sessions with ground truth.

``--format csv`` (default) writes one session folder per subject; ``--format
liberty-ascii|liberty-binary|c3d`` writes the recordings as the files those devices
produce (:mod:`fingerfit.simulate.trackerfiles`) and prints the ``fingerfit convert`` /
``session`` / ``fit`` commands that turn them into sessions.
"""

from __future__ import annotations

import shlex
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..errors import FingerfitError

if TYPE_CHECKING:
    from ..simulate.trackerfiles import TrackerFiles
from .app import Quiet, app, out, parse_list, progress, say, user_errors

#: File (in the output folder) the printed command sequence is also saved to.
COMMANDS_FILE = "commands.sh"


class SimFormat(StrEnum):
    """Output formats of ``fingerfit simulate``."""

    csv = "csv"
    liberty_ascii = "liberty-ascii"
    liberty_binary = "liberty-binary"
    c3d = "c3d"


_DESCRIPTION = {
    "liberty-ascii": "Liberty ASCII (output list 2,7,9,1: position in inches, 3 decimals; "
    "quaternion w,x,y,z, 4 decimals; frame count)",
    "liberty-binary": "Liberty binary (LY records, output list 2,7,9,1: float32 position in "
    "inches and quaternion w,x,y,z, uint32 frame count)",
    "c3d": "C3D (one ROTATION channel per sensor: 4x4 transforms, float32, mm; sensor "
    "origins as points)",
}


def _plain(text: str) -> None:
    """Print a line verbatim (no markup, no wrapping): commands must be copyable."""
    out.print(text, markup=False, highlight=False, soft_wrap=True)


@app.command()
@user_errors
def simulate(
    out_dir: Annotated[
        Path, typer.Argument(help="Directory to create; one session folder per subject.")
    ],
    subjects: Annotated[int, typer.Option(min=1, help="Number of subjects.")] = 5,
    seed: Annotated[
        int, typer.Option(help="Random seed; the output is deterministic for a seed.")
    ] = 0,
    fingers: Annotated[
        str,
        typer.Option(
            help="Comma-separated digits: thumb, index, middle, ring, little (thumb adds "
            "circumduction, opposition and pinch recordings)."
        ),
    ] = "index",
    hand: Annotated[str, typer.Option(help="left or right.")] = "left",
    noise: Annotated[
        float, typer.Option(min=0.0, help="Tracker error scale (1 = Liberty-like, 0 = none).")
    ] = 1.0,
    sta: Annotated[
        float, typer.Option(min=0.0, help="Soft-tissue artefact scale (0 = rigid sensors).")
    ] = 1.0,
    stylus: Annotated[float, typer.Option(min=0.0, help="Stylus noise SD per axis (mm).")] = 0.3,
    stylus_recordings: Annotated[
        bool,
        typer.Option(
            "--stylus-recordings",
            help="Also write stylus_pivot.csv (a pivot calibration) and stylus_landmarks.csv "
            "(the stylus placed on every landmark, three times each) with their truth "
            "(docs/lab.md); csv format only.",
        ),
    ] = False,
    tilt: Annotated[
        float, typer.Option(min=0.0, help="Axis obliquity scale (0 = axes perpendicular to bones).")
    ] = 1.0,
    rom: Annotated[
        float, typer.Option(min=0.05, max=1.3, help="Grasp range-of-motion scale.")
    ] = 1.0,
    cycles: Annotated[int, typer.Option(min=2, help="Grasp cycles of the calibration.")] = 10,
    rolling: Annotated[
        bool, typer.Option(help="Centre of rotation migrating with flexion.")
    ] = True,
    abduction: Annotated[bool, typer.Option(help="MP ab/adduction during motion.")] = True,
    distortion: Annotated[bool, typer.Option(help="Smooth tracker field distortion.")] = True,
    exact: Annotated[
        bool, typer.Option("--exact", help="No error source at all, pure hinges.")
    ] = False,
    world: Annotated[
        str,
        typer.Option(
            help="The true hand: default (fingerfit's anatomy) or myohand (the MyoHand "
            "model's fingers and thumb; right hand; needs fingerfit[myohand])."
        ),
    ] = "default",
    fmt: Annotated[
        SimFormat,
        typer.Option(
            "--format",
            case_sensitive=False,
            help="csv: session folders (canonical pose CSV). liberty-ascii, liberty-binary, "
            "c3d: one tracker file per recording plus the fingerfit convert/session/fit "
            "commands that turn them into a session (docs/simulator.md).",
        ),
    ] = SimFormat.csv,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Tracker formats: replace existing non-empty subject folders (and "
            "commands.sh) instead of refusing.",
        ),
    ] = False,
    markers: Annotated[
        str | None,
        typer.Option(
            help="Write marker sessions instead (TRC, markers.toml, markers_truth.json): skin "
            "markers in the layout todorov, phalanx or dfki (docs/markers.md)."
        ),
    ] = None,
    marker_noise: Annotated[
        float, typer.Option(min=0.0, help="Camera noise of the markers, SD per axis (mm).")
    ] = 0.3,
    quiet: Quiet = False,
) -> None:
    """Simulate sessions (reference, grasp, targets, free-motion test) with truth.json."""
    from ..digits import DIGIT_NAMES
    from ..simulate import SimConfig, simulate_cohort, write_subject
    from ..simulate.trackerfiles import require_ezc3d, write_tracker_subject

    if hand not in ("left", "right"):
        raise typer.BadParameter("must be left or right", param_hint="--hand")
    names = tuple(parse_list(fingers, DIGIT_NAMES, "--fingers") or ())
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FingerfitError(f"names {', '.join(twice)} twice", field="--fingers")
    if stylus_recordings and fmt != SimFormat.csv:
        raise FingerfitError("is for the csv format", field="--stylus-recordings")
    if stylus_recordings and markers is not None:
        raise FingerfitError("is for 6-DOF sessions, not --markers", field="--stylus-recordings")
    kw = dict(
        fingers=names,
        hand=hand,
        rom_scale=rom,
        tilt_scale=tilt,
        world=world,
        cycles=cycles,
        stylus_recordings=stylus_recordings,
    )
    if exact:
        config = SimConfig.exact(**kw)
    else:
        config = SimConfig(
            noise=noise,
            sta=sta,
            stylus_mm=stylus,
            rolling=rolling,
            abduction=abduction,
            distortion=distortion,
            **kw,
        )
    # SimConfig refuses an unknown --world; simulate_subject what the world cannot simulate,
    # before anything is written.
    if out_dir.exists() and not out_dir.is_dir():
        raise FingerfitError("exists and is not a folder", path=out_dir)
    if markers is not None:
        from ..simulate.markers import LAYOUTS

        if markers not in LAYOUTS:
            raise FingerfitError(f"must be one of {', '.join(LAYOUTS)}", field="--markers")
        if fmt is not SimFormat.csv:
            raise FingerfitError("marker sessions are written as TRC", field="--format")
    if fmt is SimFormat.c3d:
        require_ezc3d()
    if fmt is not SimFormat.csv:
        _check_tracker_outputs(out_dir, subjects, overwrite)
    written: list[TrackerFiles] = []
    with progress(quiet) as bar:
        task = bar.add_task("simulating", total=subjects)
        cohort = simulate_cohort(config, subjects, seed)
        for sim in cohort:
            target = out_dir / sim.session.subject
            if markers is not None:
                from ..simulate.markers import simulate_markers, write_marker_subject

                ms = simulate_markers(sim, markers, seed=seed, noise_mm=marker_noise)
                write_marker_subject(ms, target)
            elif fmt is SimFormat.csv:
                try:
                    write_subject(sim, target)
                except OSError as exc:
                    raise FingerfitError(
                        f"cannot write ({exc.strerror or exc})", path=exc.filename or target
                    ) from None
            else:
                written.append(write_tracker_subject(sim, target, fmt.value, overwrite=overwrite))
            bar.advance(task)
    if fmt is SimFormat.csv:
        say("wrote {} session(s) to [bold]{}[/]", subjects, out_dir)
        return
    _plain(f"wrote {subjects} subject(s) to {out_dir} as {_DESCRIPTION[fmt.value]}")
    _print_commands(out_dir, written)


def _check_tracker_outputs(out_dir: Path, subjects: int, overwrite: bool) -> None:
    """Refuse, before simulating, outputs that could not or must not be written."""
    from ..io.atomic import check_folder_target, check_target
    from ..simulate.study import subject_ids
    from ..simulate.trackerfiles import CONVERTED_DIR, SESSION_DIR

    hint = f" (its converted '{CONVERTED_DIR}' and '{SESSION_DIR}' folders too)"
    for name in subject_ids(subjects):
        check_folder_target(out_dir / name, overwrite=overwrite, hint=hint)
    check_target(out_dir / COMMANDS_FILE, overwrite=overwrite)


def _print_commands(out_dir: Path, written: list[TrackerFiles]) -> None:
    """Print the station map and the convert/session/fit commands; save them as commands.sh."""
    from ..io.atomic import atomic_write
    from ..simulate.trackerfiles import CONVERTED_DIR, SESSION_DIR

    first = written[0]
    kind = "ROTATION channels" if first.fmt == "c3d" else "Liberty stations"
    _plain(f"{kind}: " + ", ".join(f"{k}={v}" for k, v in first.mapping.items()))
    _plain(
        "landmarks.csv (mm) and events.csv (s) stay CSV, as a stylus export would; the "
        f"commands write each subject's pose CSVs to <subject>/{CONVERTED_DIR} and its "
        f"session to <subject>/{SESSION_DIR}"
    )
    commands = [c for t in written for c in t.commands]
    script = out_dir / COMMANDS_FILE
    with atomic_write(script) as fh:
        fh.write("#!/bin/sh\nset -e\n" + "\n".join(commands) + "\n")
    _plain(f"to build and fit the session(s), run (also in {shlex.quote(str(script))}):")
    for c in commands:
        _plain(c)
