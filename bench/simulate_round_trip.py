"""Tracker files vs CSV: how much a model changes through each simulated tracker format.

Run ``.venv/bin/python bench/simulate_round_trip.py [N_SUBJECTS]`` (default 5). Simulates
N subjects (``--seed 4``, fingerfit's index finger) as CSV sessions and in each tracker
format of ``fingerfit simulate --format`` (Polhemus Liberty ASCII and binary, C3D: needs
the ``c3d`` extra), runs the printed ``convert`` / ``session`` / ``fit`` commands as
printed, fits both methods (``twoaxis``, ``robust``) and prints, per format, method and
joint, the largest difference over the subjects between the model from the tracker files
and the model from the CSV session: axis angle (deg), centre distance and segment length
(mm), and the subject with the worst axis. The table of ``docs/simulator.md``; the
helpers are ``tests/_round_trip.py``, whose one-subject case
``tests/test_simulate_formats.py`` asserts.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests._round_trip import FORMATS, METHODS, SEED, model_differences, simulate_and_fit


def measure(n_subjects: int) -> None:
    """Print the Markdown table over ``n_subjects`` subjects."""
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        ref = simulate_and_fit(work, "csv", SEED, n_subjects)
        print(f"max over {n_subjects} subjects (seed {SEED}) of |tracker path - CSV path|")
        print("| format | method | joint | axis (deg) | centre (mm) | segment (mm) | worst axis |")
        print("|---|---|---|---|---|---|---|")
        for fmt in FORMATS:
            got = simulate_and_fit(work, fmt, SEED, n_subjects)
            for m in METHODS:
                diffs = [model_differences(a, b) for a, b in zip(ref[m], got[m], strict=True)]
                for j in diffs[0]:
                    row = [max(d[j][k] for d in diffs) for k in ("axis_deg", "centre_mm")]
                    row.append(max(d[j]["length_mm"] for d in diffs))
                    worst = int(np.argmax([d[j]["axis_deg"] for d in diffs])) + 1
                    cells = " | ".join(f"{v:.2g}" for v in row)
                    print(f"| {fmt} | {m} | {j} | {cells} | S{worst:02d} |")


def main() -> None:
    """Read ``N_SUBJECTS`` from the command line and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "subjects", nargs="?", type=int, default=5, help="simulated subjects (default 5)"
    )
    measure(parser.parse_args().subjects)


if __name__ == "__main__":
    main()
