"""Tracking speed: a whole hand with missing sensors, offline and one frame at a time.

Run with ``.venv/bin/python bench/tracking_speed.py --json bench/tracking_speed.json``.

A simulated whole hand (thumb and four fingers) is fitted; its free-motion test recording
repeated to ``--frames`` frames (240 Hz) is then computed, in one process, side by side:

* **offline** (:func:`fingerfit.track.track_recording`, what ``fingerfit angles`` runs):
  every sensor (the direct computation), each digit's middle sensor missing (one sensor
  per digit: the thumb's proximal phalanx, the fingers' middle), and the hand with each
  digit's distal sensor only; the user-axis model alone and both variants; best of
  ``--repeat`` wall times, and CPU time;
* **one frame at a time** (the stream's robot lane, user-axis model): per frame what
  :meth:`fingerfit.live.stream.Streamer` computes before the values -- the direct
  computation of a prepared :class:`fingerfit.kinematics.KinematicsPlan` and, where a
  sensor is missing, :meth:`fingerfit.track.live.LiveTracker.step` -- p50 / p99 / max over
  ``--live-frames`` frames, every sensor and one per digit missing, alternately;
* **live against offline**: the same frames one at a time (the filter, which cannot look
  ahead) against the offline solution of the whole recording (the smoother), RMS and
  largest difference per angle kind, for each digit's middle sensor missing and for the
  distal sensors only.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import json
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.kinematics import KinematicsPlan
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.track import track_recording
from fingerfit.track.live import LiveTracker
from fingerfit.track.recording import with_every_sensor

DIGITS = ("thumb", "index", "middle", "ring", "little")
MIDDLE = {"thumb": "thumb.proximal"} | {d: f"{d}.middle" for d in DIGITS[1:]}
DISTAL = {d: f"{d}.distal" for d in DIGITS}


def tiled(rec: Recording, n: int) -> Recording:
    """``rec`` repeated to ``n`` frames at 240 Hz."""
    idx = np.arange(n) % rec.n_frames
    poses = {k: PoseSeries(v.position[idx], v.rotation[idx]) for k, v in rec.poses.items()}
    return Recording("bench.csv", np.arange(n) / 240.0, poses)


def layouts(rec: Recording) -> dict[str, Recording]:
    keep_distal = {"hand", *DISTAL.values()}
    return {
        "every sensor": rec,
        "one sensor per digit missing (middle)": Recording(
            rec.name, rec.time, {k: v for k, v in rec.poses.items() if k not in MIDDLE.values()}
        ),
        "hand + distal sensors": Recording(
            rec.name, rec.time, {k: v for k, v in rec.poses.items() if k in keep_distal}
        ),
    }


def offline(model, rec: Recording, repeat: int) -> dict:
    out = {}
    for name, r in layouts(rec).items():
        for variants in (("user_axis",), ("user_axis", "orthogonal")):
            walls, cpus = [], []
            for _ in range(repeat):
                t, c = time.perf_counter(), time.process_time()
                track_recording(model, r, variants)
                walls.append(time.perf_counter() - t)
                cpus.append(time.process_time() - c)
            key = f"{name}, {' + '.join(variants)}"
            out[key] = {"wall_s": min(walls), "cpu_s": min(cpus), "frames": r.n_frames}
            print(f"offline {key}: {min(walls):.2f} s wall, {min(cpus):.2f} s cpu", flush=True)
    return out


def live(model, rec: Recording, n: int) -> dict:
    """Per-frame cost of the robot lane's kinematics, every sensor and one per digit
    missing, frame by frame alternately (the same load on both)."""
    sensors = list(model.reference_poses)
    full = with_every_sensor(rec, sensors)
    gone = with_every_sensor(layouts(rec)["one sensor per digit missing (middle)"], sensors)
    plan = KinematicsPlan(model, ("user_axis",))
    tracker = LiveTracker(model)
    frames = {
        "every sensor": [full.slice(slice(i, i + 1)) for i in range(n)],
        "one sensor per digit missing": [gone.slice(slice(i, i + 1)) for i in range(n)],
    }
    times: dict[str, list[float]] = {k: [] for k in frames}
    for i in range(n):
        one = frames["every sensor"][i]
        t = time.perf_counter()
        plan.run(one)
        times["every sensor"].append(time.perf_counter() - t)
        one = frames["one sensor per digit missing"][i]
        t = time.perf_counter()
        kin = tracker.blank(one)  # no digit complete: the stream skips the plan
        tracker.step(one, kin)
        times["one sensor per digit missing"].append(time.perf_counter() - t)
    out = {}
    for k, v in times.items():
        us = 1e6 * np.array(v[50:])  # the first frames warm up
        out[k] = {
            "p50_us": float(np.percentile(us, 50)),
            "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max()),
        }
        print(f"live {k}: {json.dumps(out[k])}", flush=True)
    return out


KINDS = {
    "finger MP": ("fingers", ("mp", "mp_abduction")),
    "finger PIP, DIP": ("fingers", ("pip", "dip")),
    "thumb CMC": ("thumb", ("cmc", "cmc_abduction")),
    "thumb MCP, IP": ("thumb", ("mcp", "mcp_abduction", "ip")),
}


def agreement(model, rec: Recording, n: int) -> dict:
    """The live filter, frame by frame, against the offline solution, deg."""
    sensors = list(model.reference_poses)
    out = {}
    for name, r in layouts(rec).items():
        if name == "every sensor":
            continue
        r = with_every_sensor(r.slice(slice(0, n)), sensors)
        off = track_recording(model, r, ("user_axis",)).kinematics.motions["user_axis"]
        tracker = LiveTracker(model)
        got = {d: {k: np.empty(n) for k in off[d].angles} for d in off}
        for i in range(n):
            one = r.slice(slice(i, i + 1))
            kin = tracker.blank(one)
            tracker.step(one, kin)
            for d, m in kin.motions["user_axis"].items():
                for k, a in m.angles.items():
                    got[d][k][i] = a[0]
        rows = {}
        for kind, (which, names) in KINDS.items():
            digits = ["thumb"] if which == "thumb" else [d for d in DIGITS if d != "thumb"]
            diff = np.concatenate(
                [
                    np.degrees(got[d][k] - off[d].angles[k])
                    for d in digits
                    for k in names
                    if k in off[d].angles
                ]
            )
            rows[kind] = {
                "rms_deg": float(np.sqrt(np.mean(diff**2))),
                "max_deg": float(np.abs(diff).max()),
            }
        out[name] = rows
        print(f"live vs offline, {name}: {json.dumps(rows)}", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--live-frames", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=1234)
    ap.add_argument("--agreement-frames", type=int, default=2400)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    sim = simulate_subject(SimConfig(fingers=DIGITS), args.seed)
    model = fit_session(sim.session, FitOptions(force=True))
    rec = sim.session.test[0]
    load0 = os.getloadavg()
    results = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": ("python bench/tracking_speed.py " + " ".join(sys.argv[1:])).strip(),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "offline": offline(model, tiled(rec, args.frames), args.repeat),
        "live": live(model, rec, args.live_frames),
        "live_vs_offline": agreement(model, rec, args.agreement_frames),
    }
    results["load_average"] = [load0, os.getloadavg()]
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
