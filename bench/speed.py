"""Speed benchmark: fit time per finger, angles + fingertip throughput, readers and writers.

Run with ``make bench`` (``python bench/speed.py --json bench/speed.json``).
Single-threaded BLAS so "per core" figures mean one core. Throughput is
compared, in the same run, with a plain NumPy copy of the same input arrays
(the memory-bound limit), and reported as a ratio.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.fit import METHODS, fit_finger, reference_poses
from fingerfit.kinematics import compute_kinematics
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject


def best_of(fn, repeat: int) -> float:
    """Minimum wall time (s) over ``repeat`` calls: the least disturbed run on a shared machine."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def load_kinematics(path: Path):
    """Another version of ``fingerfit/kinematics.py`` as a module of the installed package."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("fingerfit._kinematics_before", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def long_recording(rec: Recording, n_frames: int) -> Recording:
    """Tile a recording up to ``n_frames`` frames (hand + one finger's sensors)."""
    reps = -(-n_frames // rec.n_frames)
    poses = {
        k: PoseSeries(
            np.tile(v.position, (reps, 1))[:n_frames], np.tile(v.rotation, (reps, 1, 1))[:n_frames]
        )
        for k, v in rec.poses.items()
    }
    return Recording("long", np.arange(n_frames) / 240.0, poses)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--frames", type=int, default=1_200_000)
    ap.add_argument(
        "--study-subjects", type=int, default=100, help="0: no start-up and study benchmark"
    )
    ap.add_argument(
        "--cluster-subjects",
        type=int,
        default=0,
        help="also a cohort of this many subjects simulated in the workers of a local Dask "
        "cluster (bench/study_speed.py; 1000: about half an hour on 2 cores)",
    )
    ap.add_argument(
        "--before",
        type=Path,
        default=None,
        help="a kinematics.py to time beside the current one in the same run "
        "(e.g. from `git worktree add /tmp/kbefore <commit>`)",
    )
    ap.add_argument(
        "--io-rows", type=int, default=2_000_000, help="rows per reader/writer file; 0: skip"
    )
    ap.add_argument(
        "--io-before",
        type=Path,
        default=None,
        help="the src folder of older code, to time its readers and writers in the same run",
    )
    args = ap.parse_args()

    sim = simulate_subject(SimConfig(), 0)
    session = sim.session
    results: dict = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "fit": {},
        "angles": {},
    }
    ref = reference_poses(session)
    for method in METHODS:
        opts = FitOptions(method=method)
        t = best_of(lambda opts=opts: fit_finger(session, "index", ref, opts), 7)
        results["fit"][method] = {
            "seconds_per_finger": t,
            "grasp_frames": session.grasp[0].n_frames,
        }
    rec = long_recording(session.test[0], args.frames)
    arrays = [a for v in rec.poses.values() for a in (v.position, v.rotation)]
    n = rec.n_frames
    t_copy = best_of(lambda: [a.copy() for a in arrays], 3)
    results["angles"] = {
        "frames": n,
        "input_bytes": int(sum(a.nbytes for a in arrays)),
        "copy_frames_per_s": n / t_copy,
    }
    angle_rows = []
    old = load_kinematics(args.before) if args.before is not None else None
    for method in ("tang2018", FitOptions.method):
        model = fit_session(session, FitOptions(method=method))
        t_user = best_of(lambda m=model: compute_kinematics(m, rec, variants=("user_axis",)), 3)
        t_both = best_of(lambda m=model: compute_kinematics(m, rec), 3)
        kind = f"{model.angle_method}{', two-axis MP' if model.fingers['index'].second_axes.get('mp') else ''}"
        results["angles"][method] = {
            "angle_method": kind,
            "user_axis_frames_per_s": n / t_user,
            "both_variants_frames_per_s": n / t_both,
            "user_axis_time_over_copy": t_user / t_copy,
        }
        if old is not None:
            tb = best_of(lambda m=model: old.compute_kinematics(m, rec, variants=("user_axis",)), 3)
            results["angles"][method]["before_user_axis_frames_per_s"] = n / tb
            angle_rows.append(
                f"| angles + fingertip, `{method}` model, user-axis, one finger, `{args.before}` "
                f"| {n / tb / 1e6:.1f} M frames/s ({tb / t_copy:.1f}x the copy time) |"
            )
        angle_rows.append(
            f"| angles + fingertip, `{method}` model ({kind}), user-axis, one finger "
            f"| {n / t_user / 1e6:.1f} M frames/s ({t_user / t_copy:.1f}x the copy time) |\n"
            f"| angles + fingertip, `{method}` model, both variants, one finger "
            f"| {n / t_both / 1e6:.1f} M frames/s |"
        )
    fit_rows = "\n".join(
        f"| fit one finger (`{m}`, {r['grasp_frames']} grasp frames) | {1000 * r['seconds_per_finger']:.1f} ms |"
        for m, r in results["fit"].items()
    )
    a = results["angles"]
    print(f"""| measurement | result |
|---|---|
{fit_rows}
| NumPy copy of the input ({n:,} frames, {a["input_bytes"] / 1e6:.0f} MB) | {a["copy_frames_per_s"] / 1e6:.1f} M frames/s |
{chr(10).join(angle_rows)}""")
    if args.io_rows:
        import io_speed  # bench/io_speed.py, beside this file

        results["io"] = io_speed.run(args.io_rows, args.io_before)
        print(io_speed.table(results["io"]))
    if args.study_subjects or args.cluster_subjects:
        import study_speed  # bench/study_speed.py, beside this file

        results["study_speed"] = study_speed.run(
            args.study_subjects, cluster_subjects=args.cluster_subjects
        )
        print(study_speed.table(results["study_speed"]))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
