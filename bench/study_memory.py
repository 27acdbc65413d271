"""The study process's peak memory against the number of subjects, without fitting them.

``python bench/study_memory.py SESSIONS --base 20 --sizes 20,100,200,1000``

The first ``--base`` session folders of ``SESSIONS`` are studied once (``study_subject``
in 2 processes; their outcomes are kept in a pickle beside nothing: a temporary folder).
Then, for each size N, a fresh process runs ``run_study`` over N inputs with ``--jobs 2``
whose tasks return one of those outcomes under a new subject ID (``F0001``...) after
0.1 s (``FINGERFIT_BENCH_TASK_S``; a real task takes ~1 s, and outcomes arriving all at
once would wait in the study process together): the study
process does exactly what it does for N real subjects (receives each result and its
Fig. 9, gathers the tables, saves the models, the statistics, the tables, the study-wide
figures drawn in the workers, the report) at the cost of unpickling a result per subject.
It reports the study process's ``VmHWM`` (peak RSS) after each phase, the tracemalloc
peak of Python allocations is not used (NumPy and pandas allocate outside it).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

_OUTCOMES: list | None = None


def _outcome(folder: str) -> bytes:
    from fingerfit.estimate import FitOptions
    from fingerfit.evaluate.study import study_subject  # (also in its older home)

    return pickle.dumps(study_subject(Path(folder), FitOptions()))


def renamed(item: str, _options) -> object:
    """A stored outcome as the outcome of subject ``item`` (a study task in a worker)."""
    try:
        from fingerfit.evaluate.subject import SUBJECT_TABLES as tables_of
    except ImportError:  # older code (``PYTHONPATH=<its src>``, to compare)
        tables_of = ("max_flexion", "distances", "targets", "truth_axes", "truth_tips")
        tables_of += ("truth_angles", "pinches")

    # A real task takes about a second; without a pause every outcome would arrive at once
    # and wait in the study process together, a peak a real study does not have.
    time.sleep(float(os.environ.get("FINGERFIT_BENCH_TASK_S", "0.1")))
    global _OUTCOMES
    if _OUTCOMES is None:
        with open(os.environ["FINGERFIT_BENCH_OUTCOMES"], "rb") as fh:
            _OUTCOMES = [pickle.loads(b) for b in pickle.load(fh)]
    k = int(item[1:]) - 1
    got = _OUTCOMES[k % len(_OUTCOMES)]
    r = got.result
    tables = {
        key: None if getattr(r, key) is None else getattr(r, key).assign(subject=item)
        for key in tables_of
    }
    result = replace(
        r,
        subject=item,
        session=replace(r.session, subject=item),
        model=replace(r.model, subject=item),
        **tables,
    )
    return replace(
        got,
        source=item,
        subject=item,
        result=result,
        figure=(f"fig09_trajectories_{item}.png", got.figure[1]),
    )


_RUN = """
import json, sys, time
sys.path.insert(0, {bench!r})
from contextlib import contextmanager
from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import fingerfit.evaluate.study as st
import fingerfit.evaluate.report as rp
import study_memory

def peak():
    return int(open("/proc/self/status").read().split("VmHWM:")[1].split()[0]) / 1024

marks = {{}}
def wrap(mod, name):
    f = getattr(mod, name)
    def g(*a, **k):
        r = f(*a, **k); marks[name] = peak(); return r
    setattr(mod, name, g)
wrap(st, "summarize_study"); wrap(st, "_write_outputs")
wrap(st if hasattr(st, "write_report") else rp, "write_report")  # study's own name, or an older tree's lazy import

class Renaming:
    def __init__(self, pool): self.pool = pool
    def submit(self, fn, *a, **k):
        return self.pool.submit(study_memory.renamed if fn is st.study_subject else fn, *a, **k)

@contextmanager
def executor(jobs=1, scheduler=None):
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        yield Renaming(pool)

if __name__ == "__main__":
    st.study_executor = executor
    n = {n!r}
    items = [f"F{{i + 1:04d}}" for i in range(n)]
    start = peak()
    done = [0]
    def step(msg):
        done[0] += 1
        if done[0] == n:
            marks["all subjects received"] = peak()
    t = time.perf_counter()
    st.run_study(items, {out!r}, progress=step)
    wall = time.perf_counter() - t
    import resource  # the workers are joined: the largest one's peak (they draw the figures)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(json.dumps({{"subjects": n, "wall_s": wall, "start_mb": start, **marks,
                      "end_mb": peak(), "largest_worker_mb": kids}}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("sessions", type=Path)
    ap.add_argument("--base", type=int, default=20)
    ap.add_argument("--sizes", default="20,100,200,1000")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    dirs = sorted(p for p in args.sessions.iterdir() if p.is_dir())[: args.base]
    with tempfile.TemporaryDirectory(prefix="fingerfit-mem-") as tmp:
        with ProcessPoolExecutor(2) as pool:
            blobs = list(pool.map(_outcome, map(str, dirs)))
        path = Path(tmp) / "outcomes.pickle"
        path.write_bytes(pickle.dumps(blobs))
        env = {**os.environ, "FINGERFIT_BENCH_OUTCOMES": str(path), "OMP_NUM_THREADS": "1"}
        rows = []
        for n in map(int, args.sizes.split(",")):
            code = _RUN.format(bench=str(Path(__file__).parent), n=n, out=f"{tmp}/out{n}")
            script = Path(tmp) / f"run{n}.py"  # a file: spawned workers re-import __main__
            script.write_text(code)
            res = subprocess.run(
                [sys.executable, str(script)], env=env, capture_output=True, text=True
            )
            if res.returncode:
                raise RuntimeError(res.stderr[-3000:])
            rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(json.dumps(rows[-1]), flush=True)
    phases = ["start_mb", "all subjects received", "summarize_study", "_write_outputs"]
    phases += ["write_report", "end_mb", "largest_worker_mb"]
    print("| subjects | " + " | ".join(phases) + " | wall |")
    print("|---" * (len(phases) + 2) + "|")
    for r in rows:
        cells = " | ".join(f"{r.get(p, float('nan')):.0f}" for p in phases)
        print(f"| {r['subjects']} | {cells} | {r['wall_s']:.0f} s |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
