"""Kinematics of the whole hand, this tree against another revision, side by side.

Run with ``python bench/plan_speed.py --before REV`` (``--json FILE`` to keep the figures).
A simulated whole hand (thumb and four fingers, 16 sensors; the fitted model, swing-twist,
two-axis finger MP and thumb CMC and MCP) and, in child processes that import fingerfit
from this tree and from ``git archive REV``, alternately (``--rounds`` rounds, the order
swapped each round, so both see the same load):

* **one frame**: :meth:`fingerfit.kinematics.KinematicsPlan.run` of a plan built once on a
  one-frame recording, what the live stream's robot lane computes per frame -- the
  ``user_axis`` variant and both variants (``fingerfit stream --retarget ... --orthogonal``);
  milliseconds per call, p50 / mean over ``--calls`` calls (the frames of the recording in
  turn), after 200 calls of warm-up, and the process's CPU time per call (``_cpu``: on a
  shared machine, time spent waiting for a core is not in it);
* **long**: :func:`fingerfit.kinematics.compute_kinematics` of a ``--frames``-frame recording
  (the same frames repeated), both variant sets, the median of three calls (ms; wall and
  CPU time).

Each child also writes its outputs of a few hundred one-frame calls and of the long
recording; the figures end with the largest difference between the two trees (deg, mm)
and the count of values that are not the same bits. Single-threaded BLAS, as the other
benchmarks (``OPENBLAS_NUM_THREADS=1``; a child inherits an explicit setting). Medians
over the rounds and the ratios after / before, with the load average.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HAND = ("thumb", "index", "middle", "ring", "little")
VARIANT_SETS = {"user_axis": ("user_axis",), "both": ("user_axis", "orthogonal")}


def prepare(folder: Path, frames: int) -> tuple[Path, Path]:
    """The whole hand's fitted model (JSON) and a recording of it (npz), in ``folder``."""
    from fingerfit.estimate import fit_session
    from fingerfit.model import save_model
    from fingerfit.simulate import SimConfig, simulate_subject

    sim = simulate_subject(SimConfig(fingers=HAND), 0)
    model_path = save_model(fit_session(sim.session), folder / "hand.json")
    rec = sim.session.recordings()[0]
    arrays = {f"{k}|position": v.position for k, v in rec.poses.items()}
    arrays |= {f"{k}|rotation": v.rotation for k, v in rec.poses.items()}
    rec_path = folder / "hand.npz"
    np.savez(rec_path, time=rec.time, frames=frames, **arrays)
    return model_path, rec_path


def load_recording(path: Path, n: int | None = None):
    """The recording of :func:`prepare`, repeated to ``n`` frames (``None``: as saved)."""
    from fingerfit.session import PoseSeries, Recording

    data = np.load(path)
    sensors = sorted({k.split("|")[0] for k in data.files if "|" in k})
    size = len(data["time"]) if n is None else n
    reps = -(-size // len(data["time"]))

    def tile(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([a] * reps)[:size])

    poses = {
        s: PoseSeries(tile(data[f"{s}|position"]), tile(data[f"{s}|rotation"])) for s in sensors
    }
    return Recording("bench", np.arange(size) / 240.0, poses)


def child(model_path: Path, rec_path: Path, calls: int, out: Path) -> dict:
    """This process's figures (the fingerfit that ``PYTHONPATH`` names); outputs to ``out``."""
    from fingerfit.kinematics import KinematicsPlan, compute_kinematics
    from fingerfit.model import load_model

    model = load_model(model_path)
    rec = load_recording(rec_path)
    frames = [rec.slice(slice(i, i + 1)) for i in range(rec.n_frames)]
    n_long = int(np.load(rec_path)["frames"])
    long = load_recording(rec_path, n_long)
    result: dict = {}
    values: dict[str, np.ndarray] = {}
    for key, variants in VARIANT_SETS.items():
        plan = KinematicsPlan(model, variants)
        for i in range(200):
            plan.run(frames[i % len(frames)])
        times = []
        cpu = time.process_time()
        for i in range(calls):
            t = time.perf_counter()
            plan.run(frames[i % len(frames)])
            times.append(time.perf_counter() - t)
        cpu = time.process_time() - cpu
        ms = 1e3 * np.array(times)
        result[f"one_frame_{key}_p50_ms"] = float(np.median(ms))
        result[f"one_frame_{key}_mean_ms"] = float(ms.mean())
        result[f"one_frame_{key}_cpu_ms"] = 1e3 * cpu / calls
        values[f"one_frame_{key}"] = np.concatenate(
            [flat(plan.run(f)) for f in frames[: min(len(frames), 300)]]
        )
        times, cpus = [], []
        for _ in range(3):
            t, cpu = time.perf_counter(), time.process_time()
            kin = compute_kinematics(model, long, variants)
            times.append(time.perf_counter() - t)
            cpus.append(time.process_time() - cpu)
        result[f"long_{key}_ms"] = 1e3 * float(np.median(times))
        result[f"long_{key}_cpu_ms"] = 1e3 * float(np.median(cpus))
        values[f"long_{key}"] = flat(kin)
    np.savez(out, **values)
    return result


def flat(kin) -> np.ndarray:
    """Every angle (deg) and point (mm) of a :class:`~fingerfit.kinematics.Kinematics`."""
    parts = []
    for fingers in kin.motions.values():
        for m in fingers.values():
            parts += [np.degrees(a) for a in m.angles.values()]
            parts += [p.ravel() for p in (m.tip, m.pad) if p is not None]
    return np.concatenate(parts)


def compare(before: Path, after: Path) -> dict:
    """Largest difference (deg, mm) and the count of values whose bits differ."""
    a, b = np.load(before), np.load(after)
    out = {}
    for k in a.files:
        x, y = a[k], b[k]
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        both = np.isfinite(x) & np.isfinite(y)
        diff = float(np.max(np.abs(x[both] - y[both]))) if both.any() else 0.0
        out[k] = {"max_abs_diff": diff, "not_same_bits": int((~same).sum()), "values": x.size}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", metavar="REV", default="main", help="the revision to compare")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--calls", type=int, default=3000, help="one-frame calls per child")
    ap.add_argument("--frames", type=int, default=100_000, help="frames of the long recording")
    ap.add_argument("--json", type=Path, help="write the figures here")
    ap.add_argument("--run", nargs=4, help=argparse.SUPPRESS)  # a child
    args = ap.parse_args()
    if args.run:
        model_path, rec_path, calls, out = args.run
        print(json.dumps(child(Path(model_path), Path(rec_path), int(calls), Path(out))))
        return
    root = Path(__file__).resolve().parents[1]
    out: dict = {"before": args.before, "rounds": args.rounds, "load_average": [os.getloadavg()]}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "before").mkdir()
        archive = subprocess.run(
            ["git", "-C", str(root), "archive", args.before, "src"], check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(folder / "before")], input=archive, check=True)
        trees = {"before": str(folder / "before" / "src"), "after": str(root / "src")}
        model_path, rec_path = prepare(folder, args.frames)
        runs: dict[str, list] = {"before": [], "after": []}
        for r in range(args.rounds):
            for label in ("before", "after") if r % 2 == 0 else ("after", "before"):
                env = os.environ | {"PYTHONPATH": trees[label]}
                res = subprocess.run(
                    [sys.executable, __file__, "--run", str(model_path), str(rec_path),
                     str(args.calls), str(folder / f"{label}.npz")],
                    env=env, capture_output=True, text=True, check=True,
                )  # fmt: skip
                runs[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
                print(f"round {r + 1} {label}: {runs[label][-1]}", flush=True)
            out["load_average"].append(os.getloadavg())
        for label, xs in runs.items():
            out[label] = {k: float(np.median([x[k] for x in xs])) for k in xs[0]}
            out[label + "_runs"] = xs
        out["ratio_after_before"] = {k: out["after"][k] / out["before"][k] for k in out["before"]}
        out["same_numbers"] = compare(folder / "before.npz", folder / "after.npz")
    b, a, q = out["before"], out["after"], out["ratio_after_before"]
    for k in b:
        print(f"{k}: before {b[k]:.4g} ms, after {a[k]:.4g} ms, after/before {q[k]:.3f}x")
    for k, v in out["same_numbers"].items():
        print(f"{k}: max |after - before| {v['max_abs_diff']:.3g} (deg, mm), "
              f"{v['not_same_bits']} of {v['values']} values not the same bits")  # fmt: skip
    print("load average (1, 5, 15 min) at the start and after each round:", out["load_average"])
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
