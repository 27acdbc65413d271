"""``fingerfit simulate``: write simulated sessions with ground truth."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import Progress

from ..session import FINGERS
from ..simulate import SimConfig, simulate_cohort, write_subject
from .app import app, parse_list, say, user_errors


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
    fingers: Annotated[str, typer.Option(help="Comma-separated fingers.")] = "index",
    hand: Annotated[str, typer.Option(help="left or right.")] = "left",
    noise: Annotated[
        float, typer.Option(min=0.0, help="Tracker error scale (1 = Liberty-like, 0 = none).")
    ] = 1.0,
    sta: Annotated[
        float, typer.Option(min=0.0, help="Soft-tissue artefact scale (0 = rigid sensors).")
    ] = 1.0,
    stylus: Annotated[float, typer.Option(min=0.0, help="Stylus noise SD per axis (mm).")] = 0.3,
    tilt: Annotated[
        float, typer.Option(min=0.0, help="Axis obliquity scale (0 = axes perpendicular to bones).")
    ] = 1.0,
    rom: Annotated[
        float, typer.Option(min=0.05, max=1.3, help="Grasp range-of-motion scale.")
    ] = 1.0,
    rolling: Annotated[
        bool, typer.Option(help="Centre of rotation migrating with flexion.")
    ] = True,
    abduction: Annotated[bool, typer.Option(help="MP ab/adduction during motion.")] = True,
    distortion: Annotated[bool, typer.Option(help="Smooth tracker field distortion.")] = True,
    exact: Annotated[
        bool, typer.Option("--exact", help="No error source at all, pure hinges.")
    ] = False,
) -> None:
    """Simulate sessions (reference, grasp, targets, free-motion test) with truth.json."""
    if hand not in ("left", "right"):
        raise typer.BadParameter("must be left or right", param_hint="--hand")
    names = tuple(parse_list(fingers, FINGERS, "--fingers") or ())
    kw = dict(fingers=names, hand=hand, rom_scale=rom, tilt_scale=tilt)
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
    with Progress(transient=True) as bar:
        task = bar.add_task("simulating", total=subjects)
        cohort = simulate_cohort(config, subjects, seed)
        for sim in cohort:
            write_subject(sim, out_dir / sim.session.subject)
            bar.advance(task)
    say("wrote {} session(s) to [bold]{}[/]", subjects, out_dir)
