"""The study's statistics and headline (``summary.json``) and its tables.

Axis quality (Fig. 8) with the paper's t-tests between joints, fingertip error at
maximal flexion (Fig. 10) and at targets (Figs. 11-12) with paired t-tests and the
model x subject / model x target ANOVAs, ground truth of simulated sessions, the
thumb and pinches. Lengths mm, angles deg.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..digits import FINGERS, THUMB_JOINTS
from ..estimate import FitOptions
from ..model import VARIANTS
from ..session import JOINTS
from .fingertip import count_skipped
from .gather import StudyTables, study_tables
from .stats import (
    Moments,
    Skipped,
    empty_moments,
    independent_ttest_of,
    merge_moments,
    moments_at,
    paired_ttest_of,
    reduction_percent,
    summary_of,
    two_way_anova_of_cells,
)
from .subject import (
    THUMB_GEOMETRY_COLUMNS,
    SessionFailure,
    SubjectResult,
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


def _subjects_in(tables: StudyTables, name: str) -> set[str]:
    """The subjects with rows in table ``name``."""
    return {str(x) for chunk in tables.chunks(name) for x in chunk["subject"].unique()}


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
        return empty_moments(levels, list(dict.fromkeys(c[0] for c in m.columns)))
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
    """A ``prepare`` for :meth:`StudyTables.moments`: the chunk pivoted to one column per
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
    tables: StudyTables | None = None,
    out_dir: Path | None = None,
) -> tuple[dict, StudyTables]:
    """Statistics and headline of the study, plus its tables.

    Parameters
    ----------
    subjects : sequence of SubjectResult
        At least one; any mix of sessions with or without targets, test recordings,
        ground truth, and different fingers (read one at a time).
    options : FitOptions
    failures : list of SessionFailure, optional
        Sessions that could not be fitted (``--keep-going``), listed in the summary.
    tables : StudyTables, optional
        The study's tables, made from ``subjects`` (as :func:`run_study` does); by
        default made here, in the system's temporary folder.
    out_dir : Path, optional
        The study's output folder (its final name): each session's ``path`` is written
        relative to it (:func:`summary_path`).

    Returns
    -------
    summary : dict
        The ``summary.json`` document (lengths mm, angles deg; NaN stored as null).
        A statistic the data cannot support is ``{"skipped": reason}`` and listed
        under ``"skipped"``; so is each touch event the model cannot evaluate, and
        ``"events_not_evaluated"`` (only when there is one) counts them
        (:func:`~.fingertip.count_skipped`: in all and per subject).
    tables : StudyTables
        The tables the statistics were computed from.
    """
    if tables is None:
        tables = study_tables(subjects)
    with_targets = _subjects_in(tables, "targets")
    # What the summary needs of each subject's result, in one pass (each may be made
    # from its pickle on access).
    digests = [
        (
            s.subject,
            s.session.path,
            list(s.model.fingers),
            s.truth is not None,
            list(s.warnings),
            s.model.angle_method,
            s.skipped_events,
        )
        for s in subjects
    ]
    names = [d[0] for d in digests]
    summary: dict = {
        "format": "fingerfit.study/1",
        "fingerfit_version": __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "method": options.method,
        "forced": bool(options.force),
        "angle_methods": sorted({method for *_, method, _events in digests}),
        "subjects": names,
        "sessions": {
            name: {
                "path": summary_path(path, out_dir),
                "fingers": fingers,
                "has_targets": name in with_targets,
                "has_truth": has_truth,
            }
            for name, path, fingers, has_truth, *_ in digests
        },
        "failed": [f.as_dict() for f in failures or []],
        "warnings": {name: warned for name, _p, _f, _t, warned, *_ in digests if warned},
        "units": "mm",
        "paper": PAPER,
    }
    # Every statistic from moments gathered over chunks of whole subjects (no copy of a
    # whole table; the two-way ANOVAs from the moments of their cells).
    # Axis quality (Fig. 8) and the paper's t-tests between joints.
    by_joint = tables.moments("axis_quality", ["joint"], ["distance_mm"])
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
    keys = ["subject", "finger"]
    flex_m = tables.moments("max_flexion", keys, list(_PAIR), _with_difference)
    fingers = np.isin(_level(flex_m, "finger"), FINGERS)
    mf = _headline(_total(flex_m, "user_axis", fingers), _total(flex_m, "orthogonal", fingers))
    mf["paired_t_test"] = _paired(_total(flex_m, "d", fingers))
    per_subject = _by(flex_m, ["subject"], fingers)
    mf["per_subject"] = {}
    for name in names:
        u, o = (moments_at(per_subject, v, name) for v in ("user_axis", "orthogonal"))
        mf["per_subject"][name] = {
            "n": u.n,
            "user_axis_mean_mm": _num(u.mean),
            "orthogonal_mean_mm": _num(o.mean),
            "reduction_percent": _num(reduction_percent(u.mean, o.mean)),
            "paired_t_test": _paired(moments_at(per_subject, "d", name)),
        }
    mf["anova_model_x_subject"] = _anova_dict(
        two_way_anova_of_cells(_model_cells(per_subject, "subject"), "error", "model", "subject")
    )
    summary["max_flexion"] = mf
    # Targets (Figs. 11-12): only the sessions with target recordings.
    if with_targets:
        wide = tables.moments(
            "targets",
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
            cells = tables.moments("targets", ["source", factor], ["error_mm"], models)
            cells = _renamed(cells, "error")
            tg[f"anova_model_x_{factor}"] = _anova_dict(
                two_way_anova_of_cells(cells, "error", "model", factor)
            )
        summary["targets"] = tg
    # Ground truth (simulated sessions only).
    axes_m = tips_m = None
    if "truth_axes" in tables:
        values = ["axis_error_deg", "centre_to_axis_mm"]
        axes_m = tables.moments("truth_axes", ["finger", "joint"], values)
        values = ["mean_mm", "p95_mm"]
        tips_m = tables.moments("truth_fingertip", ["finger", "recording", "variant"], values)
        per_joint = _by(axes_m, ["joint"])
        joints = sorted(per_joint.index, key=str)
        tip_fingers = _by(
            tips_m, ["recording", "variant"], np.isin(_level(tips_m, "finger"), FINGERS)
        )
        summary["truth"] = {
            "subjects": sorted(_subjects_in(tables, "truth_axes")),
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
        _whole_hand_truth(tables, summary, tips_m)
    with_thumb = [name for name, _p, fingers, *_ in digests if "thumb" in fingers]
    _thumb(with_thumb, summary, tables, flex_m, axes_m, tips_m)
    _pinch(summary, tables)
    summary["skipped"] = _skips(
        {
            k: summary[k]
            for k in ("axis_quality", "max_flexion", "targets", "thumb", "pinch")
            if k in summary
        }
    )
    summary["skipped"] += [
        {
            "statistic": f"events.{name}.{e['recording']}.{e['finger']}->{e['target']}",
            "reason": e["reason"],
        }
        for name, *_, events in digests
        for e in events
    ]
    not_evaluated = {name: count_skipped(events) for name, *_, events in digests if events}
    if not_evaluated:  # absent when every event was evaluated
        summary["events_not_evaluated"] = {
            **count_skipped(e for _name, *_, events in digests for e in events),
            "per_subject": not_evaluated,
        }
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


def _whole_hand_truth(tables: StudyTables, summary: dict, tips_m: pd.DataFrame) -> None:
    """Every digit's tip and every joint angle against truth: ``summary["truth"]`` keys
    ``tip_mm_per_digit`` (digit -> ``recording/variant`` -> mean, p95 mm) and
    ``angle_error_deg`` (digit -> angle -> variant -> mean |error| deg). Digits and
    angles in order of appearance, recordings and variants sorted."""
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
    keys, values = ["finger", "joint", "variant"], ["mean_abs_deg", "p95_abs_deg"]
    ang_m = tables.moments("truth_angles", keys, values)
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
    with_thumb: list[str],
    summary: dict,
    tables: StudyTables,
    flex_m: pd.DataFrame,
    axes_m: pd.DataFrame | None,
    tips_m: pd.DataFrame | None,
) -> None:
    """``summary["thumb"]``: the thumb's fingertip at maximal flexion, axes and tip against
    truth, CMC/MCP geometry, for studies with a thumb (``with_thumb``: their subjects)."""
    if not with_thumb:
        return
    th: dict = {"subjects": with_thumb}
    thumb = _level(flex_m, "finger") == "thumb"
    if thumb.any():
        mf = _headline(_total(flex_m, "user_axis", thumb), _total(flex_m, "orthogonal", thumb))
        mf["paired_t_test"] = _paired(_total(flex_m, "d", thumb))
        th["max_flexion"] = mf
    values = THUMB_GEOMETRY_COLUMNS[2:]
    geo = tables.moments("thumb_geometry", ["joint"], values)
    th["geometry"] = {
        str(j): {
            **{v: _num(moments_at(geo, v, j).mean) for v in values},
            "n": moments_at(geo, values[0], j).rows,
        }
        for j in geo.index
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
        by_recording = tables.moments(
            "truth_fingertip",
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


def _pinch(summary: dict, tables: StudyTables) -> None:
    """``summary["pinch"]`` (tip distances and pad gaps during pinch events), for studies
    with pinch events."""
    if "pinch" not in tables:
        return
    columns = [
        "tip_distance_error_mm",
        "tip_distance_bias_mm",
        "pad_gap_mm",
        "true_pad_gap_mm",
        "pad_contact_mm",
    ]
    per_source = tables.moments("pinch", ["source"], columns)
    per_kind = tables.moments("pinch", ["kind", "target", "source"], [columns[0], columns[2]])
    pn: dict = {
        "subjects": sorted(_subjects_in(tables, "pinch")),
        "per_source": {},
        "per_kind": {},
    }
    for src in per_source.index:
        pn["per_source"][str(src)] = {
            "tip_distance_error": _mean_sd(moments_at(per_source, columns[0], src)),
            "tip_distance_bias": _mean_sd(moments_at(per_source, columns[1], src)),
            "pad_gap": _mean_sd(moments_at(per_source, columns[2], src)),
            "true_pad_gap": _mean_sd(moments_at(per_source, columns[3], src)),
            "pad_to_contact": _mean_sd(moments_at(per_source, columns[4], src)),
        }
    for kind, tgt, src in per_kind.index:
        pn["per_kind"].setdefault(f"{kind}/{tgt}", {})[str(src)] = {
            "tip_distance_error": _mean_sd(moments_at(per_kind, columns[0], (kind, tgt, src))),
            "pad_gap": _mean_sd(moments_at(per_kind, columns[2], (kind, tgt, src))),
        }
    pairs = tables.moments(
        "pinch",
        [],
        list(_PAIR),
        _wide(["subject", "recording", "target", "start"], columns[0]),
    )
    if all(_total(pairs, v).n for v in VARIANTS):  # some pinch has both models' errors
        pn["paired_t_test"] = _paired(_total(pairs, "d"))
    else:
        pn["paired_t_test"] = {"skipped": "no pinch with ground truth (true tip distances)"}
    summary["pinch"] = pn
