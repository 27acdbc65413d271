"""Accuracy on the MyoHand world (an independent truth) next to fingerfit's own world.

``python bench/myohand_accuracy.py [--subjects 5] [--seed 2018] [--no-abduction]``: simulates the index
finger of ``--subjects`` right hands (realistic noise, ``simulate_cohort`` seeds) in each
world, fits each by the default method and by ``tang2018``, and scores them as
``bench/accuracy.py`` does (its functions): axis error (deg) and centre-to-true-axis
distance (mm) per joint in the parent sensor frame, fingertip error (mm) over the
free-motion test recording; plus the true model driven by the same sensors (the floor;
on MyoHand it stores the MP axes ab/adduction-first, so it is not exact there).
Prints a Markdown table (``docs/simulator.md``, "The MyoHand world").
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import geometry_errors, tip_errors

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.fit import DEFAULT_METHOD
from fingerfit.simulate import SimConfig, simulate_cohort
from fingerfit.simulate.truthmodel import truth_model

ROWS = [
    (f"{DEFAULT_METHOD} (default)", DEFAULT_METHOD, "user_axis"),
    ("tang2018", "tang2018", "user_axis"),
    ("orthogonal (tang2018's)", "tang2018", "orthogonal"),
    ("true model (floor)", None, "user_axis"),
]


def score(world: str, n: int, seed: int, abduction: bool = True) -> dict[str, dict[str, list]]:
    """Per row: per subject axis errors (3,), centre distances (3,), mean tip error."""
    config = SimConfig(hand="right", world=world, abduction=abduction)
    cohort = simulate_cohort(config, n, seed)
    out: dict[str, dict[str, list]] = {r[0]: {"deg": [], "mm": [], "tip": []} for r in ROWS}
    for sim in cohort:
        for label, method, variant in ROWS:
            if method is None:
                model = truth_model(sim)
            else:
                model = fit_session(sim.session, FitOptions(method=method, force=True))
            deg, mm = geometry_errors(sim, model)
            out[label]["deg"].append(deg)
            out[label]["mm"].append(mm)
            out[label]["tip"].append(float(np.nanmean(tip_errors(sim, model, variant))))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2018)
    parser.add_argument(
        "--no-abduction", action="store_true", help="no MP ab/adduction motion (a control)"
    )
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    print(
        "| world | method | axis error MP / PIP / DIP (deg) | centre to true axis "
        "MP / PIP / DIP (mm) | fingertip error, free motion (mm) |"
    )
    print("|---|---|---|---|---|")
    for world in ("myohand", "default"):
        for label, s in score(world, args.subjects, args.seed, not args.no_abduction).items():
            deg, mm, tip = np.array(s["deg"]), np.array(s["mm"]), np.array(s["tip"])
            geo = label.startswith("true") or label.startswith("orthogonal")
            d = " / ".join(f"{v:.2f}" for v in deg.mean(0)) if not geo else "-"
            m = " / ".join(f"{v:.2f}" for v in mm.mean(0)) if not geo else "-"
            print(f"| {world} | {label} | {d} | {m} | {tip.mean():.2f} ({tip.std(ddof=1):.2f}) |")


if __name__ == "__main__":
    main()
