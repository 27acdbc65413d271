"""``fingerfit study``: the paper's whole evaluation over several sessions.

For each session: fit (or take a given model), then axis quality (Fig. 8),
grasp fingertip trajectories and errors at maximal flexion (Figs. 9-10),
target reaching (Figs. 11-12); with simulated sessions also the true errors.
Statistics and the headline as in the paper; outputs written to one folder.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from .. import __version__
from ..estimate import FitOptions, fit_session
from ..io import load_session
from ..io.atomic import atomic_write
from ..kinematics import compute_kinematics
from ..model import VARIANTS, HandModel, save_model
from ..session import HAND_SENSOR, Session
from ..transforms import angle_between_axes, apply_inverse_pose
from . import figures
from .fingertip import GraspEvaluation, evaluate_grasp, evaluate_targets
from .stats import (
    independent_ttest,
    paired_ttest,
    reduction_percent,
    summarize,
    two_way_anova,
)
from .truth import Truth, axis_errors, load_truth

PAPER = {
    "max_flexion": {"user_axis": (2.7, 1.3), "orthogonal": (5.4, 3.4), "reduction_percent": 50},
    "targets": {"user_axis": (2.6, 0.9), "orthogonal": (4.7, 1.7), "reduction_percent": 45},
    "axis_quality_mm": {"dip": (0.2, 0.1), "pip": (0.3, 0.1)},
}


@dataclass
class SubjectResult:
    """Everything the study computed for one session."""

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


@dataclass
class StudyResult:
    """The study's tables, statistics and output paths."""

    subjects: list[SubjectResult]
    summary: dict
    tables: dict[str, pd.DataFrame]
    out_dir: Path
    figures: dict[str, Path] = field(default_factory=dict)
    report: Path | None = None


def _subject(session: Session, options: FitOptions) -> SubjectResult:
    model = fit_session(session, options)
    truth = load_truth(session.path)
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
    res = SubjectResult(
        session.subject,
        session,
        model,
        grasp,
        pd.concat(flex, ignore_index=True),
        targets,
        pd.concat(dist, ignore_index=True),
        truth,
    )
    if truth is not None:
        res.truth_axes = pd.concat([axis_errors(model, truth, f) for f in model.fingers]).assign(
            subject=session.subject
        )
        rows = []
        for rec in session.recordings()[1:]:
            if rec.name not in truth.tips:
                continue
            kin = compute_kinematics(model, rec)
            for f in model.fingers:
                for v in VARIANTS:
                    e = np.linalg.norm(kin.motions[v][f].tip - truth.tips[rec.name][f], axis=1)
                    rows.append(
                        (
                            session.subject,
                            f,
                            rec.name,
                            v,
                            float(np.nanmean(e)),
                            float(np.nanpercentile(e, 95)),
                        )
                    )
        res.truth_tips = pd.DataFrame(
            rows, columns=["subject", "finger", "recording", "variant", "mean_mm", "p95_mm"]
        )
    return res


def _headline(table: pd.DataFrame, user: str = "user_axis", ortho: str = "orthogonal") -> dict:
    u, o = summarize(table[user]), summarize(table[ortho])
    return {
        "user_axis": {"mean_mm": u.mean, "sd_mm": u.sd, "n": u.n},
        "orthogonal": {"mean_mm": o.mean, "sd_mm": o.sd, "n": o.n},
        "reduction_percent": reduction_percent(u.mean, o.mean),
        "sd_reduction_percent": reduction_percent(u.sd, o.sd),
    }


def _anova_dict(table: pd.DataFrame) -> dict:
    return {
        idx: {
            "F": None if np.isnan(r["F"]) else float(r["F"]),
            "p": None if np.isnan(r["PR(>F)"]) else float(r["PR(>F)"]),
            "df": float(r["df"]),
        }
        for idx, r in table.iterrows()
    }


def summarize_study(
    subjects: list[SubjectResult], options: FitOptions
) -> tuple[dict, dict[str, pd.DataFrame]]:
    """Statistics and headline of the study, plus its tables."""
    flex = pd.concat([s.max_flexion for s in subjects], ignore_index=True)
    dist = pd.concat([s.distances for s in subjects], ignore_index=True)
    targets = pd.concat([s.targets for s in subjects], ignore_index=True)
    tables = {"max_flexion": flex, "axis_quality": dist, "targets": targets}
    summary: dict = {
        "format": "fingerfit.study/1",
        "fingerfit_version": __version__,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "method": options.method,
        "angle_methods": sorted({s.model.angle_method for s in subjects}),
        "subjects": [s.subject for s in subjects],
        "units": "mm",
        "paper": PAPER,
    }
    # Axis quality (Fig. 8) and the paper's t-tests between joints.
    aq = {
        j: {"mean_mm": float(g.mean()), "sd_mm": float(g.std(ddof=1)), "n": int(g.size)}
        for j, g in dist.groupby("joint")["distance_mm"]
    }
    tests = {}
    for a, b in (("dip", "pip"), ("mp", "dip"), ("mp", "pip")):
        t = independent_ttest(
            dist.loc[dist.joint == a, "distance_mm"], dist.loc[dist.joint == b, "distance_mm"]
        )
        tests[f"{a}_vs_{b}"] = t.__dict__
    summary["axis_quality"] = {"per_joint": aq, "t_tests": tests}
    # Maximal flexion (Fig. 10).
    mf = _headline(flex)
    mf["paired_t_test"] = paired_ttest(flex["user_axis"], flex["orthogonal"]).__dict__
    mf["per_subject"] = {
        s: {
            "user_axis_mean_mm": float(g["user_axis"].mean()),
            "orthogonal_mean_mm": float(g["orthogonal"].mean()),
            "reduction_percent": reduction_percent(g["user_axis"].mean(), g["orthogonal"].mean()),
            "paired_t_test": paired_ttest(g["user_axis"], g["orthogonal"]).__dict__,
        }
        for s, g in flex.groupby("subject")
    }
    long = flex.melt(
        id_vars=["subject", "cycle"],
        value_vars=list(VARIANTS),
        var_name="model",
        value_name="error",
    )
    if flex["subject"].nunique() > 1:
        mf["anova_model_x_subject"] = _anova_dict(two_way_anova(long, "error", "model", "subject"))
    summary["max_flexion"] = mf
    # Targets (Figs. 11-12).
    if not targets.empty:
        wide = targets.pivot_table(
            index=["subject", "finger", "target"], columns="source", values="error_mm"
        ).reset_index()
        tg = _headline(wide)
        ref = summarize(wide["reference"])
        tg["reference"] = {"mean_mm": ref.mean, "sd_mm": ref.sd, "n": ref.n}
        tg["paired_t_test"] = paired_ttest(wide["user_axis"], wide["orthogonal"]).__dict__
        tg["per_target"] = {
            t: {
                src: {"mean_mm": float(g[src].mean()), "sd_mm": float(g[src].std(ddof=1))}
                for src in ("reference", *VARIANTS)
            }
            for t, g in wide.groupby("target")
        }
        tl = targets[targets["source"].isin(VARIANTS)].rename(columns={"source": "model"})
        tg["anova_model_x_target"] = _anova_dict(two_way_anova(tl, "error_mm", "model", "target"))
        if tl["subject"].nunique() > 1:
            tg["anova_model_x_subject"] = _anova_dict(
                two_way_anova(tl, "error_mm", "model", "subject")
            )
        summary["targets"] = tg
    # Ground truth (simulated sessions only).
    truth_axes = [s.truth_axes for s in subjects if s.truth_axes is not None]
    if truth_axes:
        ta = pd.concat(truth_axes, ignore_index=True)
        tt = pd.concat(
            [s.truth_tips for s in subjects if s.truth_tips is not None], ignore_index=True
        )
        tables["truth_axes"], tables["truth_fingertip"] = ta, tt
        summary["truth"] = {
            "axis_error_deg": {
                j: {
                    "mean": float(g["axis_error_deg"].mean()),
                    "max": float(g["axis_error_deg"].max()),
                }
                for j, g in ta.groupby("joint")
            },
            "centre_to_axis_mm": {
                j: {
                    "mean": float(g["centre_to_axis_mm"].mean()),
                    "max": float(g["centre_to_axis_mm"].max()),
                }
                for j, g in ta.groupby("joint")
            },
            "fingertip_mm": {
                f"{r}/{v}": {"mean": float(g["mean_mm"].mean()), "p95": float(g["p95_mm"].mean())}
                for (r, v), g in tt.groupby(["recording", "variant"])
            },
        }
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
                        fm.segment_lengths[{"mp": "proximal", "pip": "middle", "dip": "distal"}[j]],
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
    return summary, tables


def run_study(
    sessions: list[Path | Session],
    out_dir: Path,
    options: FitOptions | None = None,
    progress: Callable[[str], None] | None = None,
) -> StudyResult:
    """Fit and evaluate sessions; write tables, figures, ``summary.json`` and ``report.html``.

    Parameters
    ----------
    sessions : list of Path or Session
        Session directories (or loaded sessions).
    out_dir : Path
        Output folder (created).
    options : FitOptions, optional
        Fit options (method etc.).
    progress : callable, optional
        Called with a short description after each step.

    Returns
    -------
    StudyResult
    """
    from .report import write_report

    options = options or FitOptions()
    step = progress or (lambda _msg: None)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    subjects = []
    for s in sessions:
        session = s if isinstance(s, Session) else load_session(s)
        subjects.append(_subject(session, options))
        save_model(subjects[-1].model, out_dir / "models" / f"{session.subject}.json")
        step(f"fitted and evaluated {session.subject}")
    summary, tables = summarize_study(subjects, options)
    result = StudyResult(subjects, summary, tables, out_dir)
    for name, table in tables.items():
        with atomic_write(out_dir / f"{name}.csv", newline="") as fh:
            table.to_csv(fh, index=False, lineterminator="\n", float_format="%.6g")
    fig = result.figures
    fig["fig08"] = figures.axis_quality(tables["axis_quality"], out_dir / "fig08_axis_quality.png")
    for s in subjects:
        f, ev = next(iter(s.grasp.items()))
        hand = s.session.grasp[0].pose(HAND_SENSOR)
        in_hand = {
            k: apply_inverse_pose(hand.rotation, hand.position, v) for k, v in ev.tips.items()
        }
        fig[f"fig09_{s.subject}"] = figures.trajectories(
            ev.time, in_hand, f"{s.subject} ({f})", out_dir / f"fig09_trajectories_{s.subject}.png"
        )
    fig["fig10"] = figures.paired_boxes(
        tables["max_flexion"],
        "subject",
        "Fig. 10 - fingertip error at maximal flexion (vs distal-sensor reference)",
        "error (mm)",
        out_dir / "fig10_max_flexion.png",
    )
    if not tables["targets"].empty:
        fig["fig11"] = figures.target_scatter(
            tables["targets"], out_dir / "fig11_target_offsets.png"
        )
        fig["fig12"] = figures.target_bars(tables["targets"], out_dir / "fig12_target_errors.png")
    if "truth_fingertip" in tables:
        tt = tables["truth_fingertip"]
        wide = tt.pivot_table(
            index=["subject", "recording"], columns="variant", values="mean_mm"
        ).reset_index()
        fig["truth"] = figures.paired_boxes(
            wide,
            "recording",
            "True fingertip error (simulation ground truth)",
            "mean error per recording (mm)",
            out_dir / "truth_fingertip.png",
        )
    step("figures")
    with atomic_write(out_dir / "summary.json") as fh:
        json.dump(summary, fh, indent=1, default=float)
    result.report = write_report(result, out_dir / "report.html")
    step("report")
    return result
