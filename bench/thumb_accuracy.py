"""Thumb and pinch accuracy: ``fingerfit study`` on simulated thumb + index subjects.

Run with ``.venv/bin/python bench/thumb_accuracy.py --subjects 8 --json bench/thumb_accuracy.json``.

``--subjects`` subjects of ``SimConfig(fingers=("thumb", "index"))`` (the project's
simulator at default noise: Liberty-like tracker noise and field distortion, soft-tissue
artefact, stylus noise, MyoHand/Hollister axis obliquity, centre migration, MCP
ab/adduction), seeds ``simulate_cohort(config, n, seed=2026)``, are written as session
folders with their truth and evaluated by ``fingerfit study`` (default method), exactly
as a user would. ``--world myohand`` simulates MyoHand's thumb and index instead
(``SimConfig(world="myohand", hand="right")``: MyoHand's axes, a hinge thumb MCP; the
same seeds and noise). The figures are read from the study's tables:

* **axis error** (deg): angle between each fitted thumb axis (``cmc``,
  ``cmc_abduction``, ``mcp``, ``mcp_abduction`` where the fit chose two axes, ``ip``) and
  the true one, in the joint's parent sensor frame; **centre** (mm): distance of the
  model's point of that axis to the true axis line. Mean and 95th percentile over
  subjects (``truth_axes.csv``).
* **thumb tip error** (mm): model thumb tip vs true thumb tip over the free-motion
  recording ``test.csv`` (and every other recording), user-axis vs orthogonal model;
  mean over subjects of each subject's mean over frames (``truth_fingertip.csv``).
* **pinch-distance error** (mm): during each tip-pinch event (thumb pad on index pad,
  ``events.csv``), the mean over the event's frames of ``|d_model - d_true|``, ``d`` the
  distance between the thumb's and the index's tip points; mean (SD) over events
  (``pinch.csv``). Also the pad-to-pad gap of the model and the true one.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from fingerfit import __version__
from fingerfit.evaluate import run_study
from fingerfit.evaluate.pinch import evaluate_pinches
from fingerfit.evaluate.truth import load_truth
from fingerfit.kinematics import compute_kinematics
from fingerfit.simulate import SimConfig, SimulatedSubject, simulate_cohort, write_subject
from fingerfit.simulate.truthmodel import truth_model

SEED = 2026
AXES = ("cmc", "cmc_abduction", "mcp", "mcp_abduction", "ip")


def _ms(x: pd.Series) -> dict:
    x = x[np.isfinite(x)]
    return {
        "mean": float(x.mean()) if len(x) else None,
        "sd": float(x.std(ddof=1)) if len(x) > 1 else None,
        "p95": float(np.percentile(x, 95)) if len(x) else None,
        "n": len(x),
    }


def figures(tables: dict[str, pd.DataFrame]) -> dict:
    """The issue's thumb and pinch figures from a study's tables."""
    ta = tables["truth_axes"]
    ta = ta[ta["finger"] == "thumb"]
    axes = {
        j: {
            "axis_error_deg": _ms(ta.loc[ta["joint"] == j, "axis_error_deg"]),
            "centre_to_axis_mm": _ms(ta.loc[ta["joint"] == j, "centre_to_axis_mm"]),
        }
        for j in AXES
        if (ta["joint"] == j).any()
    }
    tt = tables["truth_fingertip"]
    tips = {}
    for (f, rec), g in tt.groupby(["finger", "recording"]):
        w = g.pivot_table(index="subject", columns="variant", values="mean_mm")
        u, o = _ms(w["user_axis"]), _ms(w["orthogonal"])
        tips[f"{f}/{rec}"] = {
            "user_axis": u,
            "orthogonal": o,
            "ratio": u["mean"] / o["mean"],
            "p95_user_axis": float(g.loc[g["variant"] == "user_axis", "p95_mm"].mean()),
            "p95_orthogonal": float(g.loc[g["variant"] == "orthogonal", "p95_mm"].mean()),
        }
    pin = tables["pinch"]
    pinch = {}
    for (kind, tgt, src), g in pin.groupby(["kind", "target", "source"]):
        pinch[f"{kind}/{tgt}/{src}"] = {
            "tip_distance_error_mm": _ms(g["tip_distance_error_mm"]),
            "tip_distance_bias_mm": _ms(g["tip_distance_bias_mm"]),
            "true_tip_distance_mm": _ms(g["true_tip_distance_mm"]),
            "pad_gap_mm": _ms(g["pad_gap_mm"]),
            "true_pad_gap_mm": _ms(g["true_pad_gap_mm"]),
        }
    geo = tables["thumb_geometry"]
    geometry = {
        j: {
            c: _ms(g[c])
            for c in (
                "axis_offset_mm",
                "true_axis_offset_mm",
                "axes_angle_deg",
                "true_axes_angle_deg",
            )
        }
        for j, g in geo.groupby("joint")
    }
    test = tips["thumb/test.csv"]
    tip_pinch = pinch.get("tip_pinch/index/user_axis", {}).get("tip_distance_error_mm", {})
    targets = {
        "thumb tip error <= 1.5 mm mean (test.csv)": test["user_axis"]["mean"] <= 1.5,
        "thumb tip error <= 0.6 x orthogonal (test.csv)": test["ratio"] <= 0.6,
        "thumb-index tip-pinch distance error <= 2 mm mean": (tip_pinch.get("mean") or np.inf)
        <= 2.0,
    }
    return {"axes": axes, "tips": tips, "pinch": pinch, "geometry": geometry, "targets": targets}


def floor(sims: list[SimulatedSubject]) -> dict:
    """The true model (true axes, centres, migration and sensor mountings; swing-twist
    angles) driven by the same noisy sensors: the thumb tip error on ``test.csv`` and the
    tip-pinch distance error no estimator can beat on these data."""
    tips, pinch = [], []
    for sim in sims:
        model = truth_model(sim)
        truth = load_truth(sim.session.path)
        kin = compute_kinematics(model, sim.session.recording("test.csv"), fingers=["thumb"])
        e = np.linalg.norm(
            kin.motions["user_axis"]["thumb"].tip - truth.tips["test.csv"]["thumb"], axis=1
        )
        tips.append(float(np.nanmean(e)))
        p = evaluate_pinches(model, sim.session, truth)
        p = p[(p["kind"] == "tip_pinch") & (p["source"] == "user_axis")]
        pinch += list(p["tip_distance_error_mm"])
    return {
        "thumb_tip_test_mm": _ms(pd.Series(tips)),
        "tip_pinch_distance_error_mm": _ms(pd.Series(pinch)),
    }


def _f(d: dict | None, k: str = "mean") -> str:
    v = None if d is None else d.get(k)
    return "–" if v is None else f"{v:.2f}"


def markdown(res: dict, meta: dict) -> str:
    """The tables for docs/accuracy.md."""
    lines = [
        f"Run {meta['date']}, {meta['subjects']} subjects, {meta['seconds']:.0f} s "
        f"(fingerfit {meta['version']}).",
        "",
        "| thumb axis | axis error mean (p95) deg | centre to true axis mean (p95) mm | n |",
        "|---|---|---|---|",
    ]
    for j, v in res["axes"].items():
        a, c = v["axis_error_deg"], v["centre_to_axis_mm"]
        lines.append(f"| {j} | {_f(a)} ({_f(a, 'p95')}) | {_f(c)} ({_f(c, 'p95')}) | {a['n']} |")
    lines += [
        "",
        "| tip error vs truth | user-axis mean (SD) mm | orthogonal mean (SD) mm | ratio |",
        "|---|---|---|---|",
    ]
    for k, v in res["tips"].items():
        u, o = v["user_axis"], v["orthogonal"]
        lines.append(
            f"| {k} | {_f(u)} ({_f(u, 'sd')}) | {_f(o)} ({_f(o, 'sd')}) | {v['ratio']:.2f} |"
        )
    lines += [
        "",
        "| pinch / source | events | tip-distance error mean (SD) mm | bias mm "
        "| pad gap mm | true pad gap mm |",
        "|---|---|---|---|---|---|",
    ]
    for k, v in res["pinch"].items():
        e = v["tip_distance_error_mm"]
        lines.append(
            f"| {k} | {e['n']} | {_f(e)} ({_f(e, 'sd')}) | {_f(v['tip_distance_bias_mm'])} "
            f"| {_f(v['pad_gap_mm'])} | {_f(v['true_pad_gap_mm'])} |"
        )
    lines += [
        "",
        "| two-axis joint | offset mm (true) | angle between axes deg (true) |",
        "|---|---|---|",
    ]
    for j, v in res["geometry"].items():
        lines.append(
            f"| {j} | {_f(v['axis_offset_mm'])} ({_f(v['true_axis_offset_mm'])}) "
            f"| {_f(v['axes_angle_deg'])} ({_f(v['true_axes_angle_deg'])}) |"
        )
    fl = res["floor"]
    lines += [
        "",
        f"True model driven by the same sensors (floor): thumb tip on test.csv "
        f"{_f(fl['thumb_tip_test_mm'])} ({_f(fl['thumb_tip_test_mm'], 'sd')}) mm; "
        f"tip-pinch distance error {_f(fl['tip_pinch_distance_error_mm'])} "
        f"({_f(fl['tip_pinch_distance_error_mm'], 'sd')}) mm.",
    ]
    lines += ["", "| target | met |", "|---|---|"]
    lines += [f"| {k} | {'yes' if ok else 'no'} |" for k, ok in res["targets"].items()]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=8)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--keep", type=Path, default=None, help="folder for sessions and the study")
    ap.add_argument("--world", choices=("default", "myohand"), default="default")
    ap.add_argument(
        "--sta", type=float, default=1.0, help="soft-tissue artefact scale (SimConfig.sta)"
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.world == "myohand":
        config = SimConfig(fingers=("thumb", "index"), world="myohand", hand="right", sta=args.sta)
    else:
        config = SimConfig(fingers=("thumb", "index"), sta=args.sta)
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        sims = simulate_cohort(config, args.subjects, SEED)
        sessions = [write_subject(sim, root / sim.session.subject) for sim in sims]
        study = run_study(sessions, root / "study", jobs=args.jobs, overwrite=True)
        res = figures(study.tables)
        res["floor"] = floor(sims)
    meta = {
        "date": datetime.date.today().isoformat(),
        "subjects": args.subjects,
        "seconds": time.perf_counter() - t0,
        "version": __version__,
        "python": platform.python_version(),
        "command": "python bench/thumb_accuracy.py "
        f"--subjects {args.subjects} --json {args.json or '-'}"
        + (f" --world {args.world}" if args.world != "default" else "")
        + (f" --sta {args.sta:g}" if args.sta != 1.0 else ""),
    }
    print(markdown(res, meta))
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, **res}, indent=1, default=bool) + "\n")


if __name__ == "__main__":
    main()
