"""What the plausibility checks cost next to the whole fit.

Run ``.venv/bin/python bench/plausibility_cost.py``. On one realistic simulated subject
(``SimConfig()``, seed 2: the index finger, 10 grasp cycles) prints the median over 15
runs of ``fit_session`` (checks included) and of ``check_session`` alone (ms): the cost
quoted at the top of ``docs/plausibility.md``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import numpy as np

from fingerfit.estimate import fit_session
from fingerfit.estimate.fit import reference_poses
from fingerfit.estimate.plausibility import check_session
from fingerfit.simulate import SimConfig, simulate_subject

REPEATS = 15


def median_ms(f: Callable[[], object]) -> float:
    """Median wall time of ``REPEATS`` calls of ``f`` (ms)."""
    ts = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return 1000 * float(np.median(ts))


def main() -> None:
    """Print the two medians on one line."""
    s = simulate_subject(SimConfig(fingers=("index",)), 2).session
    ref = reference_poses(s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_ms = median_ms(lambda: fit_session(s))
    print(
        f"one finger, 10 cycles: fit_session {fit_ms:.1f} ms (checks included), "
        f"check_session {median_ms(lambda: check_session(s, ['index'], ref)):.1f} ms"
    )


if __name__ == "__main__":
    main()
