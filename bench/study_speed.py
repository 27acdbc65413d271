"""Start-up time and the parallel study: wall time, frames/s and peak memory.

Part of ``make bench`` (``bench/speed.py`` calls :func:`run`); alone:
``python bench/study_speed.py --subjects 100 --small 20``.

- start-up: median wall time of ``fingerfit --help`` / ``--version`` beside ``python -c pass``;
- a simulated cohort (4 fingers per subject; simulated in 2 processes, timed separately);
  the studies run with ``--keep-going`` and report how many sessions failed to fit;
- ``fingerfit study --jobs 1`` and ``--jobs 2`` on the small cohort, ``--jobs 2`` on the
  large one, and the large one on a local Dask cluster (2 worker processes, 1 thread each)
  through ``--scheduler``. Each study runs in a fresh process that reports its own peak
  RSS (``VmHWM``) and the largest peak RSS of its worker processes (``getrusage``
  ``RUSAGE_CHILDREN``; a worker's figure includes what it shared with its parent at start).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

BIN = Path(sys.executable).parent
FINGERS = ("index", "middle", "ring", "little")

_STUDY = """
import json, resource, sys, time
from fingerfit.cli import main
sys.argv = ["fingerfit", "study", *{args!r}]
t = time.perf_counter()
try:
    main()
except SystemExit as exc:
    assert not exc.code, exc.code
wall = time.perf_counter() - t
# VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec (the benchmark's own peak).
status = open("/proc/self/status").read().split("VmHWM:")[1].split()
me = int(status[0])
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print("\\n" + json.dumps({{"wall_s": wall, "parent_peak_mb": me / 1024,
                          "largest_child_peak_mb": kids / 1024}}))
"""

_CLUSTER = """
import json, sys
from distributed import LocalCluster
cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                       host="127.0.0.1", dashboard_address=None)
print(json.dumps(cluster.scheduler_address), flush=True)
sys.stdin.read()  # until the benchmark closes it
cluster.close()
import resource
print(json.dumps(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024), flush=True)
"""


def median_wall(cmd: list[str], repeat: int = 7) -> float:
    """Median wall time (s) of running ``cmd`` ``repeat`` times."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def startup() -> dict:
    py = median_wall([sys.executable, "-c", "pass"])
    out = {"python_c_pass_s": py}
    for flag in ("--help", "--version"):
        t = median_wall([str(BIN / "fingerfit"), flag])
        out[flag] = {"wall_s": t, "over_python_s": t - py}
    return out


def _simulate_one(args: tuple[int, int, str]) -> int:
    from fingerfit.simulate import SimConfig, simulate_subject, write_subject

    i, state, root = args
    sim = simulate_subject(SimConfig(fingers=FINGERS), state, f"S{i + 1:03d}")
    write_subject(sim, Path(root) / sim.session.subject)
    return sum(r.n_frames for r in sim.session.recordings())


def simulate(root: Path, n: int, seed: int = 2018) -> tuple[float, int]:
    """Simulate ``n`` subjects (4 fingers) into ``root`` in 2 processes: (seconds, frames)."""
    import numpy as np

    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]
    t = time.perf_counter()
    with ProcessPoolExecutor(2) as pool:
        frames = sum(pool.map(_simulate_one, [(i, s, str(root)) for i, s in enumerate(seeds)]))
    return time.perf_counter() - t, frames


def study(sessions: list[Path], out: Path, *extra: str) -> dict:
    args = [*map(str, sessions), "--out", str(out), "--quiet", "--keep-going", *extra]
    res = subprocess.run(
        [sys.executable, "-c", _STUDY.format(args=args)], capture_output=True, text=True
    )
    if res.returncode:
        raise RuntimeError("\n".join(ln for ln in res.stderr.splitlines() if "error" in ln))
    found = json.loads(res.stdout.strip().splitlines()[-1])
    found["failed"] = len(json.loads((out / "summary.json").read_text())["failed"])
    return found


def on_local_cluster(sessions: list[Path], out: Path) -> dict:
    proc = subprocess.Popen(
        [sys.executable, "-c", _CLUSTER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        address = json.loads(proc.stdout.readline())
        result = study(sessions, out, "--scheduler", address)
    finally:
        proc.stdin.close()
    # The tasks ran in the cluster's worker processes, children of the cluster process.
    result["largest_child_peak_mb"] = json.loads(proc.stdout.read().strip().splitlines()[-1])
    proc.wait(timeout=120)
    return result


def run(subjects: int = 100, small: int = 20, cluster: bool = True) -> dict:
    results: dict = {"startup": startup()}
    root = Path(tempfile.mkdtemp(prefix="fingerfit-bench-"))
    try:
        sim_s, frames = simulate(root / "sessions", subjects)
        dirs = sorted((root / "sessions").iterdir())
        per_subject = frames / subjects
        results["cohort"] = {
            "subjects": subjects,
            "fingers": len(FINGERS),
            "frames": frames,
            "simulate_s": sim_s,
        }
        runs = {}
        for name, chosen, extra in (
            (f"{small} subjects, --jobs 1", dirs[:small], ("--jobs", "1")),
            (f"{small} subjects, --jobs 2", dirs[:small], ("--jobs", "2")),
            (f"{subjects} subjects, --jobs 2", dirs, ("--jobs", "2")),
        ):
            runs[name] = study(chosen, root / name.replace(" ", "_"), *extra)
            runs[name]["subjects"] = len(chosen)
        if cluster:
            name = f"{subjects} subjects, local Dask cluster (2 workers)"
            runs[name] = on_local_cluster(dirs, root / "cluster")
            runs[name]["subjects"] = subjects
        for r in runs.values():
            r["frames_per_s"] = r["subjects"] * per_subject / r["wall_s"]
        results["study"] = runs
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return results


def table(results: dict) -> str:
    s = results["startup"]
    py = s["python_c_pass_s"]
    rows = [
        f"| `python -c pass` (baseline) | {py:.3f} s |",
        *(
            f"| `fingerfit {flag}` | {s[flag]['wall_s']:.3f} s "
            f"({s[flag]['over_python_s']:.3f} s over the baseline) |"
            for flag in ("--help", "--version")
        ),
    ]
    c = results["cohort"]
    rows.append(
        f"| simulate {c['subjects']} subjects × {c['fingers']} fingers ({c['frames']:,} frames; "
        f"2 processes) | {c['simulate_s']:.0f} s |"
    )
    for name, r in results["study"].items():
        rows.append(
            f"| `fingerfit study`, {name} | {r['wall_s']:.1f} s, "
            f"{r['frames_per_s'] / 1e3:.0f} k frames/s; peak RSS {r['parent_peak_mb']:.0f} MB "
            f"(parent), {r['largest_child_peak_mb']:.0f} MB (largest worker)"
            + (f"; {r['failed']} session(s) failed (--keep-going)" if r["failed"] else "")
            + " |"
        )
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--subjects", type=int, default=100)
    ap.add_argument("--small", type=int, default=20)
    ap.add_argument("--no-cluster", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    results = run(args.subjects, args.small, not args.no_cluster)
    print("| measurement | result |\n|---|---|\n" + table(results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
