"""Shared by the streaming tests: a fitted model and a short recording (built once)."""

from __future__ import annotations

import functools
import re
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io import write_pose_csv
from fingerfit.kinematics import kinematics_table
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import write_subject
from fingerfit.track import track_recording
from fingerfit.track.report import tracking_columns

from .conftest import subject


@functools.cache
def fitted() -> tuple[Path, Path]:
    """``(session_dir, model.json)`` of the cached realistic subject 2 (index finger)."""
    root = Path(tempfile.mkdtemp(prefix="fingerfit-live-"))
    d = write_subject(subject("realistic", 2), root / "S")
    model = root / "model.json"
    res = CliRunner().invoke(app, ["fit", str(d), "-o", str(model), "-q"])
    assert res.exit_code == 0, (res.output, repr(res.exception))
    return d, model


def short_recording(n: int = 240, holes: tuple[tuple[int, str], ...] = ()) -> Recording:
    """The first ``n`` frames of the subject's free-motion test recording (mm, tracker),
    with the sensor of each ``(frame, sensor)`` in ``holes`` missing (NaN)."""
    rec = subject("realistic", 2).session.test[0].slice(slice(0, n))
    poses = {k: PoseSeries(v.position.copy(), v.rotation.copy()) for k, v in rec.poses.items()}
    for i, s in holes:
        poses[s].position[i] = np.nan
        poses[s].rotation[i] = np.nan
    return Recording(rec.name, rec.time.copy(), poses)


def write_recording(path: Path, n: int = 240, holes: tuple[tuple[int, str], ...] = ()) -> Path:
    """:func:`short_recording` as a pose CSV (missing samples are absent rows)."""
    write_pose_csv(path, short_recording(n, holes))
    return path


#: How far a frame the model solved one frame at a time (a stream's robot lane) or block by
#: block (its files) may lie from `fingerfit angles`' solution of the whole recording:
#: deg (angles) and mm (tips, pads).
SOLVED_DEG, SOLVED_MM = 0.5, 0.5


def angles_of(model, rec: Recording) -> tuple[pd.DataFrame, np.ndarray]:
    """What `fingerfit angles` writes for ``rec`` (the model solving missing sensors), and
    the frames in which the model solved a digit."""
    tracked = track_recording(model, rec)
    table = kinematics_table(tracked.kinematics, units=model.session_units)
    table = pd.concat([table, pd.DataFrame(tracking_columns(tracked))], axis=1)
    solved = np.zeros(rec.n_frames, dtype=bool)
    for t in tracked.digits.values():
        solved |= t.model
    return table, solved


#: The same for the orthogonal model's columns, deg and mm: its axes fit the sensors
#: poorly, so a solved frame's PIP/DIP split is what its sensors determine least (about 4
#: deg SD without the middle sensor, docs/tracking.md), and a block of the stream ending
#: at that frame (no frames after it) moves it by up to 2.4 deg on this subject (every
#: block split of 10 frames either side of a hole, frames 5-300).
SOLVED_ORTHOGONAL = 4.0


def solved_tolerance(columns: list[str]) -> np.ndarray:
    """Per column of an angles table, how far a solved frame may lie from `fingerfit
    angles`' (deg or mm): :data:`SOLVED_DEG` (= :data:`SOLVED_MM`), the orthogonal model's
    columns :data:`SOLVED_ORTHOGONAL`."""
    return np.array(
        [SOLVED_ORTHOGONAL if c.startswith("orthogonal.") else SOLVED_DEG for c in columns]
    )


def assert_close_where_solved(
    got: np.ndarray, want: np.ndarray, solved: np.ndarray, tol: float | np.ndarray = SOLVED_DEG
) -> None:
    """``got`` equals ``want`` to 1e-9 in every row but the ``solved`` ones, which agree to
    ``tol`` (a number, or one per column; NaN where ``want`` is NaN)."""
    np.testing.assert_allclose(got[~solved], want[~solved], rtol=0, atol=1e-9)
    diff = np.abs(got[solved] - want[solved])
    same_nan = np.isnan(got[solved]) == np.isnan(want[solved])
    assert same_nan.all(), "NaN where the other is not"
    over = np.nan_to_num(diff) > np.broadcast_to(tol, diff.shape)
    assert not over.any(), (
        f"solved frames differ by up to {np.nanmax(diff, axis=0).round(3).tolist()} "
        f"(tolerance {np.broadcast_to(tol, diff.shape[1:]).tolist()})"
    )


def resolve_prefix(prefix: str, n: int, proc: subprocess.Popen | None = None) -> dict:
    """The LSL streams named ``<prefix>-*`` by name, once at least ``n`` are seen, or
    ``proc`` (the process that makes them) has ended (or after :data:`HANG_S`). Find every
    stream before opening any: ``fingerfit stream --wait`` starts 1 s after its first
    consumer, and a second search can take longer on a loaded machine."""
    import pylsl

    found: dict = {}

    def look() -> bool:
        got = pylsl.resolve_bypred(f"starts-with(name,'{prefix}-')", minimum=n, timeout=1.0)
        found.update({i.name(): i for i in got})
        return len(found) >= n or (proc is not None and proc.poll() is not None)

    until(look, step=0.0)
    return found


#: Seconds a live test waits for anything (a stream to appear, a consumer, a frame, a
#: process to end) before it calls it a hang: a guard, never what a test waits for, so a
#: machine busy with other processes makes the tests slower, not failed.
HANG_S = 120.0


def until(cond: Callable[[], bool], timeout: float = HANG_S, step: float = 0.005) -> bool:
    """Call ``cond`` until it returns True (every ``step`` s). ``timeout`` only guards
    against a hang: a test waits on what it needs, not for a duration.

    Returns
    -------
    bool
        Whether ``cond`` came true (False: ``timeout`` s passed).
    """
    t_end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > t_end:
            return False
        time.sleep(step)
    return True


_COUNT = re.compile(r"(\d+) (frames received|sent|skipped|stale|recorded)\b")


def stream_counts(output: str) -> dict[str, int]:
    """The counts of ``fingerfit stream``'s last line: ``received``, and ``sent``,
    ``skipped``, ``stale`` (a robot lane) and ``recorded`` (a data lane) when there."""
    line = next(ln for ln in output.splitlines() if "frames received" in ln)
    return {k.split()[-1]: int(n) for n, k in _COUNT.findall(line)}


def max_age_ms(output: str) -> float:
    """``age at send max X ms`` of the last line: the oldest frame the robot lane sent."""
    return float(re.search(r"age at send max ([0-9.]+) ms", output).group(1))


def robot_lane_over(model, rec: Recording, frames: np.ndarray) -> np.ndarray:
    """The person's angles the robot lane sends for exactly ``frames`` of ``rec``, in
    order, handed over one at a time (nothing skipped).

    The robot lane's live filter sees only the frames it computes, so a frame it solved
    depends on which frames came before it -- on the machine's load. A stream that sent
    ``frames`` (and computed no other: none stale after its compute) sent these values,
    whatever the load; `fingerfit angles` (the whole recording) is only near them.

    Returns
    -------
    ndarray, shape (len(frames), k)
        The LSL angles rows (deg), the channels of :func:`channels_of`.
    """
    from fingerfit.live.sources import Block
    from fingerfit.live.stream import Streamer

    lsl = FakeLsl()
    streamer = Streamer(model, lsl=lsl, max_age=3600.0)
    for i in frames:
        one = rec.slice(slice(int(i), int(i) + 1))
        streamer.process(Block(one, np.array([time.monotonic()])))
    return np.vstack(lsl.angles)


def sent_frames(
    stamps: np.ndarray,
    t_rec: np.ndarray,
    speed: float,
    got: np.ndarray,
    want: np.ndarray,
    exact: np.ndarray | None = None,
) -> np.ndarray:
    """Which frames of a replay a consumer received (the robot lane sends a subset).

    A replayed frame's timestamp is its due time, start + recording time / ``speed``, so
    the received stamps fix the frames up to the first one; that one is the shift under
    which every received row of a frame with all values finite equals the recording's.

    Parameters
    ----------
    stamps : ndarray, shape (m,)
        Received timestamps (s), any clock.
    t_rec : ndarray, shape (n,)
        Recording time of every frame (s).
    speed : float
    got, want : ndarray, shape (m, k) and (n, k)
        Received values and the recording's (e.g. `fingerfit angles`' columns).
    exact : ndarray of bool, shape (n,), optional
        The frames whose values must match to 1e-9 (default: those with every value
        finite); others (solved by the model one frame at a time) are not compared.

    Returns
    -------
    ndarray of int, shape (m,)
        Frame index of each received row.
    """
    rel = (stamps - stamps[0]) * speed
    tr = t_rec - t_rec[0]
    for k0 in range(len(tr)):
        target = tr[k0] + rel
        idx = np.clip(np.searchsorted(tr, target - 1e-4), 0, len(tr) - 1)
        if np.abs(tr[idx] - target).max() > 1e-4:
            continue
        full = np.isfinite(want[idx]).all(axis=1)  # frames with a missing sensor are held
        if exact is not None:
            full &= exact[idx]
        if full.any() and np.allclose(got[full], want[idx][full], rtol=0, atol=1e-9):
            return idx
    raise AssertionError("the received rows are no subset of the recording's frames")


# Stand-ins for the live outputs and a logging source (the lanes' and watchdog's tests).


class FakeLsl:
    """An LSL output that keeps every push; each takes ``delay`` s (a slow network)."""

    def __init__(self, delay: float = 0.0) -> None:
        self.delay = delay
        self.angles: list[np.ndarray] = []
        self.tips: list[np.ndarray] = []
        self.valid: list[np.ndarray] = []
        self.arrival: list[np.ndarray] = []
        self.robot: list[np.ndarray] = []
        self.source: list[np.ndarray] = []

    def push(self, angles, tips, valid, arrival, robot=None, source=None) -> None:
        self.angles.append(angles.copy())
        self.tips.append(tips.copy())
        if source is not None:
            self.source.append(source.copy())
        self.valid.append(valid.copy())
        self.arrival.append(arrival.copy())
        if robot is not None:
            self.robot.append(robot.copy())
        if self.delay:
            time.sleep(self.delay)

    def has_consumers(self) -> bool:
        return True

    def close(self) -> None:
        pass


class FakeRos2:
    """A DDS output that keeps every message's positions."""

    def __init__(self) -> None:
        self.positions: list[np.ndarray] = []

    def push(self, positions, wall) -> None:
        self.positions.append(positions.copy())

    def push_source(self, codes, wall) -> None:
        pass

    def has_consumers(self) -> bool:
        return True

    def close(self) -> None:
        pass


class Logged:
    """A source that notes every block it hands over (arrival times, sizes); its
    ``warn`` and ``stats`` are the wrapped source's."""

    live = False

    def __init__(self, source) -> None:
        self.source = source
        self.blocks_seen: list[np.ndarray] = []

    @property
    def stats(self):
        return self.source.stats

    @property
    def warn(self):
        return getattr(self.source, "warn", None)

    @warn.setter
    def warn(self, fn) -> None:
        self.source.warn = fn

    def blocks(self):
        for b in self.source.blocks():
            if b is not None:
                self.blocks_seen.append(b.arrival.copy())
            yield b

    def close(self) -> None:
        self.source.close()


def stream_from_outlet(
    stream_type: str,
    labels: list[str],
    units: list[str],
    data: np.ndarray,
    times: np.ndarray,
    model_path: Path,
    record: Path,
    channel_type: str | None = None,
) -> tuple[int, str, str]:
    """Publish ``data`` (n, channels) with ``times`` (s from 0) on an LSL outlet of type
    ``stream_type`` (channel ``labels``, ``units``), 10 samples every 10 ms, to a
    ``fingerfit stream MODEL --source lsl:NAME --record RECORD --duration 1.5`` subprocess
    started first; its exit code, stdout and stderr. The duration ends the stream before
    the source's silence limit (:data:`~fingerfit.live.sources.lsl.NO_DATA_SECONDS`, 2 s)
    would, also when a busy machine starts the stream's loop after every sample was sent
    (they then come in one block, the silence counted from its arrival as the duration
    is)."""
    import os
    import sys

    import pylsl

    name = f"ff{stream_type.lower()}{os.getpid()}"
    info = pylsl.StreamInfo(name, stream_type, len(labels), 240.0, pylsl.cf_double64, name)
    chans = info.desc().append_child("channels")
    for lab, unit in zip(labels, units, strict=True):
        ch = chans.append_child("channel")
        ch.append_child_value("label", lab)
        ch.append_child_value("unit", unit)
        if channel_type is not None:
            ch.append_child_value("type", channel_type)
    outlet = pylsl.StreamOutlet(info)
    fingerfit = str(Path(sys.executable).with_name("fingerfit"))
    proc = subprocess.Popen(
        [fingerfit, "stream", str(model_path), "--source", f"lsl:{name}", "--record",
         str(record), "--duration", "1.5", "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert outlet.wait_for_consumers(HANG_S), "the stream did not connect"
        time.sleep(0.3)
        t0 = pylsl.local_clock()
        for i in range(0, data.shape[0], 10):  # 10 samples every 10 ms
            outlet.push_chunk(data[i : i + 10], (t0 + times[i : i + 10]).tolist())
            time.sleep(0.01)
        out, err = proc.communicate(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, out, err
