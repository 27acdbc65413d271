"""The one-axis/two-axis MP decision of the default fit method, before vs after a change.

Run ``python bench/twoaxis_decision.py --before /tmp/before/src`` (``/tmp/before`` a
``git worktree`` of the commit to compare with). Every simulated subject of every
condition is fitted by the default method twice on the same data -- once by the code
under ``--before`` (a subprocess with that ``PYTHONPATH``) and once by this tree -- and
scored as in ``bench/accuracy.py`` (same conditions and seeds): MP axis error (deg),
fingertip error over the free-motion test recording (mm, mean over frames) and whether
the MP became a two-axis joint. Differences are paired per subject (after - before):
mean, SD and a 95 % t interval.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import multiprocessing as mp
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CONDITIONS, FINGER, geometry_errors, tip_errors

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.fit import DEFAULT_METHOD, joint_data, reference_poses
from fingerfit.estimate.robust import robust_hinge
from fingerfit.estimate.twoaxis import fit_two_axis
from fingerfit.session import joint_sensors
from fingerfit.simulate import SimConfig, simulate_subject

DEFAULT_CONDITIONS = "realistic,MP ab/adduction off,ROM small (0.4)"


def rest_ratio(sim) -> float:
    """Lower bound of the rest ab/adduction spread over the RMS misfit (criterion 4).

    The MP fit of ``twoaxis`` repeated by hand (as ``fit._robust_family``); NaN for code
    without the test.
    """
    session = sim.session
    ref = reference_poses(session)
    marks = np.array([session.landmark(f"{FINGER}.{k}") for k in ("mp", "pip", "dip", "tip")])
    _, _, vt = np.linalg.svd(marks - marks.mean(axis=0))
    along = vt[0] if vt[0] @ (marks[-1] - marks[0]) > 0 else -vt[0]
    parent, child = joint_sensors(FINGER)["mp"]
    d = joint_data(session, parent, child, ref, "mp")
    rh = robust_hinge(d.rotation, d.translation, d.periods)
    k = rh.frames
    noise = max(float(np.sqrt(np.mean(rh.fit.centre_residual**2) / 3.0)), 1e-6)
    tf = fit_two_axis(
        d.rotation[k], d.translation[k], d.reference_rotation, rh.fit.axis_parent,
        rh.weights, noise, ref[parent][1].T @ along, groups=rh.labels,
    )  # fmt: skip
    low = getattr(tf, "rest_spread_low_deg", float("nan"))
    return float(low / np.degrees(tf.rms_two_axis_rad))


def run_subject(task: tuple[str, int, int]) -> dict:
    """MP axis error, mean fingertip error and the two-axis flag of one subject."""
    cond, index, seed = task
    warnings.simplefilter("ignore")
    sim = simulate_subject(SimConfig(**CONDITIONS[cond]), seed)
    model = fit_session(sim.session, FitOptions(method=DEFAULT_METHOD, force=True))
    deg, _ = geometry_errors(sim, model)
    return {
        "condition": cond,
        "index": index,
        "mp_deg": deg[0],
        "tip_mm": float(np.nanmean(tip_errors(sim, model))),
        "two_axis": model.fingers[FINGER].second_axes.get("mp") is not None,
        "rest_ratio": rest_ratio(sim),
    }


def run_all(conditions: list[str], subjects: int, seed: int, workers: int) -> list[dict]:
    """Every subject of every condition (seeds as ``bench/accuracy.py``)."""
    tasks = []
    for ci, cond in enumerate(conditions):
        seeds = np.random.SeedSequence([seed, ci]).spawn(subjects)
        tasks += [(cond, i, int(s.generate_state(1)[0])) for i, s in enumerate(seeds)]
    with mp.get_context("spawn").Pool(workers) as pool:
        return pool.map(run_subject, tasks)


def paired(after: np.ndarray, before: np.ndarray) -> str:
    """``mean +/- half-width of the 95 % t interval`` of ``after - before``."""
    d = after - before
    if d.size < 2 or np.all(d == 0):
        return f"{d.mean():+.3f} (identical)" if np.all(d == 0) else f"{d.mean():+.3f}"
    half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
    return f"{d.mean():+.3f} +/- {half:.3f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", type=Path, help="src/ folder of the code to compare with")
    ap.add_argument("--subjects", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=2018)
    ap.add_argument("--conditions", default=DEFAULT_CONDITIONS)
    ap.add_argument("--emit-json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    conditions = [c.strip() for c in args.conditions.split(",")]
    for c in conditions:
        if c not in CONDITIONS:
            ap.error(f"unknown condition '{c}'")
    if args.emit_json:
        print(json.dumps(run_all(conditions, args.subjects, args.seed, args.workers)))
        return
    if args.before is None:
        ap.error("--before is required")
    env = dict(os.environ, PYTHONPATH=str(args.before))
    cmd = [sys.executable, __file__, "--emit-json", "--conditions", args.conditions]
    cmd += ["--subjects", str(args.subjects), "--workers", str(args.workers)]
    cmd += ["--seed", str(args.seed)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
    before = json.loads(out)
    after = run_all(conditions, args.subjects, args.seed, args.workers)
    print(f"command: python bench/twoaxis_decision.py {' '.join(sys.argv[1:])}")
    print(
        "\n| condition | two-axis MP before | after | MP axis before (deg) | after | "
        "paired diff | fingertip before (mm) | after | paired diff |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for cond in conditions:
        b = sorted((r for r in before if r["condition"] == cond), key=lambda r: r["index"])
        a = sorted((r for r in after if r["condition"] == cond), key=lambda r: r["index"])
        row = [cond, f"{sum(r['two_axis'] for r in b)}/{len(b)}"]
        row.append(f"{sum(r['two_axis'] for r in a)}/{len(a)}")
        for key in ("mp_deg", "tip_mm"):
            xb = np.array([r[key] for r in b])
            xa = np.array([r[key] for r in a])
            row += [f"{xb.mean():.2f}", f"{xa.mean():.2f}", paired(xa, xb)]
        print("| " + " | ".join(row) + " |")
        ratio = np.array([r["rest_ratio"] for r in a])
        print(
            f"<!-- {cond}: rest spread bound / RMS misfit {ratio.min():.2f}-{ratio.max():.2f} -->"
        )
        flips = [r["index"] for r, s in zip(b, a, strict=True) if r["two_axis"] != s["two_axis"]]
        if flips:
            print(f"<!-- {cond}: decision changed for subjects {flips} -->")


if __name__ == "__main__":
    main()
