"""`fingerfit stream --source replay:...` to LSL, ROS 2 (DDS), rosbag2 and the angles CSV.

A consumer in this process (pylsl inlets, a cyclonedds reader) receives what a
`fingerfit stream` subprocess sends and compares it with `fingerfit angles` on the same
recording to 1e-9: the live outputs get the frames the robot lane sent (latest-wins: a
subset when frames waited), the files every frame. Every network wait has a timeout.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fingerfit.export.geometry import joint_names
from fingerfit.export.trajectory import trajectory_table
from fingerfit.kinematics import compute_kinematics, kinematics_table
from fingerfit.live.stream import block_values, channels_of, hold, model_sensors
from fingerfit.model import load_model

from ._live import (
    HANG_S,
    fitted,
    resolve_prefix,
    sent_frames,
    short_recording,
    stream_counts,
    until,
    write_recording,
)
from .bad_inputs._cli import run

pylsl = pytest.importorskip("pylsl")
pytest.importorskip("cyclonedds")
pytest.importorskip("rosbags")

FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
N = 240
HOLES = ((50, "index.middle"), (51, "index.middle"), (120, "hand"))
DEADLINE = HANG_S
#: How far a frame the model solved one at a time (the robot lane) or block by block (the
#: files) may lie from `fingerfit angles`' solution of the whole recording: deg, mm.
SOLVED_DEG, SOLVED_MM = 0.5, 0.5


def _angles(tmp_path: Path, csv: Path, model: Path) -> pd.DataFrame:
    out = tmp_path / "angles.csv"
    res = run("angles", model, csv, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    return pd.read_csv(out)


def _env(domain: int) -> dict[str, str]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    env.pop("CYCLONEDDS_URI", None)
    return env


def _finish(proc: subprocess.Popen) -> tuple[int, str]:
    try:
        out, err = proc.communicate(timeout=DEADLINE)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return proc.returncode, out + err


def test_stream_to_lsl_dds_bag_and_csv_equals_angles(tmp_path: Path) -> None:
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from fingerfit.live.ros2types import JointState

    _, model_path = fitted()
    model = load_model(model_path)
    csv = write_recording(tmp_path / "rec.csv", N, HOLES)
    want = _angles(tmp_path, csv, model_path)
    prefix = f"fftest{os.getpid()}"
    domain = 1 + os.getpid() % 200
    topic = f"/fftest_{os.getpid()}/joint_states"
    participant = DomainParticipant(domain)
    qos = Qos(Policy.Reliability.Reliable(0), Policy.History.KeepAll)
    reader = DataReader(participant, Topic(participant, "rt" + topic, JointState, qos=qos), qos=qos)
    sq = Qos(
        Policy.Reliability.Reliable(0), Policy.History.KeepLast(1), Policy.Durability.TransientLocal
    )
    src_reader = DataReader(
        participant, Topic(participant, "rt" + topic + "/source", JointState, qos=sq), qos=sq
    )
    sources: list = []
    record, bag = tmp_path / "live.csv", tmp_path / "bag"
    lsl_start, wall_start = pylsl.local_clock(), time.time()  # before any frame's arrival
    proc = subprocess.Popen(
        [FINGERFIT, "stream", str(model_path), "--source", f"replay:{csv}@2", "--lsl",
         "--lsl-name", prefix, "--ros2", topic, "--ros2-bag", str(bag), "--record",
         str(record), "--wait", "--wait-timeout", str(HANG_S), "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(domain),
    )  # fmt: skip
    inlets, data, stamps, received = {}, {}, {}, {}
    messages = []
    try:
        found = resolve_prefix(prefix, 2, proc)  # both found before either is opened
        for kind in ("angles", "tips"):
            assert f"{prefix}-{kind}" in found, f"no LSL stream {prefix}-{kind}"
            inlets[kind] = pylsl.StreamInlet(
                found[f"{prefix}-{kind}"], max_buflen=60, processing_flags=0
            )
            data[kind], stamps[kind], received[kind] = [], [], []
        for inlet in inlets.values():
            inlet.open_stream(timeout=HANG_S)
        # A consumer that goes away mid-stream does not stop the stream.
        leaver = pylsl.StreamInlet(
            pylsl.resolve_byprop("name", f"{prefix}-tips", timeout=HANG_S)[0]
        )
        leaver.open_stream(timeout=HANG_S)

        def pull() -> None:
            nonlocal leaver
            for kind, inlet in inlets.items():
                x, ts = inlet.pull_chunk(timeout=0.0)
                if ts:
                    now = pylsl.local_clock()
                    data[kind] += x
                    stamps[kind] += ts
                    received[kind] += [now] * len(ts)
            messages.extend(m for m in reader.take(N=1000) if isinstance(m, JointState))
            sources.extend(m for m in src_reader.take(N=1000) if isinstance(m, JointState))
            if leaver is not None and len(data["tips"]) > 20:
                leaver.close_stream()
                leaver = None

        until(lambda: pull() or proc.poll() is not None, DEADLINE, 0.003)
    finally:
        code, output = _finish(proc)
    assert code == 0, output
    counts = stream_counts(output)
    assert counts["received"] == N == counts["recorded"]
    assert counts["sent"] + counts["skipped"] + counts["stale"] == N
    sent = counts["sent"]
    # What is still on its way: until every consumer has every frame sent.
    until(lambda: pull() or min(len(data["angles"]), len(data["tips"]), len(messages)) >= sent)
    infos = {k: inlet.info(timeout=HANG_S) for k, inlet in inlets.items()}

    # --- LSL: channels, metadata, values, validity, timestamps -----------------------
    ch = channels_of(model, compute_kinematics(model, short_recording(2), ("user_axis",)))
    t_rec = want["time"].to_numpy()
    valid = np.ones(N)
    valid[[i for i, _ in HOLES]] = 0
    # Frames 50 and 51 lack index.middle: solved by the model (the robot lane one frame at
    # a time, `angles` and the files with the frames around them: the same within
    # SOLVED_DEG and SOLVED_MM); frame 120 lacks the hand: nothing to solve, held.
    solved = np.zeros(N, dtype=bool)
    solved[[50, 51]] = True
    source = np.zeros((N, len(ch.digits)))
    source[solved, ch.digits.index("index")] = 1
    source[120] = 2
    idx = None
    for kind, labels, unit, ctype, tol in (
        ("angles", ch.angle_labels, "degrees", "JointAngles", SOLVED_DEG),
        ("tips", ch.tip_labels, "millimeters", "MoCap", SOLVED_MM),
    ):
        info = infos[kind]
        assert info.type() == ctype and info.channel_format() == pylsl.cf_double64
        assert info.nominal_srate() == pytest.approx(480.0, rel=1e-6)  # 240 Hz at @2
        root = ET.fromstring(info.as_xml())
        chans = root.find("desc/channels").findall("channel")
        assert [c.findtext("label") for c in chans] == [*labels, *ch.source_labels, "valid"]
        assert [c.findtext("unit") for c in chans][: len(labels)] == [unit] * len(labels)
        assert all(c.findtext("type") for c in chans)
        x = np.asarray(data[kind])
        k = len(labels)
        assert x.shape == (sent, k + len(ch.digits) + 1)  # every frame sent is received
        ts, rx = np.asarray(stamps[kind]), np.asarray(received[kind])
        # Which frames were sent: the same on every outlet (one push per frame).
        idx = sent_frames(ts, t_rec, 2.0, x[:, :k], want[labels].to_numpy(), ~solved)
        assert np.all(np.diff(idx) > 0)  # in order, never one twice
        # A frame nothing can solve holds the last value sent; a solved one is close to
        # `angles`' solution; every other frame is `angles`' value.
        held = want[labels].iloc[idx].ffill().to_numpy()
        close = solved[idx]
        np.testing.assert_allclose(x[~close, :k], held[~close], rtol=0, atol=1e-9)
        np.testing.assert_allclose(x[close, :k], held[close], rtol=0, atol=tol)
        np.testing.assert_array_equal(x[:, k:-1], source[idx])
        np.testing.assert_array_equal(x[:, -1], valid[idx])
        assert np.all(np.diff(ts) > 0)
        assert np.all(ts > lsl_start) and np.all(rx > ts)  # arrival on the LSL clock
    assert ch.angle_labels == [
        c for c in want.columns if c.count(".") == 1 and c != "time" and "ik_rms" not in c
    ]

    # --- ROS 2 over DDS: names, radians, stamps (the frames LSL got) --------------------
    assert len(messages) == sent
    names = joint_names(model)
    assert all(list(m.name) == names for m in messages)
    pos = np.array([m.position for m in messages])
    rad = np.radians(want[[n.replace("_", ".", 1) for n in names]])
    close = solved[idx]
    expect = rad.iloc[idx].ffill().to_numpy()
    np.testing.assert_allclose(pos[~close], expect[~close], rtol=0, atol=1e-9)
    np.testing.assert_allclose(pos[close], expect[close], rtol=0, atol=np.radians(SOLVED_DEG))
    stamp = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in messages])
    assert np.all(np.diff(stamp) > 0) and wall_start < stamp[0] and stamp[-1] < time.time()
    np.testing.assert_allclose(np.diff(stamp), np.diff(stamps["angles"]), atol=1e-6)
    assert {m.header.frame_id for m in messages} == {"hand"}
    # The source topic: what each digit's values come from, as the frames sent changed it.
    # The writer keeps the current message only (a state, not a log): a change superseded
    # before it went out may be skipped, and DDS may hand the transient-local sample over
    # twice (repeats dropped here); the messages are the changes in order, ending with the
    # last.
    assert sources and all(list(m.name) == ch.digits for m in sources)
    changes = [list(m.position) for m in sources]
    changes = [c for i, c in enumerate(changes) if i == 0 or c != changes[i - 1]]
    rows = [list(r) for r in source[idx]]
    expected = [r for i, r in enumerate(rows) if i == 0 or r != rows[i - 1]]
    it = iter(expected)
    assert all(c in it for c in changes) and changes[-1] == expected[-1], (changes, expected)

    # --- rosbag2: every frame ------------------------------------------------------------
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(bag) as r:
        conns = {c.topic: c for c in r.connections}
        assert set(conns) == {topic, f"{topic}/source"}
        conn = conns[topic]
        assert conn.msgtype == "sensor_msgs/msg/JointState"
        msgs = [store.deserialize_cdr(raw, conn.msgtype) for _, _, raw in r.messages([conn])]
        src = conns[f"{topic}/source"]
        src_msgs = [store.deserialize_cdr(raw, src.msgtype) for _, _, raw in r.messages([src])]
    assert len(msgs) == N
    bag_pos = np.array([m.position for m in msgs])
    all_rad = rad.ffill().to_numpy()
    np.testing.assert_allclose(bag_pos[~solved], all_rad[~solved], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        bag_pos[solved], all_rad[solved], rtol=0, atol=np.radians(SOLVED_DEG)
    )
    # Every change of source, in order: from the sensors, the model (50), the sensors
    # (52), held (120), the sensors (121).
    assert [list(m.position)[ch.digits.index("index")] for m in src_msgs] == [0, 1, 0, 2, 0]

    # --- the angles CSV: `fingerfit angles` for the same frames ---------------------------
    got = pd.read_csv(record)
    assert list(got.columns) == list(want.columns)
    pd.testing.assert_frame_equal(got[~solved], want[~solved], check_exact=False, rtol=0, atol=1e-9)
    index = [c for c in want.columns if c.startswith("index.") and "ik_rms" not in c]
    np.testing.assert_allclose(
        got.loc[solved, index].to_numpy(), want.loc[solved, index].to_numpy(), atol=SOLVED_MM
    )


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_ends_with_exit_0_and_complete_files(tmp_path: Path) -> None:
    _, model_path = fitted()
    csv = write_recording(tmp_path / "rec.csv", 4800)  # 20 s of replay
    record = tmp_path / "live.csv"
    proc = subprocess.Popen(
        [FINGERFIT, "stream", str(model_path), "--source", f"replay:{csv}", "--record",
         str(record), "--lsl", "--lsl-name", f"ffint{os.getpid()}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # Ctrl-C as a terminal delivers it: a suite run in the background (`make test &`,
        # nohup) hands its children SIGINT ignored, and Python then keeps it ignored.
        preexec_fn=_default_sigint,
    )  # fmt: skip
    try:
        found = pylsl.resolve_byprop("name", f"ffint{os.getpid()}-angles", timeout=HANG_S)
        assert found
        # Ctrl-C once the stream runs: a frame has come through (however loaded the
        # machine is; the timeout only guards against a hang).
        inlet = pylsl.StreamInlet(found[0])
        assert inlet.pull_sample(timeout=DEADLINE)[1] is not None, "no frame came"
        proc.send_signal(signal.SIGINT)
    finally:
        code, output = _finish(proc)
    assert code == 0, output
    assert "stopped by Ctrl-C" in output and "Traceback" not in output
    got = pd.read_csv(record)
    counts = stream_counts(output)
    # The data lane wrote every frame received, and the robot lane accounted for each.
    assert 0 < len(got) == counts["recorded"] == counts["received"] < 4800
    assert counts["sent"] + counts["skipped"] + counts["stale"] == counts["received"]
    assert not list(tmp_path.glob(".*"))  # no temporary file left


def test_hold_and_tips_in_the_hand_frame() -> None:
    _, model_path = fitted()
    model = load_model(model_path)
    rec = short_recording(30, ((3, "index.distal"), (4, "hand")))
    kin = compute_kinematics(model, rec, ("user_axis",))
    ch = channels_of(model, kin)
    sensors = model_sensors(model)
    tracker = block_values(kin, ch, rec, sensors, "tracker")
    hand = block_values(kin, ch, rec, sensors, "hand")
    h = rec.poses["hand"]
    for k, d in enumerate(ch.digits):
        tip = kin.motions["user_axis"][d].tip
        local = np.einsum("nji,nj->ni", h.rotation, tip - h.position)  # R^T (tip - p)
        np.testing.assert_allclose(hand.tips[:, 3 * k : 3 * k + 3], local, atol=1e-9)
    np.testing.assert_array_equal(tracker.valid, np.r_[1, 1, 1, 0, 0, np.ones(25)])
    table = kinematics_table(kin)
    np.testing.assert_array_equal(tracker.angles, table[ch.angle_labels].to_numpy())
    traj = trajectory_table(kin, model)  # what `angles --urdf-names` writes (rad)
    np.testing.assert_array_equal(tracker.joints, traj[ch.joint_names].to_numpy())
    held = hold(tracker.angles, np.full(tracker.angles.shape[1], np.nan))
    np.testing.assert_array_equal(held, table[ch.angle_labels].ffill().to_numpy())
    # Before any value has been seen, nothing to hold: NaN stays.
    first = hold(tracker.tips[3:5], np.full(tracker.tips.shape[1], np.nan))
    assert np.isnan(first).all()


def _stderr_on_a_terminal(args: list[str]) -> str:
    """Run ``fingerfit ARGS`` with stderr on a pseudo-terminal; return what it showed."""
    import pty
    import select

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [FINGERFIT, *args], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave
    )
    os.close(slave)
    data = b""
    t_end = time.monotonic() + DEADLINE
    while time.monotonic() < t_end:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(master, 4096)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            data += chunk
        elif proc.poll() is not None:
            break
    os.close(master)
    proc.communicate(timeout=DEADLINE)
    return data.decode(errors="replace")


def test_status_line_on_a_terminal_unless_quiet(tmp_path: Path) -> None:
    _, model_path = fitted()
    csv = write_recording(tmp_path / "rec.csv", 480)
    args = ["stream", str(model_path), "--source", f"replay:{csv}", "--duration", "1.2"]
    shown = _stderr_on_a_terminal(args)
    assert "frames/s" in shown and "latency" in shown and "lost 0" in shown
    assert "frames/s" not in _stderr_on_a_terminal([*args, "--quiet"])


_BURST_THEN_CLOSE = """
import sys, time
import numpy as np
from fingerfit.live.outputs import LslOutput
angles = [f"index.a{k}" for k in range(16)]  # a finger's widths of the real streams
tips = [f"index.tip{k}.{c}" for k in range(4) for c in "xyz"]
out = LslOutput(sys.argv[1], angles, tips, rate_hz=480.0)
t_end = time.monotonic() + 120
while not out.has_consumers() and time.monotonic() < t_end:
    time.sleep(0.01)
n = int(sys.argv[2])
a = np.repeat(np.arange(n, dtype=float)[:, None], len(angles), axis=1)
x = np.repeat(np.arange(n, dtype=float)[:, None], len(tips), axis=1)
t = time.monotonic() + np.arange(n) / 480
for i in range(n):  # one-frame blocks at 480 Hz, the last half in a burst
    out.push(a[i : i + 1], x[i : i + 1], np.ones(1), t[i : i + 1])
    if i < n // 2:
        time.sleep(1 / 480)
out.close()
"""


def test_lsl_consumer_receives_the_frames_pushed_just_before_close() -> None:
    """A stream that ends (replay done, Ctrl-C) still delivers its last frames."""
    prefix, n = f"ffclose{os.getpid()}", 400
    proc = subprocess.Popen([sys.executable, "-c", _BURST_THEN_CLOSE, prefix, str(n)])
    try:
        found = resolve_prefix(prefix, 2, proc)
        assert len(found) == 2, f"LSL streams {prefix}-*: {sorted(found)}"
        inlets = {k: pylsl.StreamInlet(i, processing_flags=0) for k, i in found.items()}
        for inlet in inlets.values():
            inlet.open_stream(timeout=HANG_S)
        got: dict[str, list] = {k: [] for k in inlets}
        t_end = time.monotonic() + HANG_S
        while min(map(len, got.values())) < n and time.monotonic() < t_end:
            for k, inlet in inlets.items():
                got[k] += inlet.pull_chunk(timeout=0.0)[0]
            time.sleep(0.01)
    finally:
        proc.wait(timeout=HANG_S)
    assert proc.returncode == 0
    # Both outlets (without the linger the one destroyed first lost the burst).
    for k, rows in got.items():
        np.testing.assert_array_equal(np.asarray(rows)[:, 0], np.arange(n), err_msg=k)


@pytest.mark.parametrize("verbose", [False, True])
def test_liblsl_log_lines_only_with_verbose(tmp_path: Path, verbose: bool) -> None:
    _, model_path = fitted()
    csv = write_recording(tmp_path / "rec.csv", 24)
    proc = subprocess.run(
        [FINGERFIT, "stream", str(model_path), "--source", f"replay:{csv}@10", "--lsl",
         "--lsl-name", f"fflog{os.getpid()}", "-q", *(["--verbose"] if verbose else [])],
        capture_output=True, text=True, timeout=DEADLINE, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert ("INFO|" in proc.stderr) == verbose, proc.stderr
