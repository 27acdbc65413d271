"""The study's statistics and headline (``summary.json``) and its tables.

Axis quality (Fig. 8) with the paper's t-tests between joints, fingertip error at
maximal flexion (Fig. 10) and at targets (Figs. 11-12) with paired t-tests and the
model x subject / model x target ANOVAs, ground truth of simulated sessions, the
thumb and pinches. Lengths mm, angles deg.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..digits import FINGERS, THUMB_JOINTS
from ..estimate import FitOptions
from ..model import VARIANTS
from ..session import JOINTS
from ..transforms import angle_between_axes
from .gather import StudyTables
from .stats import (
    MOMENT_FIELDS,
    Moments,
    Skipped,
    independent_ttest_of,
    merge_moments,
    moments_at,
    paired_ttest_of,
    reduction_percent,
    summary_of,
    table_moments,
    two_way_anova_of_cells,
)
from .subject import (
    SUBJECT_TABLES,
    THUMB_GEOMETRY_COLUMNS,
    SessionFailure,
    SubjectResult,
    concat_tables,
    thumb_geometry,
)

PAPER = {
    "max_flexion": {"user_axis": (2.7, 1.3), "orthogonal": (5.4, 3.4), "reduction_percent": 50},
    "targets": {"user_axis": (2.6, 0.9), "orthogonal": (4.7, 1.7), "reduction_percent": 45},
    "axis_quality_mm": {"dip": (0.2, 0.1), "pip": (0.3, 0.1)},
}


def _stat(result) -> dict:
    """A test result or a skip reason as the dict stored in ``summary.json``."""
    return result.as_dict() if isinstance(result, Skipped) else dict(result.__dict__)


def _num(v: float) -> float | None:
    """A finite float, or None (JSON ``null``) for NaN/inf."""
    v = float(v)
    return v if np.isfinite(v) else None


def _mean_sd(m: Moments) -> dict:
    sm = summary_of(m)
    return {"mean_mm": _num(sm.mean), "sd_mm": _num(sm.sd), "n": sm.n}


def _headline(u: Moments, o: Moments) -> dict:
    """User-axis and orthogonal error (mean, SD, n; mm) and the reductions in %."""
    su, so = summary_of(u), summary_of(o)
    return {
        "user_axis": {"mean_mm": _num(su.mean), "sd_mm": _num(su.sd), "n": su.n},
        "orthogonal": {"mean_mm": _num(so.mean), "sd_mm": _num(so.sd), "n": so.n},
        "reduction_percent": _num(reduction_percent(su.mean, so.mean)),
        "sd_reduction_percent": _num(reduction_percent(su.sd, so.sd)),
    }


def _mean_max(m: Moments) -> dict:
    return {"mean": _num(m.mean), "max": _num(m.max)}


def _anova_dict(table: pd.DataFrame | Skipped) -> dict:
    if isinstance(table, Skipped):
        return table.as_dict()
    return {
        idx: {"F": _num(r["F"]), "p": _num(r["PR(>F)"]), "df": float(r["df"])}
        for idx, r in table.iterrows()
    }


SUBJECTS_PER_CHUNK = 32


def subject_chunks(table: pd.DataFrame, size: int | None = None) -> Iterator[pd.DataFrame]:
    """Slices of a study table holding ``size`` whole subjects each (default
    :data:`SUBJECTS_PER_CHUNK`; rows in the subjects' order, as :meth:`StudyTables.tables`
    gives them; views, not copies)."""
    if table.empty:
        return
    size = size or SUBJECTS_PER_CHUNK
    codes = pd.factorize(table["subject"])[0]
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    bounds = [*starts[::size], len(table)]
    for a, b in itertools.pairwise(bounds):
        yield table.iloc[a:b]


def _moments(
    table: pd.DataFrame,
    keys: list[str],
    values: list[str],
    prepare: Callable[[pd.DataFrame], pd.DataFrame] | None = None,
) -> pd.DataFrame:
    """:func:`~.stats.table_moments` of a study table, gathered over its chunks of whole
    subjects (:func:`subject_chunks`), so no copy of the whole table is made.

    ``prepare``: applied to each chunk first (a filter, a new column, or a pivot whose
    rows lie within one subject).
    """
    parts = []
    for chunk in subject_chunks(table):
        c = chunk if prepare is None else prepare(chunk)
        if len(c):
            parts.append(table_moments(c, keys, values))
    return merge_moments(pd.concat(parts)) if parts else _no_moments(keys, values)


def _no_moments(keys: list[str], values: list[str]) -> pd.DataFrame:
    """A moments table without groups."""
    columns = pd.MultiIndex.from_tuples([(v, f) for v in values for f in MOMENT_FIELDS])
    if len(keys) > 1:
        index = pd.MultiIndex.from_tuples([], names=keys)
    else:
        index = pd.Index([], name=keys[0] if keys else None)
    return pd.DataFrame(index=index, columns=columns, dtype=float)


def _total(m: pd.DataFrame, value: str, rows=None) -> Moments:
    """The moments of ``value`` over all groups of ``m`` (or those where ``rows``)."""
    sel = m if rows is None else m[np.asarray(rows, dtype=bool)]
    if sel.empty:
        return Moments.of([])
    return moments_at(merge_moments(sel[[value]], levels=[]), value)


def _by(m: pd.DataFrame, levels: list[str], rows=None) -> pd.DataFrame:
    """``m`` merged by some of its index levels (groups in order of first appearance)."""
    sel = m if rows is None else m[np.asarray(rows, dtype=bool)]
    if sel.empty:
        return _no_moments(levels, list(dict.fromkeys(c[0] for c in m.columns)))
    return merge_moments(sel, levels=levels)


def _level(m: pd.DataFrame, name: str) -> np.ndarray:
    """The values of index level ``name`` of ``m``, as text."""
    return m.index.get_level_values(name).astype(str).to_numpy()


def _paired(d: Moments) -> dict:
    return _stat(paired_ttest_of(d))


def _with_difference(chunk: pd.DataFrame) -> pd.DataFrame:
    """A chunk with ``d = user_axis - orthogonal`` (the paired t-tests' differences)."""
    return chunk.assign(d=chunk["user_axis"].astype(float) - chunk["orthogonal"].astype(float))


def _wide(index: list[str], value: str):
    """A ``prepare`` for :func:`_moments`: the chunk pivoted to one column per
    ``source``/``variant`` (``reference``, ``user_axis``, ``orthogonal``; the mean of
    duplicates, NaN where missing), with ``d`` (user_axis - orthogonal)."""

    def prepare(chunk: pd.DataFrame) -> pd.DataFrame:
        col = "source" if "source" in chunk.columns else "variant"
        w = chunk.pivot_table(index=index, columns=col, values=value, observed=True, sort=False)
        w.columns = w.columns.astype(str)
        w = w.reindex(columns=["reference", *VARIANTS]).reset_index()
        return _with_difference(w)

    return prepare


def _skips(node, where: str = "") -> list[dict]:
    """Every ``{"skipped": reason}`` in a summary, with its dotted key."""
    if isinstance(node, dict):
        if set(node) == {"skipped"}:
            return [{"statistic": where, "reason": node["skipped"]}]
        return [x for k, v in node.items() for x in _skips(v, f"{where}.{k}".lstrip("."))]
    return []


def _or_empty(tables: dict[str, pd.DataFrame | None], key: str) -> pd.DataFrame:
    """The study's table ``key`` (a field of SubjectResult), or an empty one."""
    table = tables[key]
    return concat_tables([], SUBJECT_TABLES[key]) if table is None else table


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
    flex_all = _or_empty(study_rows, "max_flexion")
    dist = _or_empty(study_rows, "distances")
    targets = _or_empty(study_rows, "targets")
    tables = {"max_flexion": flex_all, "axis_quality": dist, "targets": targets}
    with_targets = {str(x) for c in subject_chunks(targets) for x in c["subject"].unique()}
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
    # Every statistic from moments gathered over chunks of whole subjects (no copy of a
    # whole table; the two-way ANOVAs from the moments of their cells).
    # Axis quality (Fig. 8) and the paper's t-tests between joints.
    by_joint = _moments(dist, ["joint"], ["distance_mm"])
    joint = lambda j: moments_at(by_joint, "distance_mm", j)  # noqa: E731
    aq = {
        j: _mean_sd(joint(j))
        for j in (*JOINTS, *THUMB_JOINTS)
        if j in by_joint.index and joint(j).rows
    }
    tests = {
        f"{a}_vs_{b}": _stat(independent_ttest_of(joint(a), joint(b)))
        for a, b in (("dip", "pip"), ("mp", "dip"), ("mp", "pip"))
    }
    summary["axis_quality"] = {"per_joint": aq, "t_tests": tests}
    # Maximal flexion (Fig. 10): the paper's figures are the four fingers'.
    flex_m = _moments(flex_all, ["subject", "finger"], list(_PAIR), _with_difference)
    fingers = np.isin(_level(flex_m, "finger"), FINGERS)
    mf = _headline(_total(flex_m, "user_axis", fingers), _total(flex_m, "orthogonal", fingers))
    mf["paired_t_test"] = _paired(_total(flex_m, "d", fingers))
    per_subject = _by(flex_m, ["subject"], fingers)
    mf["per_subject"] = {}
    for s in subjects:
        u, o = (moments_at(per_subject, v, s.subject) for v in ("user_axis", "orthogonal"))
        mf["per_subject"][s.subject] = {
            "n": u.n,
            "user_axis_mean_mm": _num(u.mean),
            "orthogonal_mean_mm": _num(o.mean),
            "reduction_percent": _num(reduction_percent(u.mean, o.mean)),
            "paired_t_test": _paired(moments_at(per_subject, "d", s.subject)),
        }
    mf["anova_model_x_subject"] = _anova_dict(
        two_way_anova_of_cells(_model_cells(per_subject, "subject"), "error", "model", "subject")
    )
    summary["max_flexion"] = mf
    # Targets (Figs. 11-12): only the sessions with target recordings.
    if not targets.empty:
        wide = _moments(
            targets,
            ["target"],
            ["reference", *_PAIR],
            _wide(["subject", "finger", "target"], "error_mm"),
        )
        tg = _headline(_total(wide, "user_axis"), _total(wide, "orthogonal"))
        tg["subjects"] = sorted(with_targets)
        tg["reference"] = _mean_sd(_total(wide, "reference"))
        tg["paired_t_test"] = _paired(_total(wide, "d"))
        tg["per_target"] = {}
        for t in sorted(wide.index, key=str):
            tg["per_target"][str(t)] = {"n": moments_at(wide, "reference", t).rows}
            for src in ("reference", *VARIANTS):
                sm = summary_of(moments_at(wide, src, t))
                tg["per_target"][str(t)][src] = {"mean_mm": _num(sm.mean), "sd_mm": _num(sm.sd)}
        models = lambda c: c[c["source"].isin(VARIANTS)]  # noqa: E731
        for factor in ("target", "subject"):
            cells = _renamed(_moments(targets, ["source", factor], ["error_mm"], models), "error")
            tg[f"anova_model_x_{factor}"] = _anova_dict(
                two_way_anova_of_cells(cells, "error", "model", factor)
            )
        summary["targets"] = tg
    # Ground truth (simulated sessions only).
    axes_m = tips_m = None
    if study_rows["truth_axes"] is not None:
        ta = study_rows["truth_axes"]
        tt = _or_empty(study_rows, "truth_tips")
        tables["truth_axes"], tables["truth_fingertip"] = ta, tt
        axes_m = _moments(ta, ["finger", "joint"], ["axis_error_deg", "centre_to_axis_mm"])
        tips_m = _moments(tt, ["finger", "recording", "variant"], ["mean_mm", "p95_mm"])
        per_joint = _by(axes_m, ["joint"])
        joints = sorted(per_joint.index, key=str)
        tip_fingers = _by(
            tips_m, ["recording", "variant"], np.isin(_level(tips_m, "finger"), FINGERS)
        )
        summary["truth"] = {
            "subjects": sorted({str(x) for c in subject_chunks(ta) for x in c["subject"].unique()}),
            "axis_error_deg": {
                str(j): _mean_max(moments_at(per_joint, "axis_error_deg", j)) for j in joints
            },
            "centre_to_axis_mm": {
                str(j): _mean_max(moments_at(per_joint, "centre_to_axis_mm", j)) for j in joints
            },
            "fingertip_mm": {
                f"{r}/{v}": {
                    "mean": _num(moments_at(tip_fingers, "mean_mm", (r, v)).mean),
                    "p95": _num(moments_at(tip_fingers, "p95_mm", (r, v)).mean),
                }
                for r, v in sorted(tip_fingers.index, key=lambda k: (str(k[0]), str(k[1])))
            },
        }
        _whole_hand_truth(_or_empty(study_rows, "truth_angles"), summary, tables, tips_m)
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
    _thumb(subjects, summary, tables, flex_m, axes_m, tips_m)
    _pinch(summary, tables, _or_empty(study_rows, "pinches"))
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


_PAIR = ("user_axis", "orthogonal", "d")  # d: user_axis - orthogonal, per row


def _model_cells(m: pd.DataFrame, factor: str) -> pd.DataFrame:
    """The cells (model, ``factor``) of a model x ``factor`` ANOVA of the error, from
    moments by ``factor`` of the user-axis and orthogonal errors (a long table's cells)."""
    cells = {model: _renamed(m[[model]], "error") for model in VARIANTS}
    return pd.concat(cells, names=["model", factor])


def _renamed(m: pd.DataFrame, value: str) -> pd.DataFrame:
    """A moments table of one value, the value renamed."""
    out = m.copy(deep=False)
    out.columns = pd.MultiIndex.from_tuples([(value, f) for _v, f in m.columns])
    return out


def _whole_hand_truth(ang: pd.DataFrame, summary: dict, tables: dict, tips_m: pd.DataFrame) -> None:
    """Every digit's tip and every joint angle against truth: ``summary["truth"]`` keys
    ``tip_mm_per_digit`` (digit -> ``recording/variant`` -> mean, p95 mm) and
    ``angle_error_deg`` (digit -> angle -> variant -> mean |error| deg), table
    ``truth_angles`` (``ang``). Digits and angles in order of appearance, recordings and
    variants sorted."""
    tables["truth_angles"] = ang
    tips: dict = {}
    keys = sorted(tips_m.index, key=lambda k: (str(k[1]), str(k[2])))
    for f, r, v in keys:
        tips.setdefault(str(f), {})[f"{r}/{v}"] = {
            "mean": _num(moments_at(tips_m, "mean_mm", (f, r, v)).mean),
            "p95": _num(moments_at(tips_m, "p95_mm", (f, r, v)).mean),
        }
    order = list(dict.fromkeys(str(f) for f, _r, _v in tips_m.index))
    summary["truth"]["tip_mm_per_digit"] = {f: tips[f] for f in order}
    angles: dict = {}
    ang_m = _moments(ang, ["finger", "joint", "variant"], ["mean_abs_deg", "p95_abs_deg"])
    for key in ang_m.index:
        f, j, v = (str(k) for k in key)
        angles.setdefault(f, {}).setdefault(j, {})[v] = {
            "mean": _num(moments_at(ang_m, "mean_abs_deg", key).mean),
            "p95": _num(moments_at(ang_m, "p95_abs_deg", key).mean),
        }
    summary["truth"]["angle_error_deg"] = {
        f: {j: dict(sorted(by_variant.items())) for j, by_variant in by_joint.items()}
        for f, by_joint in angles.items()
    }


def _thumb(
    subjects: Sequence[SubjectResult],
    summary: dict,
    tables: dict,
    flex_m: pd.DataFrame,
    axes_m: pd.DataFrame | None,
    tips_m: pd.DataFrame | None,
) -> None:
    """``summary["thumb"]``: the thumb's fingertip at maximal flexion, axes and tip against
    truth, CMC/MCP geometry (table ``thumb_geometry``), for studies with a thumb."""
    # One subject at a time (a study's subjects may be packed, one made per access).
    with_thumb = [s.subject for s in subjects if "thumb" in s.model.fingers]
    if not with_thumb:
        return
    th: dict = {"subjects": with_thumb}
    thumb = _level(flex_m, "finger") == "thumb"
    if thumb.any():
        mf = _headline(_total(flex_m, "user_axis", thumb), _total(flex_m, "orthogonal", thumb))
        mf["paired_t_test"] = _paired(_total(flex_m, "d", thumb))
        th["max_flexion"] = mf
    geo = concat_tables(
        [thumb_geometry(s) for s in subjects if "thumb" in s.model.fingers],
        THUMB_GEOMETRY_COLUMNS,
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
        thumb_axes = axes_m[_level(axes_m, "finger") == "thumb"]
        th["truth_axes"] = {
            str(j): {
                "axis_error_deg": _mean_max(moments_at(thumb_axes, "axis_error_deg", ("thumb", j))),
                "centre_to_axis_mm": _mean_max(
                    moments_at(thumb_axes, "centre_to_axis_mm", ("thumb", j))
                ),
                "n": moments_at(thumb_axes, "axis_error_deg", ("thumb", j)).rows,
            }
            for _f, j in thumb_axes.index
        }
        # Per recording, one row per subject: the mean of its thumb's tip errors.
        per_subject = _wide(["recording", "subject"], "mean_mm")
        by_recording = _moments(
            tables["truth_fingertip"],
            ["recording"],
            list(_PAIR),
            lambda c: per_subject(c[c["finger"] == "thumb"]),
        )
        tips = {}
        for r in by_recording.index:
            u, o = (moments_at(by_recording, v, r) for v in VARIANTS)
            if u.n and o.n:  # both models' errors known for this recording
                h = _headline(u, o)
                h["orthogonal_ratio"] = _num(u.mean / o.mean)
                h["paired_t_test"] = _paired(moments_at(by_recording, "d", r))
                tips[str(r)] = h
        th["truth_tip"] = tips
    summary["thumb"] = th


def _pinch(summary: dict, tables: dict, pin: pd.DataFrame) -> None:
    """``summary["pinch"]`` (tip distances and pad gaps during pinch events) and table
    ``pinch``, for studies with pinch events."""
    if pin.empty:
        return
    tables["pinch"] = pin
    columns = ["tip_distance_error_mm", "tip_distance_bias_mm", "pad_gap_mm", "true_pad_gap_mm"]
    per_source = _moments(pin, ["source"], columns)
    per_kind = _moments(pin, ["kind", "target", "source"], columns[:1] + columns[2:3])
    pn: dict = {
        "subjects": sorted({str(x) for c in subject_chunks(pin) for x in c["subject"].unique()}),
        "per_source": {},
        "per_kind": {},
    }
    for src in per_source.index:
        pn["per_source"][str(src)] = {
            "tip_distance_error": _mean_sd(moments_at(per_source, columns[0], src)),
            "tip_distance_bias": _mean_sd(moments_at(per_source, columns[1], src)),
            "pad_gap": _mean_sd(moments_at(per_source, columns[2], src)),
            "true_pad_gap": _mean_sd(moments_at(per_source, columns[3], src)),
        }
    for kind, tgt, src in per_kind.index:
        pn["per_kind"].setdefault(f"{kind}/{tgt}", {})[str(src)] = {
            "tip_distance_error": _mean_sd(moments_at(per_kind, columns[0], (kind, tgt, src))),
            "pad_gap": _mean_sd(moments_at(per_kind, columns[2], (kind, tgt, src))),
        }
    pairs = _moments(
        pin, [], list(_PAIR), _wide(["subject", "recording", "target", "start"], columns[0])
    )
    if all(_total(pairs, v).n for v in VARIANTS):  # some pinch has both models' errors
        pn["paired_t_test"] = _paired(_total(pairs, "d"))
    else:
        pn["paired_t_test"] = {"skipped": "no pinch with ground truth (true tip distances)"}
    summary["pinch"] = pn
