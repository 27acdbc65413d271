"""The lab's protocol from the device: stylus pivot, landmarks, pinch holds, against truth.

    python bench/lab.py [--subjects 6] [--styli 8] [--conditions realistic,...] [--json OUT]

**Pivot calibration** (``fingerfit.stylus.fit_pivot``): ``--styli`` simulated styli per
cone of 25, 30, 35 and 40 deg, 10 s at 240 Hz, with Liberty-like white noise (0.25 mm and
0.1 deg per axis): the tip offset's and the pivot's errors (mm), the uncertainty the fit
reports, and how many were refused; the same styli wiggled through 1 deg (all must be
refused). Then each simulated subject's own pivot recording, seen through its world's
tracker (white noise *and* the smooth field distortion of ``docs/simulator.md``).

**Landmarks** (``fingerfit.capture.landmarks.LandmarkTaker`` over the subject's
``stylus_landmarks.csv``, the still trigger, 3 takes): each landmark against the mean of
the placements the stylus truly rested on (what the simulator's ``landmarks.csv`` holds),
with the true tip offset and with the subject's own pivot calibration; the tip points'
error against the anatomical truth, one take against the mean of three.

**Models**: the subject fitted (``fit_session``) with the captured landmarks (the
calibrated stylus) against the same subject fitted with the simulator's
``landmarks.csv``: the largest difference of a joint axis (deg) and centre (mm), and of the
tips (mm).

**Pinch holds** (``fingerfit.capture.pinch.find_holds`` on the opposition and pinch
recordings, pads from the simulator's landmarks): the holds found against the simulator's
``events.csv``, and the pads fitted to them (``fit_session``: pads from the pinch holds)
against the pads fitted to the simulator's events (mm).

**Reference**: how many of the subjects' reference recordings the stillness check refuses
(none should be), and how many moving ones it takes (the first 1.5 s of each grasp: none
should be).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CONDITIONS
from revision import run_meta

from fingerfit.capture.landmarks import LandmarkTaker
from fingerfit.capture.pinch import find_holds, pad_points
from fingerfit.capture.reference import reference_motion
from fingerfit.errors import FingerfitError
from fingerfit.estimate import fit_session
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.stylus import Stylus, pivot_motion, white_noise
from fingerfit.stylus import StylusCalibration, fit_pivot
from fingerfit.transforms import angle_between_axes

DIGITS = ("thumb", "index")
#: ``bench/accuracy.py``'s conditions and one that takes the tracker's field distortion
#: away (what is left is white noise: the stylus's error without the field's).
WORLDS = {**CONDITIONS, "distortion off": {"distortion": False}}
HOLD_RECORDINGS = ("thumb_opposition.csv", "pinch.csv")


def pivot_study(n: int, seed: int) -> dict:
    """Simulated pivots with white noise (module docstring)."""
    rng = np.random.default_rng(seed)
    rows: dict[str, dict] = {}
    for cone in (25.0, 30.0, 35.0, 40.0, 1.0):
        tip, piv, ci, refused = [], [], [], 0
        for _ in range(n):
            stylus = Stylus.sample(rng)
            pivot = rng.normal(0.0, 150.0, 3)
            _, pos, rot = pivot_motion(rng, stylus, pivot, 240.0, cone_deg=cone)
            pos, rot = white_noise(rng, pos, rot, 0.25, 0.1)
            try:
                fit = fit_pivot(pos, rot)
            except FingerfitError:
                refused += 1
                continue
            tip.append(float(np.linalg.norm(fit.tip_offset_mm - stylus.tip_offset)))
            piv.append(float(np.linalg.norm(fit.pivot_mm - pivot)))
            ci.append(fit.tip_ci_mm)
        rows[f"cone {cone:g} deg"] = {
            "styli": n,
            "refused": refused,
            "tip_error_mm_max": max(tip, default=None),
            "tip_error_mm_mean": float(np.mean(tip)) if tip else None,
            "pivot_error_mm_max": max(piv, default=None),
            "tip_ci_mm_max": max(ci, default=None),
        }
    return rows


def _landmarks(sim, tip_offset) -> tuple[dict, dict, LandmarkTaker]:
    st = sim.stylus
    taker = LandmarkTaker(list(st.truth["order"]), StylusCalibration("stylus", tip_offset), 240.0)
    rec = st.landmarks
    for a in range(0, rec.n_frames, 24):  # blocks of 0.1 s, as a live source's
        taker.add(rec.slice(slice(a, a + 24)))
    means = {s: p.mean() for s, p in sim.session.reference.poses.items()}
    points, sds = taker.result(means)
    return points, sds, taker


def _anatomical(sim) -> dict[str, np.ndarray]:
    """The true (noise-free) landmarks of the digits: dorsal points, tips, pads."""
    t = sim.truth
    out = {f"{f}.{k}": v for f, a in t.fingers.items() for k, v in a.landmarks.items()}
    if t.thumb is not None:
        out |= {f"thumb.{k}": v for k, v in t.thumb.landmarks.items() if k != "pad"}
    out |= {f"{d}.pad": p.surface for d, p in t.pads.items()}
    return out


def _compare(a, b) -> dict:
    """Largest differences between two models: axes (deg), centres, tips, pads (mm)."""
    ax, ce, tip, pad = [], [], [], []
    for d, fa in a.fingers.items():
        fb = b.fingers[d]
        for j, ja in {**fa.joints, **{f"{k}_ab": v for k, v in fa.second_axes.items()}}.items():
            jb = fb.joints[j] if j in fb.joints else fb.second_axes[j.removesuffix("_ab")]
            ax.append(float(angle_between_axes(ja.axis, jb.axis)))
            ce.append(float(np.linalg.norm(ja.center - jb.center)))
        tip.append(float(np.linalg.norm(fa.tip - fb.tip)))
        if fa.pad is not None and fb.pad is not None:
            pad.append(float(np.linalg.norm(fa.pad - fb.pad)))
    return {
        "axis_deg_max": max(ax),
        "centre_mm_max": max(ce),
        "tip_mm_max": max(tip),
        "pad_mm_max": max(pad, default=None),
    }


def subject_study(condition: str, seed: int) -> dict:
    """One subject of one condition (module docstring)."""
    kw = dict(WORLDS[condition])
    sim = simulate_subject(SimConfig(fingers=DIGITS, stylus_recordings=True, **kw), seed)
    st, session = sim.stylus, sim.session
    true_tip = np.asarray(st.truth["tip_offset_mm"])
    out: dict = {}
    p = st.pivot.poses["stylus"]
    try:
        fit = fit_pivot(p.position, p.rotation)
    except FingerfitError:  # refused: the landmarks are taken with the true tip below
        fit = None
    out["pivot"] = {
        "refused": fit is None,
        "tip_error_mm": None
        if fit is None
        else float(np.linalg.norm(fit.tip_offset_mm - true_tip)),
        "pivot_error_mm": None
        if fit is None
        else float(np.linalg.norm(fit.pivot_mm - np.asarray(st.truth["pivot_mm"]))),
        "tip_ci_mm": None if fit is None else fit.tip_ci_mm,
        "rms_mm": None if fit is None else fit.rms_mm,
    }
    calibrated = true_tip if fit is None else fit.tip_offset_mm
    placed = session.landmarks  # the mean of the placements (simulate/stylus.py)
    anatomy = _anatomical(sim)
    for label, tip in (("true stylus", true_tip), ("calibrated stylus", calibrated)):
        points, sds, taker = _landmarks(sim, tip)
        err = [float(np.linalg.norm(points[k] - placed[k])) for k in points]
        out[f"landmarks, {label}"] = {
            "taken": len(points),
            "wanted": len(st.truth["order"]),
            "error_mm_mean": float(np.mean(err)),
            "error_mm_max": float(np.max(err)),
        }
        if label == "calibrated stylus":
            captured, captured_sd, done = points, sds, taker.done
    # One take against three, at the tips, against the anatomy.
    means = {s: p.mean() for s, p in session.reference.poses.items()}
    one, three = [], []
    for lm in done:
        if lm.name.endswith(".tip"):
            pos, rot = means[lm.segment]
            one.append(float(np.linalg.norm(rot @ lm.takes[0] + pos - anatomy[lm.name])))
            three.append(float(np.linalg.norm(lm.at_reference(means) - anatomy[lm.name])))
    out["tips vs anatomy"] = {"one_take_mm": one, "three_takes_mm": three}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base = fit_session(session)
        lm_session = replace(session, landmarks=captured, landmark_sd=captured_sd)
        out["model, captured landmarks"] = _compare(fit_session(lm_session), base)
        pads = pad_points(session.landmarks, session.reference, list(DIGITS))
        found = [
            e
            for r in session.grasp
            if r.name in HOLD_RECORDINGS
            for e in find_holds(r, pads, session.rate_hz)
        ]
        kept = [e for e in session.events if e.recording not in HOLD_RECORDINGS]
        ev_session = replace(session, events=[*kept, *found])
        truth_ev = [e for e in session.events if e.recording in HOLD_RECORDINGS]
        out["pinch holds"] = {
            "found": len(found),
            "events": len(truth_ev),
            "found_covers_event": sum(
                any(f.start <= e.start and f.end >= e.end for f in found) for e in truth_ev
            ),
            **_compare(fit_session(ev_session), base),
        }
    ref_moved = [m.too_much for m in reference_motion(session.reference, session.reference.sensors)]
    grasp = session.grasp[0].slice(slice(0, 360))
    moving = [m.too_much for m in reference_motion(grasp, grasp.sensors)]
    out["reference"] = {"still_refused": any(ref_moved), "moving_taken": not any(moving)}
    return out


def summarise(rows: list[dict]) -> dict:
    """Per condition: the worst and mean figures over its subjects."""

    def worst(key, field):
        vals = [r[key][field] for r in rows if r[key][field] is not None]
        return {"max": max(vals), "mean": float(np.mean(vals))} if vals else None

    one = np.concatenate([r["tips vs anatomy"]["one_take_mm"] for r in rows])
    three = np.concatenate([r["tips vs anatomy"]["three_takes_mm"] for r in rows])
    return {
        "subjects": len(rows),
        "own pivots refused": sum(r["pivot"]["refused"] for r in rows),
        "pivot tip error (mm)": worst("pivot", "tip_error_mm"),
        "pivot tip CI (mm)": worst("pivot", "tip_ci_mm"),
        "pivot error (mm)": worst("pivot", "pivot_error_mm"),
        "landmarks taken": f"{sum(r['landmarks, true stylus']['taken'] for r in rows)}/"
        f"{sum(r['landmarks, true stylus']['wanted'] for r in rows)}",
        "landmark vs placements, true stylus (mm)": worst("landmarks, true stylus", "error_mm_max"),
        "landmark vs placements, calibrated stylus (mm)": worst(
            "landmarks, calibrated stylus", "error_mm_max"
        ),
        "tip vs anatomy RMS, one take (mm)": float(np.sqrt(np.mean(one**2))),
        "tip vs anatomy RMS, three takes (mm)": float(np.sqrt(np.mean(three**2))),
        "one / three": float(np.sqrt(np.mean(one**2)) / np.sqrt(np.mean(three**2))),
        "model axis diff (deg)": worst("model, captured landmarks", "axis_deg_max"),
        "model centre diff (mm)": worst("model, captured landmarks", "centre_mm_max"),
        "model tip diff (mm)": worst("model, captured landmarks", "tip_mm_max"),
        "holds found / events covered": f"{sum(r['pinch holds']['found'] for r in rows)} / "
        f"{sum(r['pinch holds']['found_covers_event'] for r in rows)} of "
        f"{sum(r['pinch holds']['events'] for r in rows)}",
        "pads from found holds diff (mm)": worst("pinch holds", "pad_mm_max"),
        "axes from found holds diff (deg)": worst("pinch holds", "axis_deg_max"),
        "still references refused": sum(r["reference"]["still_refused"] for r in rows),
        "moving references taken": sum(r["reference"]["moving_taken"] for r in rows),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subjects", type=int, default=6)
    ap.add_argument("--styli", type=int, default=8)
    ap.add_argument(
        "--conditions", default="realistic,distortion off,MyoHand world,noise 2x,STA 2x"
    )
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    t0 = time.perf_counter()
    report: dict = {"pivot, white noise": pivot_study(args.styli, 11)}
    print(json.dumps(report["pivot, white noise"], indent=1))
    for cond in args.conditions.split(","):
        rows = [subject_study(cond, 1000 + i) for i in range(args.subjects)]
        report[cond] = summarise(rows)
        print(cond, json.dumps(report[cond], indent=1), flush=True)
    report["meta"] = run_meta("lab.py", round(time.perf_counter() - t0, 1))
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
