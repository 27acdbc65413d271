"""Where a finger's fit spends its time: a CPU-clock profile of ``fit_session``.

Run with ``PYTHONPATH=src .venv/bin/python bench/fit_profile.py`` (or another tree's
``src``, to profile that revision the same way).

Simulates one default-world index-finger subject (``SimConfig()``, ``--seed``), fits it
once to warm up, times ``--fits`` fits of the default method without the profiler (CPU
time per fit), then profiles as many more with :mod:`cProfile` on the CPU clock and prints,
for the functions of the fit that matter to the two-axis MP (those of :data:`FUNCTIONS`
present in the tree), their calls and cumulative CPU time per fit and their share of
``fit_session``'s. The profiler's own cost weighs most on code that makes many small calls.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
import warnings

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.simulate import SimConfig, simulate_subject

#: Functions reported (by name), outermost first.
FUNCTIONS = [
    "fit_session",
    "_robust_family",
    "_second_axis",
    "estimate_hinge",
    "estimate_two_axis",
    "estimate_two_axis_directions",
    "fit_two_axis_directions",
    "least_squares",
    "approx_derivative",
    "_skew_residual",
    "skew_residual_jacobian",
    "direction_jacobian",
    "choose_joint_model",
    "_two_axis_folds",
    "_held_out_sq",
    "fit_axis_points",
    "joint_data",
    "check_session",
    "cross",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--fits", type=int, default=5)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    session = simulate_subject(SimConfig(), args.seed).session
    options = FitOptions(force=True)
    fit_session(session, options)
    t = time.process_time()
    for _ in range(args.fits):
        fit_session(session, options)
    plain = (time.process_time() - t) / args.fits
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    for _ in range(args.fits):
        fit_session(session, options)
    prof.disable()
    rows: dict[str, list[float]] = {}
    for (path, _, name), (_, calls, _, cum, _) in pstats.Stats(prof).stats.items():  # type: ignore[attr-defined]
        if name in FUNCTIONS and ("fingerfit" in path or "scipy" in path or "numeric" in path):
            row = rows.setdefault(name, [0.0, 0.0])
            row[0] += calls
            row[1] += cum
    total = rows["fit_session"][1]
    print(f"fit one finger: {1e3 * plain:.1f} ms CPU without the profiler, "
          f"{1e3 * total / args.fits:.1f} ms with it")  # fmt: skip
    print(f"{'function':30s} {'calls/fit':>9s} {'ms/fit':>8s} {'share':>7s}")
    for name in FUNCTIONS:
        if name in rows:
            calls, cum = rows[name]
            print(f"{name:30s} {calls / args.fits:9.1f} {1e3 * cum / args.fits:8.1f} "
                  f"{100 * cum / total:6.1f}%")  # fmt: skip


if __name__ == "__main__":
    main()
