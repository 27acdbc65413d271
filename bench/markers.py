"""Marker benchmark: the individual model from skin markers against the simulator's truth.

Run with ``python bench/markers.py --json bench/markers.json``.

For every condition of ``bench/accuracy.py`` chosen (``--conditions``) and every marker
layout (``--layouts``), ``--subjects`` simulated subjects (index finger, the paper's
protocol) get skin markers (:func:`fingerfit.simulate.markers.simulate_markers`, 0.3 mm
camera noise, skin sliding with the joint below) and are fitted by the marker bundle
adjustment from its data-driven start (:func:`fingerfit.estimate.markers.fit.
fit_marker_session`). Scored against the truth:

* **axis error** (deg) of the MP, PIP and DIP flexion axes (tracker coordinates at the
  reference posture);
* **covered**: whether the true axis lies within the fit's 95 % region of its direction
  (``x^T C^-1 x <= 5.99``, ``C`` the covariance of :func:`~fingerfit.estimate.markers.
  bundle.line_covariance`);
* **tip error** (mm): the fingertip over the free-motion test recording, angles from the
  markers (:func:`~fingerfit.estimate.markers.angles.marker_angles`), against the 6-DOF
  fit of the same simulated motion (``fingerfit fit``'s default, the same subject's
  sensors, ``bench/accuracy.py``'s fingertip error): the ratio of the means;
* **floor**: the same bundle adjustment started from the true parameters (lines in the
  fit's chain, marker places and slides, every frame's angles) on the same markers.

``--speed`` adds the time of a marker fit of 10,000 grasp frames of one finger and of the
four fingers (:func:`speed`); ``--speed-only`` times them alone (``--json bench/markers_speed.json``), with
the machine's load average before and after each.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CONDITIONS, tip_errors

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.markers.angles import marker_angles
from fingerfit.estimate.markers.bundle import adjust, line_covariance
from fingerfit.estimate.markers.chain import Lines
from fingerfit.estimate.markers.fit import (
    CHI2_95,
    DigitFit,
    fit_marker_session,
)
from fingerfit.simulate.markers import simulate_markers
from fingerfit.simulate.study import SimConfig, simulate_cohort
from fingerfit.simulate.truthmodel import truth_model
from fingerfit.transforms import orthonormal_basis

#: The axes scored per digit benchmarked (``--digit``): a finger's flexion axes; the
#: thumb's, and its CMC's ab/adduction axis (always fitted).
AXES = {"index": ("mp", "pip", "dip"), "thumb": ("cmc", "cmc_abduction", "mcp", "ip")}
#: Issue targets (Todorov's layout, a finger); the thumb has none.
TARGETS_DEG = {"mp": 6.0, "pip": 1.5, "dip": 5.0}
TIP_RATIO_TARGET = 2.0
DEFAULT_CONDITIONS = "realistic,MyoHand world,MP ab/adduction off"


def _axis_errors(fit: DigitFit, lines, truth) -> dict:
    """Per scored axis (:data:`AXES`): angle to the true axis (deg; sign ignored for an
    ab/adduction axis) and whether the truth is inside the 95 % region of the fit's
    direction."""
    out = {}
    for name in AXES[fit.digit]:
        level = fit.layout.names.index(name)
        a = lines.axis[level]
        t = truth.axis(fit.digit, name).axis
        if level not in fit.layout.first:
            t = t * np.sign(a @ t)
        err = float(np.degrees(np.arccos(np.clip(a @ t, -1.0, 1.0))))
        b = orthonormal_basis(a)[:2]
        x = b @ t
        c = fit.covariance[level, :2, :2]
        covered = bool(np.all(np.isfinite(c)) and x @ np.linalg.solve(c, x) <= CHI2_95)
        ci = fit.axis_ci_deg(level) if np.all(np.isfinite(c)) else float("nan")
        out[name] = {"axis_deg": err, "covered": covered, "ci_deg": ci}
    return out


def _floor(fit: DigitFit, sim, ms) -> dict:
    """The adjustment started from the true parameters, in the fit's chain (a second axis
    the truth lacks: the fit's own, its angles 0; MyoHand's flexion-first MP in the fit's
    ab/adduction-first order)."""
    truth = truth_model(sim)
    layout = fit.layout
    axis, centre = [], []
    for k, n in enumerate(layout.names):
        try:
            jm = truth.axis(fit.digit, n)
            axis.append(jm.axis)
            centre.append(jm.center)
        except KeyError:
            axis.append(fit.result.lines.axis[k])
            centre.append(fit.result.lines.centre[k])
    lines = Lines(np.array(axis), np.array(centre))
    u = np.array([ms.markers.position[k] for k in fit.data.labels])
    frames = [sim.truth.frames[r.name]["angles"][fit.digit] for r in sim.session.grasp]
    q = np.stack(
        [
            np.concatenate([f.get(n, np.zeros_like(f[layout.names[0]])) for f in frames])
            for n in layout.names
        ]
    )
    slide = None
    if fit.result.slide is not None:  # the true slides where the fit estimates them
        slide = np.array([ms.markers.slide[k] for k in fit.data.labels])
        slide[~fit.result.free[-slide.size :].reshape(slide.shape)] = 0.0
    result = adjust(fit.data, layout.structure, lines, u, q, slide=slide, free=fit.result.free)
    floor = DigitFit(fit.digit, layout, fit.data, result, line_covariance(result))
    return _axis_errors(floor, result.lines, truth)


def run_subject(
    cond: str,
    layout: str,
    sim,
    sixdof_tip: float,
    seed: int,
    slide: bool = False,
    slide_law: str = "linear",
    name: str = "index",
) -> dict:
    """One subject in one layout: the fit of digit ``name``, its errors, the floor, the
    tip ratio."""
    ms = simulate_markers(sim, layout, seed=seed, slide_law=slide_law)
    t0 = time.perf_counter()
    fit = fit_marker_session(replace(ms.session, fingers=[name]), slide=slide)
    seconds = time.perf_counter() - t0
    digit = fit.digits[name]
    truth = truth_model(sim)
    test = ms.session.test[0]
    tip = marker_angles(fit.model, test)[name].tip
    true_tip = sim.truth.frames[sim.session.test[0].name]["tip"][name]
    tip_err = float(np.nanmean(np.linalg.norm(tip - true_tip, axis=1)))
    return {
        "condition": cond,
        "layout": layout,
        "subject": sim.session.subject,
        "seconds": seconds,
        "frames": int(digit.data.frames),
        "mp_axes": 2 if digit.layout.choice in digit.layout.second else 1,
        "mp_order": digit.layout.order,
        "slide_sd": None if digit.slide_sd is None else [float(x) for x in digit.slide_sd],
        "rms_mm": digit.result.rms_mm,
        "notes": fit.notes,
        "fit": _axis_errors(digit, digit.result.lines, truth),
        "floor": _floor(digit, sim, ms),
        "tip_mm": tip_err,
        "sixdof_tip_mm": sixdof_tip,
        "tip_ratio": tip_err / sixdof_tip,
    }


def summarise(rows: list[dict], name: str = "index") -> dict:
    """Per condition and layout: mean and largest axis errors, coverage, tip ratio (digit
    ``name``'s axes, :data:`AXES`)."""
    out: dict = {}
    for r in rows:
        out.setdefault(r["condition"], {}).setdefault(r["layout"], []).append(r)
    summary: dict = {}
    for cond, layouts in out.items():
        for layout, vals in layouts.items():
            s = {
                "subjects": len(vals),
                "seconds_mean": float(np.mean([v["seconds"] for v in vals])),
            }
            for j in AXES[name]:
                fit = [v["fit"][j]["axis_deg"] for v in vals]
                floor = [v["floor"][j]["axis_deg"] for v in vals]
                s[j] = {
                    "axis_deg_mean": float(np.mean(fit)),
                    "axis_deg_max": float(np.max(fit)),
                    "floor_deg_mean": float(np.mean(floor)),
                    "floor_deg_max": float(np.max(floor)),
                    "covered": float(np.mean([v["fit"][j]["covered"] for v in vals])),
                    "ci_deg_mean": float(np.nanmean([v["fit"][j]["ci_deg"] for v in vals])),
                    "target_deg": TARGETS_DEG.get(j) if name != "thumb" else None,
                    "met": bool(np.max(fit) <= TARGETS_DEG[j]) if name != "thumb" else None,
                }
            s["tip_mm_mean"] = float(np.mean([v["tip_mm"] for v in vals]))
            s["sixdof_tip_mm_mean"] = float(np.mean([v["sixdof_tip_mm"] for v in vals]))
            s["tip_ratio"] = s["tip_mm_mean"] / s["sixdof_tip_mm_mean"]
            s["tip_ratio_met"] = s["tip_ratio"] <= TIP_RATIO_TARGET
            summary[f"{cond} / {layout}"] = s
    return summary


def _session_of(fingers: tuple[str, ...], frames: int):
    """A simulated subject whose grasp recordings have about ``frames`` frames: the
    fingers' at 240 Hz, ``frames / 500`` grasp cycles; with the thumb, whose own
    recordings (circumduction, opposition, pinches) are 13 thousand frames at 240 Hz,
    at 100 Hz (the rate of the issue's session command) and as many grasp cycles as
    bring the total to ``frames`` (the frames grow by the same count per cycle)."""

    def sim_of(cycles: int, rate: float):
        config = SimConfig(fingers=fingers, cycles=cycles, targets=False, test=False, rate_hz=rate)
        return simulate_cohort(config, 1, 5)[0]

    def count(sim) -> int:
        return sum(r.n_frames for r in sim.session.grasp)

    if "thumb" not in fingers:
        return sim_of(int(np.ceil(frames / 500)), 240.0)
    one, ten = count(sim_of(1, 100.0)), count(sim_of(10, 100.0))
    return sim_of(max(1, round(1 + 9 * (frames - one) / (ten - one))), 100.0)


def speed(frames: int = 10_000) -> dict:
    """Seconds of a marker fit of ``frames`` grasp frames: one finger with all its frames
    in one block (:data:`~fingerfit.estimate.markers.chain.BLOCK_FRAMES`, the solver
    before the blocks), by blocks, and by blocks in two threads (``fingerfit fit --jobs
    2`` of one finger); four fingers in one process, and with ``--jobs 2`` (two worker
    processes; CPU seconds of this process only); the whole hand with ``--jobs 2``
    (:func:`_session_of`)."""
    from fingerfit.estimate.markers import chain
    from fingerfit.evaluate.study import study_executor

    out = {}
    four = ("index", "middle", "ring", "little")
    block = chain.BLOCK_FRAMES
    for label, fingers, jobs, blocks in (
        ("one finger, one block", ("index",), 1, False),
        ("one finger", ("index",), 1, True),
        ("one finger, --jobs 2 (2 threads)", ("index",), 2, True),
        ("four fingers", four, 1, True),
        ("four fingers, --jobs 2 (2 worker processes)", four, 2, True),
        ("whole hand, --jobs 2 (2 worker processes)", ("thumb", *four), 2, True),
    ):
        chain.BLOCK_FRAMES = block if blocks else 10**9
        sim = _session_of(fingers, frames)
        ms = simulate_markers(sim, "todorov", seed=1)
        n = sum(r.n_frames for r in ms.session.grasp)
        workers = min(jobs, len(fingers))  # as fingerfit fit --jobs
        load = os.getloadavg()[0]
        t0, c0 = time.perf_counter(), time.process_time()
        with study_executor(workers) as pool:
            fit_marker_session(ms.session, executor=pool, threads=max(1, jobs // workers))
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        out[label] = {
            "frames": n,
            "seconds": seconds,
            "cpu_seconds": cpu,
            "load_average_1min": [load, os.getloadavg()[0]],
        }
        print(
            f"speed {label}: {n} frames, {seconds:.1f} s ({cpu:.1f} s CPU; load average "
            f"{load:.1f} before, {os.getloadavg()[0]:.1f} after)",
            flush=True,
        )
    chain.BLOCK_FRAMES = block
    one = out["one finger, one block"]["seconds"]
    print(f"speed: blocks {one / out['one finger']['seconds']:.2f}x faster on one finger")
    print(
        f"speed: blocks in 2 threads {one / out['one finger, --jobs 2 (2 threads)']['seconds']:.2f}x"
    )
    four_one = out["four fingers"]["seconds"]
    four_two = out["four fingers, --jobs 2 (2 worker processes)"]["seconds"]
    print(
        f"speed: 2 worker processes {four_one / four_two:.2f}x faster on four fingers", flush=True
    )
    whole = out["whole hand, --jobs 2 (2 worker processes)"]
    print(f"speed: the whole hand, --jobs 2: {whole['seconds']:.1f} s", flush=True)
    return out


def markdown(summary: dict, name: str = "index") -> str:
    """The summary as the table of ``docs/markers.md``."""
    axes = AXES[name]
    up = " / ".join(a.upper().replace("_ABDUCTION", " ab") for a in axes)
    lines = [
        f"| condition / layout | {axes[0].upper()} deg mean (max) | "
        + " | ".join(a.upper().replace("_ABDUCTION", " ab") for a in axes[1:])
        + f" | floor {up} | truth in 95 % region {up} | 95 % half-angle {up} "
        "| tip mm (6-DOF) | ratio |",
        "|---|" + "---|" * (len(axes) + 5),
    ]
    for key, s in summary.items():
        n = s["subjects"]
        cells = [f"{s[j]['axis_deg_mean']:.1f} ({s[j]['axis_deg_max']:.1f})" for j in axes]
        floor = " / ".join(f"{s[j]['floor_deg_mean']:.1f}" for j in axes)
        covered = " / ".join(f"{round(s[j]['covered'] * n)}" for j in axes) + f" of {n}"
        ci = " / ".join(f"{s[j].get('ci_deg_mean', float('nan')):.1f}" for j in axes)
        tip = f"{s['tip_mm_mean']:.2f} ({s['sixdof_tip_mm_mean']:.2f})"
        lines.append(
            f"| {key} | {' | '.join(cells)} | {floor} | {covered} | {ci} | {tip} "
            f"| {s['tip_ratio']:.2f}x |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--subjects", type=int, default=3)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--conditions", default=DEFAULT_CONDITIONS)
    parser.add_argument("--layouts", default="todorov,phalanx")
    parser.add_argument(
        "--digit",
        default="index",
        choices=tuple(AXES),
        help="the digit fitted and scored (the thumb's subjects have the index finger too)",
    )
    parser.add_argument("--speed", action="store_true")
    parser.add_argument("--speed-only", action="store_true", help="time the fits alone")
    parser.add_argument("--slide", action="store_true", help="estimate the markers' slide")
    parser.add_argument(
        "--slide-law",
        default="linear",
        choices=("linear", "coupled"),
        help="how the simulated skin slides (simulate_markers)",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    conditions = args.conditions.split(",")
    for c in conditions:
        if c not in CONDITIONS:
            parser.error(f"unknown condition {c!r}; one of {', '.join(CONDITIONS)}")
    if args.speed_only:
        doc = {"command": "python bench/markers.py " + " ".join(sys.argv[1:]), "speed": speed()}
        if args.json:
            args.json.write_text(json.dumps(doc, indent=1) + "\n")
        return
    rows = []
    t0 = time.perf_counter()
    for cond in conditions:
        fingers = ("index",) if args.digit == "index" else ("index", args.digit)
        config = SimConfig(**{"fingers": fingers, **CONDITIONS[cond]})
        for sim in simulate_cohort(config, args.subjects, args.seed):
            model = fit_session(sim.session, FitOptions())
            sixdof = float(np.nanmean(tip_errors(sim, model, digit=args.digit)))
            for k, layout in enumerate(args.layouts.split(",")):
                r = run_subject(
                    cond,
                    layout,
                    sim,
                    sixdof,
                    seed=k + 1,
                    slide=args.slide,
                    slide_law=args.slide_law,
                    name=args.digit,
                )
                rows.append(r)
                print(
                    f"{cond} / {layout} {r['subject']}: axis deg "
                    + " ".join(f"{j} {r['fit'][j]['axis_deg']:.2f}" for j in AXES[args.digit])
                    + "; floor "
                    + " ".join(f"{j} {r['floor'][j]['axis_deg']:.2f}" for j in AXES[args.digit])
                    + f"; tip {r['tip_mm']:.2f} mm vs 6-DOF {sixdof:.2f} ({r['seconds']:.0f} s)",
                    flush=True,
                )
    doc = {
        "command": "python bench/markers.py " + " ".join(sys.argv[1:]),
        "subjects": args.subjects,
        "seconds": time.perf_counter() - t0,
        "digit": args.digit,
        "summary": summarise(rows, args.digit),
        "rows": rows,
    }
    if args.speed:
        doc["speed"] = speed()
    print(json.dumps(doc["summary"], indent=1))
    print(markdown(doc["summary"], args.digit))
    if args.json:
        args.json.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
