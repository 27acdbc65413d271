"""Device-precision stability of the default fit (``docs/methods.md``, "Numerical stability").

Fits each simulated subject (``SimConfig()`` seeds ``--seeds``, index finger, and the
demo cohort ``simulate_cohort(SimConfig(), 5, 2018)``) as simulated and after rounding
every pose to each device's precision (:mod:`fingerfit.simulate.precision`), and prints
the largest movement of each model quantity, in the joint's parent sensor frame:
flexion axes (deg), joint centres (mm), the MP ab/adduction axis (deg) and its point
(mm). Run with ``python bench/precision.py [--method twoaxis] [--seeds 21]``.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.simulate import SimConfig, simulate_cohort, simulate_subject
from fingerfit.simulate.precision import DEVICES, device_rounded
from fingerfit.transforms import angle_between_axes

JOINTS = ("mp", "pip", "dip")


def movement(m0, m1) -> dict[str, float]:
    """Axis (deg) and centre (mm) movement per joint between two models (parent frames)."""
    out = {}
    for j in JOINTS:
        c0, a0 = m0.in_parent("index", j)
        c1, a1 = m1.in_parent("index", j)
        out[f"{j} deg"] = float(np.degrees(angle_between_axes(a0, a1)))
        out[f"{j} mm"] = float(np.linalg.norm(c1 - c0))
    f0, f1 = m0.fingers["index"].second_axes.get("mp"), m1.fingers["index"].second_axes.get("mp")
    out["flips"] = float((f0 is None) != (f1 is None))
    if f0 is not None and f1 is not None:
        p0, r0 = m0.reference_poses[f0.parent]
        p1, r1 = m1.reference_poses[f1.parent]
        out["ab deg"] = float(np.degrees(angle_between_axes(r0.T @ f0.axis, r1.T @ f1.axis)))
        out["ab mm"] = float(np.linalg.norm(r0.T @ (f0.center - p0) - r1.T @ (f1.center - p1)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--method", default="twoaxis")
    ap.add_argument("--seeds", type=int, default=21)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    config = SimConfig(targets=False, test=False)
    subjects = [(f"seed {s}", simulate_subject(config, s)) for s in range(args.seeds)]
    cohort = simulate_cohort(config, 5, 2018)
    subjects += [(f"demo {c.session.subject}", c) for c in cohort]
    keys = [f"{j} {u}" for j in JOINTS for u in ("deg", "mm")] + ["ab deg", "ab mm", "flips"]
    worst = {d: dict.fromkeys(keys, 0.0) for d in DEVICES}
    who = {d: dict.fromkeys(keys, "") for d in DEVICES}
    for name, sim in subjects:
        m0 = fit_session(sim.session, FitOptions(method=args.method))
        for d in DEVICES:
            mv = movement(
                m0, fit_session(device_rounded(sim.session, d), FitOptions(method=args.method))
            )
            for k, v in mv.items():
                if k == "flips":
                    worst[d][k] += v
                elif v > worst[d][k]:
                    worst[d][k], who[d][k] = v, name
    print(f"method {args.method}, {len(subjects)} subjects; largest movement (subject)\n")
    print("| device | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for d in DEVICES:
        cells = [
            f"{worst[d][k]:.0f}" if k == "flips" else f"{worst[d][k]:.3f} ({who[d][k]})"
            for k in keys
        ]
        print(f"| {d} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
