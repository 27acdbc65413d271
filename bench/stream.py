"""Streaming benchmark: per-frame compute and end-to-end latency of ``fingerfit stream``.

Run with ``python bench/stream.py`` (``--seconds 10`` for a quick run, ``--json FILE`` to
keep the figures). Two parts, in one run:

1. **Per-frame compute** for each model (one finger; the four fingers; the whole hand
   with the thumb when the simulator has it): one frame at a time through what the
   stream does per block -- :meth:`fingerfit.kinematics.KinematicsPlan.run` of a plan
   built once (user-axis variant), side by side with a fresh
   :func:`fingerfit.kinematics.compute_kinematics` per frame, and the streamed values
   (:func:`fingerfit.live.stream.block_values`) --
   p50 / p99 / max over 2000 frames. The ``hand5-shadow`` row adds, per frame, the
   robot's joints (:meth:`fingerfit.retarget.Retargeter.step` on the block's
   kinematics, Shadow hand, ``tip`` method): what ``fingerfit stream --retarget shadow``
   computes per block.
2. **End to end**: a ``fingerfit stream`` subprocess replays a 240 Hz recording in real
   time (``--seconds`` long) to LSL and to ROS 2 over DDS; this process receives both
   (a pylsl inlet and a cyclonedds reader, each in its own blocking thread) and measures,
   per frame, receipt minus the frame's arrival at fingerfit (LSL: ``local_clock()``
   minus the sample timestamp; DDS: ``time.time()`` minus ``header.stamp``), the frames
   each consumer missed, and the stream process's CPU time over the streaming period
   (``/proc/PID/stat``) as a share of one core, and that of its child processes (the
   live view's, with ``--view-save``). With ``--retarget`` the LSL consumer
   reads the ``PREFIX-robot`` outlet and the DDS reader the robot's ``JointState``.
3. **Overload** (``--overload SPEED,...``, default 4): the whole hand with ``--retarget
   shadow``, ``--lsl --ros2 --record``, replayed ``SPEED`` times faster than real time,
   so frames come faster than one core computes them. The robot lane sends the newest
   frame and none older than ``--max-age`` (20 ms); measured: the age of what the
   consumers receive (arrival at fingerfit -> receipt) against ``--max-age``, the
   stream's own counts (sent, skipped, stale, recorded) and age at send, and whether
   the record holds every frame.
4. **Robot lane per frame, before and after** (``--lane-before REV``, alone): the robot
   lane's own work per one-frame block -- :meth:`fingerfit.live.stream.Streamer.process`:
   the frame's validity, kinematics, the streamed values, the hold, the pushes to three
   real LSL outlets and a DDS writer with no consumer -- p50 / p99 / mean over 3000
   frames, for the one-finger and whole-hand models, measured in child processes that
   import fingerfit from this tree and from ``git archive REV``, alternately
   (``--lane-rounds`` rounds, the order swapped each round) so both see the same load.
5. **The robot lane with and without the view** (``--view-compare``, alone): part 2's end
   to end run of the whole hand with ``--retarget shadow``, once as is and once with
   ``--view-save OUT.rrd`` (the live view of ``--view``, written to a file: the data
   lane hands every frame to the view's own process, which logs it to Rerun; the robot
   lane's sent joints pose its robot),
   alternately (``--view-rounds`` rounds, the order swapped each round); per run the
   consumers' latency (LSL, DDS) and the stream's own arrival -> sent, and the ratios
   with / without of the medians over the rounds.
6. **Against a bare publisher** (``--against-bare``, alone): per model (``--models``,
   default one finger, the whole hand, the whole hand with ``--retarget shadow``), part
   2's end to end run of ``fingerfit stream`` and, alternately in the same run
   (``--bare-rounds`` rounds, the order swapped each round), of a bare publisher: a
   process that publishes the values fingerfit streams for the same recording, computed
   once up front (:func:`bare_frames`), on the replay's schedule to one LSL outlet of the
   same channel count and format as the consumed one and a DDS ``JointState`` writer of
   the same QoS and topic naming, each frame stamped with its due time as the replay
   stamps its arrival, latest-wins and never older than ``--max-age`` as the robot lane
   (:func:`bare_publish`). The same consumers measure both; per model and consumer the
   p50 / p99 of arrival -> receipt over the rounds' frames, for both, and fingerfit's
   added latency (fingerfit minus bare, of the p50 and of the p99). With ``--realtime``
   both publishers ask for the real-time class (their ``realtime:`` lines are kept);
   ``--background-load N`` runs N busy processes (a Python spin loop, normal priority)
   during the measurement (:func:`background_load`). With ``--realtime`` the consumers
   run at a real-time priority too, below the publishers' (:func:`realtime_consumers`),
   unless ``--consumers-normal``.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from fingerfit.estimate import fit_session
from fingerfit.io import write_pose_csv
from fingerfit.kinematics import KinematicsPlan, compute_kinematics
from fingerfit.live.stream import block_values, channels_of, model_sensors
from fingerfit.model import save_model
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject

FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
HAND = ("thumb", "index", "middle", "ring", "little")


def subject_for(fingers: tuple[str, ...]):
    """A simulated subject with these digits, or None if the simulator lacks one."""
    try:
        return simulate_subject(SimConfig(fingers=fingers), 1)
    except (KeyError, ValueError):
        return None


def per_frame_compute(model, rec: Recording, n: int = 2000, retargeter=None) -> dict[str, float]:
    """Microseconds per single-frame block, p50, p99, max: the stream's plan (built once)
    and, interleaved frame by frame, a fresh ``compute_kinematics`` call (``call_*``).
    With a ``retargeter``, each frame's robot joints are part of the stream's time and
    also timed alone (``retarget_*``: :meth:`~fingerfit.retarget.Retargeter.step`;
    ``solver_*``: the tip solver's own time it reports)."""
    sensors = model_sensors(model)
    plan = KinematicsPlan(model, ("user_axis",))
    ch = None
    times, calls, solves, solver = [], [], [], []
    for i in range(n):
        block = rec.slice(slice(i, i + 1))
        t = time.perf_counter()
        kin = plan.run(block)
        if retargeter is not None:
            t_solve = time.perf_counter()
            solver.append(retargeter.step(block, kin)[2][0])  # the tip solver's own time
            solves.append(time.perf_counter() - t_solve)
        ch = ch or channels_of(model, kin)
        block_values(kin, ch, block, sensors, "tracker")
        times.append(time.perf_counter() - t)
        t = time.perf_counter()
        block_values(
            compute_kinematics(model, block, ("user_axis",)), ch, block, sensors, "tracker"
        )
        calls.append(time.perf_counter() - t)
    us, cus = 1e6 * np.array(times[50:]), 1e6 * np.array(calls[50:])  # first frames warm up
    extra = {}
    if solves:
        sus, gus = 1e6 * np.array(solves[50:]), 1e6 * np.array(solver[50:])
        extra = {
            "retarget_p50_us": float(np.percentile(sus, 50)),
            "retarget_p99_us": float(np.percentile(sus, 99)),
            "retarget_max_us": float(sus.max()),
            "solver_p50_us": float(np.percentile(gus, 50)),
            "solver_p99_us": float(np.percentile(gus, 99)),
        }
    return extra | {
        "p50_us": float(np.percentile(us, 50)),
        "p99_us": float(np.percentile(us, 99)),
        "max_us": float(us.max()),
        "call_p50_us": float(np.percentile(cus, 50)),
        "call_p99_us": float(np.percentile(cus, 99)),
        "joints": len(ch.angles),
        "digits": len(ch.digits),
    }


#: Sensors left out of every replayed recording (``--drop``): the stream solves their
#: digits' frames with the model.
DROP: list[str] = []


def long_recording(rec: Recording, seconds: float, rate: float = 240.0) -> Recording:
    """``rec`` repeated to ``seconds`` at ``rate`` (time continues across repeats), without
    the sensors of :data:`DROP`."""
    n = round(seconds * rate)
    idx = np.arange(n) % rec.n_frames
    poses = {
        k: PoseSeries(v.position[idx], v.rotation[idx])
        for k, v in rec.poses.items()
        if k not in DROP
    }
    return Recording("bench.csv", np.arange(n) / rate, poses)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` now (the live view's process of
    ``--view-save``, multiprocessing's resource tracker)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError, IndexError, ValueError):
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(stat.parent.name))
    return found


def total_cpu_seconds(pids: list[int]) -> float:
    """User + system CPU time (s) of these processes (those ended: not counted)."""
    total = 0.0
    for pid in pids:
        with contextlib.suppress(OSError):
            total += cpu_seconds(pid)
    return total


def stream_counts(line: str) -> dict[str, float]:
    """The counts and the age at send of ``fingerfit stream``'s last line."""
    out: dict[str, float] = {
        k.split()[-1]: int(n)
        for n, k in re.findall(r"(\d+) (frames received|sent|skipped|stale|recorded)\b", line)
    }
    age = re.search(r"age at send max ([0-9.]+) ms", line)
    if age:
        out["age_at_send_max_ms"] = float(age.group(1))
    sent = re.search(r"arrival -> sent p50 ([0-9.]+) ms, p99 ([0-9.]+) ms", line)
    if sent:
        out["sent_p50_ms"], out["sent_p99_ms"] = float(sent.group(1)), float(sent.group(2))
    return out


def end_to_end(
    model_path: Path,
    csv: Path,
    n: int,
    tag: str,
    retarget: str | None = None,
    speed: float = 1.0,
    record: Path | None = None,
    extra: tuple[str, ...] = (),
    bare: tuple[str, ...] | None = None,
    raw: bool = False,
) -> dict:
    """Stream ``csv`` (``speed`` times real time) to LSL and DDS; measure latency, losses
    and CPU (``retarget``: ``--retarget ROBOT``, the robot's outlet and JointState;
    ``record``: ``--record`` too, whose rows are counted; ``extra``: more options of
    ``fingerfit stream``).

    ``bare``: the publisher is not ``fingerfit stream`` but :func:`bare_publish`, with
    these arguments after its outlet name and topic (the frames file first). ``raw``: the
    consumers' latencies (ms) too, as arrays ``lsl_ms`` and ``dds_ms``. ``realtime`` is
    the publisher's ``realtime:`` line, if any."""
    import pylsl
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from fingerfit.live.ros2types import JointState

    domain = 1 + os.getpid() % 200
    topic = f"/bench_{tag}_{os.getpid()}"
    participant = DomainParticipant(domain)
    qos = Qos(Policy.Reliability.Reliable(0), Policy.History.KeepAll)
    reader = DataReader(participant, Topic(participant, "rt" + topic, JointState, qos=qos), qos=qos)
    name = f"bench{tag}{os.getpid()}"
    outlet = "robot" if retarget else "angles"
    if bare is None:
        command = [
            FINGERFIT, "stream", str(model_path), "--source", f"replay:{csv}@{speed:g}",
            "--lsl", "--lsl-name", name, "--ros2", topic, "--wait", "--wait-timeout", "60",
            "-q", *(["--retarget", retarget] if retarget else []),
            *(["--record", str(record)] if record else []), *extra,
        ]  # fmt: skip
    else:
        command = [sys.executable, __file__, "--bare-run", f"{name}-{outlet}", topic, *bare]
    proc = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)), preexec_fn=_normal_class,
    )  # fmt: skip
    lsl_lat: list[float] = []
    dds_lat: list[float] = []
    marks: dict[str, float] = {}
    kids: list[int] = []  # the stream's child processes, found at its first frame
    seconds = n / 240.0 / speed
    deadline = time.monotonic() + seconds + 90

    def lsl_consumer() -> None:
        found = pylsl.resolve_byprop("name", f"{name}-{outlet}", timeout=30)
        inlet = pylsl.StreamInlet(found[0], max_buflen=60, processing_flags=0)
        inlet.open_stream(timeout=10)
        while len(lsl_lat) < n and time.monotonic() < deadline:
            _, ts = inlet.pull_sample(timeout=1.0)
            if ts is None:
                if proc.poll() is not None:
                    return
                continue
            lsl_lat.append(pylsl.local_clock() - ts)
            if len(lsl_lat) == 1:
                marks["cpu0"], marks["t0"] = cpu_seconds(proc.pid), time.monotonic()
                kids.extend(children(proc.pid))  # the view's process is up before the stream
                marks["kids0"] = total_cpu_seconds(kids)
            elif len(lsl_lat) % 64 == 0 or len(lsl_lat) == n - 1:  # the last before the end
                with contextlib.suppress(OSError):
                    marks["cpu1"], marks["t1"] = cpu_seconds(proc.pid), time.monotonic()
                    marks["kids1"] = total_cpu_seconds(kids)

    def dds_consumer() -> None:
        while len(dds_lat) < n and time.monotonic() < deadline:
            ended = proc.poll() is not None  # before the take: nothing comes after it
            got = 0
            for m in reader.take_iter(timeout=duration(seconds=1)):
                if isinstance(m, JointState):
                    s = m.header.stamp
                    dds_lat.append(time.time() - (s.sec + 1e-9 * s.nanosec))
                    got += 1
            if ended and not got:  # the writer's last messages are acknowledged by now
                return

    threads = [threading.Thread(target=lsl_consumer), threading.Thread(target=dds_consumer)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=seconds + 120)
    out, err = proc.communicate(timeout=60)
    summary = [ln for ln in out.splitlines() if "frames received" in ln]
    lsl_ms, dds_ms = 1e3 * np.array(lsl_lat), 1e3 * np.array(dds_lat)
    cpu = kids_cpu = None
    if "t1" in marks:
        cpu = (marks["cpu1"] - marks["cpu0"]) / (marks["t1"] - marks["t0"])
        kids_cpu = (marks["kids1"] - marks["kids0"]) / (marks["t1"] - marks["t0"])

    def stats(x: np.ndarray) -> dict[str, float]:
        if not x.size:
            return {}
        return {k: float(np.percentile(x, q)) for k, q in (("p50_ms", 50), ("p99_ms", 99))} | {
            "max_ms": float(x.max())
        }

    counts = stream_counts(summary[0]) if summary else {}
    sent = int(counts.get("sent", n))  # the robot lane's frames: what the consumers can get
    result = {
        "frames": n,
        "speed": speed,
        "counts": counts,
        "lsl": stats(lsl_ms) | {"received": int(lsl_ms.size), "lost": sent - int(lsl_ms.size)},
        "dds": stats(dds_ms) | {"received": int(dds_ms.size), "lost": sent - int(dds_ms.size)},
        "cpu_share_of_one_core": cpu,
        "children_cpu_share_of_one_core": kids_cpu,
        "stream_summary": summary[0] if summary else (out + err)[-500:],
        "realtime": next((ln for ln in err.splitlines() if ln.startswith("realtime:")), None),
    }
    if raw:
        result["lsl_ms"], result["dds_ms"] = lsl_ms, dds_ms
    if record is not None:
        with record.open() as fh:
            result["record_rows"] = sum(1 for _ in fh) - 1
    return result


def print_overload(speed: float, e2e: dict) -> None:
    """One Markdown table row of the overload case."""
    c, lsl, dds = e2e["counts"], e2e["lsl"], e2e["dds"]

    def pq(x: dict) -> str:
        return f"{x.get('p50_ms', float('nan')):.2f} / {x.get('p99_ms', float('nan')):.2f} / {x.get('max_ms', float('nan')):.1f} ms"

    n = e2e["frames"]
    print(
        f"| @{speed:g} ({240 * speed:g} frames/s) | {c.get('received', 0):,} | {c.get('sent', 0):,} "
        f"| {c.get('skipped', 0):,} | {c.get('stale', 0):,} | {c.get('age_at_send_max_ms', float('nan')):.2f} ms "
        f"| {pq(lsl)} | {pq(dds)} | {c.get('recorded', 0):,} of {n:,} (CSV rows {e2e.get('record_rows')}) |",
        flush=True,
    )


def lane_per_frame(model_path: Path, rec_path: Path, n: int = 3000) -> dict[str, float]:
    """Microseconds of the robot lane's work per one-frame block (``Streamer.process``
    with an LSL output and a DDS writer, neither with a consumer), p50 / p99 / mean,
    after 200 frames of warm-up; the fingerfit imported is whichever ``PYTHONPATH``
    names."""
    from fingerfit.io import read_pose_csv
    from fingerfit.live.outputs import LslOutput, Ros2Output
    from fingerfit.live.sources import Block
    from fingerfit.live.stream import Streamer, empty_recording
    from fingerfit.model import load_model

    model = load_model(model_path)
    rec = read_pose_csv(rec_path)
    sensors = model_sensors(model)
    ch = channels_of(model, compute_kinematics(model, empty_recording(sensors), ("user_axis",)))
    tag = f"lane{os.getpid()}"
    lsl = LslOutput(tag, ch.angle_labels, ch.tip_labels, 240.0)
    ros = Ros2Output(f"/{tag}", ch.joint_names)
    streamer = Streamer(model, lsl=lsl, ros2=ros, channels=ch, max_age=60.0)
    blocks = [Block(rec.slice(slice(i, i + 1)), np.zeros(1)) for i in range(rec.n_frames)]
    times = []
    for i in range(n + 200):
        block = blocks[i % len(blocks)]
        block.arrival[0] = time.monotonic()
        t = time.perf_counter()
        streamer.process(block)
        times.append(time.perf_counter() - t)
    streamer.close()
    us = 1e6 * np.array(times[200:])
    return {
        "p50_us": float(np.percentile(us, 50)),
        "p99_us": float(np.percentile(us, 99)),
        "mean_us": float(us.mean()),
        "sent": streamer.summary.sent,
    }


def lane_before_after(rev: str, rounds: int) -> dict:
    """:func:`lane_per_frame` of this tree and of revision ``rev``, in child processes,
    alternately; medians over the rounds and the ratio before / after."""
    root = Path(__file__).resolve().parents[1]
    out: dict = {"before": rev, "rounds": rounds, "load_average_at_start": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "before"
        old.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(root), "archive", rev, "src"], check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
        trees = {"before": str(old / "src"), "after": str(root / "src")}
        for key in ("index", "hand5"):
            sim = subject_for(("index",) if key == "index" else HAND)
            model_path = save_model(fit_session(sim.session), Path(tmp) / f"{key}.json")
            rec_path = write_pose_csv(Path(tmp) / f"{key}.csv", sim.session.test[0])
            runs: dict[str, list] = {"before": [], "after": []}
            for r in range(rounds):
                for label in ("before", "after") if r % 2 == 0 else ("after", "before"):
                    env = os.environ | {"PYTHONPATH": trees[label]}
                    res = subprocess.run(
                        [sys.executable, __file__, "--lane-run", str(model_path), str(rec_path)],
                        env=env, capture_output=True, text=True, check=True,
                    )  # fmt: skip
                    runs[label].append(json.loads(res.stdout.strip().splitlines()[-1]))
            row = {}
            for label, xs in runs.items():
                row[label] = {k: float(np.median([x[k] for x in xs])) for k in xs[0]}
                row[label + "_runs"] = xs
            row["ratio_p50"] = row["before"]["p50_us"] / row["after"]["p50_us"]
            row["ratio_p99"] = row["before"]["p99_us"] / row["after"]["p99_us"]
            row["ratio_mean"] = row["before"]["mean_us"] / row["after"]["mean_us"]
            out[key] = row
            b, a = row["before"], row["after"]
            print(
                f"{key}: robot lane per frame, before ({rev}) p50 {b['p50_us']:.0f} us, p99 "
                f"{b['p99_us']:.0f} us, mean {b['mean_us']:.0f} us; after p50 {a['p50_us']:.0f}"
                f" us, p99 {a['p99_us']:.0f} us, mean {a['mean_us']:.0f} us; before/after "
                f"p50 {row['ratio_p50']:.2f}x, p99 {row['ratio_p99']:.2f}x, mean "
                f"{row['ratio_mean']:.2f}x",
                flush=True,
            )
    out["load_average_at_end"] = os.getloadavg()
    return out


def view_compare(seconds: float, rounds: int) -> dict:
    """Part 5: the whole hand with ``--retarget shadow`` to LSL and DDS, without and with
    ``--view-save``, alternately; medians over the rounds and the ratios with / without."""
    out: dict = {"seconds": seconds, "rounds": rounds, "load_average_at_start": os.getloadavg()}
    keys = {
        "lsl_p50_ms": ("lsl", "p50_ms"),
        "lsl_p99_ms": ("lsl", "p99_ms"),
        "dds_p50_ms": ("dds", "p50_ms"),
        "dds_p99_ms": ("dds", "p99_ms"),
        "sent_p50_ms": ("counts", "sent_p50_ms"),
        "sent_p99_ms": ("counts", "sent_p99_ms"),
    }
    with tempfile.TemporaryDirectory() as tmp:
        sim = subject_for(HAND)
        model_path = save_model(fit_session(sim.session), Path(tmp) / "view.json")
        long = long_recording(sim.session.test[0], seconds)
        csv = write_pose_csv(Path(tmp) / "view.csv", long)
        runs: dict[str, list] = {"without": [], "with": []}
        for r in range(rounds):
            for label in ("without", "with") if r % 2 == 0 else ("with", "without"):
                rrd = Path(tmp) / f"view{r}.rrd"
                extra = ("--view-save", str(rrd)) if label == "with" else ()
                e2e = end_to_end(
                    model_path, csv, long.n_frames, f"view{r}{label}", "shadow", extra=extra
                )
                row = {k: e2e[a].get(b, float("nan")) for k, (a, b) in keys.items()}
                row["lsl_lost"], row["dds_lost"] = e2e["lsl"]["lost"], e2e["dds"]["lost"]
                row["cpu_share_of_one_core"] = e2e["cpu_share_of_one_core"]
                row["view_process_cpu_share"] = e2e["children_cpu_share_of_one_core"]
                row["recorded"] = e2e["counts"].get("recorded", 0)
                if label == "with":
                    row["rrd_mb"] = rrd.stat().st_size / 1e6 if rrd.exists() else None
                runs[label].append(row)
                print(f"view {label} (round {r + 1}): {json.dumps(row)}", flush=True)
    for label, xs in runs.items():
        out[label] = {k: float(np.median([x[k] for x in xs])) for k in keys}
        out[label + "_runs"] = xs
    out["ratio_with_over_without"] = {
        k: out["with"][k] / out["without"][k] for k in keys if out["without"][k] > 0
    }
    out["load_average_at_end"] = os.getloadavg()
    print(
        f"| robot lane ({long.n_frames} frames, 240 Hz, whole hand, --retarget shadow) "
        "| without --view | with --view-save | with / without |"
    )
    print("|---|---|---|---|")
    for k in keys:
        w, v = out["without"][k], out["with"][k]
        print(f"| {k} | {w:.3f} | {v:.3f} | {v / w if w else float('nan'):.2f} |")
    return out


#: A busy process of ``--background-load``: a pure-Python spin loop.
SPIN = "while True: pass"
#: ``prctl`` option (Linux ``<sys/prctl.h>``): the signal a child gets when its parent dies.
PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In a child before ``exec``: SIGKILL when the bench dies, however it ends."""
    import ctypes
    import signal

    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


@contextlib.contextmanager
def background_load(n: int) -> Iterator[list[int]]:
    """``n`` busy processes (:data:`SPIN`, normal priority) while the block runs.

    Parameters
    ----------
    n : int
        How many (0: none).

    Yields
    ------
    list of int
        Their process ids.

    Notes
    -----
    They are stopped when the block ends, however it ends (an error, Ctrl-C), and are
    killed by the kernel if this process dies first (``PR_SET_PDEATHSIG``).
    """
    procs: list[subprocess.Popen] = []
    try:
        for _ in range(n):
            procs.append(
                subprocess.Popen([sys.executable, "-c", SPIN], preexec_fn=_die_with_parent)
            )
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


#: SCHED_FIFO priority of the bench's consumers with ``--realtime``: below the robot
#: lane's (:data:`fingerfit.live.realtime.REALTIME_PRIORITY`).
CONSUMER_PRIORITY = 40


def _normal_class() -> None:
    """In a child before ``exec``: the normal scheduling class (a publisher does not
    inherit the real-time class of :func:`realtime_consumers`)."""
    if hasattr(os, "sched_setscheduler"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


@contextlib.contextmanager
def realtime_consumers(on: bool) -> Iterator[str | None]:
    """SCHED_FIFO (:data:`CONSUMER_PRIORITY`) for this thread while the block runs, and
    so for the threads started meanwhile: the consumers and liblsl's and cyclonedds'
    receive threads (a robot's controller runs at a real-time priority too; at normal
    priority, beside busy processes, the consumers measure their own waits).

    Parameters
    ----------
    on : bool
        Ask for it (False: nothing changes).

    Yields
    ------
    str or None
        What was granted, or why not (None when not asked).
    """
    if not on:
        yield None
        return
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(CONSUMER_PRIORITY))
    except OSError as exc:
        yield f"consumers: SCHED_FIFO not permitted ({errno.errorcode.get(exc.errno or 0)})"
        return
    try:
        yield f"consumers: SCHED_FIFO {CONSUMER_PRIORITY} granted"
    finally:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))


def bare_frames(model, rec: Recording, robot: str | None, path: Path) -> Path:
    """The values ``fingerfit stream`` sends for ``rec``, computed once, for
    :func:`bare_publish`.

    Parameters
    ----------
    model : HandModel
    rec : Recording
        The replayed recording.
    robot : str, optional
        ``--retarget ROBOT``: the robot's joints (the offline ``fingerfit retarget``
        joints, ``tip`` method) instead of the person's.
    path : Path
        The ``.npz`` to write.

    Returns
    -------
    Path
        ``path``, holding ``time (n,)`` s; ``lsl (n, k + 1)``: the consumed outlet's
        channels, ``valid`` last (``PREFIX-angles``, deg; ``PREFIX-robot``, rad);
        ``dds (n, j)`` rad and ``names (j,)``: the ``JointState``'s.
    """
    from fingerfit.live.values import sensor_presence, source_codes
    from fingerfit.track import track_recording
    from fingerfit.track.recording import with_every_sensor

    sensors = model_sensors(model)
    rec = with_every_sensor(rec, sensors)
    kin = track_recording(model, rec, ("user_axis",)).kinematics  # a sensor left out: solved
    ch = channels_of(model, kin)
    source = source_codes(sensor_presence(rec, sensors), sensors, model, ch.digits, True)
    values = block_values(kin, ch, rec, sensors, "tracker", source)
    if robot is None:
        from fingerfit.export.geometry import joint_names

        # The angles outlet's channels: the angles, each digit's source, then valid.
        lsl, dds, names = (
            np.hstack([values.angles, values.source]),
            values.joints,
            joint_names(model),
        )
    else:
        from fingerfit.retarget import Retargeter, resolve

        hand, rmap = resolve(robot, None, model.hand)
        lsl = dds = Retargeter(model, hand, rmap, "tip").step(rec, kin)[0]
        names = list(hand.joint_names)
    np.savez(
        path,
        time=rec.time,
        lsl=np.column_stack([lsl, values.valid]),
        dds=dds,
        names=np.array(names),
    )
    return path


def bare_publish(
    frames: Path, name: str, topic: str, max_age_ms: float, realtime: bool
) -> tuple[str, str | None]:
    """A bare publisher of :func:`bare_frames`' values, in real time.

    One LSL outlet ``name`` (double64, the frames' channel count, as
    :class:`~fingerfit.live.outputs.LslOutput`'s: unchunked, 10 s buffered) and a DDS
    ``JointState`` writer on ``rt/<topic>`` (:func:`~fingerfit.live.outputs.ros2_qos`,
    domain ``ROS_DOMAIN_ID``). Once both have a consumer, frame *i* falls due at start +
    its recording time, as the replay source hands it over; it is stamped with its due
    time (LSL clock; ``header.stamp`` on the system clock), as fingerfit stamps a
    frame's arrival. Of the frames due at a wake-up only the newest is sent, and none
    older than ``max_age_ms``, as the robot lane does.

    Parameters
    ----------
    frames : Path
        :func:`bare_frames`' file.
    name : str
        The LSL outlet's name (``PREFIX-angles`` or ``PREFIX-robot``, as fingerfit's).
    topic : str
        ROS 2 topic (DDS ``rt/<topic>``).
    max_age_ms : float
        ``--max-age``.
    realtime : bool
        Ask for the real-time class (:class:`~fingerfit.live.realtime.Realtime`) once the
        consumers are there, for the outlet's and the writer's threads too, as
        ``fingerfit stream --realtime`` does.

    Returns
    -------
    line : str
        ``fingerfit stream``'s last line for what it did (its counts, arrival -> sent,
        age at send).
    realtime : str or None
        The ``--realtime`` line (``realtime``: asked for as the robot lane asks).
    """
    import pylsl
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from fingerfit.cli.stream import summary_line
    from fingerfit.live.outputs import LslOutput, dds_topic, ros2_qos, ros_domain_id, stamp
    from fingerfit.live.realtime import Realtime, task_ids, threads_started
    from fingerfit.live.ros2types import Header, JointState, Time
    from fingerfit.live.stream import Summary

    data = np.load(frames)
    t = data["time"] - data["time"][0]
    lsl_rows, dds_rows = data["lsl"].tolist(), data["dds"].tolist()
    names = [str(x) for x in data["names"]]
    n, rate = len(t), (len(t) - 1) / t[-1]
    threads_before = task_ids()  # the outlet's and the writer's threads: started from here on
    info = pylsl.StreamInfo(name, "JointAngles", len(lsl_rows[0]), rate, pylsl.cf_double64, name)
    outlet = pylsl.StreamOutlet(info, chunk_size=0, max_buffered=10)
    participant = DomainParticipant(ros_domain_id())
    qos = ros2_qos()
    writer = DataWriter(
        participant, Topic(participant, dds_topic(topic), JointState, qos=qos), qos=qos
    )
    give_up = time.monotonic() + 60
    while not (outlet.have_consumers() and writer.get_matched_subscriptions()):
        if time.monotonic() > give_up:
            raise SystemExit("bare publisher: no consumer within 60 s")
        time.sleep(0.01)
    max_age = max_age_ms / 1e3
    s = Summary()
    line = None
    with contextlib.ExitStack() as rt:
        if realtime:
            native = threads_started(threads_before)  # as fingerfit stream's outputs'
            line = rt.enter_context(Realtime(lane="bare publisher", threads=native)).line()
        lsl_offset = pylsl.local_clock() - time.monotonic()
        wall_offset = time.time() - time.monotonic()
        due = time.monotonic() + t
        i = 0
        while i < n:
            now = time.monotonic()
            if due[i] > now:
                time.sleep(due[i] - now)
                continue
            j = int(np.searchsorted(due, now, side="right"))
            k = j - 1  # the newest frame due; the older ones skipped, or stale
            old = int(np.count_nonzero(now - due[i:k] > max_age))
            s.stale, s.skipped, s.received = (
                s.stale + old,
                s.skipped + k - i - old,
                s.received + j - i,
            )
            i = j
            age = time.monotonic() - due[k]
            if age > max_age:
                s.stale += 1
                continue
            outlet.push_sample(lsl_rows[k], due[k] + lsl_offset)
            sec, nsec = stamp(due[k] + wall_offset)
            writer.write(JointState(Header(Time(sec, nsec), "hand"), names, dds_rows[k], [], []))
            s.sent += 1
            s.add(time.monotonic() - due[k], 0.0, 0, age)
        s.seconds = time.monotonic() - due[0]
    time.sleep(LslOutput.LINGER_S)  # as fingerfit's outputs close: the last frames out
    with contextlib.suppress(Exception):
        writer.wait_for_acks(duration(seconds=1))
    return summary_line(s, True, False, max_age_ms), line


def _pooled(runs: list[dict], key: str) -> dict[str, float]:
    """p50 / p99 (ms) of one consumer's latencies over every run, and the medians of the
    runs' own."""
    x = np.concatenate([r[key] for r in runs])
    out = {"frames": int(x.size)}
    if x.size:
        out |= {"p50_ms": float(np.percentile(x, 50)), "p99_ms": float(np.percentile(x, 99))}
        out["max_ms"] = float(x.max())
    for q in ("p50_ms", "p99_ms"):
        out[f"median_run_{q}"] = float(
            np.median([r[key.split("_")[0]].get(q, np.nan) for r in runs])
        )
    return out


def against_bare(
    models: list[str],
    seconds: float,
    rounds: int,
    load: int,
    realtime: bool,
    max_age_ms: float,
    consumers_realtime: bool = True,
) -> dict:
    """Part 6: ``fingerfit stream`` and a bare publisher of the same frames, alternately,
    to the same consumers; fingerfit's added latency per model and consumer.

    Parameters
    ----------
    models : list of str
        ``index``, ``hand5``, ``hand5-shadow`` (the whole hand with ``--retarget shadow``).
    seconds : float
        Length of each run's replay (240 Hz).
    rounds : int
        Runs of each publisher per model (the order swapped each round).
    load : int
        Busy processes beside the measurement (:func:`background_load`).
    realtime : bool
        ``--realtime`` for both publishers.
    max_age_ms : float
        ``--max-age`` for both publishers.
    consumers_realtime : bool
        With ``realtime``, the consumers at SCHED_FIFO too (:func:`realtime_consumers`).

    Returns
    -------
    dict
        Per model: ``bare`` and ``fingerfit`` (per consumer the p50 / p99 over the rounds'
        frames, the age at send, stale, skipped, lost, the ``realtime:`` lines), their
        runs, and ``added`` (fingerfit minus bare, of the p50 and of the p99); the load
        averages and times.
    """
    out: dict = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "seconds": seconds,
        "rounds": rounds,
        "background_load": load,
        "realtime": realtime,
        "max_age_ms": max_age_ms,
        "started_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "load_average_at_start": os.getloadavg(),
        "models": {},
    }
    wanted = {"index": ("index",), "hand5": HAND, "hand5-shadow": HAND}
    flags = ("--max-age", f"{max_age_ms:g}") + (("--realtime",) if realtime else ())
    with tempfile.TemporaryDirectory() as tmp:
        cases = []
        for key in models:
            sim = subject_for(wanted[key])
            model = fit_session(sim.session)
            model_path = save_model(model, Path(tmp) / f"{key}.json")
            long = long_recording(sim.session.test[0], seconds)
            csv = write_pose_csv(Path(tmp) / f"{key}.csv", long)
            robot = "shadow" if key.endswith("-shadow") else None
            frames = bare_frames(model, long, robot, Path(tmp) / f"{key}.npz")
            cases.append((key, model_path, csv, long.n_frames, robot, frames))
        with (
            background_load(load) as pids,
            realtime_consumers(realtime and consumers_realtime) as consumers,
        ):
            out["background_pids"], out["consumers"] = pids, consumers
            out["load_average_measuring"] = os.getloadavg()
            for key, model_path, csv, n, robot, frames in cases:
                runs: dict[str, list] = {"bare": [], "fingerfit": []}
                for r in range(rounds):
                    for label in ("bare", "fingerfit") if r % 2 == 0 else ("fingerfit", "bare"):
                        tag = f"{key.replace('-', '')}{r}{label[0]}"
                        if label == "bare":
                            bare = (
                                str(frames),
                                f"{max_age_ms:g}",
                                *(("--realtime",) if realtime else ()),
                            )
                            e2e = end_to_end(model_path, csv, n, tag, robot, bare=bare, raw=True)
                        else:
                            e2e = end_to_end(model_path, csv, n, tag, robot, extra=flags, raw=True)
                        runs[label].append(e2e)
                        brief = {k: v for k, v in e2e.items() if k not in ("lsl_ms", "dds_ms")}
                        print(f"{key} {label} (round {r + 1}): {json.dumps(brief)}", flush=True)
                row: dict = {}
                for label, xs in runs.items():
                    row[label] = {c: _pooled(xs, f"{c}_ms") for c in ("lsl", "dds")}
                    row[label]["age_at_send_max_ms"] = max(
                        x["counts"].get("age_at_send_max_ms", np.nan) for x in xs
                    )
                    row[label]["stale"] = sum(int(x["counts"].get("stale", 0)) for x in xs)
                    row[label]["skipped"] = sum(int(x["counts"].get("skipped", 0)) for x in xs)
                    row[label]["lost"] = {c: sum(x[c]["lost"] for x in xs) for c in ("lsl", "dds")}
                    row[label]["realtime"] = sorted({x["realtime"] for x in xs if x["realtime"]})
                    row[label + "_runs"] = [
                        {k: v for k, v in x.items() if k not in ("lsl_ms", "dds_ms")} for x in xs
                    ]
                row["added"] = {
                    c: {q: row["fingerfit"][c][q] - row["bare"][c][q] for q in ("p50_ms", "p99_ms")}
                    for c in ("lsl", "dds")
                }
                out["models"][key] = row
            out["load_average_before_stop"] = os.getloadavg()
    out["load_average_at_end"] = os.getloadavg()
    out["ended_utc"] = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())
    print_against_bare(out)
    return out


def print_against_bare(out: dict) -> None:
    """The Markdown table of part 6: per model and consumer, bare and fingerfit p50 / p99
    and fingerfit's added latency, the age at send and the stale frames."""
    names = {
        "index": "one finger",
        "hand5": "whole hand",
        "hand5-shadow": "whole hand, `--retarget shadow`",
    }
    print(
        "| model | consumer | bare p50 / p99 | fingerfit p50 / p99 | added p50 / p99 "
        "| fingerfit age at send max (stale) | bare age at send max (stale) |"
    )
    print("|---|---|---|---|---|---|---|")
    for key, row in out["models"].items():
        b, f, a = row["bare"], row["fingerfit"], row["added"]
        for c in ("lsl", "dds"):
            print(
                f"| {names.get(key, key)} | {c.upper()} | {b[c]['p50_ms']:.2f} / {b[c]['p99_ms']:.2f} ms "
                f"| {f[c]['p50_ms']:.2f} / {f[c]['p99_ms']:.2f} ms "
                f"| {a[c]['p50_ms']:+.2f} / {a[c]['p99_ms']:+.2f} ms "
                f"| {f['age_at_send_max_ms']:.2f} ms ({f['stale']}) "
                f"| {b['age_at_send_max_ms']:.2f} ms ({b['stale']}) |",
                flush=True,
            )
    if out.get("consumers"):
        print(out["consumers"])
    for key, row in out["models"].items():
        for label in ("fingerfit", "bare"):
            for line in row[label]["realtime"]:
                print(f"{key}, {label}: {line}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="replay length (s)")
    ap.add_argument("--json", type=Path, help="write the figures here")
    ap.add_argument(
        "--models",
        default="index,hand4,hand5,hand5-shadow",
        help="which models to run (hand5-shadow: the whole hand with --retarget shadow; "
        "'none': only the overload case)",
    )
    ap.add_argument(
        "--overload",
        default="4",
        help="replay speeds of the overload case (whole hand, --retarget shadow); '' for none",
    )
    ap.add_argument(
        "--lane-before",
        metavar="REV",
        help="only part 4: the robot lane per frame, this tree against revision REV",
    )
    ap.add_argument("--lane-rounds", type=int, default=3, help="rounds of part 4")
    ap.add_argument(
        "--view-compare",
        action="store_true",
        help="only part 5: the robot lane's latency without and with --view-save",
    )
    ap.add_argument("--view-rounds", type=int, default=2, help="rounds of part 5")
    ap.add_argument(
        "--against-bare",
        action="store_true",
        help="only part 6: fingerfit stream against a bare publisher of the same frames "
        "(--models default index,hand5,hand5-shadow)",
    )
    ap.add_argument("--bare-rounds", type=int, default=3, help="rounds of part 6")
    ap.add_argument(
        "--background-load",
        type=int,
        default=0,
        metavar="N",
        help="part 6: N busy processes (a Python spin loop) while measuring",
    )
    ap.add_argument(
        "--realtime", action="store_true", help="part 6: --realtime for both publishers"
    )
    ap.add_argument(
        "--consumers-normal",
        action="store_true",
        help="part 6 with --realtime: the consumers at normal priority",
    )
    ap.add_argument("--max-age", type=float, default=20.0, help="part 6: --max-age (ms)")
    ap.add_argument(
        "--drop",
        default="",
        help="comma-separated sensors left out of every replayed recording (the model "
        "solves their digits' frames)",
    )
    ap.add_argument("--lane-run", nargs=2, type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--bare-run", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    DROP[:] = [x.strip() for x in args.drop.split(",") if x.strip()]
    from fingerfit.live import quiet_lsl

    quiet_lsl()  # this process's consumers: no liblsl log lines in the report
    if args.lane_run:  # a child of --lane-before
        print(json.dumps(lane_per_frame(*args.lane_run)), flush=True)
        return
    if args.bare_run:  # a child of --against-bare: NAME TOPIC FRAMES MAX_AGE [--realtime]
        name, topic, frames, max_age = args.bare_run[:4]
        line, rt = bare_publish(Path(frames), name, topic, float(max_age), args.realtime)
        if rt is not None:
            print(f"realtime: {rt}", file=sys.stderr, flush=True)
        print(line, flush=True)
        return
    if args.against_bare:
        models = (
            args.models if args.models != ap.get_default("models") else "index,hand5,hand5-shadow"
        )
        results = against_bare(
            models.split(","), args.seconds, args.bare_rounds, args.background_load,
            args.realtime, args.max_age, not args.consumers_normal,
        )  # fmt: skip
        if args.json:
            args.json.write_text(json.dumps(results, indent=1) + "\n")
        return
    if args.view_compare:
        results = view_compare(args.seconds, args.view_rounds)
        if args.json:
            args.json.write_text(json.dumps(results, indent=1) + "\n")
        return
    if args.lane_before:
        results = lane_before_after(args.lane_before, args.lane_rounds)
        if args.json:
            args.json.write_text(json.dumps(results, indent=1) + "\n")
        return
    wanted = {
        "index": ("index",),
        "hand4": ("index", "middle", "ring", "little"),
        "hand5": HAND,
        "hand5-shadow": HAND,
    }
    results: dict = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "seconds": args.seconds,
        "load_average_at_start": os.getloadavg(),
        "models": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        for key in [k for k in args.models.split(",") if k and k != "none"]:
            sim = subject_for(wanted[key])
            if sim is None:
                results["models"][key] = "not available (the simulator has no such digit yet)"
                print(f"{key}: not available", flush=True)
                continue
            model = fit_session(sim.session)
            model_path = save_model(model, Path(tmp) / f"{key}.json")
            rec = sim.session.test[0]
            robot = "shadow" if key.endswith("-shadow") else None
            retargeter = None
            if robot is not None:
                from fingerfit.retarget import Retargeter, resolve

                retargeter = Retargeter(model, *resolve(robot, None, model.hand), "tip")
            compute = per_frame_compute(model, rec, retargeter=retargeter)
            print(f"{key}: per-frame compute {compute}", flush=True)
            long = long_recording(rec, args.seconds)
            csv = write_pose_csv(Path(tmp) / f"{key}.csv", long)
            e2e = end_to_end(model_path, csv, long.n_frames, key.replace("-", ""), robot)
            print(f"{key}: end to end {json.dumps(e2e)}", flush=True)
            results["models"][key] = {"per_frame_compute": compute, "end_to_end": e2e}
        speeds = [float(x) for x in args.overload.split(",") if x.strip()]
        if speeds:
            sim = subject_for(HAND)
            model_path = save_model(fit_session(sim.session), Path(tmp) / "overload.json")
            long = long_recording(sim.session.test[0], args.seconds)
            csv = write_pose_csv(Path(tmp) / "overload.csv", long)
            results["overload"] = {}
            for speed in speeds:
                record = Path(tmp) / f"overload@{speed:g}.csv"
                load0 = os.getloadavg()
                e2e = end_to_end(
                    model_path, csv, long.n_frames, f"over{round(speed)}", "shadow", speed, record
                )
                e2e["load_average"] = [load0, os.getloadavg()]
                print(f"overload @{speed:g}: {json.dumps(e2e)}", flush=True)
                results["overload"][f"@{speed:g}"] = e2e
                print_overload(speed, e2e)
    results["load_average_at_end"] = os.getloadavg()
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
