"""``fingerfit study`` and ``fingerfit demo``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

if TYPE_CHECKING:
    from ..evaluate import StudyResult
from ._names import DEFAULT_METHOD, METHODS
from .app import Quiet, app, debugging, notice, out, progress, say, user_errors


def _cell(d: dict) -> str:
    m, sd = d["mean_mm"], d["sd_mm"]
    return "—" if m is None else f"{m:.1f} ({'—' if sd is None else f'{sd:.1f}'})"


def _pct(v: float | None) -> str:
    return "—" if v is None else f"{v:.0f} %"


def headline_table(result: StudyResult) -> Table:
    """The paper's headline: user-axis vs orthogonal fingertip error, mean (SD) mm, next to the paper."""
    sm = result.summary
    t = Table(
        title="Fingertip error, mean (SD) mm",
        title_justify="left",
        caption="user-axis, orthogonal: fingertip error of each model (max flexion: vs the "
        "distal-sensor reference; targets: vs the stylus target); reduction: how much "
        "smaller the user-axis mean and SD are; paper: Tang et al. 2018 (docs/study.md)",
        caption_justify="left",
    )
    for c in ("", "user-axis", "orthogonal", "reduction (mean / SD)", "paper"):
        t.add_column(c, justify="left" if not c else "right")
    for key, name in (("max_flexion", "max flexion"), ("targets", "targets")):
        if key not in sm:
            continue
        h, p = sm[key], sm["paper"][key]
        t.add_row(
            name,
            _cell(h["user_axis"]),
            _cell(h["orthogonal"]),
            f"{_pct(h['reduction_percent'])} / {_pct(h['sd_reduction_percent'])}",
            f"{p['user_axis'][0]} ({p['user_axis'][1]}) vs {p['orthogonal'][0]} ({p['orthogonal'][1]}), "
            f"−{p['reduction_percent']} %",
        )
    return t


def _run(
    sessions: list,
    out_dir: Path,
    method: str,
    *,
    force: bool = False,
    keep_going: bool = False,
    overwrite: bool = False,
    jobs: int = 1,
    scheduler: str | None = None,
    quiet: bool = False,
    tables: str = "csv",
) -> StudyResult:
    from ..estimate import FitOptions
    from ..estimate.fit import METHODS
    from ..evaluate import run_study

    if method not in METHODS:
        raise typer.BadParameter(f"must be one of {', '.join(METHODS)}", param_hint="--method")
    with progress(quiet) as bar:
        task = bar.add_task("fitting and evaluating", total=len(sessions) + 2)
        result = run_study(
            sessions,
            out_dir,
            FitOptions(method=method, force=force),
            progress=lambda msg: bar.update(task, advance=1, description=msg),
            keep_going=keep_going,
            overwrite=overwrite,
            jobs=jobs,
            scheduler=scheduler,
            debug=debugging(),
            tables_format=tables,
        )
    for f in result.failures:
        notice("warning", f"skipped {f.message}")
    not_evaluated = result.summary.get("events_not_evaluated", {}).get("per_subject", {})
    for subject, n in not_evaluated.items():
        notice(
            "warning",
            f"{subject}: {n['target_touches']} target touch(es) and {n['pinches']} pinch(es) "
            "not evaluated: the model lacks their digit (listed in the report)",
        )
    for subject, warned in result.summary.get("warnings", {}).items():
        for w in warned:
            notice("warning", f"{subject}: {w}")
    out.print(headline_table(result))
    return result


@app.command()
@user_errors
def study(
    sessions: Annotated[list[Path], typer.Argument(help="Session directories.")],
    out_dir: Annotated[
        Path, typer.Option("--out", help="Output folder (absent or empty, or see --overwrite).")
    ],
    method: Annotated[
        str, typer.Option(help=f"Axis estimator: {', '.join(METHODS)}.")
    ] = DEFAULT_METHOD,
    force: Annotated[
        bool,
        typer.Option(
            "--force", help="Fit past plausibility checks; the warnings go in the report."
        ),
    ] = False,
    keep_going: Annotated[
        bool,
        typer.Option(
            "--keep-going",
            help="Skip sessions that fail (listed as warnings and in the report); "
            "exit 2 only if none succeeds.",
        ),
    ] = False,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace a non-empty --out folder.")
    ] = False,
    jobs: Annotated[
        int,
        typer.Option("--jobs", "-j", min=1, help="Worker processes fitting subjects in parallel."),
    ] = 1,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Dask distributed scheduler (tcp://HOST:PORT) whose workers fit the "
            "subjects instead (needs fingerfit[cluster]; workers must read the sessions).",
        ),
    ] = None,
    tables: Annotated[
        str,
        typer.Option(
            "--tables",
            help="Tables as csv (NAME.csv) or parquet (NAME.parquet/subject=ID/part-0.parquet "
            "datasets, full precision).",
        ),
    ] = "csv",
    quiet: Quiet = False,
) -> None:
    """The paper's evaluation over sessions: report.html, summary.json, CSV tables, PNG figures."""
    result = _run(
        list(sessions),
        out_dir,
        method,
        force=force,
        keep_going=keep_going,
        overwrite=overwrite,
        jobs=jobs,
        scheduler=scheduler,
        quiet=quiet,
        tables=tables,
    )
    say("report: [bold]{}[/]", result.report)


@app.command()
@user_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("fingerfit-demo"),
    subjects: Annotated[int, typer.Option(min=1, help="Simulated subjects.")] = 5,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 2018,
    method: Annotated[
        str, typer.Option(help=f"Axis estimator: {', '.join(METHODS)}.")
    ] = DEFAULT_METHOD,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace a non-empty --out folder.")
    ] = False,
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", min=1, help="Worker processes fitting subjects.")
    ] = 1,
    quiet: Quiet = False,
) -> None:
    """Simulate a cohort (the whole hand, left, Liberty-like), fit, and run the study.

    Writes ``OUT/sessions/<subject>`` and ``OUT/study``; all of it appears at once
    when everything succeeded.
    """
    from ..digits import DIGIT_NAMES
    from ..io.atomic import staged_directory
    from ..simulate import SimConfig, simulate_cohort, write_subject

    config = SimConfig(fingers=DIGIT_NAMES, hand="left")
    with staged_directory(out_dir, overwrite=overwrite) as tmp:
        with progress(quiet) as bar:
            task = bar.add_task(f"simulating {subjects} subjects", total=subjects)
            dirs = []
            for sim in simulate_cohort(config, subjects, seed):
                dirs.append(write_subject(sim, tmp / "sessions" / sim.session.subject))
                bar.advance(task)
        _run(dirs, tmp / "study", method, jobs=jobs, quiet=quiet)
    say("sessions: {}", out_dir / "sessions")
    say("report: [bold]{}[/]", out_dir / "study" / "report.html")
