"""``fingerfit study`` and ``fingerfit demo``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from ..estimate import FitOptions
from ..estimate.fit import METHODS
from ..evaluate import StudyResult, run_study
from ..simulate import SimConfig, simulate_cohort, write_subject
from .app import app, out, say, user_errors


def _progress() -> Progress:
    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        transient=True,
    )


def headline_table(result: StudyResult) -> Table:
    """The paper's headline: user-axis vs orthogonal fingertip error, mean (SD) mm, next to the paper."""
    sm = result.summary
    t = Table(title="Fingertip error, mean (SD) mm", title_justify="left")
    for c in ("", "user-axis", "orthogonal", "reduction (mean / SD)", "paper"):
        t.add_column(c, justify="left" if not c else "right")
    for key, name in (("max_flexion", "max flexion"), ("targets", "targets")):
        if key not in sm:
            continue
        h, p = sm[key], sm["paper"][key]
        t.add_row(
            name,
            f"{h['user_axis']['mean_mm']:.1f} ({h['user_axis']['sd_mm']:.1f})",
            f"{h['orthogonal']['mean_mm']:.1f} ({h['orthogonal']['sd_mm']:.1f})",
            f"{h['reduction_percent']:.0f} % / {h['sd_reduction_percent']:.0f} %",
            f"{p['user_axis'][0]} ({p['user_axis'][1]}) vs {p['orthogonal'][0]} ({p['orthogonal'][1]}), "
            f"−{p['reduction_percent']} %",
        )
    return t


def _run(sessions: list, out_dir: Path, method: str) -> StudyResult:
    if method not in METHODS:
        raise typer.BadParameter(f"must be one of {', '.join(METHODS)}", param_hint="--method")
    with _progress() as bar:
        task = bar.add_task("fitting and evaluating", total=len(sessions) + 2)
        result = run_study(
            sessions,
            out_dir,
            FitOptions(method=method),
            progress=lambda msg: bar.update(task, advance=1, description=msg),
        )
    out.print(headline_table(result))
    return result


@app.command()
@user_errors
def study(
    sessions: Annotated[list[Path], typer.Argument(help="Session directories.")],
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")],
    method: Annotated[
        str, typer.Option(help=f"Axis estimator: {', '.join(METHODS)}.")
    ] = FitOptions.method,
) -> None:
    """The paper's evaluation over sessions: report.html, summary.json, CSV tables, PNG figures."""
    result = _run(list(sessions), out_dir, method)
    say("report: [bold]{}[/]", result.report)


@app.command()
@user_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("fingerfit-demo"),
    subjects: Annotated[int, typer.Option(min=2, help="Simulated subjects.")] = 5,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 2018,
    method: Annotated[
        str, typer.Option(help=f"Axis estimator: {', '.join(METHODS)}.")
    ] = FitOptions.method,
) -> None:
    """Simulate the paper's cohort (index finger, left hand, Liberty-like), fit, and run the study."""
    config = SimConfig(fingers=("index",), hand="left")
    with _progress() as bar:
        task = bar.add_task(f"simulating {subjects} subjects", total=subjects)
        dirs = []
        for sim in simulate_cohort(config, subjects, seed):
            dirs.append(write_subject(sim, out_dir / "sessions" / sim.session.subject))
            bar.advance(task)
    result = _run(dirs, out_dir / "study", method)
    say("sessions: {}", out_dir / "sessions")
    say("report: [bold]{}[/]", result.report)
