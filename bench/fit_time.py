"""Fit time per finger, this tree against a git revision, side by side in one run.

Run with ``.venv/bin/python bench/fit_time.py --before 56e9747 --subjects 4 --rounds 5``.

Each round runs, one after the other in fresh processes, this tree's ``src`` and the
revision's (``git archive REV src``): each process simulates the same ``--subjects``
default-world index-finger subjects (``SimConfig()``, seeds 1000...) and times
``fit_session`` with the default method on each, once to warm up, then ``--repeat`` times,
keeping the best. The figure per version is the median over rounds of the mean over
subjects of that best time, and the ratio is this tree over the revision. The rounds
alternate the order of the two versions, so a machine whose load drifts during the run
weighs on both. ``--cpu`` times the processes' CPU time (``time.process_time``) instead of
the wall clock: on a shared machine another job's load then costs waiting, not time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CHILD = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.simulate import SimConfig, simulate_subject
n, repeat = int(sys.argv[1]), int(sys.argv[2])
clock = time.process_time if sys.argv[3] == "cpu" else time.perf_counter
best = []
for s in range(n):
    session = simulate_subject(SimConfig(), 1000 + s).session
    fit_session(session, FitOptions(force=True))
    times = []
    for _ in range(repeat):
        t = clock()
        fit_session(session, FitOptions(force=True))
        times.append(clock() - t)
    best.append(min(times))
print(json.dumps(best))
"""


def timed(src: Path, subjects: int, repeat: int, cpu: bool = False) -> float:
    """Mean over subjects of the best fit time (s) with the package in ``src`` (CPU time
    with ``cpu``, else wall-clock)."""
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(subjects), str(repeat), "cpu" if cpu else "wall"],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    ).stdout
    return float(np.mean(json.loads(out.strip().splitlines()[-1])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="git revision to compare with")
    ap.add_argument("--subjects", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cpu", action="store_true", help="CPU time instead of the wall clock")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", args.before, "src"],
            check=True,
            capture_output=True,
        ).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        versions = {"this tree": ROOT / "src", args.before: Path(tmp) / "src"}
        seconds: dict[str, list[float]] = {k: [] for k in versions}
        for r in range(args.rounds):
            order = list(versions) if r % 2 == 0 else list(versions)[::-1]
            for name in order:
                seconds[name].append(timed(versions[name], args.subjects, args.repeat, args.cpu))
    now, before = (float(np.median(seconds[k])) for k in versions)
    clock = "CPU time" if args.cpu else "wall clock"
    print(f"fit one finger (default method, {clock}), median of {args.rounds} rounds:")
    print(f"  this tree {1000 * now:.0f} ms, {args.before} {1000 * before:.0f} ms")
    print(f"  ratio {now / before:.2f}x")


if __name__ == "__main__":
    main()
