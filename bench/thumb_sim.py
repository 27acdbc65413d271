"""Figures of the simulator's thumb (docs/simulator.md, "Thumb").

python bench/thumb_sim.py [--anatomy 50] [--subjects 6]

Prints the sampled thumb anatomy over ``--anatomy`` subjects (means and SDs beside the
literature values) and, over ``--subjects`` simulated whole-hand subjects at default
noise, the touches: pad-centre distance minus the sum of the pulp half-thicknesses, the
nail-edge distance, the CMC angle ranges of the thumb protocols and the time per subject.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fingerfit.simulate import SimConfig, simulate_cohort
from fingerfit.simulate.thumb import NOMINAL_HAND_LENGTH, sample_thumb

HAND = ("thumb", "index", "middle", "ring", "little")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--anatomy", type=int, default=50)
    ap.add_argument("--subjects", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    rows = []
    for i in range(a.anatomy):
        length = NOMINAL_HAND_LENGTH * rng.normal(1.0, 0.06)
        t = sample_thumb(
            rng,
            length,
            "left" if i % 2 else "right",
            hand_rotation=np.eye(3),
            hand_origin=np.zeros(3),
        )
        rows.append(
            [
                *(t.lengths / length),
                *t.lengths,
                t.offset("cmc"),
                np.degrees(t.axes_angle("cmc")),
                t.offset("mcp"),
                np.degrees(t.axes_angle("mcp")),
                np.degrees(np.arccos(abs(t.axis["ip"] @ t.frame[:, 0]))),
            ]
        )
    r = np.array(rows)
    names = [
        "ratio metacarpal",
        "ratio proximal",
        "ratio distal (to nail edge)",
        "metacarpal mm",
        "proximal mm",
        "distal mm",
        "CMC offset mm",
        "CMC axes angle deg",
        "MCP offset mm",
        "MCP axes angle deg",
        "IP axis to bone deg",
    ]
    print(f"anatomy over {a.anatomy} subjects (mean, SD):")
    for n, col in zip(names, r.T, strict=True):
        print(f"  {n:28s} {col.mean():8.3f} {col.std(ddof=1):7.3f}")
    t0 = time.perf_counter()
    cohort = simulate_cohort(SimConfig(fingers=HAND), a.subjects, a.seed)
    dt = (time.perf_counter() - t0) / a.subjects
    gap_err, tips, key_err = [], [], []
    ranges = {"cmc": [], "cmc_abduction": []}
    for sim in cohort:
        for c in sim.truth.contacts:
            err = max(
                abs(c["distance_min_mm"] - c["gap_mm"]), abs(c["distance_max_mm"] - c["gap_mm"])
            )
            if c["in_events_csv"]:
                gap_err.append(err)
                tips += [c["tip_distance_min_mm"], c["tip_distance_max_mm"]]
            else:
                key_err.append(err)
        for k in ranges:
            v = np.concatenate(
                [
                    sim.truth.frames[n]["angles"]["thumb"][k]
                    for n in ("thumb_circumduction.csv", "thumb_opposition.csv", "pinch.csv")
                ]
            )
            ranges[k].append(np.degrees(np.ptp(v)))
    print(f"{a.subjects} whole-hand subjects, default noise, {dt:.1f} s per subject:")
    print(
        f"  pad touches: {len(gap_err)}; |pad-centre distance - sum of half-thicknesses| max {max(gap_err):.1e} mm"
    )
    print(f"  nail-edge distance during pad touches: {min(tips):.1f}-{max(tips):.1f} mm")
    print(
        f"  key pinches: {len(key_err)}; |thumb pad centre - side site| - half-thickness max {max(key_err):.1e} mm"
    )
    for k, v in ranges.items():
        print(f"  thumb.{k} range over the thumb protocols: {min(v):.0f}-{max(v):.0f} deg")


if __name__ == "__main__":
    main()
