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
from ..transforms import angle_between_axes
from .gather import StudyTables
from .stats import (
    Skipped,
    independent_ttest_or_skip,
    paired_ttest_or_skip,
    reduction_percent,
    summarize,
    two_way_anova_or_skip,
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
    # The paper's figures (headline, Fig. 10) are the four fingers'; the thumb's own section.
    flex = flex_all[flex_all["finger"].isin(FINGERS)]
    dist = _or_empty(study_rows, "distances")
    targets = _or_empty(study_rows, "targets")
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
        tt = _or_empty(study_rows, "truth_tips")
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
        _whole_hand_truth(_or_empty(study_rows, "truth_angles"), summary, tables, tt)
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
    _thumb_and_pinch(subjects, summary, tables, flex_all, _or_empty(study_rows, "pinches"))
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
