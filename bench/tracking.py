"""Tracking benchmark: joint angles and fingertips from fewer sensors, against the truth.

Run with ``.venv/bin/python bench/tracking.py --json bench/tracking.json`` (``--subjects``,
``--conditions``, ``--workers``; ``--variants`` to compare the cost's switches).

For every condition (a :class:`~fingerfit.simulate.SimConfig` of the whole hand: the thumb
and four fingers) ``--subjects`` simulated subjects are fitted (the default method, on
their own calibration recordings), then the free-motion test recording -- which no fit
sees -- is tracked under each sensor layout:

* ``full``: every sensor (the direct computation);
* ``no middle``: each digit's middle sensor absent (the fingers' middle phalanx, the
  thumb's proximal phalanx);
* ``distal only``: the hand and each digit's distal sensor (6 sensors for the hand);
* ``dropout <segment>``: that sensor of every digit missing for 20 % of the frames, in
  bursts of 0.1-2 s (independent per digit).

Per layout, side by side in one run on the same subjects: the fitted model (fingerfit's
tracking, :func:`fingerfit.track.track_recording`) and the floor -- the true model
(:func:`fingerfit.simulate.truthmodel.truth_model`, its calibration statistics measured the
same way) driven by the same reduced sensors through the same solver. Figures:

* **tip** (mm): model fingertip vs true fingertip, mean over frames then subjects (the four
  fingers and the thumb pooled), and ``x full``: over the full layout's;
* **angle vs truth** (deg): RMS over frames and subjects of each joint kind's angle minus
  the true one (fingers: MP, MP ab/adduction, PIP, DIP; thumb: CMC, CMC ab/adduction, MCP,
  IP), and ``x floor``;
* **angle vs full** (deg): RMS of each angle minus the full layout's angle of the same
  model and frame;
* frames with a tip (every frame should have one), and the solve time.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import json
import platform
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pool import run_tasks

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.truthmodel import truth_model
from fingerfit.track import TrackOptions, track_recording, tracking_statistics

DIGITS = ("thumb", "index", "middle", "ring", "little")
CONDITIONS: dict[str, dict] = {
    "realistic": {},
    "MyoHand world": {"world": "myohand", "hand": "right"},
    "STA 2x": {"sta": 2.0},
    "MP ab/adduction coupled": {
        "abduction_coupling": (-0.065, 0.02),
        "abduction_wander_deg": 0.3,
        "abduction_wander_hz": 0.08,
    },
    "noise 2x": {"noise": 2.0},
}
#: Joint kinds reported: (label, digits, angle names).
KINDS = [
    ("MP", "fingers", ("mp",)),
    ("MP ab", "fingers", ("mp_abduction",)),
    ("PIP", "fingers", ("pip",)),
    ("DIP", "fingers", ("dip",)),
    ("CMC", "thumb", ("cmc",)),
    ("CMC ab", "thumb", ("cmc_abduction",)),
    ("MCP", "thumb", ("mcp",)),
    ("IP", "thumb", ("ip",)),
]
#: The cost's switches compared with ``--variants`` (label -> TrackOptions).
OPTION_VARIANTS = {
    "default": TrackOptions(),
    "no temporal prior": TrackOptions(temporal=False),
    "no bounds": TrackOptions(bounds=False),
    "neither": TrackOptions(temporal=False, bounds=False),
    "bounds 0.25": TrackOptions(bound_fraction=0.25),
}
DROPOUT_FRACTION = 0.2
BURST_S = (0.1, 2.0)


def segment_sensor(digit: str, which: str) -> str:
    """The digit's sensor of ``which`` (``proximal``, ``middle``, ``distal``): the thumb's
    middle segment is its proximal phalanx, its proximal its metacarpal."""
    if digit == "thumb":
        which = {"proximal": "metacarpal", "middle": "proximal"}.get(which, which)
    return f"{digit}.{which}"


def dropout_mask(rng: np.random.Generator, n: int, rate: float) -> np.ndarray:
    """Bursts of 0.1-2 s covering about :data:`DROPOUT_FRACTION` of ``n`` frames."""
    mask = np.zeros(n, dtype=bool)
    target = DROPOUT_FRACTION * n
    while mask.sum() < target:
        length = int(rng.uniform(*BURST_S) * rate)
        start = int(rng.integers(0, max(1, n - length)))
        mask[start : start + length] = True
    return mask


def layouts(rec: Recording, rate: float, rng: np.random.Generator) -> dict[str, Recording]:
    """The test recording under each layout."""
    out = {"full": rec}
    for name, drop in (("no middle", "middle"), ("distal only", None)):
        if drop is None:
            keep = {"hand", *(segment_sensor(d, "distal") for d in DIGITS)}
        else:
            keep = set(rec.poses) - {segment_sensor(d, drop) for d in DIGITS}
        out[name] = Recording(rec.name, rec.time, {k: v for k, v in rec.poses.items() if k in keep})
    for seg in ("proximal", "middle", "distal"):
        poses = dict(rec.poses)
        for d in DIGITS:
            s = segment_sensor(d, seg)
            mask = dropout_mask(rng, rec.n_frames, rate)
            p = poses[s].position.copy()
            r = poses[s].rotation.copy()
            p[mask], r[mask] = np.nan, np.nan
            poses[s] = PoseSeries(p, r)
        out[f"dropout {seg}"] = Recording(rec.name, rec.time, poses)
    return out


def angle_errors(kin, reference: dict, variant: str = "user_axis") -> dict[str, np.ndarray]:
    """Per joint kind, the angle minus ``reference`` (digit -> name -> (n,) rad), deg."""
    out = {}
    for label, which, names in KINDS:
        digits = ["thumb"] if which == "thumb" else [d for d in DIGITS if d != "thumb"]
        parts = []
        for d in digits:
            for k in names:
                a = kin.motions[variant][d].angles.get(k)
                b = reference.get(d, {}).get(k)
                if a is not None and b is not None:
                    parts.append(np.degrees(a - b))
        if parts:
            out[label] = np.concatenate(parts)
    return out


def tip_error(kin, truth_tips: dict) -> tuple[float, int]:
    """Mean tip error over the digits' frames (mm) and frames without a tip."""
    errs, missing = [], 0
    for d in DIGITS:
        tip = kin.motions["user_axis"][d].tip
        e = np.linalg.norm(tip - truth_tips[d], axis=1)
        missing += int(np.count_nonzero(~np.isfinite(e)))
        errs.append(e[np.isfinite(e)])
    return float(np.concatenate(errs).mean()), missing


def run_subject(task: tuple[str, dict, int, tuple[str, ...]]) -> dict:
    """Every layout for one simulated subject of one condition."""
    cond, overrides, seed, variants = task
    warnings.simplefilter("ignore")
    config = SimConfig(fingers=DIGITS, **overrides)
    sim = simulate_subject(config, seed)
    out: dict = {"condition": cond, "seed": seed, "rows": {}}
    try:
        model = fit_session(sim.session, FitOptions(force=True))
    except FingerfitError as exc:
        out["failure"] = str(exc)
        return out
    true = truth_model(sim)
    true = replace(true, tracking=tracking_statistics(true, sim.session.grasp))
    rec = sim.session.test[0]
    truth = sim.truth.frames[rec.name]
    rng = np.random.default_rng(seed + 1)
    full_kin = {}
    for layout, r in layouts(rec, sim.session.rate_hz, rng).items():
        for who, m in (("fitted", model), ("floor", true)):
            for label in variants if who == "fitted" else ("default",):
                t0 = time.perf_counter()
                tracked = track_recording(
                    m, r, variants=("user_axis",), options=OPTION_VARIANTS[label]
                )
                seconds = time.perf_counter() - t0
                kin = tracked.kinematics
                if layout == "full":
                    full_kin[who] = kin
                tip, missing = tip_error(kin, truth["tip"])
                vs_truth = angle_errors(kin, truth["angles"])
                vs_full = angle_errors(
                    kin, {d: full_kin[who].motions["user_axis"][d].angles for d in DIGITS}
                )
                key = f"{layout} | {who}" + ("" if label == "default" else f" | {label}")
                out["rows"][key] = {
                    "tip_mm": tip,
                    "missing_tips": missing,
                    "seconds": seconds,
                    "frames": r.n_frames,
                    "truth_sq": {k: float(np.nanmean(v**2)) for k, v in vs_truth.items()},
                    "full_sq": {k: float(np.nanmean(v**2)) for k, v in vs_full.items()},
                }
    return out


def summarise(results: list[dict]) -> dict:
    """Per condition and row: means over subjects (tips) and RMS (angles)."""
    summary: dict = {}
    for cond in dict.fromkeys(r["condition"] for r in results):
        subj = [r for r in results if r["condition"] == cond and "failure" not in r]
        rows: dict = {}
        for key in subj[0]["rows"] if subj else []:
            vals = [s["rows"][key] for s in subj]
            kinds = vals[0]["truth_sq"].keys()
            rows[key] = {
                "subjects": len(vals),
                "tip_mm": float(np.mean([v["tip_mm"] for v in vals])),
                "missing_tips": int(sum(v["missing_tips"] for v in vals)),
                "seconds_per_frame_us": float(
                    1e6 * np.sum([v["seconds"] for v in vals]) / np.sum([v["frames"] for v in vals])
                ),
                "vs_truth_deg": {
                    k: float(np.sqrt(np.mean([v["truth_sq"][k] for v in vals]))) for k in kinds
                },
                "vs_full_deg": {
                    k: float(np.sqrt(np.mean([v["full_sq"][k] for v in vals]))) for k in kinds
                },
            }
        for key, r in rows.items():
            layout = key.split(" | ")[0]
            full = rows.get(f"full | {key.split(' | ')[1]}")
            floor = rows.get(f"{layout} | floor")
            r["tip_over_full"] = r["tip_mm"] / full["tip_mm"] if full else None
            if floor:
                r["vs_truth_over_floor"] = {
                    k: r["vs_truth_deg"][k] / floor["vs_truth_deg"][k]
                    for k in r["vs_truth_deg"]
                    if floor["vs_truth_deg"].get(k)
                }
        summary[cond] = {
            "rows": rows,
            "failures": [
                r["failure"] for r in results if r["condition"] == cond and "failure" in r
            ],
        }
    return summary


def targets(summary: dict) -> list[tuple[str, bool, str]]:
    """The issue's targets, per condition."""
    out = []

    def each(name: str, check) -> None:
        bad = []
        for cond, s in summary.items():
            rows = s["rows"]
            if not rows:
                continue
            ok, value = check(rows)
            if not ok:
                bad.append(f"{cond} ({value})")
        out.append((name, not bad, "; ".join(bad) or "all conditions"))

    each(
        "no middle: tip <= 1.10 x full",
        lambda r: (
            r["no middle | fitted"]["tip_over_full"] <= 1.10,
            f"{r['no middle | fitted']['tip_over_full']:.2f}x",
        ),
    )
    each(
        "no middle: PIP, DIP within 2.0 deg RMS of full",
        lambda r: (
            max(r["no middle | fitted"]["vs_full_deg"][k] for k in ("PIP", "DIP")) <= 2.0,
            ", ".join(
                f"{k} {r['no middle | fitted']['vs_full_deg'][k]:.2f}" for k in ("PIP", "DIP")
            ),
        ),
    )
    each(
        "distal only: tip <= 1.20 x full",
        lambda r: (
            r["distal only | fitted"]["tip_over_full"] <= 1.20,
            f"{r['distal only | fitted']['tip_over_full']:.2f}x",
        ),
    )
    limits = {"MP": 4.0, "PIP": 9.0, "DIP": 7.0}
    each(
        "distal only: MP <= 4, PIP <= 9, DIP <= 7 deg RMS of full",
        lambda r: (
            all(r["distal only | fitted"]["vs_full_deg"][k] <= v for k, v in limits.items()),
            ", ".join(f"{k} {r['distal only | fitted']['vs_full_deg'][k]:.2f}" for k in limits),
        ),
    )
    for seg in ("proximal", "middle", "distal"):
        key = f"dropout {seg} | fitted"
        each(
            f"dropout {seg}: every frame a tip, tip <= 1.10 x full",
            lambda r, key=key: (
                r[key]["missing_tips"] == 0 and r[key]["tip_over_full"] <= 1.10,
                f"{r[key]['tip_over_full']:.2f}x, {r[key]['missing_tips']} without a tip",
            ),
        )

    def floor_check(rows: dict) -> tuple[bool, str]:
        worst = []
        for key, r in rows.items():
            if not key.endswith("| fitted") or key.startswith("full"):
                continue
            for k, x in r.get("vs_truth_over_floor", {}).items():
                if x > 1.25:
                    worst.append(f"{key.split(' | ')[0]} {k} {x:.2f}x")
        return not worst, ", ".join(worst)

    each("every layout and joint: error vs truth <= 1.25 x floor", floor_check)
    return out


def markdown(summary: dict, meta: dict) -> str:
    lines = [
        f"Run {meta['date']}: `{meta['command']}` ({meta['subjects']} subjects per condition, "
        f"whole hand, {meta['seconds']:.0f} s on {meta['workers']} worker(s)).",
        "",
        "| condition | layout | model | tip mm | x full | "
        + " | ".join(f"{k} vs truth" for k, _, _ in KINDS)
        + " | "
        + " | ".join(f"{k} vs full" for k, _, _ in KINDS)
        + " | no tip | us/frame |",
        "|---|---|---|---|---|" + "---|" * (2 * len(KINDS)) + "---|---|",
    ]
    for cond, s in summary.items():
        for key, r in s["rows"].items():
            parts = key.split(" | ")
            layout, who = parts[0], " | ".join(parts[1:])
            truth = " | ".join(
                f"{r['vs_truth_deg'].get(k, float('nan')):.2f}"
                + (
                    f" ({r['vs_truth_over_floor'][k]:.2f}x)"
                    if who != "floor" and k in r.get("vs_truth_over_floor", {})
                    else ""
                )
                for k, _, _ in KINDS
            )
            full = " | ".join(f"{r['vs_full_deg'].get(k, float('nan')):.2f}" for k, _, _ in KINDS)
            lines.append(
                f"| {cond} | {layout} | {who} | {r['tip_mm']:.2f} | {r['tip_over_full']:.2f} | "
                f"{truth} | {full} | {r['missing_tips']} | {r['seconds_per_frame_us']:.0f} |"
            )
        if s["failures"]:
            lines.append(f"| {cond} | fits refused: {len(s['failures'])} | | | |")
    lines += ["", "### Targets", "", "| target | met | value |", "|---|---|---|"]
    for name, ok, val in meta["targets"]:
        lines.append(f"| {name} | {'yes' if ok else '**no**'} | {val} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--subjects", type=int, default=8)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--seed", type=int, default=36)
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument(
        "--variants",
        default="default",
        help=f"comma-separated switches of the cost to compare: {', '.join(OPTION_VARIANTS)}",
    )
    args = ap.parse_args()
    chosen = [c.strip() for c in args.conditions.split(",")]
    variants = tuple(v.strip() for v in args.variants.split(","))
    for c in chosen:
        if c not in CONDITIONS:
            ap.error(f"unknown condition '{c}'")
    for v in variants:
        if v not in OPTION_VARIANTS:
            ap.error(f"unknown variant '{v}'")
    tasks = []
    for ci, cond in enumerate(chosen):
        seeds = np.random.SeedSequence([args.seed, ci]).spawn(args.subjects)
        tasks += [(cond, CONDITIONS[cond], int(s.generate_state(1)[0]), variants) for s in seeds]
    t0 = time.perf_counter()
    results = run_tasks(run_subject, tasks, args.workers)
    results.sort(key=lambda r: (chosen.index(r["condition"]), r["seed"]))
    summary = summarise(results)
    meta = {
        "date": datetime.date.today().isoformat(),
        "command": ("python bench/tracking.py " + " ".join(sys.argv[1:])).strip(),
        "subjects": args.subjects,
        "workers": args.workers,
        "seconds": time.perf_counter() - t0,
        "python": platform.python_version(),
        "numpy": np.__version__,
    }
    meta["targets"] = targets(summary)
    print(markdown(summary, meta))
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
