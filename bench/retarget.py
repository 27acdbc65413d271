"""Retargeting benchmark: tip vs joint method vs the orthogonal model as source, one run.

    python bench/retarget.py [--subjects 1] [--frames 3000] [--out bench/retarget.json]

Simulated subjects (four fingers, ``fingerfit.simulate``), model fitted by
``fit_session``, the grasp recording retargeted onto Shadow (MJCF, MuJoCo) and Allegro
(URDF, Pinocchio). Per robot and source: fingertip error in the robot palm frame against
the scaled targets of the fitted (user-axis) model (median / p95, mm), joint-limit and
coupling violations, jerk (RMS third difference of the joint trajectory, rad/s^3),
per-frame solve time (p50 / p99, ms). Then whole-hand subjects (thumb, pad points) on
``pinch.csv``: the robot pad points' distance during the person's touches (person's pad
points closer than ``CONTACT_MM``), per thumb-finger pair the map names. dex-retargeting is not run: see docs/retargeting.md.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from fingerfit.estimate import fit_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.retarget import (
    CONTACT_MM,
    person_points,
    pinch_terms,
    resolve,
    retarget,
    setup,
)
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject

FINGERS = ("index", "middle", "ring", "little")
SOURCES = (
    ("tip", "user_axis"),
    ("joint", "user_axis"),
    ("tip", "orthogonal"),
    ("joint", "orthogonal"),
)


def jerk(q: np.ndarray, dt: float) -> float:
    """RMS over frames and joints of the third difference (rad/s^3)."""
    d3 = np.diff(q, n=3, axis=0) / dt**3
    return float(np.sqrt(np.mean(d3**2)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--subjects", type=int, default=1)
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--out", type=Path, default=Path("bench/retarget.json"))
    a = ap.parse_args()
    rows = []
    for seed in range(a.subjects):
        sub = simulate_subject(SimConfig(fingers=FINGERS), seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = fit_session(sub.session)
        rec = sub.session.grasp[0]
        n = min(a.frames, rec.n_frames)
        rec = Recording(
            rec.name,
            rec.time[:n],
            {k: PoseSeries(v.position[:n], v.rotation[:n]) for k, v in rec.poses.items()},
        )
        dt = float(np.median(np.diff(rec.time)))
        for robot_name in ("shadow", "allegro"):
            robot, rmap = resolve(robot_name, None, model.hand)
            ref = None
            for method, variant in SOURCES:
                t0 = time.perf_counter()
                res = retarget(model, rec, robot, rmap, method, variant)
                wall = time.perf_counter() - t0
                if ref is None:
                    ref = res.targets  # user-axis targets: what the person did
                err = np.linalg.norm(res.tips - ref, axis=2)
                rows.append(
                    {
                        "subject": seed,
                        "robot": robot_name,
                        "method": method,
                        "source": variant,
                        "frames": len(res.time),
                        "tip_err_median_mm": float(np.nanmedian(err)),
                        "tip_err_p95_mm": float(np.nanpercentile(err, 95)),
                        "violations": res.violations,
                        "jerk_rad_s3": jerk(res.q, dt),
                        "solve_p50_ms": float(np.median(res.seconds) * 1e3),
                        "solve_p99_ms": float(np.percentile(res.seconds, 99) * 1e3),
                        "wall_s": wall,
                    }
                )
                r = rows[-1]
                print(
                    f"| {robot_name} | {method} | {variant} | {r['tip_err_median_mm']:.2f} | "
                    f"{r['tip_err_p95_mm']:.1f} | {r['violations']} | {r['jerk_rad_s3']:.0f} | "
                    f"{r['solve_p50_ms']:.3f} | {r['solve_p99_ms']:.2f} |",
                    flush=True,
                )
    # Whole hand (thumb + four fingers, pad points): the pinch recording.
    print(
        "| robot | method | source | pinch distance median mm | p95 mm | touch frames | "
        "tip error median mm | violations | jerk rad/s^3 | solve p50 ms | p99 ms |"
    )
    pinch_rows = []
    for seed in range(a.subjects):
        sub = simulate_subject(SimConfig(fingers=("thumb", *FINGERS)), seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = fit_session(sub.session)
        rec = sub.session.recording("pinch.csv")
        dt = float(np.median(np.diff(rec.time)))
        for robot_name in ("shadow", "allegro"):
            robot, rmap = resolve(robot_name, None, model.hand)
            s = setup(model, robot, rmap)
            kin = compute_kinematics(model, rec)
            pads = person_points(s, model, kin, rec, "user_axis", "pad")
            pairs, _, _, dist = pinch_terms(s, pads)
            touch = dist < CONTACT_MM  # the person's pads touch (pair, frame)
            ref = None
            for method, variant in SOURCES:
                res = retarget(model, rec, robot, rmap, method, variant, kin=kin)
                ref = res.targets if ref is None else ref
                pa = robot.positions(res.q, [rmap.digits[x].pad for x, _ in pairs])
                pb = robot.positions(res.q, [rmap.digits[y].pad for _, y in pairs])
                rd = np.linalg.norm(pa - pb, axis=2) * 1000.0
                err = np.linalg.norm(res.tips - ref, axis=2)
                r = {
                    "subject": seed,
                    "robot": robot_name,
                    "method": method,
                    "source": variant,
                    "touch_frames": int(touch.sum()),
                    "pinch_median_mm": float(np.median(rd[touch])),
                    "pinch_p95_mm": float(np.percentile(rd[touch], 95)),
                    "tip_err_median_mm": float(np.nanmedian(err)),
                    "violations": res.violations,
                    "jerk_rad_s3": jerk(res.q, dt),
                    "solve_p50_ms": float(np.median(res.seconds) * 1e3),
                    "solve_p99_ms": float(np.percentile(res.seconds, 99) * 1e3),
                }
                pinch_rows.append(r)
                print(
                    f"| {robot_name} | {method} | {variant} | {r['pinch_median_mm']:.1f} | "
                    f"{r['pinch_p95_mm']:.1f} | {r['touch_frames']} | "
                    f"{r['tip_err_median_mm']:.2f} | {r['violations']} | "
                    f"{r['jerk_rad_s3']:.0f} | {r['solve_p50_ms']:.3f} | "
                    f"{r['solve_p99_ms']:.2f} |",
                    flush=True,
                )
    a.out.write_text(
        json.dumps(
            {
                "command": " ".join(["python", *sys.argv]),
                "python": platform.python_version(),
                "rows": rows,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
