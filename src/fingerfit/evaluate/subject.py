"""One study task: read, fit and evaluate one session (:func:`study_subject`).

A task runs in a worker process, on a Dask worker or in the calling process; it holds
one subject's arrays and sends back a compact :class:`SubjectResult` (model, the
subject's rows of the study's tables, warnings) and the PNG of its Fig. 9.
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..estimate import FitOptions, fit_session
from ..io import load_session
from ..kinematics import compute_kinematics
from ..model import VARIANTS, HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording, Session, check_subject_id
from ..transforms import angle_between_axes, apply_inverse_pose, distance_between_lines
from . import figures
from .fingertip import GraspEvaluation, evaluate_grasp, evaluate_targets, skipped_events
from .pinch import PINCH_COLUMNS, evaluate_pinches
from .truth import Truth, axis_errors, check_truth_frames, load_truth

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
THUMB_GEOMETRY_COLUMNS = [
    "subject",
    "joint",
    "axis_offset_mm",
    "true_axis_offset_mm",
    "axes_angle_deg",
    "true_axes_angle_deg",
]


_FLEX_COLUMNS = ["subject", "finger", "cycle", "user_axis", "orthogonal"]
_TARGET_COLUMNS = ["subject", "finger", "target", "source", "error_mm", "dx", "dy", "dz"]
_DIST_COLUMNS = ["subject", "finger", "joint", "cycle", "distance_mm"]
_PINCH_COLUMNS = ["subject", *PINCH_COLUMNS]
_TRUTH_AXIS_COLUMNS = ["subject", "finger", "joint", "axis_error_deg", "centre_to_axis_mm"]
# SubjectResult field -> its columns in the study's table.
SUBJECT_TABLES = {
    "max_flexion": _FLEX_COLUMNS,
    "distances": _DIST_COLUMNS,
    "targets": _TARGET_COLUMNS,
    "truth_axes": _TRUTH_AXIS_COLUMNS,
    "truth_tips": _TRUTH_TIP_COLUMNS,
    "truth_angles": _TRUTH_ANGLE_COLUMNS,
    "pinches": _PINCH_COLUMNS,
}


def concat_tables(frames: list[pd.DataFrame], columns: list[str]) -> pd.DataFrame:
    """Concatenate non-empty tables (an empty one would turn float columns into object)."""
    frames = [f[columns] for f in frames if not f.empty]
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=float) for c in columns})
    return pd.concat(frames, ignore_index=True)


@dataclass
class SubjectResult:
    """Everything the study computed for one session.

    The tables (``max_flexion`` ... ``pinches``, :data:`SUBJECT_TABLES`) are the
    subject's rows of the study's tables. In :attr:`StudyResult.subjects` of
    :func:`run_study` they are None: the study took them into :attr:`StudyResult.tables`
    (:class:`~.gather.StudyTables`, on disk) as the subject arrived.
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


def _fit(session: Session, options: FitOptions) -> tuple[HandModel, tuple[str, ...]]:
    """Fit a session; its warnings (``--force``) from the model and any the fit emitted."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        model = fit_session(session, options)
    found = [*model.warnings]
    found += [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    return model, tuple(dict.fromkeys(found))


def evaluate_subject(session: Session, options: FitOptions) -> SubjectResult:
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
        concat_tables(flex, _FLEX_COLUMNS),
        targets,
        concat_tables(dist, _DIST_COLUMNS),
        truth,
        warnings=warned,
        pinches=pinches,
        skipped_events=tuple(skipped_events(model, session)),
        frames=sum(rec.n_frames for rec in session.recordings()),
    )
    if truth is not None:
        fingers = [f for f in model.fingers if f in truth.document.get("fingers", {})]
        res.truth_axes = concat_tables(
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


MODEL_COLUMNS = [
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
]


def model_geometry(subject: SubjectResult) -> pd.DataFrame:
    """Per joint of the subject's model: its centre (mm) and flexion axis (unit) in the
    parent sensor's frame, how far the axis is from the orthogonal one (deg), and the
    length of the segment it moves (mm); ``MODEL_COLUMNS``."""
    rows = []
    for f, fm in subject.model.fingers.items():
        for k, (j, jm) in enumerate(fm.joints.items()):
            tilt = np.degrees(angle_between_axes(jm.axis, jm.orthogonal_axis))
            rows.append(
                (
                    subject.subject,
                    f,
                    j,
                    *jm.center,
                    *jm.axis,
                    float(tilt),
                    fm.segment_lengths[fm.segments[k]],
                )
            )
    return pd.DataFrame(rows, columns=MODEL_COLUMNS)


def thumb_geometry(subject: SubjectResult) -> pd.DataFrame:
    """Per two-axis thumb joint: the offset between its two axis lines (mm) and the angle
    between them (deg), fitted and (with ground truth) true; ``THUMB_GEOMETRY_COLUMNS``."""
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
    return pd.DataFrame(rows, columns=THUMB_GEOMETRY_COLUMNS)


def one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _session_error(subject: str, exc: Exception) -> str:
    """``"<subject>: <the session's own error>"``, one line."""
    if isinstance(exc, FingerfitError):
        return f"{subject}: {one_line(exc)}"
    return (
        f"{subject}: unexpected {type(exc).__name__} while fitting and evaluating "
        f"({one_line(exc)}); please report this"
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


def is_source(item: object) -> bool:
    """A :class:`SessionSource` (a Path has an ``open`` method too: not one)."""
    return not isinstance(item, Path | str | Session) and isinstance(item, SessionSource)


def study_subject(
    item: Path | str | Session | SessionSource, options: FitOptions, *, debug: bool = False
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
    debug : bool
        Raise an unexpected exception (not a :class:`FingerfitError`) as it is, with its
        traceback, instead of returning it as one line.

    Returns
    -------
    SubjectOutcome
        Never raises for a bad session: its error comes back as one line (unless
        ``debug`` and the error is not fingerfit's).
    """
    if is_source(item):
        try:
            with item.open() as folder:
                got = study_subject(folder, options, debug=debug)
        except Exception as exc:  # the source could not make its session: named
            if debug and not isinstance(exc, FingerfitError):
                raise
            return SubjectOutcome(
                str(item), read_error=f"{item}: could not be made ({one_line(exc)})"
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
        msg = one_line(exc)
        return SubjectOutcome(source, read_error=msg if source in msg else f"{source}: {msg}")
    path = None if session.path is None else str(session.path)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            result = evaluate_subject(session, options)
            name, time, tips, label = fig09_data(result)
            png = figures.trajectories_png(time, tips, label)
    except Exception as exc:  # one bad session is named, never a traceback (but --debug)
        if debug and not isinstance(exc, FingerfitError):
            raise
        return SubjectOutcome(
            str(session.path or session.subject),
            fit_error=_session_error(session.subject, exc),
            subject=session.subject,
            path=path,
        )
    return SubjectOutcome(source, result.compact(), (name, png), subject=session.subject, path=path)


def fig09_data(s: SubjectResult) -> tuple[str, np.ndarray, dict[str, np.ndarray], str]:
    """Fig. 9 of one subject (its first finger, hand-sensor frame): file name, time (s),
    fingertips ``(n, 3)`` mm in the hand sensor's frame, and the subject's label."""
    f, ev = next(iter(s.grasp.items()))
    hand = s.session.grasp[0].pose(HAND_SENSOR)
    in_hand = {k: apply_inverse_pose(hand.rotation, hand.position, v) for k, v in ev.tips.items()}
    return f"fig09_trajectories_{s.subject}.png", ev.time, in_hand, f"{s.subject} ({f})"
