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
  ``RUSAGE_CHILDREN``; a worker's figure includes what it shared with its parent at start);
  the study process's growth per subject between the two cohort sizes;
- ``--cluster-subjects N``: an ``N``-subject cohort on a local Dask cluster (2 worker
  processes, 1 thread each) that is simulated in the workers: each study task simulates
  its subject (:class:`fingerfit.simulate.source.SimulatedSession`), writes the session
  folder to a temporary folder there, studies it like any folder and removes it, so the
  cohort needs neither the time nor the disk (34 MB per subject) up front. Its wall time
  therefore includes the simulation, measured separately per subject in this process.
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

_SOURCES = """
import json, sys, time
from pathlib import Path
from fingerfit.evaluate import run_study
from fingerfit.simulate import SimConfig
from fingerfit.simulate.source import simulated_cohort
n, out, address = {n!r}, Path({out!r}), {address!r}
sources = simulated_cohort(SimConfig(fingers={fingers!r}), n, 2018)
t = time.perf_counter()
done = [0]
def step(msg):
    done[0] += 1
    if done[0] % 50 == 0 or not msg.startswith(("fitted", "failed", "could not")):
        print(f"{{time.perf_counter() - t:7.1f}} s  {{done[0]}} steps  {{msg}}", file=sys.stderr,
              flush=True)
result = run_study(sources, out, progress=step, keep_going=True, scheduler=address)
wall = time.perf_counter() - t
status = open("/proc/self/status").read().split("VmHWM:")[1].split()
print("\\n" + json.dumps({{"wall_s": wall, "parent_peak_mb": int(status[0]) / 1024,
                          "frames": sum(s.frames for s in result.subjects),
                          "failed": len(result.failures)}}))
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


def simulated_in_workers(address: str, n: int, out: Path) -> dict:
    """``run_study`` of an ``n``-subject cohort simulated in the workers of ``address``,
    in a fresh process: wall time, its peak RSS, frames studied, failed sessions."""
    code = _SOURCES.format(n=n, out=str(out), address=address, fingers=FINGERS)
    # stderr (progress every 50 subjects) goes to the benchmark's own stderr.
    res = subprocess.run([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    if res.returncode:
        raise RuntimeError(f"the {n}-subject study failed (its error above)")
    found = json.loads(res.stdout.strip().splitlines()[-1])
    found["subjects"] = n
    return found


def simulate_one_s(repeat: int = 3) -> float:
    """Mean wall time (s) to simulate and write one subject (4 fingers), in this process."""
    from fingerfit.simulate import SimConfig, simulate_subject, write_subject

    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            t = time.perf_counter()
            sim = simulate_subject(SimConfig(fingers=FINGERS), 1000 + i, f"T{i}")
            write_subject(sim, Path(tmp) / f"T{i}")
            times.append(time.perf_counter() - t)
    return statistics.mean(times)


def on_local_cluster(sessions: list[Path] | int, out: Path) -> dict:
    """The study on a fresh local Dask cluster: of session folders (through ``fingerfit
    study --scheduler``), or of that many subjects simulated in the workers."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _CLUSTER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        address = json.loads(proc.stdout.readline())
        if isinstance(sessions, int):
            result = simulated_in_workers(address, sessions, out)
        else:
            result = study(sessions, out, "--scheduler", address)
    finally:
        proc.stdin.close()
    # The tasks ran in the cluster's worker processes, children of the cluster process.
    result["largest_child_peak_mb"] = json.loads(proc.stdout.read().strip().splitlines()[-1])
    proc.wait(timeout=120)
    return result


def run(
    subjects: int = 100, small: int = 20, cluster: bool = True, cluster_subjects: int = 0
) -> dict:
    results: dict = {"startup": startup(), "study": {}}
    root = Path(tempfile.mkdtemp(prefix="fingerfit-bench-"))
    try:
        if subjects:
            folder_studies(results, root, subjects, small, cluster)
        if cluster_subjects:
            name = f"{cluster_subjects} subjects simulated in the workers, local Dask cluster"
            results["simulate_one_s"] = simulate_one_s()
            started, load = time.strftime("%Y-%m-%d %H:%M", time.gmtime()), os.getloadavg()[0]
            r = on_local_cluster(cluster_subjects, root / "cluster-sim")
            r["frames_per_s"] = r["frames"] / r["wall_s"]
            r["started"], r["load_average"] = started, load
            r["load_average_end"] = os.getloadavg()[0]
            results["study"][name] = r
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return results


def folder_studies(results: dict, root: Path, subjects: int, small: int, cluster: bool) -> None:
    """Simulate ``subjects`` session folders and study them: ``--jobs 1`` and ``2`` on the
    first ``small``, ``--jobs 2`` and (``cluster``) a local Dask cluster on all."""
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
    a, b = runs[f"{small} subjects, --jobs 2"], runs[f"{subjects} subjects, --jobs 2"]
    results["growth_kb_per_subject"] = {
        "parent": (b["parent_peak_mb"] - a["parent_peak_mb"]) * 1024 / (subjects - small),
        "largest_worker": (b["largest_child_peak_mb"] - a["largest_child_peak_mb"])
        * 1024
        / (subjects - small),
    }
    results["study"].update(runs)


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
    c = results.get("cohort")
    if c:
        rows.append(
            f"| simulate {c['subjects']} subjects × {c['fingers']} fingers ({c['frames']:,} "
            f"frames; 2 processes) | {c['simulate_s']:.0f} s |"
        )
    if "simulate_one_s" in results:
        rows.append(
            f"| simulate and write one subject × {len(FINGERS)} fingers (mean of 3, one process) "
            f"| {results['simulate_one_s']:.2f} s |"
        )
    for name, r in results["study"].items():
        what = "`run_study`" if "simulated in the workers" in name else "`fingerfit study`"
        frames = f" ({r['frames']:,} frames)" if "frames" in r else ""
        when = (
            f"; started {r['started']} UTC, load average {r['load_average']:.1f} before, "
            f"{r['load_average_end']:.1f} after"
            if "started" in r
            else ""
        )
        rows.append(
            f"| {what}, {name}{frames} | {r['wall_s']:.1f} s, "
            f"{r['frames_per_s'] / 1e3:.0f} k frames/s; peak RSS {r['parent_peak_mb']:.0f} MB "
            "(study process)"
            + (
                f", {r['largest_child_peak_mb']:.0f} MB (largest worker)"
                if r["largest_child_peak_mb"] >= 1
                else " (no workers)"
            )
            + (f"; {r['failed']} session(s) failed (--keep-going)" if r["failed"] else "")
            + when
            + " |"
        )
    g = results.get("growth_kb_per_subject")
    if g:
        rows.append(
            f"| peak RSS growth per subject, {c['subjects']} vs the small cohort, `--jobs 2` "
            f"| {g['parent']:.0f} KB (study process), {g['largest_worker']:.0f} KB "
            "(largest worker) |"
        )
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--subjects", type=int, default=100)
    ap.add_argument("--small", type=int, default=20)
    ap.add_argument("--no-cluster", action="store_true", help="no Dask run of the folders")
    ap.add_argument(
        "--cluster-subjects",
        type=int,
        default=0,
        help="also study this many subjects simulated in the workers of a local Dask cluster",
    )
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    results = run(args.subjects, args.small, not args.no_cluster, args.cluster_subjects)
    print("| measurement | result |\n|---|---|\n" + table(results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
