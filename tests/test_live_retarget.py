"""`fingerfit stream --retarget ROBOT`: the robot's joints, live, equal `fingerfit retarget`.

A simulated whole hand (thumb + four fingers, pad points) is replayed through a pinch with
sensors missing in a few frames. What an LSL consumer receives on ``PREFIX-robot``, what a
DDS subscriber receives as ``JointState`` and what the rosbag2 holds equal the joints
``fingerfit retarget`` writes for the same recording to 1e-9 rad, frame for frame, within
the robot's limits and couplings.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fingerfit.io import write_pose_csv
from fingerfit.session import PoseSeries, Recording

from ._live import (
    HANG_S,
    assert_close_where_solved,
    max_age_ms,
    resolve_prefix,
    robot_lane_over,
    sent_frames,
    solved_tolerance,
    stream_counts,
    until,
)
from .bad_inputs._cli import run
from .conftest import subject

pylsl = pytest.importorskip("pylsl")
pytest.importorskip("rosbags")
pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
HAND = ("thumb", "index", "middle", "ring", "little")
N = 240
#: (frame, sensor) missing in the replayed recording (absent rows of the pose CSV).
HOLES = ((60, "index.middle"), (61, "index.middle"), (150, "hand"), (151, "thumb.distal"))
#: The frames the model solves (a digit's sensor missing, the hand present).
SOLVED = np.isin(np.arange(N), [60, 61, 151])
#: How far the robot's joints may lie from `fingerfit retarget`'s from the first frame the
#: model solved on: the files (block by block), the robot lane (one frame at a time), rad.
BAG_RAD, SOLVED_RAD = np.radians(0.5), np.radians(1.0)
DEADLINE = HANG_S


@pytest.fixture(scope="module")
def hand(tmp_path_factory) -> tuple[Path, Path, np.ndarray]:
    """``(model.json, rec.csv, valid)``: a fitted whole-hand model and N frames of its
    pinch recording around the first thumb-index touch, with :data:`HOLES`."""
    from fingerfit.estimate import fit_session
    from fingerfit.kinematics import compute_kinematics
    from fingerfit.model import save_model

    sub = subject("realistic", 2, HAND)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    full = sub.session.recording("pinch.csv")
    kin = compute_kinematics(model, full, ("user_axis",))
    m = kin.motions["user_axis"]
    gap = np.linalg.norm(m["thumb"].pad - m["index"].pad, axis=1)
    first = int(np.argmax(gap < 8.0))
    assert gap[first] < 8.0, "the pinch recording has no touch"
    start = max(first - N // 2, 0)
    cut = slice(start, start + N)
    poses = {
        k: PoseSeries(v.position[cut].copy(), v.rotation[cut].copy()) for k, v in full.poses.items()
    }
    for i, s in HOLES:
        poses[s].position[i] = np.nan
        poses[s].rotation[i] = np.nan
    rec = Recording("pinch.csv", full.time[cut].copy(), poses)
    d = tmp_path_factory.mktemp("live-retarget")
    model_path = save_model(model, d / "model.json")
    csv = write_pose_csv(d / "rec.csv", rec, units=model.session_units)
    valid = np.ones(N)
    valid[[i for i, _ in HOLES]] = 0
    return model_path, csv, valid


def _offline(tmp_path: Path, model: Path, csv: Path, *args: str) -> pd.DataFrame:
    out = tmp_path / "offline" / "q.csv"
    out.parent.mkdir()
    res = run("retarget", model, csv, "-o", out, "-q", *args)
    assert res.exit_code == 0, res.output
    return pd.read_csv(out)


def _limits_hold(robot_name: str, model_path: Path, q: np.ndarray) -> None:
    from fingerfit.model import load_model
    from fingerfit.retarget import resolve, setup

    model = load_model(model_path)
    robot, rmap = resolve(robot_name, None, model.hand)
    assert np.all(q >= robot.lower - 1e-12) and np.all(q <= robot.upper + 1e-12)
    assert setup(model, robot, rmap).limits.violations(q) == 0


def _bag(path: Path) -> tuple[list[str], np.ndarray, str]:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(path) as r:
        (conn,) = [c for c in r.connections if not c.topic.endswith("/source")]
        msgs = [store.deserialize_cdr(raw, conn.msgtype) for _, _, raw in r.messages([conn])]
    assert {tuple(m.name) for m in msgs} == {tuple(msgs[0].name)}
    return list(msgs[0].name), np.array([m.position for m in msgs]), conn.topic


def _bag_equals_retarget(pos: np.ndarray, want: np.ndarray) -> None:
    """The bag's joints are `fingerfit retarget`'s: to 1e-9 before the first frame the model
    solved (block by block in the stream, the whole recording offline), to BAG_RAD from it
    on (that frame, and the robot solver's warm start from it)."""
    first = int(np.argmax(SOLVED))
    np.testing.assert_allclose(pos[:first], want[:first], rtol=0, atol=1e-9)
    np.testing.assert_allclose(pos[first:], want[first:], rtol=0, atol=BAG_RAD)


def _record_equals_angles(tmp_path: Path, model_path: Path, csv: Path, record: Path) -> None:
    """``--record`` is `fingerfit angles`' CSV of the same frames (where the model solved a
    frame: block by block against the whole recording, within SOLVED_DEG)."""
    out = tmp_path / "angles.csv"
    assert run("angles", model_path, csv, "-o", out, "-q").exit_code == 0
    got, want = pd.read_csv(record), pd.read_csv(out)
    assert list(got.columns) == list(want.columns)
    cols = [c for c in want.columns if "ik_rms" not in c]
    assert_close_where_solved(
        got[cols].to_numpy(), want[cols].to_numpy(), SOLVED, solved_tolerance(cols)
    )


def test_stream_retarget_shadow_over_lsl_and_bag_equals_retarget(hand, tmp_path: Path) -> None:
    model_path, csv, valid = hand
    want = _offline(tmp_path, model_path, csv, "--robot", "shadow")
    names = [c for c in want.columns if c != "time"]
    q_want = want[names].to_numpy()
    assert len(q_want) == N and len(names) == 24  # the Shadow hand's 24 joints

    pytest.importorskip("cyclonedds")
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from fingerfit.live.ros2types import JointState

    prefix = f"ffrt{os.getpid()}"
    domain = 1 + (os.getpid() + 97) % 200
    topic = f"/ffrt_{os.getpid()}/joint_states"
    participant = DomainParticipant(domain)
    qos = Qos(Policy.Reliability.Reliable(0), Policy.History.KeepAll)
    reader = DataReader(participant, Topic(participant, "rt" + topic, JointState, qos=qos), qos=qos)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    env.pop("CYCLONEDDS_URI", None)
    bag, record = tmp_path / "bag", tmp_path / "live.csv"
    proc = subprocess.Popen(
        [FINGERFIT, "stream", str(model_path), "--source", f"replay:{csv}@2", "--retarget",
         "shadow", "--lsl", "--lsl-name", prefix, "--ros2", topic, "--ros2-bag", str(bag),
         "--record", str(record), "--wait", "--wait-timeout", str(HANG_S), "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    inlets, data, stamps, messages = {}, {}, {}, []
    try:
        found = resolve_prefix(prefix, 3, proc)  # angles, tips, robot: found before any is opened
        for kind in ("robot", "angles"):
            assert f"{prefix}-{kind}" in found, f"no LSL stream {prefix}-{kind}"
            inlets[kind] = pylsl.StreamInlet(
                found[f"{prefix}-{kind}"], max_buflen=60, processing_flags=0
            )
            data[kind], stamps[kind] = [], []
        for inlet in inlets.values():
            inlet.open_stream(timeout=HANG_S)

        def pull() -> None:
            for kind, inlet in inlets.items():
                x, ts = inlet.pull_chunk(timeout=0.0)
                data[kind] += x
                stamps[kind] += ts
            messages.extend(m for m in reader.take(N=1000) if isinstance(m, JointState))

        until(lambda: pull() or proc.poll() is not None, DEADLINE)
    finally:
        try:
            out, err = proc.communicate(timeout=DEADLINE)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
    assert proc.returncode == 0, out + err
    assert "Traceback" not in err
    counts = stream_counts(out)
    assert counts["received"] == N == counts["recorded"]
    assert counts["sent"] + counts["skipped"] + counts["stale"] == N
    sent = counts["sent"]
    # What is still on its way: until every consumer has every frame sent.
    until(lambda: pull() or min(len(data["robot"]), len(data["angles"]), len(messages)) >= sent)
    info = inlets["robot"].info(timeout=HANG_S)
    assert "compute per frame (retargeting included) p50" in out

    # --- which frames the robot lane sent (the person's angles identify them) ------------
    live = pd.read_csv(record)
    labels = [c.findtext("label") for c in ET.fromstring(inlets["angles"].info(HANG_S).as_xml())
              .find("desc/channels").findall("channel")]  # fmt: skip
    angles = [c for c in labels[:-1] if not c.endswith(".source")]
    assert angles == [
        c for c in live.columns if c.count(".") == 1 and c != "time" and "ik_rms" not in c
    ]
    a = np.asarray(data["angles"])
    assert a.shape == (sent, len(labels))  # every frame sent reaches the consumer
    t_rec = live["time"].to_numpy()
    idx = sent_frames(
        np.asarray(stamps["angles"]),
        t_rec,
        2.0,
        a[:, : len(angles)],
        live[angles].to_numpy(),
        ~SOLVED,
    )
    # A frame the model solved, one at a time from the frames sent before it (the load
    # chose them): the values of the same frames handed over one by one.
    assert_close_where_solved(
        a[:, : len(angles)], live[angles].iloc[idx].ffill().to_numpy(), SOLVED[idx], np.inf
    )
    if counts["stale"] == 0:  # else a frame went stale after its compute: the filter saw it
        from fingerfit.io import read_pose_csv
        from fingerfit.model import load_model

        model = load_model(model_path)
        rec = read_pose_csv(csv, units=model.session_units)
        np.testing.assert_allclose(
            a[:, : len(angles)], robot_lane_over(model, rec, idx), rtol=0, atol=1e-9
        )

    # --- LSL PREFIX-robot: channels, units, the frames sent, the offline joints ----------
    assert info.type() == "JointAngles" and info.channel_format() == pylsl.cf_double64
    chans = ET.fromstring(info.as_xml()).find("desc/channels").findall("channel")
    assert [c.findtext("label") for c in chans] == [*names, "valid"]
    assert {c.findtext("unit") for c in chans[:-1]} == {"radians"}
    x = np.asarray(data["robot"])
    assert x.shape == (sent, len(names) + 1)
    np.testing.assert_array_equal(np.asarray(stamps["robot"]), np.asarray(stamps["angles"]))
    # Up to the first frame skipped, the tip solver's warm start is the offline one: the
    # same joints. After a skip it starts from the last frame sent, not the one before.
    run_ = (
        int(np.argmax(idx != np.arange(len(idx)))) if np.any(idx != np.arange(len(idx))) else sent
    )
    # The frames the model solved one at a time (this lane) or with the frames around them
    # (offline) agree within SOLVED_RAD, and so does the warm start from them.
    early = min(run_, int(np.argmax(SOLVED[idx])) if SOLVED[idx].any() else run_)
    np.testing.assert_allclose(x[:early, :-1], q_want[idx[:early]], rtol=0, atol=1e-9)
    np.testing.assert_allclose(x[early:run_, :-1], q_want[idx[early:run_]], rtol=0, atol=SOLVED_RAD)
    np.testing.assert_array_equal(x[:, -1], valid[idx])
    _limits_hold("shadow", model_path, x[:, :-1])
    # The person's frames that lost a sensor keep the robot's pose (tip method).
    for k in np.flatnonzero(valid[idx] == 0):
        if k > 0 and idx[k] == 150 and idx[k - 1] == 149:
            np.testing.assert_array_equal(x[k, :-1], x[k - 1, :-1])

    # --- ROS 2 over DDS: the robot's JointState of the frames sent; the bag: every frame ---
    assert len(messages) == sent and all(list(m.name) == names for m in messages)
    np.testing.assert_array_equal(np.array([m.position for m in messages]), x[:, :-1])
    bag_names, pos, bag_topic = _bag(bag)
    assert bag_names == names and bag_topic == topic
    _bag_equals_retarget(pos, q_want)


def test_overload_robot_lane_sends_fresh_frames_files_keep_every_frame(
    hand, tmp_path: Path
) -> None:
    """Frames arrive faster than the whole hand and the Shadow hand are computed (@8: one
    every 0.52 ms): the robot lane skips frames and sends none older than --max-age; the
    files still hold every frame, equal to `fingerfit angles` and `fingerfit retarget`."""
    model_path, csv, _ = hand
    want = _offline(tmp_path, model_path, csv, "--robot", "shadow")
    names = [c for c in want.columns if c != "time"]
    bag, record = tmp_path / "bag", tmp_path / "live.csv"
    res = run(
        "stream", model_path, "--source", f"replay:{csv}@8", "--retarget", "shadow", "--lsl",
        "--lsl-name", f"ffover{os.getpid()}", "--ros2-bag", bag, "--record", record, "-q",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    counts = stream_counts(res.output)
    assert counts["received"] == N == counts["recorded"]
    assert counts["sent"] + counts["skipped"] + counts["stale"] == N
    # Behind, the lane skips; what it sends is never older than the default --max-age.
    # (A machine too busy to finish any frame within it sends none: every frame is then
    # skipped or stale, counted, never sent late.)
    assert counts["skipped"] > 0
    if counts["sent"] > 0:
        assert max_age_ms(res.output) <= 20.0
    bag_names, pos, _ = _bag(bag)
    assert bag_names == names
    _bag_equals_retarget(pos, want[names].to_numpy())
    _record_equals_angles(tmp_path, model_path, csv, record)


def test_stream_retarget_allegro_joint_orthogonal_equals_retarget(hand, tmp_path: Path) -> None:
    model_path, csv, _ = hand
    args = ("--method", "joint", "--orthogonal")
    want = _offline(tmp_path, model_path, csv, "--robot", "allegro", *args)
    names = [c for c in want.columns if c != "time"]
    bag, record = tmp_path / "bag", tmp_path / "live.csv"
    res = run(
        "stream", model_path, "--source", f"replay:{csv}@50", "--retarget", "allegro", *args,
        "--ros2-bag", bag, "--record", record, "-q",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert stream_counts(res.output) == {"received": N, "recorded": N}
    bag_names, pos, _ = _bag(bag)
    assert bag_names == names and pos.shape == (N, 16)  # the Allegro hand's 16 joints
    _bag_equals_retarget(pos, want[names].to_numpy())
    _limits_hold("allegro", model_path, pos)
    # --record is still the person's angles CSV of `fingerfit angles`.
    _record_equals_angles(tmp_path, model_path, csv, record)


SLIDE_XML = """
<mujoco model="slide">
  <worldbody>
    <body name="palm">
      <body name="f1">
        <joint name="hinge" type="hinge" axis="1 0 0" range="0 1"/>
        <geom type="sphere" size="0.01"/>
        <body name="f2" pos="0 0 0.04">
          <joint name="slide" type="slide" axis="0 0 1" range="0 0.02"/>
          <geom type="sphere" size="0.01"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

SLIDE_URDF = """<?xml version="1.0"?>
<robot name="slide">
  <link name="palm"/><link name="f1"/><link name="f2"/>
  <joint name="slide" type="prismatic">
    <parent link="palm"/><child link="f1"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.02" effort="1" velocity="1"/>
  </joint>
  <joint name="hinge" type="revolute">
    <parent link="f1"/><child link="f2"/><origin xyz="0 0 0.04"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""


@pytest.mark.parametrize(("name", "text"), [("r.xml", SLIDE_XML), ("r.urdf", SLIDE_URDF)])
def test_robot_outlet_units_name_slide_joints_in_meters(tmp_path: Path, name, text) -> None:
    from fingerfit.live.stream import robot_joint_units
    from fingerfit.retarget import load_robot

    (tmp_path / name).write_text(text)
    robot = load_robot(tmp_path / name)
    units = dict(zip(robot.joint_names, robot_joint_units(robot), strict=True))
    assert units == {"hinge": "radians", "slide": "meters"}


def test_stream_takes_retargets_robot_options() -> None:
    """The robot options are `fingerfit retarget`'s: same names, help and defaults."""
    import inspect

    from fingerfit.cli.retarget import retarget as retarget_command
    from fingerfit.cli.stream import stream as stream_command
    from fingerfit.retarget import Retargeter

    ours = inspect.signature(stream_command).parameters
    theirs = inspect.signature(retarget_command).parameters
    for name in ("map_path", "method", "orthogonal", "contact_mm"):
        assert ours[name].annotation == theirs[name].annotation, name
        assert ours[name].default == theirs[name].default, name
    # No --contact-mm: each pinch pair's distance from the model (Retargeter's default).
    assert ours["contact_mm"].default is None
    assert inspect.signature(Retargeter).parameters["contact_mm"].default is None
