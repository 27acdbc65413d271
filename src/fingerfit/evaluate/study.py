"""``fingerfit study``: the paper's whole evaluation over several sessions.

For each session: fit (or take a given model), then axis quality (Fig. 8),
grasp fingertip trajectories and errors at maximal flexion (Figs. 9-10),
target reaching (Figs. 11-12); with simulated sessions also the true errors.
Statistics and the headline as in the paper; outputs written to one folder.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import shutil
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, as_completed
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..digits import FINGERS
from ..errors import FingerfitError
from ..estimate import FitOptions
from ..io.atomic import atomic_write, staged_directory
from ..model import save_model
from ..processes import worker_pool
from ..session import Session
from . import figures
from .gather import PackedSubjects, StudyTables
from .report import write_report
from .results import StudyResult
from .subject import (
    SessionFailure,
    SessionSource,
    SubjectOutcome,
    SubjectResult,
    fig09_data,
    is_source,
    one_line,
    study_subject,
)
from .summary import summarize_study

_SESSION_FILES = {"session.toml", "landmarks.csv", "events.csv", "truth.json", "truth"}


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _check_not_input(out_dir: Path, folders: list[Path]) -> None:
    """Refuse an output folder that is, holds, or sits on a file of an input session folder.

    Every folder given is checked, whether or not its session could be read or fitted
    (with ``--keep-going --overwrite`` a failed session's folder must survive too).
    """
    out = out_dir.resolve()
    for folder in folders:
        src = Path(folder).resolve()
        first = out.relative_to(src).parts[0] if out != src and _inside(out, src) else None
        if _inside(src, out) or (
            first is not None and (first in _SESSION_FILES or (src / first).is_file())
        ):
            raise FingerfitError(
                f"would replace the input session '{folder}' (choose another --out)",
                path=out_dir,
            )


class _InProcess(Executor):
    """An executor that runs each task at once in the calling process (``--jobs 1``)."""

    def submit(self, fn, /, *args, **kwargs) -> Future:
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:
            future.set_exception(exc)
        return future


@contextlib.contextmanager
def study_executor(jobs: int = 1, scheduler: str | None = None) -> Iterator[Executor]:
    """The executor the study's per-subject tasks run on.

    Parameters
    ----------
    jobs : int
        Worker processes on this machine (1: in the calling process).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://HOST:PORT``); its workers
        run the tasks (they must be able to read the session folders and have
        fingerfit installed). Overrides ``jobs``.

    Raises
    ------
    FingerfitError
        ``jobs`` < 1; dask.distributed not installed; scheduler unreachable.
    """
    if scheduler is not None:
        try:
            from distributed import Client
        except ImportError:
            raise FingerfitError(
                "needs dask.distributed: pip install 'fingerfit[cluster]'", field="--scheduler"
            ) from None
        try:
            client = Client(scheduler, timeout=10, set_as_default=False)
        except (OSError, ValueError, TypeError) as exc:
            raise FingerfitError(
                f"cannot connect to the scheduler '{scheduler}' ({one_line(exc)})",
                field="--scheduler",
            ) from None
        try:
            yield client.get_executor(pure=False)
        finally:
            client.close()
        return
    if jobs < 1:
        raise FingerfitError(f"must be at least 1, not {jobs}", field="--jobs")
    if jobs == 1:
        yield _InProcess()
        return
    # spawn: workers never inherit the parent's threads (progress bar, Dask) or locks;
    # Ctrl-C is this process's: the workers print nothing and are ended at once.
    with worker_pool(jobs) as pool:
        yield pool


def run_study(
    sessions: list[Path | Session | SessionSource],
    out_dir: Path,
    options: FitOptions | None = None,
    progress: Callable[[str], None] | None = None,
    *,
    keep_going: bool = False,
    overwrite: bool = False,
    jobs: int = 1,
    scheduler: str | None = None,
    debug: bool = False,
    tables_format: str = "csv",
) -> StudyResult:
    """Fit and evaluate sessions; write tables, figures, ``summary.json`` and ``report.html``.

    Everything is built in a temporary sibling folder of ``out_dir`` and moved into
    place at the end: after an error nothing is left behind. Each session is one task
    (:func:`study_subject`) on :func:`study_executor`; the results are identical for
    any ``jobs`` or scheduler, and this process keeps only each subject's compact
    result (model and tables; no per-frame arrays).

    Parameters
    ----------
    sessions : list of Path, Session or SessionSource
        Session directories (or loaded sessions, or sources that make their folder
        in the study task, e.g. :class:`~fingerfit.simulate.source.SimulatedSession`),
        one subject each; any mix of sessions with or without target recordings, test
        recordings, ground truth and fingers.
    out_dir : Path
        Output folder; must be absent or empty unless ``overwrite``.
    options : FitOptions, optional
        Fit options (method, ``force`` etc.).
    progress : callable, optional
        Called with a short description after each step (one per session, then
        figures and report).
    keep_going : bool
        Skip a session that cannot be read or fitted (listed in
        :attr:`StudyResult.failures`, the summary and the report) instead of
        stopping; an error still when no session succeeds.
    overwrite : bool
        Replace an existing non-empty ``out_dir``.
    jobs : int
        Worker processes (1: in this process).
    scheduler : str, optional
        Dask distributed scheduler address; see :func:`study_executor`.
    debug : bool
        An unexpected exception (not a :class:`FingerfitError`) of a session, a source
        or a study worker is raised as it is, with its traceback (a worker's traceback
        as its ``__cause__``), instead of becoming one line; ``keep_going`` does not
        skip it.
    tables_format : {"csv", "parquet"}
        The tables as ``<name>.csv`` (6 significant digits) or as Parquet datasets
        ``<name>.parquet/subject=<id>/part-0.parquet`` (float64, full precision; readable by
        ``pandas.read_parquet(folder)`` and ``dask.dataframe.read_parquet``).

    Returns
    -------
    StudyResult
        Paths point into ``out_dir``; ``subjects`` are compact
        (:meth:`SubjectResult.compact`).

    Raises
    ------
    FingerfitError
        A session that cannot be read or fitted (``"<subject>: <its error>"``) unless
        ``keep_going``; two sessions with one subject ID (both folders named); an
        unusable output folder. Read errors come before the subject-ID and output
        checks, which come before fit errors, each in the order the sessions were given.
    """
    if tables_format not in ("csv", "parquet"):
        raise FingerfitError(f"must be csv or parquet, not '{tables_format}'", field="--tables")
    options = options or FitOptions()
    step = progress or (lambda _msg: None)
    out_dir = Path(out_dir)
    failures: list[SessionFailure] = []

    def failed(source: str, subject: str | None, message: str) -> None:
        if not keep_going:
            raise FingerfitError(message)
        failures.append(SessionFailure(source, subject, message))

    with staged_directory(out_dir, overwrite=overwrite) as tmp, contextlib.ExitStack() as stack:
        outcomes: list[SubjectOutcome | None] = [None] * len(sessions)
        fig09: dict[int, tuple[str, Path]] = {}
        # Parquet datasets: each subject's rows written as it arrives
        gathered = StudyTables(
            folder=tmp.parent, datasets=tmp if tables_format == "parquet" else None
        )
        subjects = PackedSubjects(folder=tmp.parent)  # as they arrive; selected below
        stored: dict[int, int] = {}  # session -> its place in ``subjects``
        pool = stack.enter_context(study_executor(jobs, scheduler))
        task = functools.partial(study_subject, debug=True) if debug else study_subject
        futures = {pool.submit(task, s, options): i for i, s in enumerate(sessions)}
        for future in as_completed(futures):
            # Dropped once read: a Dask worker keeps a task's result while its future lives.
            i = futures.pop(future)
            try:
                got = outcomes[i] = future.result()
            except Exception as exc:  # a lost worker, not a bad session
                if debug:
                    raise
                raise FingerfitError(
                    f"a study worker failed on '{sessions[i]}' "
                    f"({type(exc).__name__}: {one_line(exc)})"
                ) from None
            if got.result is not None and got.figure is not None:
                # Written as it arrives; only the path is kept.
                name, png = got.figure
                with atomic_write(tmp / name, "wb") as fh:
                    fh.write(png)
                fig09[i] = (f"fig09_{got.subject}", tmp / name)
                got.figure = None
            if got.result is not None:
                # Its rows go to the study's tables and its model is written now; the
                # rest (model, landmarks, names) is kept as one pickle. All on disk.
                light = gathered.add(i, got.result)
                save_model(light.model, tmp / "models" / f"{light.subject}.json")
                stored[i] = len(subjects)
                subjects.append(light)
                got.result = light = None
            if got.read_error is not None:
                step(f"could not read {got.source}")
            elif got.fit_error is not None:
                step(f"failed: {got.subject}")
            else:
                step(f"fitted and evaluated {got.subject}")
        done = [o for o in outcomes if o is not None]
        for o in done:
            if o.read_error is not None:
                failed(o.source, None, o.read_error)
        ok = [o for o in done if o.read_error is None]
        seen: dict[str, SubjectOutcome] = {}
        for o in ok:
            assert o.subject is not None
            first = seen.setdefault(o.subject, o)
            if first is not o:
                raise FingerfitError(
                    f"subject ID '{o.subject}' is used by two sessions: "
                    f"'{first.path or '(in memory)'}' and '{o.path or '(in memory)'}'",
                    field="subject",
                )
        given = [
            x.path if isinstance(x, Session) else Path(x)
            for x in sessions
            if not is_source(x)  # made and removed on the worker
        ]
        _check_not_input(out_dir, [p for p in given if p is not None])
        keep, orders = [], []
        for i, o in enumerate(outcomes):
            if o is None or o.read_error is not None:
                continue
            if o.fit_error is not None:
                failed(o.source, o.subject, o.fit_error)
                continue
            keep.append(stored[i])
            orders.append(i)
        subjects.select(keep)
        if not subjects:
            detail = "; ".join(f.message for f in failures) or "no sessions given"
            raise FingerfitError(f"no session could be fitted and evaluated: {detail}")
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            tables = gathered.finish(orders)  # in the order given
            summary, tables = summarize_study(subjects, options, failures, tables, out_dir)
            result = StudyResult(subjects, summary, tables, tmp, failures=failures)
            kept = {o.subject for o in ok if o.fit_error is None}
            drawn = dict(fig09[i] for i in sorted(fig09) if outcomes[i].subject in kept)
            _write_outputs(result, tmp, drawn, pool, debug=debug, tables_format=tables_format)
        step("figures")
        with atomic_write(tmp / "summary.json") as fh:
            json.dump(_json_safe(summary), fh, indent=1, allow_nan=False)
        result.report = write_report(result, tmp / "report.html")
        step("report")
    result.out_dir = out_dir
    result.figures = {k: out_dir / p.relative_to(tmp) for k, p in result.figures.items()}
    result.report = out_dir / "report.html"
    return result


def _json_safe(node):
    """NaN/inf as None, NumPy scalars as Python numbers, tuples as lists (strict JSON)."""
    if isinstance(node, dict):
        return {str(k): _json_safe(v) for k, v in node.items()}
    if isinstance(node, list | tuple):
        return [_json_safe(v) for v in node]
    if isinstance(node, np.generic):
        node = node.item()
    if isinstance(node, float) and not np.isfinite(node):
        return None
    return node


def _short_recording(names: pd.Series) -> pd.Series:
    """Recording names short enough to stand side by side under a figure's axis:
    ``thumb_circumduction.csv`` -> ``circumduction``."""
    return names.str.removesuffix(".csv").str.removeprefix("thumb_")


def figure_builders(
    subjects: list[SubjectResult], tables: dict[str, pd.DataFrame]
) -> dict[str, tuple[str, Callable[[], Figure]]]:
    """Every figure of a study: key -> (PNG file name, function building the Figure).

    Fig. 8, Fig. 9 per subject (its first finger, hand-sensor frame; not for a compact
    result, whose study task drew it), Fig. 10; Figs. 11-12 when any session has targets;
    the true fingertip error when any has ground truth.
    """
    out: dict[str, tuple[str, Callable[[], Figure]]] = {
        "fig08": (
            "fig08_axis_quality.png",
            lambda: figures.make_axis_quality(tables["axis_quality"]),
        )
    }
    for s in subjects:
        if s.grasp:  # a compact result's Fig. 9 was drawn by its study task
            name, time, tips, label = fig09_data(s)
            out[f"fig09_{s.subject}"] = (
                name,
                lambda t=time, p=tips, x=label: figures.make_trajectories(t, p, x),
            )
    fingers_flex = tables["max_flexion"][tables["max_flexion"]["finger"].isin(FINGERS)]
    if not fingers_flex.empty:  # a thumb-only study has no Fig. 10 (the fingers')
        out["fig10"] = (
            "fig10_max_flexion.png",
            lambda: figures.make_paired_boxes(
                fingers_flex,
                "subject",
                "Fig. 10 - fingertip error at maximal flexion (vs distal-sensor reference)",
                "fingertip error at maximal flexion (mm)",
                xlabel="subject",
            ),
        )
    if not tables["targets"].empty:
        out["fig11"] = (
            "fig11_target_offsets.png",
            lambda: figures.make_target_scatter(tables["targets"]),
        )
        out["fig12"] = (
            "fig12_target_errors.png",
            lambda: figures.make_target_bars(tables["targets"]),
        )
    tips = tables.get("truth_fingertip")
    if tips is not None and tips["finger"].isin(FINGERS).any():
        wide = (
            tips[tips["finger"].isin(FINGERS)]
            .pivot_table(index=["subject", "recording"], columns="variant", values="mean_mm")
            .reset_index()
        )
        if (tips["finger"] == "thumb").any():  # the thumb's recordings too: short names
            wide["recording"] = _short_recording(wide["recording"])
        out["truth"] = (
            "truth_fingertip.png",
            lambda: figures.make_paired_boxes(
                wide,
                "recording",
                "True fingertip error (simulation ground truth)",
                "mean fingertip error per recording (mm)",
                xlabel="recording",
            ),
        )
    if tips is not None and (tips["finger"] == "thumb").any():
        thumb = (
            tips[tips["finger"] == "thumb"]
            .pivot_table(index=["subject", "recording"], columns="variant", values="mean_mm")
            .reset_index()
        )
        thumb["recording"] = _short_recording(thumb["recording"])
        out["thumb"] = (
            "thumb_tip.png",
            lambda: figures.make_paired_boxes(
                thumb,
                "recording",
                "Thumb tip error against ground truth (simulation)",
                "mean thumb tip error per recording (mm)",
                xlabel="recording",
            ),
        )
    if "pinch" in tables and not tables["pinch"].empty:
        out["pinch"] = ("pinch.png", lambda: figures.make_pinch(tables["pinch"]))
    return out


# The one table each study-wide figure draws (figure_builders).
_FIGURE_TABLE = {
    "fig08": "axis_quality",
    "fig10": "max_flexion",
    "fig11": "targets",
    "fig12": "targets",
    "truth": "truth_fingertip",
    "thumb": "truth_fingertip",
    "pinch": "pinch",
}


def figure_tables(key: str, tables: StudyTables) -> dict[str, pd.DataFrame]:
    """What a study task drawing figure ``key`` needs of the study's tables: its own table,
    and ``max_flexion`` and ``targets`` without rows (:func:`figure_builders` looks at
    them), so each task is sent one table rather than all of them."""
    out = {k: tables.empty(k) for k in ("max_flexion", "targets")}
    out[_FIGURE_TABLE[key]] = tables[_FIGURE_TABLE[key]]
    return out


def draw_study_figure(key: str, tables: dict[str, pd.DataFrame]) -> bytes:
    """PNG bytes of one figure of the whole study (a study task; no per-subject Fig. 9).

    Parameters
    ----------
    key : str
        A key of :func:`figure_builders` other than ``fig09_*`` (``fig08``, ``fig10``, ...).
    tables : dict of str to DataFrame
        The study's tables (:func:`summarize_study`).
    """
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        _name, build = figure_builders([], tables)[key]
        png = io.BytesIO()
        figures.save_to(build(), png)
    return png.getvalue()


_FIGURES_AT_ONCE = 3  # study-wide figures sent to the executor at a time (each with a table)


def _write_outputs(
    result: StudyResult,
    out_dir: Path,
    drawn: dict[str, Path],
    pool: Executor,
    *,
    debug: bool = False,
    tables_format: str = "csv",
) -> None:
    """CSV tables and PNG figures into ``out_dir``; figure paths into ``result.figures``.

    ``drawn``: figures already written (key -> path), the per-subject Fig. 9 drawn by
    the study tasks; listed after Fig. 8 in the order given. ``pool``: the study's
    executor, where the study-wide figures are drawn (:func:`draw_study_figure`), each
    sent its own table, a few at a time, while this process writes the tables chunk by
    chunk (:meth:`StudyTables.chunks`). ``debug``: a worker's exception is raised as it
    is rather than as one line. ``tables_format``: ``csv`` or ``parquet``
    (:func:`_write_tables`).
    """
    tables = result.tables
    sending: dict[str, tuple[str, Future]] = {}  # figure -> (file name, PNG bytes to come)
    written: dict[str, Path] = {}

    def receive(key: str) -> None:
        filename, future = sending.pop(key)
        try:
            png = future.result()
        except Exception as exc:  # a lost worker: named, never a traceback (but debug)
            if debug:
                raise
            raise FingerfitError(
                f"a study worker failed drawing {filename} ({type(exc).__name__}: {one_line(exc)})"
            ) from None
        with atomic_write(out_dir / filename, "wb") as fh:
            fh.write(png)
        written[key] = out_dir / filename

    tables_written = False
    for key, name in _FIGURE_TABLE.items():
        if name not in tables:
            continue
        sent = figure_tables(key, tables)
        made = figure_builders([], sent)
        if key not in made:  # e.g. no Fig. 10 in a thumb-only study
            continue
        if len(sending) == _FIGURES_AT_ONCE:
            receive(next(iter(sending)))
        sending[key] = (made[key][0], pool.submit(draw_study_figure, key, sent))
        del sent, made
        if len(sending) == _FIGURES_AT_ONCE and not tables_written:
            _write_tables(tables, out_dir, tables_format)  # while the first figures are drawn
            tables_written = True
    if not tables_written:
        _write_tables(tables, out_dir, tables_format)
    for key in list(sending):
        receive(key)
    for key in _FIGURE_TABLE:
        if key in written:
            result.figures[key] = written[key]
        if key == "fig08":
            result.figures.update(drawn)


def _arrow_schema(tables: StudyTables, name: str):
    """The Parquet schema of study table ``name``: text columns (text or categorical in any
    chunk) string, columns integer in every chunk int64, booleans bool, the rest float64."""
    from ..io.parquet import table_schema

    return table_schema(tables.chunks(name), empty=tables.empty(name))


def _parts_written(tables: StudyTables, name: str, out_dir: Path, schema) -> bool:
    """Whether the Parquet dataset of table ``name`` written subject by subject as they
    arrived (:meth:`StudyTables.add`) is the whole table: a file for exactly the subjects
    with rows, each of the table's schema. When not (a subject left out, a column typed
    otherwise by one subject), the caller writes the dataset again from the table."""
    import pyarrow.parquet as pq

    written = tables.written.get(name, {})
    folder = out_dir / f"{name}.parquet"
    want: set[str] = set()
    for chunk in tables.chunks(name):
        want.update(chunk["subject"].astype(str).unique())
    if not want or set(written) != want or "subject" not in schema.names:
        return False
    rest = schema.remove(schema.get_field_index("subject"))
    if sorted(p for p in folder.rglob("*") if p.is_file()) != sorted(written.values()):
        return False
    return all(pq.read_schema(p).remove_metadata().equals(rest) for p in written.values())


def _write_tables(tables: StudyTables, out_dir: Path, tables_format: str = "csv") -> None:
    """Each table as ``<name>.csv``, written chunk by chunk (6 significant digits), or as a
    Parquet dataset ``<name>.parquet/subject=<id>/part-0.parquet`` (full precision), written a
    subject at a time from the same chunks."""
    if tables_format == "parquet":
        from ..io.parquet import STUDY_TABLE, TABLE_KEY, TableMeta, write_partitioned

        for name in tables:
            schema = _arrow_schema(tables, name)
            if _parts_written(tables, name, out_dir, schema):
                continue
            meta = TableMeta(STUDY_TABLE, time_units=None, extra={TABLE_KEY: name})
            shutil.rmtree(out_dir / f"{name}.parquet", ignore_errors=True)
            write_partitioned(out_dir / f"{name}.parquet", tables.chunks(name), schema, meta)
        return
    for name in tables:
        with atomic_write(out_dir / f"{name}.csv", newline="") as fh:
            header = True
            for chunk in tables.chunks(name):
                chunk.to_csv(
                    fh, index=False, header=header, lineterminator="\n", float_format="%.6g"
                )
                header = False
            if header:  # no rows
                tables.empty(name).to_csv(fh, index=False, lineterminator="\n")
