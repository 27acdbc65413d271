"""Validation of the paper's method (``tang2018``) against simulator ground truth.

Prints a markdown table: per joint, the axis error (deg) and the distance of the
fitted joint centre to the true axis (mm), mean and max over subjects, and the
free-motion fingertip error of the user-axis and orthogonal models (mm), for
noise-free and realistic simulated sessions. Axes are compared in the parent
sensor frame, which does not depend on the reference pose.

    python bench/paper_method.py --subjects 10
"""

from __future__ import annotations

import argparse

import numpy as np

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.simulate import SimConfig, simulate_cohort
from fingerfit.simulate.study import relative_truth_in_parent
from fingerfit.transforms import angle_between_axes, distance_point_to_line

JOINTS = ("mp", "pip", "dip")


def evaluate(config: SimConfig, n: int, seed: int, method: str) -> dict[str, np.ndarray]:
    """Axis errors (deg), centre distances (mm) ``(n, 3)`` and tip errors ``(n, 2)`` (mm)."""
    axis, centre, tips = [], [], []
    for sim in simulate_cohort(config, n, seed):
        model = fit_session(sim.session, FitOptions(method=method))
        a_row, c_row = [], []
        for j in JOINTS:
            c, a = model.in_parent("index", j)
            ct, at = relative_truth_in_parent(sim, "index", j)
            a_row.append(np.degrees(angle_between_axes(a, at)))
            c_row.append(distance_point_to_line(c, ct, at))
        axis.append(a_row)
        centre.append(c_row)
        kin = compute_kinematics(model, sim.session.test[0])
        true_tip = sim.truth.frames["test.csv"]["tip"]["index"]
        tips.append(
            [
                np.linalg.norm(kin.motions[v]["index"].tip - true_tip, axis=1).mean()
                for v in ("user_axis", "orthogonal")
            ]
        )
    return {"axis": np.array(axis), "centre": np.array(centre), "tips": np.array(tips)}


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--subjects", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--method", default="tang2018")
    args = ap.parse_args()
    print(
        f"method `{args.method}`, {args.subjects} simulated subjects per condition, index finger\n"
    )
    print(
        "| condition | joint | axis error mean / max (deg) | centre to true axis mean / max (mm) |"
    )
    print("|---|---|---|---|")
    tips = {}
    for name, cfg in (("noise-free", SimConfig.exact()), ("realistic", SimConfig())):
        r = evaluate(cfg, args.subjects, args.seed, args.method)
        for k, j in enumerate(JOINTS):
            a, c = r["axis"][:, k], r["centre"][:, k]
            print(
                f"| {name} | {j.upper()} | {a.mean():.3g} / {a.max():.3g} | {c.mean():.3g} / {c.max():.3g} |"
            )
        tips[name] = r["tips"]
    print(
        "\n| condition | free-motion fingertip error, user-axis (mm) | orthogonal (mm) | user / orthogonal |"
    )
    print("|---|---|---|---|")
    for name, t in tips.items():
        u, o = t.mean(axis=0)
        print(f"| {name} | {u:.3g} | {o:.3g} | {u / o:.2f} |")


if __name__ == "__main__":
    main()
