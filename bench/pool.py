"""Run a benchmark's tasks in worker processes, with a progress line on stderr."""

from __future__ import annotations

import multiprocessing as mp
import sys
import time
from collections.abc import Callable


def run_tasks(fn: Callable, tasks: list, workers: int, what: str = "subjects") -> list:
    """``fn(task)`` for every task in ``workers`` spawned processes, results as they come
    (any order), a ``k/n subjects (s)`` line on stderr."""
    t0 = time.perf_counter()
    results = []
    with mp.get_context("spawn").Pool(workers) as pool:
        for i, r in enumerate(pool.imap_unordered(fn, tasks), 1):
            results.append(r)
            print(
                f"\r{i}/{len(tasks)} {what} ({time.perf_counter() - t0:.0f} s)",
                end="",
                file=sys.stderr,
                flush=True,
            )
    print(file=sys.stderr)
    return results
