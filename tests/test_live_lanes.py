"""The stream's two lanes and its watchdog, in-process and without a network.

Stand-in live outputs keep what the robot lane pushes (and can be slow, which overloads
the stream whatever the machine); a replayed recording is the source. The tests assert
counts, order and values -- never a duration, which belongs in ``bench/stream.py``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fingerfit.io import write_pose_csv
from fingerfit.kinematics import compute_kinematics, kinematics_table
from fingerfit.live.outputs import RecordOutput
from fingerfit.live.sources import ReplaySource
from fingerfit.live.stream import Streamer, channels_of, run
from fingerfit.model import load_model
from fingerfit.session import PoseSeries, Recording

from ._live import (
    FakeLsl,
    FakeRos2,
    Logged,
    angles_of,
    assert_close_where_solved,
    fitted,
    robot_lane_over,
    short_recording,
    solved_tolerance,
    stream_counts,
)
from .bad_inputs._cli import refused
from .bad_inputs._cli import run as cli

N = 480
HOLES = ((50, "index.middle"), (51, "index.middle"), (120, "hand"), (300, "index.distal"))


def test_overload_sends_the_newest_fresh_frame_and_records_every_frame(tmp_path: Path) -> None:
    model = load_model(fitted()[1])
    rec = short_recording(N, HOLES)
    # Frames every 0.52 ms (@8), a push takes 4 ms: frames wait on any machine.
    lsl = FakeLsl(delay=0.004)
    record = RecordOutput(tmp_path / "live.csv")
    streamer = Streamer(model, lsl=lsl, record=record, record_units=model.session_units)
    source = Logged(ReplaySource(rec, 8.0))
    s = run(source, streamer, status=False)

    # The counts add up, by construction.
    assert s.received == N == s.sent + s.skipped + s.stale
    assert s.recorded == N
    assert s.skipped > 0 and s.sent == len(lsl.angles) > 0
    # No frame sent older than --max-age (20 ms): the age the stream measured at each push.
    ages = s.age_ms()
    assert ages.size == s.sent and ages.max() <= 20.0
    # Each frame sent is the newest of the frames handed over together, in order.
    blocks = source.blocks_seen
    arrivals = np.concatenate(blocks)
    newest = {float(b[-1]) for b in blocks}
    sent = np.concatenate(lsl.arrival)
    assert all(float(t) in newest for t in sent)
    idx = np.searchsorted(arrivals, sent)
    np.testing.assert_array_equal(arrivals[idx], sent)
    assert np.all(np.diff(idx) > 0)
    # Its values: `fingerfit angles`' row, a frame nothing can solve holding the last frame
    # sent; a frame with a missing sensor solved by the model one frame at a time, from the
    # frames sent before it (which the load chose): those of the same frames handed over
    # one by one.
    table, solved = angles_of(model, rec)
    ch = channels_of(model, compute_kinematics(model, rec.slice(slice(0, 2)), ("user_axis",)))
    held = table[ch.angle_labels].iloc[idx].ffill().to_numpy()
    got = np.vstack(lsl.angles)
    assert_close_where_solved(got, held, solved[idx], np.inf)
    if s.stale == 0:  # else a frame went stale after its compute: the filter saw it too
        np.testing.assert_allclose(got, robot_lane_over(model, rec, idx), rtol=0, atol=1e-9)
    # The source channels: the model solved frames 50, 51 (index.middle) and 300
    # (index.distal); frame 120 (no hand) was held.
    source = np.vstack(lsl.source)[:, ch.digits.index("index")]
    code = np.zeros(N)
    code[[50, 51, 300]], code[120] = 1, 2
    np.testing.assert_array_equal(source, code[idx])
    # The record: every frame, `fingerfit angles`' numbers (block by block where solved).
    got = pd.read_csv(tmp_path / "live.csv")
    assert list(got.columns) == list(table.columns)
    cols = [c for c in table.columns if "ik_rms" not in c]
    assert_close_where_solved(
        got[cols].to_numpy(), table[cols].to_numpy(), solved, solved_tolerance(cols)
    )
    assert np.isfinite(got.loc[solved, "index.ik_rms_mm"]).all()
    assert not np.isfinite(got.loc[~solved, "index.ik_rms_mm"]).any()


def test_a_frame_older_than_max_age_is_never_sent(tmp_path: Path) -> None:
    """A push that takes longer than --max-age: the frames that waited for it are stale."""
    model = load_model(fitted()[1])
    lsl = FakeLsl(delay=0.03)  # 30 ms per push, --max-age 10 ms
    streamer = Streamer(model, lsl=lsl, max_age=0.010)
    s = run(ReplaySource(short_recording(240), 1.0), streamer, status=False)
    assert s.received == 240 == s.sent + s.skipped + s.stale
    assert s.stale > 0 and s.age_ms().max() <= 10.0 and s.recorded == 0


def _with_gap(n: int, at: int, gap_s: float) -> Recording:
    """:func:`short_recording` with the frames from ``at`` on ``gap_s`` later: a source that
    falls silent and comes back."""
    rec = short_recording(n)
    t = rec.time.copy()
    t[at:] += gap_s
    poses = {k: PoseSeries(v.position, v.rotation) for k, v in rec.poses.items()}
    return Recording(rec.name, t, poses)


@pytest.mark.parametrize("policy", ["hold", "release"])
def test_watchdog_marks_silence_invalid_and_applies_the_robot_policy(policy: str) -> None:
    pytest.importorskip("mujoco")
    from fingerfit.retarget import Retargeter, resolve

    model = load_model(fitted()[1])
    retargeter = Retargeter(model, *resolve("shadow", None, model.hand), "tip")
    lsl, ros2 = FakeLsl(), FakeRos2()
    streamer = Streamer(model, lsl=lsl, ros2=ros2, retargeter=retargeter, on_silence=policy)
    warnings: list[str] = []
    # 0.4 s without a frame after frame 60, against a 50 ms watchdog: generous margins.
    source = Logged(ReplaySource(_with_gap(120, 60, 0.4), 1.0))
    s = run(source, streamer, status=False, silence=0.05, warn=warnings.append)

    assert s.silences == 1 and len(warnings) == 1 and policy in warnings[0]
    assert s.received == 120 == s.sent + s.skipped + s.stale
    valid = np.concatenate(lsl.valid)
    arrival = np.concatenate(lsl.arrival)
    (k,) = np.flatnonzero(valid == 0)  # the one sample of the silence
    assert np.all(np.diff(arrival) > 0)  # stamped between the frames around the gap
    frames = np.concatenate(source.blocks_seen)
    assert frames[59] < arrival[k] < frames[60]
    assert k < len(valid) - 1  # frames came back, valid again
    robot = np.vstack(lsl.robot)
    rest = np.asarray(retargeter.setup.hold)
    n_sent = s.sent
    if policy == "release":
        np.testing.assert_array_equal(robot[k], rest)  # the robot's rest pose
        assert not np.allclose(robot[k - 1], rest)
        assert len(ros2.positions) == n_sent + 1  # DDS gets the rest pose too
        np.testing.assert_array_equal(ros2.positions[k][0], rest)
    else:
        np.testing.assert_array_equal(robot[k], robot[k - 1])  # the last pose, held
        assert len(ros2.positions) == n_sent  # nothing on DDS: JointState has no valid
    np.testing.assert_array_equal(np.vstack(lsl.angles)[k], np.vstack(lsl.angles)[k - 1])


def test_cli_watchdog_warning_counts_and_complete_record(tmp_path: Path) -> None:
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "gap.csv", _with_gap(120, 60, 0.4))
    res = cli(
        "stream", model_path, "--source", f"replay:{csv}", "--record", tmp_path / "live.csv",
        "--silence-ms", "50", "-q",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert res.output.count("no frame for 50 ms") == 1 and "1 silence)" in res.output
    assert stream_counts(res.output) == {"received": 120, "recorded": 120}
    assert len(pd.read_csv(tmp_path / "live.csv")) == 120


@pytest.mark.parametrize(
    ("args", "field", "text"),
    [
        (["--max-age", "0"], "--max-age", "positive"),
        (["--max-age", "nan"], "--max-age", "positive"),
        (["--silence-ms", "-5"], "--silence-ms", "positive"),
        (["--on-silence", "drop"], "--on-silence", "hold, release"),
        (["--on-silence", "release"], "--on-silence", "--retarget"),
    ],
)
def test_bad_lane_options_are_refused_in_one_line(tmp_path: Path, args, field, text) -> None:
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "rec.csv", short_recording(24))
    out = tmp_path / "live.csv"
    res = cli("stream", model_path, "--source", f"replay:{csv}", "--record", out, *args)
    refused(res, field, text)
    assert not out.exists()


@pytest.mark.parametrize("tips_frame", ["tracker", "hand"])
def test_robot_lane_frame_values_equal_block_values(tips_frame: str) -> None:
    """The robot lane's buffers (allocated once) hold, frame by frame, what the data
    lane's block_values gives; the validity is the sensors' own."""
    from fingerfit.live.stream import FrameValues, block_values, frames_valid, model_sensors

    model = load_model(fitted()[1])
    rec = short_recording(60, ((5, "index.middle"), (9, "hand"), (20, "index.distal")))
    sensors = model_sensors(model)
    kin = compute_kinematics(model, rec, ("user_axis",))
    ch = channels_of(model, kin)
    want = block_values(kin, ch, rec, sensors, tips_frame)
    valid = np.ones(rec.n_frames, dtype=bool)
    for s in sensors:
        valid &= rec.poses[s].valid
    np.testing.assert_array_equal(frames_valid(rec, sensors), valid)
    np.testing.assert_array_equal(want.valid, valid.astype(float))
    frame = FrameValues(ch, tips_frame)
    for i in range(rec.n_frames):
        one = rec.slice(slice(i, i + 1))
        robot = np.array([[float(i), np.nan]])
        got = frame.values(compute_kinematics(model, one, ("user_axis",)), one, robot)
        for key in ("angles", "tips", "joints"):
            np.testing.assert_allclose(
                got[key][0], getattr(want, key)[i], rtol=0, atol=1e-9, equal_nan=True
            )
        np.testing.assert_array_equal(got["robot"], robot)
        assert got["robot"] is not robot  # a copy: the retargeter's array is its own


class _SlowOnce:
    """A retargeter stand-in whose step for one frame (by its recording time) takes
    ``delay`` s: that frame goes stale in its compute. ``fired``: whether it did."""

    variant = "user_axis"

    def __init__(self, slow_time: float, delay: float) -> None:
        self.slow_time, self.delay = slow_time, delay
        self.fired = False

    def step(self, rec, kin):
        if rec.time[0] == self.slow_time:
            self.fired = True
            time.sleep(self.delay)
        return (np.zeros((1, 2)),)


def test_a_frame_that_goes_stale_in_its_compute_is_not_held() -> None:
    """The hold is the last frame sent: a frame computed but too old to send (its compute
    outlasted --max-age) does not become the value a later frame's missing sensor keeps."""
    model = load_model(fitted()[1])
    # Frame 30 computes for 0.6 s (--max-age 0.25 s); every frame after it that can be sent
    # next lacks the hand sensor, so nothing can be computed or solved: its values are held.
    # From frame 27 on the frames come 0.15 s apart, so that a busy machine neither skips
    # frame 30 (a newer frame in its block) nor lets a frame age past --max-age on arrival
    # (the watchdog off: those gaps are not silences here).
    rec = short_recording(40, tuple((i, "hand") for i in range(31, 40)))
    gap = np.maximum(np.arange(40) - 26, 0) * 0.15
    rec = Recording(rec.name, rec.time + gap, rec.poses)
    lsl = FakeLsl()
    slow = _SlowOnce(float(rec.time[30]), 0.6)
    streamer = Streamer(model, lsl=lsl, retargeter=slow, max_age=0.25)
    source = Logged(ReplaySource(rec, 1.0))
    s = run(source, streamer, status=False, silence=None)
    assert slow.fired
    assert s.received == 40 == s.sent + s.skipped + s.stale and s.stale >= 1
    arrivals = np.concatenate(source.blocks_seen)
    sent = np.searchsorted(arrivals, np.concatenate(lsl.arrival))
    assert 30 not in sent  # stale: not sent
    angles = np.vstack(lsl.angles)
    after = int(np.flatnonzero(sent > 30)[0])  # the first frame sent after it
    kin = compute_kinematics(model, rec, ("user_axis",))
    ch = channels_of(model, kin)
    table = kinematics_table(kin)[ch.angle_labels].to_numpy()
    held = ~np.isfinite(table[sent[after]])
    assert held.any() and np.isfinite(table[30, held]).all()
    # Held from the frame sent before it, not from frame 30 (which differs there).
    np.testing.assert_array_equal(angles[after, held], angles[after - 1, held])
    assert not np.allclose(angles[after, held], table[30, held])
