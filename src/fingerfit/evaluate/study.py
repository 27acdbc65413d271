"""``fingerfit study``: the paper's whole evaluation over several sessions.

For each session: fit (or take a given model), then axis quality (Fig. 8),
grasp fingertip trajectories and errors at maximal flexion (Figs. 9-10),
target reaching (Figs. 11-12); with simulated sessions also the true errors.
Statistics and the headline as in the paper; outputs written to one folder.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import pickle
import tempfile
import warnings
import weakref
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from .. import __version__
from ..digits import FINGERS, THUMB_JOINTS
from ..errors import FingerfitError
from ..estimate import FitOptions, fit_session
from ..io import load_session
from ..io.atomic import atomic_write, staged_directory
from ..kinematics import compute_kinematics
from ..memory import release_freed_memory
from ..model import VARIANTS, HandModel, save_model
from ..session import HAND_SENSOR, JOINTS, PoseSeries, Recording, Session, check_subject_id
from ..transforms import angle_between_axes, apply_inverse_pose, distance_between_lines
from . import figures
from .fingertip import GraspEvaluation, evaluate_grasp, evaluate_targets, skipped_events
from .pinch import PINCH_COLUMNS, evaluate_pinches
from .stats import (
    Skipped,
    independent_ttest_or_skip,
    paired_ttest_or_skip,
    reduction_percent,
    summarize,
    two_way_anova_or_skip,
)
from .truth import Truth, axis_errors, check_truth_frames, load_truth

PAPER = {
    "max_flexion": {"user_axis": (2.7, 1.3), "orthogonal": (5.4, 3.4), "reduction_percent": 50},
    "targets": {"user_axis": (2.6, 0.9), "orthogonal": (4.7, 1.7), "reduction_percent": 45},
    "axis_quality_mm": {"dip": (0.2, 0.1), "pip": (0.3, 0.1)},
}

_TRUTH_TIP_COLUMNS = ["subject", "finger", "recording", "variant", "mean_mm", "p95_mm"]
_TRUTH_ANGLE_COLUMNS = [
    "subject",
    "finger",
    "recording",
    "joint",
    "variant",
    "mean_abs_deg",
    "p95_abs_deg",
]
_THUMB_GEOMETRY_COLUMNS = [
    "subject",
    "joint",
    "axis_offset_mm",
    "true_axis_offset_mm",
    "axes_angle_deg",
    "true_axes_angle_deg",
]


@dataclass
class SubjectResult:
    """Everything the study computed for one session.

    The tables (``max_flexion`` ... ``truth_angles``) are the subject's rows of the
    study's tables. In :attr:`StudyResult.subjects` of :func:`run_study` they are None:
    the study moved them into :attr:`StudyResult.tables` as each subject arrived
    (:class:`StudyTables`), so it keeps a few KB per subject, not a DataFrame each.
    """

    subject: str
    session: Session
    model: HandModel
    grasp: dict[str, GraspEvaluation]
    max_flexion: pd.DataFrame
    targets: pd.DataFrame
    distances: pd.DataFrame
    truth: Truth | None
    truth_axes: pd.DataFrame | None = None
    truth_tips: pd.DataFrame | None = None
    warnings: tuple[str, ...] = ()
    pinches: pd.DataFrame | None = None  # evaluate_pinches, with ``subject``
    skipped_events: tuple[dict, ...] = ()  # fingertip.skipped_events
    truth_angles: pd.DataFrame | None = None  # _TRUTH_ANGLE_COLUMNS
    frames: int = 0  # rows of all the session's recordings that were read

    def compact(self) -> SubjectResult:
        """The same result without the per-frame arrays (what a study task sends back).

        The session keeps its subject, path, landmarks and recording names (every
        recording with zero frames, one shared empty pose series per sensor); the grasp
        evaluations and the true trajectories are dropped, and of the truth document
        only what :func:`thumb_geometry` reads (``fingers.<digit>.axis_offset_mm`` and
        ``axes_angle_deg``). Model, tables and warnings are kept as they are.
        """
        truth = None
        if self.truth is not None:
            keep = ("axis_offset_mm", "axes_angle_deg")
            digits = self.truth.document.get("fingers", {})
            doc = {"fingers": {f: {k: d[k] for k in keep if k in d} for f, d in digits.items()}}
            truth = Truth(doc, {})
        return replace(self, session=_without_frames(self.session), grasp={}, truth=truth)


_NO_FRAMES = PoseSeries(np.empty((0, 3)), np.empty((0, 3, 3)))


def _empty(rec: Recording) -> Recording:
    """A recording with its name and sensors but no frames (no view on the original)."""
    return Recording(rec.name, np.empty(0), dict.fromkeys(rec.poses, _NO_FRAMES), list(rec.notes))


def _without_frames(session: Session) -> Session:
    return replace(
        session,
        reference=_empty(session.reference),
        grasp=[_empty(r) for r in session.grasp],
        targets=[_empty(r) for r in session.targets],
        test=[_empty(r) for r in session.test],
    )


@dataclass(frozen=True)
class SessionFailure:
    """A session the study could not use.

    Attributes
    ----------
    source : str
        The session folder as given (or the subject of an in-memory session).
    subject : str or None
        Its subject ID, when the session could be read.
    message : str
        One line: ``"<subject>: <the session's own error>"`` (or the folder when the
        subject is unknown).
    """

    source: str
    subject: str | None
    message: str

    def as_dict(self) -> dict:
        return {"session": self.source, "subject": self.subject, "error": self.message}


class PackedSubjects(Sequence):
    """A study's subjects, each kept as one pickle in an anonymous temporary file; every
    access makes a fresh :class:`SubjectResult` from it.

    Holding a thousand subjects costs this process a file offset each, not their
    pickles (about 20 KB each with four fingers) nor the ~1500 Python objects of each
    model and session. The file is made in ``folder`` (default: the system's temporary
    folder; :func:`run_study` uses the output folder's parent, where its staging folder
    is, so the pickles go to the disk the user chose and not to a RAM-backed /tmp). It
    has no name on Linux and is removed by the operating system when it is closed, at
    the latest when this object goes.

    Read-only: a subject changed after access is not stored back. Not for several
    threads at once (reads seek one shared file).
    """

    def __init__(
        self, subjects: list[SubjectResult] | None = None, folder: Path | None = None
    ) -> None:
        self._file = tempfile.TemporaryFile(prefix=".fingerfit-subjects-", dir=folder)
        weakref.finalize(self, self._file.close)  # closed with this object, quietly
        self._spans: list[tuple[int, int]] = []  # (offset, bytes) of each pickle
        self._end = 0
        for s in subjects or []:
            self.append(s)

    def append(self, subject: SubjectResult | bytes) -> None:
        """Keep a subject (or its pickle) after the others."""
        if not isinstance(subject, bytes):
            subject = pickle.dumps(subject, protocol=pickle.HIGHEST_PROTOCOL)
        self._file.seek(self._end)
        self._file.write(subject)
        self._spans.append((self._end, len(subject)))
        self._end += len(subject)

    def select(self, positions: Sequence[int]) -> None:
        """Keep the subjects at ``positions`` (indices into the current order), in that
        order, and drop the others (no pickle is moved)."""
        self._spans = [self._spans[k] for k in positions]

    def __len__(self) -> int:
        return len(self._spans)

    def _load(self, k: int) -> SubjectResult:
        start, size = self._spans[k]
        self._file.seek(start)
        return pickle.loads(self._file.read(size))

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self._load(k) for k in range(len(self))[i]]
        return self._load(range(len(self))[i])

    def __iter__(self) -> Iterator[SubjectResult]:
        for k in range(len(self)):
            yield self._load(k)

    def __getstate__(self) -> dict:
        raise TypeError("PackedSubjects holds an open temporary file and cannot be pickled")


@dataclass
class StudyResult:
    """The study's tables, statistics and output paths.

    ``subjects``: from :func:`run_study` a :class:`PackedSubjects` (compact results
    without their tables, which are in ``tables``).
    """

    subjects: Sequence[SubjectResult]
    summary: dict
    tables: dict[str, pd.DataFrame]
    out_dir: Path
    figures: dict[str, Path] = field(default_factory=dict)
    report: Path | None = None
    failures: list[SessionFailure] = field(default_factory=list)


def _fit(session: Session, options: FitOptions) -> tuple[HandModel, tuple[str, ...]]:
    """Fit a session; its warnings (``--force``) from the model and any the fit emitted."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        model = fit_session(session, options)
    found = [*model.warnings]
    found += [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    return model, tuple(dict.fromkeys(found))


def _subject(session: Session, options: FitOptions) -> SubjectResult:
    truth = load_truth(session.path)  # a broken truth file fails before the fit
    if truth is not None:
        check_truth_frames(truth, session)
    model, warned = _fit(session, options)
    grasp, flex, dist = {}, [], []
    for f, fm in model.fingers.items():
        ev = evaluate_grasp(model, f, session.grasp[0], session.rate_hz)
        grasp[f] = ev
        flex.append(ev.errors.assign(subject=session.subject, finger=f))
        for j, jm in fm.joints.items():
            d = jm.quality.centre_distance_mm
            dist.append(
                pd.DataFrame(
                    {
                        "subject": session.subject,
                        "finger": f,
                        "joint": j,
                        "cycle": np.arange(1, len(d) + 1),
                        "distance_mm": d,
                    }
                )
            )
    targets = evaluate_targets(model, session).assign(subject=session.subject)
    pinches = evaluate_pinches(model, session, truth).assign(subject=session.subject)
    res = SubjectResult(
        session.subject,
        session,
        model,
        grasp,
        _concat(flex, _FLEX_COLUMNS),
        targets,
        _concat(dist, _DIST_COLUMNS),
        truth,
        warnings=warned,
        pinches=pinches,
        skipped_events=tuple(skipped_events(model, session)),
        frames=sum(rec.n_frames for rec in session.recordings()),
    )
    if truth is not None:
        fingers = [f for f in model.fingers if f in truth.document.get("fingers", {})]
        res.truth_axes = _concat(
            [axis_errors(model, truth, f).assign(subject=session.subject) for f in fingers],
            _TRUTH_AXIS_COLUMNS,
        )
        rows, angle_rows = [], []
        for rec in session.recordings()[1:]:
            if rec.name not in truth.tips:
                continue
            kin = compute_kinematics(model, rec, fingers=fingers)
            for f in fingers:
                for v in VARIANTS:
                    angle_rows += _angle_errors(
                        session.subject, f, rec.name, v, kin.motions[v][f].angles, truth
                    )
                    e = np.linalg.norm(kin.motions[v][f].tip - truth.tips[rec.name][f], axis=1)
                    e = e[np.isfinite(e)]
                    if not e.size:
                        continue
                    rows.append(
                        (
                            session.subject,
                            f,
                            rec.name,
                            v,
                            float(e.mean()),
                            float(np.percentile(e, 95)),
                        )
                    )
        res.truth_tips = pd.DataFrame(rows, columns=_TRUTH_TIP_COLUMNS)
        res.truth_angles = pd.DataFrame(angle_rows, columns=_TRUTH_ANGLE_COLUMNS)
    return res


def _angle_errors(
    subject: str, digit: str, recording: str, variant: str, angles: dict, truth: Truth
) -> list[tuple]:
    """Rows of ``_TRUTH_ANGLE_COLUMNS``: each model angle (rad, ``(n,)``) against the true
    angle of the same name over a recording, mean and 95th percentile of ``|error|`` (deg)."""
    true = truth.angles.get(recording, {}).get(digit, {})
    rows = []
    for name, a in angles.items():
        if name not in true or true[name].shape != a.shape:
            continue
        e = np.degrees(np.abs(a - true[name]))
        e = e[np.isfinite(e)]
        if e.size:
            rows.append(
                (
                    subject,
                    digit,
                    recording,
                    name,
                    variant,
                    float(e.mean()),
                    float(np.percentile(e, 95)),
                )
            )
    return rows


def thumb_geometry(subject: SubjectResult) -> pd.DataFrame:
    """Per two-axis thumb joint: the offset between its two axis lines (mm) and the angle
    between them (deg), fitted and (with ground truth) true; ``_THUMB_GEOMETRY_COLUMNS``."""
    fm = subject.model.fingers.get("thumb")
    rows = []
    if fm is not None:
        doc = {} if subject.truth is None else subject.truth.document["fingers"].get("thumb", {})
        for j, second in fm.second_axes.items():
            first = fm.joints[j]
            rows.append(
                (
                    subject.subject,
                    j,
                    distance_between_lines(first.center, first.axis, second.center, second.axis),
                    float(doc.get("axis_offset_mm", {}).get(j, np.nan)),
                    float(np.degrees(angle_between_axes(first.axis, second.axis))),
                    float(doc.get("axes_angle_deg", {}).get(j, np.nan)),
                )
            )
    return pd.DataFrame(rows, columns=_THUMB_GEOMETRY_COLUMNS)


def _stat(result) -> dict:
    """A test result or a skip reason as the dict stored in ``summary.json``."""
    return result.as_dict() if isinstance(result, Skipped) else dict(result.__dict__)


def _num(v: float) -> float | None:
    """A finite float, or None (JSON ``null``) for NaN/inf."""
    v = float(v)
    return v if np.isfinite(v) else None


def _headline(table: pd.DataFrame, user: str = "user_axis", ortho: str = "orthogonal") -> dict:
    u, o = summarize(table[user]), summarize(table[ortho])
    return {
        "user_axis": {"mean_mm": _num(u.mean), "sd_mm": _num(u.sd), "n": u.n},
        "orthogonal": {"mean_mm": _num(o.mean), "sd_mm": _num(o.sd), "n": o.n},
        "reduction_percent": _num(reduction_percent(u.mean, o.mean)),
        "sd_reduction_percent": _num(reduction_percent(u.sd, o.sd)),
    }


def _anova_dict(table: pd.DataFrame | Skipped) -> dict:
    if isinstance(table, Skipped):
        return table.as_dict()
    return {
        idx: {"F": _num(r["F"]), "p": _num(r["PR(>F)"]), "df": float(r["df"])}
        for idx, r in table.iterrows()
    }


def _skips(node, where: str = "") -> list[dict]:
    """Every ``{"skipped": reason}`` in a summary, with its dotted key."""
    if isinstance(node, dict):
        if set(node) == {"skipped"}:
            return [{"statistic": where, "reason": node["skipped"]}]
        return [x for k, v in node.items() for x in _skips(v, f"{where}.{k}".lstrip("."))]
    return []


_FLEX_COLUMNS = ["subject", "finger", "cycle", "user_axis", "orthogonal"]
_TARGET_COLUMNS = ["subject", "finger", "target", "source", "error_mm", "dx", "dy", "dz"]
_DIST_COLUMNS = ["subject", "finger", "joint", "cycle", "distance_mm"]
_PINCH_COLUMNS = ["subject", *PINCH_COLUMNS]


def _concat(frames: list[pd.DataFrame], columns: list[str]) -> pd.DataFrame:
    """Concatenate non-empty tables (an empty one would turn float columns into object)."""
    frames = [f[columns] for f in frames if not f.empty]
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=float) for c in columns})
    return pd.concat(frames, ignore_index=True)


def _categorical(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with each text column categorical (categories sorted, as text sorts).

    A study's text columns (subject, finger, joint, recording, ...) repeat a few hundred
    values: as categories its tables take a third of the memory of Arrow text, and
    ``pd.concat`` of Arrow text would keep one small chunk per input table.
    """
    text = [c for c, t in table.dtypes.items() if isinstance(t, pd.StringDtype)]
    if not text:
        return table
    return table.astype(dict.fromkeys(text, "category"))


def _join_categorical(frames: list[pd.DataFrame], columns: list[str]) -> pd.DataFrame:
    """Concatenate tables whose text columns are categorical with their own categories:
    the result's categories are the union, sorted (``pd.concat`` would fall back to
    Python objects)."""
    from pandas.api.types import union_categoricals

    frames = [f for f in frames if not f.empty]
    if len(frames) <= 1:
        return _concat(frames, columns)

    def categorical(x: pd.Series) -> pd.Series:  # a chunk's column may be all missing
        return x if isinstance(x.dtype, pd.CategoricalDtype) else x.astype("str").astype("category")

    union = {
        c: pd.CategoricalDtype(
            union_categoricals(
                [categorical(f[c]) for f in frames], sort_categories=True, ignore_order=True
            ).categories
        )
        for c in columns
        if any(isinstance(f[c].dtype, pd.CategoricalDtype) for f in frames)
    }
    if union:
        frames = [f.astype(union) for f in frames]
    return _concat(frames, columns)


_TRUTH_AXIS_COLUMNS = ["subject", "finger", "joint", "axis_error_deg", "centre_to_axis_mm"]
# SubjectResult field -> its columns in the study's table.
_SUBJECT_TABLES = {
    "max_flexion": _FLEX_COLUMNS,
    "distances": _DIST_COLUMNS,
    "targets": _TARGET_COLUMNS,
    "truth_axes": _TRUTH_AXIS_COLUMNS,
    "truth_tips": _TRUTH_TIP_COLUMNS,
    "truth_angles": _TRUTH_ANGLE_COLUMNS,
    "pinches": _PINCH_COLUMNS,
}


def _or_empty(table: pd.DataFrame | None, columns: list[str]) -> pd.DataFrame:
    return _concat([], columns) if table is None else table


class StudyTables:
    """The per-subject rows of a study, gathered as the subjects arrive, in any order.

    A subject's tables (one small DataFrame each, a few KB of rows but tens of KB of
    pandas overhead) are taken out of its result; every ``chunk`` subjects the ones
    held are joined into one DataFrame per table, so memory grows by the rows alone,
    and each row is copied twice in all (into its chunk, then into the study's table).
    :meth:`tables` gives the same tables as concatenating every subject's, in the
    subjects' order.

    Parameters
    ----------
    chunk : int
        Subjects whose tables are held as separate DataFrames before they are joined.
    """

    def __init__(self, chunk: int = 32) -> None:
        self._chunk = chunk
        self._pending: dict[str, list[pd.DataFrame]] = {k: [] for k in _SUBJECT_TABLES}
        self._joined: dict[str, list[pd.DataFrame]] = {k: [] for k in _SUBJECT_TABLES}
        self._rows: dict[str, list[tuple[int, int]]] = {k: [] for k in _SUBJECT_TABLES}
        self._present: set[str] = set()  # tables some subject has (not None)

    def add(self, order: int, result: SubjectResult) -> SubjectResult:
        """Take a subject's tables; the result without them (its table fields None).

        ``order``: the subject's place in the study (its rows come out in this order).
        """
        for key, columns in _SUBJECT_TABLES.items():
            table = getattr(result, key)
            if table is None:
                continue
            self._present.add(key)
            if table.empty:
                continue
            self._pending[key].append(table[columns])
            self._rows[key].append((order, len(table)))
            if len(self._pending[key]) >= self._chunk:
                self._join(key)
        return replace(result, **dict.fromkeys(_SUBJECT_TABLES))

    def _join(self, key: str) -> None:
        if self._pending[key]:
            joined = _concat(self._pending[key], _SUBJECT_TABLES[key])
            self._joined[key].append(_categorical(joined))
            self._pending[key] = []

    def tables(self) -> dict[str, pd.DataFrame | None]:
        """SubjectResult field -> the study's table, rows in the subjects' order
        (None: no subject has the table). Its text columns are categorical, categories
        sorted (``str`` operations need ``.astype(str)``; grouping, sorting, comparing
        and writing give what text columns give)."""
        out: dict[str, pd.DataFrame | None] = {}
        for key, columns in _SUBJECT_TABLES.items():
            if key not in self._present:
                out[key] = None
                continue
            self._join(key)
            joined = _join_categorical(self._joined[key], columns)
            self._joined[key] = [joined]  # the chunks go before the reordering's copy
            rows = self._rows[key]
            given = [o for o, _n in rows]
            if given != sorted(given):  # arrived in another order
                starts = np.cumsum([0] + [n for _o, n in rows])
                order = np.argsort(given, kind="stable")
                take = np.concatenate([np.arange(starts[i], starts[i] + rows[i][1]) for i in order])
                joined = joined.take(take).reset_index(drop=True)
                self._joined[key] = [joined]
                self._rows[key] = [rows[i] for i in order]
            out[key] = joined
        release_freed_memory()  # the chunks' and the reordering's copies
        return out


def summary_path(session: Path | None, out_dir: Path | None) -> str | None:
    """How ``summary.json`` names a session folder: relative to the study's output folder
    when both lie in one folder (``../sessions/S01`` for ``fingerfit demo``, whose folder
    is renamed into place; ``../c100/S01`` for ``fingerfit study c100/* --out OUT``),
    otherwise absolute; as given without ``out_dir``."""
    if session is None:
        return None
    if out_dir is None:
        return str(session)
    folder, out = Path(os.path.abspath(session)), Path(os.path.abspath(out_dir))
    if folder.is_relative_to(out.parent):
        return os.path.relpath(folder, out)
    return str(folder)


def summarize_study(
    subjects: Sequence[SubjectResult],
    options: FitOptions,
    failures: list[SessionFailure] | None = None,
    gathered: StudyTables | None = None,
    out_dir: Path | None = None,
) -> tuple[dict, dict[str, pd.DataFrame]]:
    """Statistics and headline of the study, plus its tables.

    Parameters
    ----------
    subjects : sequence of SubjectResult
        At least one; any mix of sessions with or without targets, test recordings,
        ground truth, and different fingers (read one at a time, a few passes).
    options : FitOptions
    failures : list of SessionFailure, optional
        Sessions that could not be fitted (``--keep-going``), listed in the summary.
    gathered : StudyTables, optional
        The subjects' tables, already taken out of ``subjects`` (whose table fields
        are then None), as :func:`run_study` does; by default they are gathered here.
    out_dir : Path, optional
        The study's output folder (its final name): each session's ``path`` is written
        relative to it (:func:`summary_path`).

    Returns
    -------
    summary : dict
        The ``summary.json`` document (lengths mm, angles deg; NaN stored as null).
        A statistic the data cannot support is ``{"skipped": reason}`` and listed
        under ``"skipped"``.
    tables : dict of str to DataFrame
    """
    if gathered is None:
        gathered = StudyTables()
        for i, s in enumerate(subjects):
            gathered.add(i, s)
    study_rows = gathered.tables()
    flex_all = _or_empty(study_rows["max_flexion"], _FLEX_COLUMNS)
    # The paper's figures (headline, Fig. 10) are the four fingers'; the thumb's own section.
    flex = flex_all[flex_all["finger"].isin(FINGERS)]
    dist = _or_empty(study_rows["distances"], _DIST_COLUMNS)
    targets = _or_empty(study_rows["targets"], _TARGET_COLUMNS)
    with_targets = set(targets["subject"])
    tables = {"max_flexion": flex_all, "axis_quality": dist, "targets": targets}
    summary: dict = {
        "format": "fingerfit.study/1",
        "fingerfit_version": __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "method": options.method,
        "forced": bool(options.force),
        "angle_methods": sorted({s.model.angle_method for s in subjects}),
        "subjects": [s.subject for s in subjects],
        "sessions": {
            s.subject: {
                "path": summary_path(s.session.path, out_dir),
                "fingers": list(s.model.fingers),
                "has_targets": s.subject in with_targets,
                "has_truth": s.truth is not None,
            }
            for s in subjects
        },
        "failed": [f.as_dict() for f in failures or []],
        "warnings": {s.subject: list(s.warnings) for s in subjects if s.warnings},
        "units": "mm",
        "paper": PAPER,
    }
    # Axis quality (Fig. 8) and the paper's t-tests between joints.
    aq = {}
    for j in [j for j in (*JOINTS, *THUMB_JOINTS) if (dist["joint"] == j).any()]:
        sm = summarize(dist.loc[dist["joint"] == j, "distance_mm"])
        aq[j] = {"mean_mm": _num(sm.mean), "sd_mm": _num(sm.sd), "n": sm.n}
    tests = {}
    for a, b in (("dip", "pip"), ("mp", "dip"), ("mp", "pip")):
        t = independent_ttest_or_skip(
            dist.loc[dist.joint == a, "distance_mm"], dist.loc[dist.joint == b, "distance_mm"]
        )
        tests[f"{a}_vs_{b}"] = _stat(t)
    summary["axis_quality"] = {"per_joint": aq, "t_tests": tests}
    # Maximal flexion (Fig. 10).
    mf = _headline(flex)
    mf["paired_t_test"] = _stat(paired_ttest_or_skip(flex["user_axis"], flex["orthogonal"]))
    mf["per_subject"] = {}
    rows_of = flex.groupby("subject", sort=False).indices  # one pass, not one per subject
    for s in subjects:
        g = flex.iloc[rows_of.get(s.subject, [])]
        u, o = summarize(g["user_axis"]), summarize(g["orthogonal"])
        mf["per_subject"][s.subject] = {
            "n": u.n,
            "user_axis_mean_mm": _num(u.mean),
            "orthogonal_mean_mm": _num(o.mean),
            "reduction_percent": _num(reduction_percent(u.mean, o.mean)),
            "paired_t_test": _stat(paired_ttest_or_skip(g["user_axis"], g["orthogonal"])),
        }
    long = flex.melt(
        id_vars=["subject", "cycle"],
        value_vars=list(VARIANTS),
        var_name="model",
        value_name="error",
    )
    mf["anova_model_x_subject"] = _anova_dict(
        two_way_anova_or_skip(long, "error", "model", "subject")
    )
    summary["max_flexion"] = mf
    # Targets (Figs. 11-12): only the sessions with target recordings.
    if not targets.empty:
        wide = targets.pivot_table(
            index=["subject", "finger", "target"], columns="source", values="error_mm"
        ).reset_index()
        tg = _headline(wide)
        ref = summarize(wide["reference"])
        tg["subjects"] = sorted(targets["subject"].unique())
        tg["reference"] = {"mean_mm": _num(ref.mean), "sd_mm": _num(ref.sd), "n": ref.n}
        tg["paired_t_test"] = _stat(paired_ttest_or_skip(wide["user_axis"], wide["orthogonal"]))
        tg["per_target"] = {}
        for t, g in wide.groupby("target"):
            tg["per_target"][t] = {"n": len(g)}
            for src in ("reference", *VARIANTS):
                sm = summarize(g[src])
                tg["per_target"][t][src] = {"mean_mm": _num(sm.mean), "sd_mm": _num(sm.sd)}
        tl = targets[targets["source"].isin(VARIANTS)].rename(columns={"source": "model"})
        tg["anova_model_x_target"] = _anova_dict(
            two_way_anova_or_skip(tl, "error_mm", "model", "target")
        )
        tg["anova_model_x_subject"] = _anova_dict(
            two_way_anova_or_skip(tl, "error_mm", "model", "subject")
        )
        summary["targets"] = tg
    # Ground truth (simulated sessions only).
    if study_rows["truth_axes"] is not None:
        ta = study_rows["truth_axes"]
        tt = _or_empty(study_rows["truth_tips"], _TRUTH_TIP_COLUMNS)
        tables["truth_axes"], tables["truth_fingertip"] = ta, tt
        summary["truth"] = {
            "subjects": sorted(ta["subject"].unique()),
            "axis_error_deg": {
                j: {
                    "mean": _num(g["axis_error_deg"].mean()),
                    "max": _num(g["axis_error_deg"].max()),
                }
                for j, g in ta.groupby("joint")
            },
            "centre_to_axis_mm": {
                j: {
                    "mean": _num(g["centre_to_axis_mm"].mean()),
                    "max": _num(g["centre_to_axis_mm"].max()),
                }
                for j, g in ta.groupby("joint")
            },
            "fingertip_mm": {
                f"{r}/{v}": {"mean": _num(g["mean_mm"].mean()), "p95": _num(g["p95_mm"].mean())}
                for (r, v), g in tt[tt["finger"].isin(FINGERS)].groupby(["recording", "variant"])
            },
        }
        _whole_hand_truth(
            _or_empty(study_rows["truth_angles"], _TRUTH_ANGLE_COLUMNS), summary, tables, tt
        )
    # Model geometry per subject: how far the fitted axes are from perpendicular.
    rows = []
    for s in subjects:
        for f, fm in s.model.fingers.items():
            for j, jm in fm.joints.items():
                tilt = np.degrees(angle_between_axes(jm.axis, jm.orthogonal_axis))
                rows.append(
                    (
                        s.subject,
                        f,
                        j,
                        *jm.center,
                        *jm.axis,
                        float(tilt),
                        fm.segment_lengths[fm.segments[list(fm.joints).index(j)]],
                    )
                )
    tables["models"] = pd.DataFrame(
        rows,
        columns=[
            "subject",
            "finger",
            "joint",
            "center_x",
            "center_y",
            "center_z",
            "axis_x",
            "axis_y",
            "axis_z",
            "tilt_from_orthogonal_deg",
            "segment_length_mm",
        ],
    )
    _thumb_and_pinch(
        subjects, summary, tables, flex_all, _or_empty(study_rows["pinches"], _PINCH_COLUMNS)
    )
    summary["skipped"] = _skips(
        {
            k: summary[k]
            for k in ("axis_quality", "max_flexion", "targets", "thumb", "pinch")
            if k in summary
        }
    )
    summary["skipped"] += [
        {
            "statistic": f"events.{s.subject}.{e['recording']}.{e['finger']}->{e['target']}",
            "reason": e["reason"],
        }
        for s in subjects
        for e in s.skipped_events
    ]
    return summary, tables


def _mean_sd(x: pd.Series) -> dict:
    sm = summarize(x)
    return {"mean_mm": _num(sm.mean), "sd_mm": _num(sm.sd), "n": sm.n}


def _group_means(table: pd.DataFrame, keys: list[str], values: list[str]) -> dict[tuple, list]:
    """Means of ``values`` for each combination of ``keys`` (NaN skipped), in order of first
    appearance: one grouping pass instead of one sub-table per level (a thousand
    subjects' truth tables are tens of MB as nested groups)."""
    agg = table.groupby(keys, sort=False)[values].mean()
    return dict(zip(agg.index, agg.to_numpy().tolist(), strict=True))


def _whole_hand_truth(ang: pd.DataFrame, summary: dict, tables: dict, tt: pd.DataFrame) -> None:
    """Every digit's tip and every joint angle against truth: ``summary["truth"]`` keys
    ``tip_mm_per_digit`` (digit -> ``recording/variant`` -> mean, p95 mm) and
    ``angle_error_deg`` (digit -> angle -> variant -> mean |error| deg), table
    ``truth_angles`` (``ang``). Digits and angles in order of appearance, recordings and
    variants sorted."""
    tables["truth_angles"] = ang
    tips: dict = {}
    means = _group_means(tt, ["finger", "recording", "variant"], ["mean_mm", "p95_mm"])
    for (f, r, v), (mean, p95) in sorted(means.items(), key=lambda kv: kv[0][1:]):
        tips.setdefault(f, {})[f"{r}/{v}"] = {"mean": _num(mean), "p95": _num(p95)}
    order = list(dict.fromkeys(f for f, _r, _v in means))
    summary["truth"]["tip_mm_per_digit"] = {f: tips[f] for f in order}
    angles: dict = {}
    means = _group_means(ang, ["finger", "joint", "variant"], ["mean_abs_deg", "p95_abs_deg"])
    for (f, j, v), (mean, p95) in means.items():
        angles.setdefault(f, {}).setdefault(j, {})[v] = {"mean": _num(mean), "p95": _num(p95)}
    summary["truth"]["angle_error_deg"] = {
        f: {j: dict(sorted(by_variant.items())) for j, by_variant in by_joint.items()}
        for f, by_joint in angles.items()
    }


def _thumb_and_pinch(
    subjects: list[SubjectResult],
    summary: dict,
    tables: dict,
    flex_all: pd.DataFrame,
    pin: pd.DataFrame,
) -> None:
    """``summary["thumb"]`` (the thumb's fingertip at maximal flexion, axes and tip against
    truth, CMC/MCP geometry) and ``summary["pinch"]`` (tip distances and pad gaps during
    pinch events), with their tables, for studies with a thumb or pinch events."""
    # One subject at a time (a study's subjects may be packed, one made per access).
    with_thumb = [s.subject for s in subjects if "thumb" in s.model.fingers]
    if with_thumb:
        th: dict = {"subjects": with_thumb}
        tf = flex_all[flex_all["finger"] == "thumb"]
        if not tf.empty:
            mf = _headline(tf)
            mf["paired_t_test"] = _stat(paired_ttest_or_skip(tf["user_axis"], tf["orthogonal"]))
            th["max_flexion"] = mf
        geo = _concat(
            [thumb_geometry(s) for s in subjects if "thumb" in s.model.fingers],
            _THUMB_GEOMETRY_COLUMNS,
        )
        tables["thumb_geometry"] = geo
        th["geometry"] = {
            j: {
                "axis_offset_mm": _num(g["axis_offset_mm"].mean()),
                "true_axis_offset_mm": _num(g["true_axis_offset_mm"].mean()),
                "axes_angle_deg": _num(g["axes_angle_deg"].mean()),
                "true_axes_angle_deg": _num(g["true_axes_angle_deg"].mean()),
                "n": len(g),
            }
            for j, g in geo.groupby("joint", sort=False)
        }
        if "truth_axes" in tables:
            ta = tables["truth_axes"]
            ta = ta[ta["finger"] == "thumb"]
            th["truth_axes"] = {
                j: {
                    "axis_error_deg": {
                        "mean": _num(g["axis_error_deg"].mean()),
                        "max": _num(g["axis_error_deg"].max()),
                    },
                    "centre_to_axis_mm": {
                        "mean": _num(g["centre_to_axis_mm"].mean()),
                        "max": _num(g["centre_to_axis_mm"].max()),
                    },
                    "n": len(g),
                }
                for j, g in ta.groupby("joint", sort=False)
            }
            tt = tables["truth_fingertip"]
            tt = tt[tt["finger"] == "thumb"]
            tips = {}
            for r, g in tt.groupby("recording", sort=False):
                w = g.pivot_table(index="subject", columns="variant", values="mean_mm")
                if not set(VARIANTS) <= set(w.columns):
                    continue
                h = _headline(w)
                h["orthogonal_ratio"] = _num(w["user_axis"].mean() / w["orthogonal"].mean())
                h["paired_t_test"] = _stat(paired_ttest_or_skip(w["user_axis"], w["orthogonal"]))
                tips[r] = h
            th["truth_tip"] = tips
        summary["thumb"] = th
    if pin.empty:
        return
    tables["pinch"] = pin
    pn: dict = {"subjects": sorted(pin["subject"].unique()), "per_source": {}, "per_kind": {}}
    for src, g in pin.groupby("source", sort=False):
        pn["per_source"][src] = {
            "tip_distance_error": _mean_sd(g["tip_distance_error_mm"]),
            "tip_distance_bias": _mean_sd(g["tip_distance_bias_mm"]),
            "pad_gap": _mean_sd(g["pad_gap_mm"]),
            "true_pad_gap": _mean_sd(g["true_pad_gap_mm"]),
        }
    for (kind, tgt), g in pin.groupby(["kind", "target"], sort=False):
        pn["per_kind"][f"{kind}/{tgt}"] = {
            src: {
                "tip_distance_error": _mean_sd(gs["tip_distance_error_mm"]),
                "pad_gap": _mean_sd(gs["pad_gap_mm"]),
            }
            for src, gs in g.groupby("source", sort=False)
        }
    wide = pin.pivot_table(
        index=["subject", "recording", "target", "start"],
        columns="source",
        values="tip_distance_error_mm",
    )
    if set(VARIANTS) <= set(wide.columns):
        pn["paired_t_test"] = _stat(paired_ttest_or_skip(wide["user_axis"], wide["orthogonal"]))
    else:
        pn["paired_t_test"] = {"skipped": "no pinch with ground truth (true tip distances)"}
    summary["pinch"] = pn


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _session_error(subject: str, exc: Exception) -> str:
    """``"<subject>: <the session's own error>"``, one line."""
    if isinstance(exc, FingerfitError):
        return f"{subject}: {_one_line(exc)}"
    return (
        f"{subject}: unexpected {type(exc).__name__} while fitting and evaluating "
        f"({_one_line(exc)}); please report this"
    )


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


@dataclass
class SubjectOutcome:
    """What one study task sends back: a compact result and its Fig. 9 PNG, or a failure.

    Attributes
    ----------
    source : str
        The session as given (folder path, or the subject of an in-memory session).
    result : SubjectResult or None
        :meth:`SubjectResult.compact` (no per-frame arrays); None when the session failed.
    figure : tuple of (str, bytes) or None
        File name and PNG bytes of the subject's Fig. 9 (fingertip trajectories).
    read_error, fit_error : str or None
        One-line messages: the session could not be read, or not be fitted and evaluated.
    """

    source: str
    result: SubjectResult | None = None
    figure: tuple[str, bytes] | None = None
    read_error: str | None = None
    fit_error: str | None = None
    subject: str | None = None
    path: str | None = None


@runtime_checkable
class SessionSource(Protocol):
    """A study input that makes its session folder where the study task runs.

    ``open()`` is a context manager giving the folder (read like any session folder)
    and cleaning up after the task; ``str(source)`` names it in messages. Picklable,
    so it can travel to a worker process or a Dask worker.
    (:class:`fingerfit.simulate.source.SimulatedSession`: simulate on the worker.)
    """

    def open(self) -> contextlib.AbstractContextManager[Path]: ...


def _is_source(item: object) -> bool:
    """A :class:`SessionSource` (a Path has an ``open`` method too: not one)."""
    return not isinstance(item, Path | str | Session) and isinstance(item, SessionSource)


def study_subject(
    item: Path | str | Session | SessionSource, options: FitOptions
) -> SubjectOutcome:
    """Read, fit and evaluate one session; render its Fig. 9 (one study task).

    Runs in a worker process (``--jobs``), on a Dask worker (``--scheduler``) or in
    the calling process: it takes a session folder, so a worker holds one subject's
    arrays at a time and returns only the compact result (model, tables, PNG bytes).

    Parameters
    ----------
    item : Path, str, Session or SessionSource
        Session folder (or an in-memory session, or a source that makes the folder
        here: the outcome then names the source, and its session has no path).
    options : FitOptions

    Returns
    -------
    SubjectOutcome
        Never raises for a bad session: its error comes back as one line.
    """
    if _is_source(item):
        try:
            with item.open() as folder:
                got = study_subject(folder, options)
        except Exception as exc:  # the source could not make its session: named
            return SubjectOutcome(
                str(item), read_error=f"{item}: could not be made ({_one_line(exc)})"
            )
        got.source, got.path = str(item), None
        if got.read_error is not None:
            got.read_error = got.read_error.replace(str(folder), str(item))
        if got.result is not None:
            got.result.session.path = None  # the folder is gone
        return got
    if isinstance(item, Session):
        source = str(item.path or item.subject)
    else:
        source = str(item)
    try:
        if isinstance(item, Session):  # load_session checks the ID of a session folder
            session = item
            check_subject_id(
                session.subject,
                path=None if session.path is None else Path(session.path) / "session.toml",
            )
        else:
            session = load_session(Path(item))
    except FingerfitError as exc:
        msg = _one_line(exc)
        return SubjectOutcome(source, read_error=msg if source in msg else f"{source}: {msg}")
    path = None if session.path is None else str(session.path)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            result = _subject(session, options)
            name, time, tips, label = _trajectory(result)
            png = figures.trajectories_png(time, tips, label)
    except Exception as exc:  # one bad session is named, never a traceback
        return SubjectOutcome(
            str(session.path or session.subject),
            fit_error=_session_error(session.subject, exc),
            subject=session.subject,
            path=path,
        )
    return SubjectOutcome(source, result.compact(), (name, png), subject=session.subject, path=path)


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
                f"cannot connect to the scheduler '{scheduler}' ({_one_line(exc)})",
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
    import multiprocessing

    # spawn: workers never inherit the parent's threads (progress bar, Dask) or locks.
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
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
    from .report import write_report

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
        gathered = StudyTables()
        subjects = PackedSubjects(folder=tmp.parent)  # as they arrive; selected below
        stored: dict[int, int] = {}  # session -> its place in ``subjects``
        pool = stack.enter_context(study_executor(jobs, scheduler))
        futures = {pool.submit(study_subject, s, options): i for i, s in enumerate(sessions)}
        for future in as_completed(futures):
            # Dropped once read: a Dask worker keeps a task's result while its future lives.
            i = futures.pop(future)
            try:
                got = outcomes[i] = future.result()
            except Exception as exc:  # a lost worker, not a bad session
                raise FingerfitError(
                    f"a study worker failed on '{sessions[i]}' "
                    f"({type(exc).__name__}: {_one_line(exc)})"
                ) from None
            if got.result is not None and got.figure is not None:
                # Written as it arrives; only the path is kept.
                name, png = got.figure
                with atomic_write(tmp / name, "wb") as fh:
                    fh.write(png)
                fig09[i] = (f"fig09_{got.subject}", tmp / name)
                got.figure = None
            if got.result is not None:
                # Its rows join the study's tables and its model is written now; the
                # rest (model, landmarks, names) is kept as one pickle.
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
            if not _is_source(x)  # made and removed on the worker
        ]
        _check_not_input(out_dir, [p for p in given if p is not None])
        keep = []
        for i, o in enumerate(outcomes):
            if o is None or o.read_error is not None:
                continue
            if o.fit_error is not None:
                failed(o.source, o.subject, o.fit_error)
                continue
            keep.append(stored[i])
        subjects.select(keep)
        if not subjects:
            detail = "; ".join(f.message for f in failures) or "no sessions given"
            raise FingerfitError(f"no session could be fitted and evaluated: {detail}")
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            summary, tables = summarize_study(subjects, options, failures, gathered, out_dir)
            result = StudyResult(subjects, summary, tables, tmp, failures=failures)
            kept = {o.subject for o in ok if o.fit_error is None}
            drawn = dict(fig09[i] for i in sorted(fig09) if outcomes[i].subject in kept)
            _write_outputs(result, tmp, drawn, pool)
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


def _trajectory(s: SubjectResult) -> tuple[str, np.ndarray, dict[str, np.ndarray], str]:
    """Fig. 9 of one subject (its first finger, hand-sensor frame): file name, time (s),
    fingertips ``(n, 3)`` mm in the hand sensor's frame, and the subject's label."""
    f, ev = next(iter(s.grasp.items()))
    hand = s.session.grasp[0].pose(HAND_SENSOR)
    in_hand = {k: apply_inverse_pose(hand.rotation, hand.position, v) for k, v in ev.tips.items()}
    return f"fig09_trajectories_{s.subject}.png", ev.time, in_hand, f"{s.subject} ({f})"


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
            name, time, tips, label = _trajectory(s)
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


def figure_tables(key: str, tables: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """What a study task drawing figure ``key`` needs of the study's tables: its own table,
    and ``max_flexion`` and ``targets`` without rows (:func:`figure_builders` looks at
    them), so each task is sent one table rather than all of them."""
    out = {k: tables[k].iloc[:0] for k in ("max_flexion", "targets")}
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


def _write_outputs(
    result: StudyResult,
    out_dir: Path,
    drawn: dict[str, Path] | None = None,
    pool: Executor | None = None,
) -> None:
    """CSV tables and PNG figures into ``out_dir``; figure paths into ``result.figures``.

    ``drawn``: figures already written (key -> path), the per-subject Fig. 9 drawn by
    the study tasks; listed after Fig. 8 in the order given. ``pool``: the study's
    executor; the study-wide figures are drawn there side by side
    (:func:`draw_study_figure`) while this process writes the tables, and written here.
    """
    built = figure_builders(result.subjects, result.tables)
    pending = {}
    if pool is not None:
        pending = {
            key: pool.submit(draw_study_figure, key, figure_tables(key, result.tables))
            for key in built
            if not key.startswith("fig09")
        }
    for name, table in result.tables.items():
        with atomic_write(out_dir / f"{name}.csv", newline="") as fh:
            table.to_csv(fh, index=False, lineterminator="\n", float_format="%.6g")
    for key, (filename, build) in built.items():
        if key in pending:
            try:
                png = pending[key].result()
            except Exception as exc:  # a lost worker: named, never a traceback
                raise FingerfitError(
                    f"a study worker failed drawing {filename} "
                    f"({type(exc).__name__}: {_one_line(exc)})"
                ) from None
            with atomic_write(out_dir / filename, "wb") as fh:
                fh.write(png)
            result.figures[key] = out_dir / filename
        else:
            result.figures[key] = figures.save(build(), out_dir / filename)
        if key == "fig08":
            result.figures.update(drawn or {})
