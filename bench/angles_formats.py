"""``fingerfit angles`` from Parquet against CSV on a 2 M-row pose recording, before and
after a change, side by side in one run.

    python bench/angles_formats.py [--rows 2000000] [--rounds 5] [--before REV] [--json OUT]

The inputs are ``bench/io_share.py``'s (one finger: the hand sensor and three on the
finger; the free-motion test recording tiled to ``--rows`` rows, ``--rows / 4`` frames),
the test recording also written as a pose CSV, and the subject's model fitted once. Each
round runs, as separate processes in alternating order, ``fingerfit angles model.json
test.EXT -o angles.EXT -q`` for EXT = csv and parquet, on this checkout's ``src`` and on
``--before``'s (``git archive``). Wall time per command (process start to exit: the
imports are part of what a user waits for) and its CPU time (user + system, less sensitive
to other load); medians over the rounds; the ratio Parquet / CSV per revision, and after /
before. The angles CSVs of both revisions are compared byte for byte.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

RUN = "import sys; from fingerfit.cli import main; sys.argv[0] = 'fingerfit'; sys.exit(main())"


def make(work: Path, rows: int) -> tuple[Path, dict[str, Path]]:
    """The model and the test recording as ``{"csv": ..., "parquet": ...}``."""
    from io_share import make_inputs

    from fingerfit.estimate import fit_session
    from fingerfit.io import read_pose_csv, write_pose_csv
    from fingerfit.model import save_model
    from fingerfit.simulate import SimConfig, simulate_subject

    files = make_inputs(work, rows)
    rec = read_pose_csv(files["test"])
    csv = write_pose_csv(work / "test.csv", rec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(simulate_subject(SimConfig(fingers=("index",)), 0).session)
    return save_model(model, work / "model.json"), {"csv": csv, "parquet": files["test"]}


def one(src: Path, model: Path, rec: Path, out: Path) -> tuple[float, float]:
    """``(wall s, CPU s)`` of one ``fingerfit angles`` process on ``src``'s code."""
    out.unlink(missing_ok=True)
    env = dict(os.environ, PYTHONPATH=str(src))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    cmd = [sys.executable, "-c", RUN, "angles", str(model), str(rec), "-o", str(out), "-q"]
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--before", default="HEAD", help="the revision to compare")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    out: dict = {
        "command": " ".join(["python", "bench/angles_formats.py", *sys.argv[1:]]),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "before": args.before,
        "rows": args.rows,
        "rounds": args.rounds,
        "load_average": [os.getloadavg()],
    }
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", args.before, "src"], check=True, capture_output=True
        ).stdout
        (work / "before").mkdir()
        subprocess.run(["tar", "-x", "-C", str(work / "before")], input=archive, check=True)
        trees = {"before": work / "before" / "src", "after": ROOT / "src"}
        model, recs = make(work, args.rows)
        times: dict = {(t, f): [] for t in trees for f in recs}
        for r in range(args.rounds + 1):  # round 0 warms the file cache, not counted
            order = [(t, f) for t in trees for f in recs]
            for tree, fmt in order if r % 2 else order[::-1]:
                w = one(trees[tree], model, recs[fmt], work / f"{tree}.{fmt}")
                if r:
                    times[tree, fmt].append(w)
            out["load_average"].append(os.getloadavg())
        same = (work / "before.csv").read_bytes() == (work / "after.csv").read_bytes()
    out["angles_csv_identical"] = same
    for tree in trees:
        med = {f: np.median(np.array(times[tree, f]), axis=0) for f in recs}
        out[tree] = {
            f"{f}_{k}_s": float(med[f][i]) for f in recs for i, k in enumerate(("wall", "cpu"))
        }
        out[tree]["parquet_over_csv_wall"] = med["parquet"][0] / med["csv"][0]
        out[tree]["parquet_over_csv_cpu"] = med["parquet"][1] / med["csv"][1]
    out["after_over_before"] = {k: out["after"][k] / out["before"][k] for k in out["after"]}
    print(f"{args.rows:,} rows, {args.rounds} rounds, before = {args.before}")
    print("| revision | CSV wall s | Parquet wall s | Parquet / CSV (wall) | CSV CPU s | "
          "Parquet CPU s | Parquet / CSV (CPU) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for tree in trees:
        o = out[tree]
        print(
            f"| {tree} | {o['csv_wall_s']:.2f} | {o['parquet_wall_s']:.2f} | "
            f"{o['parquet_over_csv_wall']:.2f} | {o['csv_cpu_s']:.2f} | {o['parquet_cpu_s']:.2f} "
            f"| {o['parquet_over_csv_cpu']:.2f} |"
        )
    print(f"angles CSV identical before/after: {same}; load average {out['load_average']}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
