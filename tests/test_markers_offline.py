"""`fingerfit retarget` and `fingerfit view` of a marker recording with a model fitted from
skin markers: the robot's joints are the stream's for the same frames, near those of the
6-DOF fit of the same simulated subject, the view that of `stream --view-save`; the other
kind of recording and a missing marker are refused in one line."""

from __future__ import annotations

import functools
import os
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.estimate.fit import FitOptions, fit_session
from fingerfit.estimate.markers.angles import marker_angles
from fingerfit.estimate.markers.fit import fit_marker_session
from fingerfit.io import write_pose_csv
from fingerfit.io.markers import read_marker_recording
from fingerfit.io.opensim import write_markers
from fingerfit.kinematics.markers import hand_poses, with_hand
from fingerfit.live.markers import marker_kinematics
from fingerfit.model import load_model, save_model
from fingerfit.retarget import resolve, retarget
from fingerfit.retarget.palm import person_palm
from fingerfit.retarget.pipeline import setup
from fingerfit.session import HAND_SENSOR, PoseSeries
from fingerfit.simulate.markers import simulate_markers
from fingerfit.simulate.study import SimConfig, simulate_subject
from fingerfit.track import track_recording

from .test_live_markers import marker_subject
from .test_live_markers_robot import ROBOT_RAD, _replay, _retarget_angles, check_marker_view, robot

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

#: Frames of the simulated subjects' free-motion recording retargeted (4.2 s at 240 Hz).
FRAMES = 1000


def _cli(*args: str) -> str:
    res = CliRunner().invoke(app, list(args))
    assert res.exit_code == 0, (res.output, repr(res.exception))
    return res.output


def test_retarget_equals_the_streams_robot(tmp_path: Path) -> None:
    """`retarget MODEL X.trc --robot shadow` gives the robot joints of `stream --source
    replay:X.trc --retarget shadow --ros2-bag` for every frame (to ROBOT_RAD: the stream
    solves the angles block by block), and exactly those of retargeting the angles of
    `fingerfit angles` with the hand's pose of its markers' rigid fit."""
    pytest.importorskip("rosbags")
    from .test_live_retarget import _bag

    model, bot, rmap = robot()
    bag = tmp_path / "bag"
    rec, _ = _replay(tmp_path, "--ros2-bag", str(bag))  # writes tmp_path/test.trc
    out = tmp_path / "robot.csv"
    output = _cli("retarget", str(marker_subject()[1]), str(tmp_path / "test.trc"), "-o", str(out))
    assert f"{rec.n_frames} frames, {bot.nq} robot joints" in output, output
    got = np.load(out.with_suffix(".npz"))
    assert list(got["joint_names"]) == list(bot.joint_names)
    np.testing.assert_allclose(got["time"], rec.time, rtol=0, atol=1e-9)
    names, streamed, _ = _bag(bag)
    assert names == list(bot.joint_names)
    np.testing.assert_allclose(got["q"], streamed, rtol=0, atol=ROBOT_RAD)
    exp = _retarget_angles(model, bot, rmap, rec, marker_angles(model, rec)["index"])
    np.testing.assert_allclose(got["q"], exp, rtol=0, atol=1e-9)
    assert np.ptp(got["q"], axis=0).max() > np.radians(20)  # the robot moved


def test_view_save_is_the_streams_view(tmp_path: Path) -> None:
    """`view MODEL X.trc --robot shadow --save OUT.rrd`: what `stream --view-save` logs
    (tests/test_live_markers_robot.py), every frame; beside a simulated session's
    recording its true tips (truth/test.csv for test.trc)."""
    pytest.importorskip("rerun")
    from fingerfit.view.scene import truth_tips

    d, model = marker_subject()
    rec = read_marker_recording(d / "test.trc").slice(slice(0, 120))
    trc = write_markers(tmp_path / "test.trc", rec, units="mm")
    out = tmp_path / "view.rrd"
    output = _cli("view", str(model), str(trc), "--robot", "shadow", "--save", str(out))
    assert "120 frames, 1 digit, shadow robot" in output, output
    check_marker_view(out, rec)
    full = read_marker_recording(d / "test.trc")
    tips, note = truth_tips(d / "test.trc", full.n_frames)
    assert note == "" and tips is not None
    sim = simulate_subject(SimConfig(fingers=["index"], cycles=2), 3)  # marker_subject's
    np.testing.assert_array_equal(tips["index"], sim.truth.frames["test.csv"]["tip"]["index"])


#: The simulated worlds compared, each its index finger with Todorov's layout.
WORLDS = {
    "realistic": SimConfig(fingers=["index"], cycles=2),
    "myohand": SimConfig(world="myohand", hand="right", fingers=["index"], cycles=2),
}


@functools.cache
def fitted_twice(world: str) -> tuple:
    """A simulated subject (seed 3; 0.3 mm marker noise, skin sliding) fitted from its
    markers and from its 6-DOF sensors (two grasp cycles: ``min_cycles=2``):
    ``(sim, markers session, marker model, 6-DOF model)``. The realistic world's is
    :func:`marker_subject`'s, whose fit is reused."""
    sim = simulate_subject(WORLDS[world], 3)
    ms = simulate_markers(sim, "todorov", seed=3)
    if world == "realistic":
        marker_model = load_model(marker_subject()[1])
    else:
        marker_model = fit_marker_session(ms.session, mp_axes="hinge").model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        six = fit_session(sim.session, FitOptions(min_cycles=2))
    return sim, ms, marker_model, six


def _palm_in_tracker(model, palm, hand: PoseSeries) -> tuple[np.ndarray, np.ndarray]:
    """The person's palm frame in each frame: origin ``(n, 3)`` mm and rotation
    ``(n, 3, 3)`` (palm -> tracker), as :func:`fingerfit.retarget.palm.in_palm` reads it."""
    p0, r0 = model.reference_poses[HAND_SENSOR]
    turn = hand.rotation @ r0.T
    return turn @ (palm.origin - p0) + hand.position, turn @ palm.rotation


@pytest.mark.parametrize("world", list(WORLDS))
def test_retargeting_markers_is_near_retargeting_the_six_dof_fit(world: str) -> None:
    """The same simulated motion, retargeted onto the Shadow hand from the marker model
    and its marker recording, and from the 6-DOF fit and its pose recording.

    The robot's targets are each model's fingertip in its palm frame, scaled
    (docs/retargeting.md), so the two differ by what the two fits differ by. Frame by
    frame the difference of the robot's tips is at most (the triangle inequality; the
    index's base is the palm frame's origin): the scale times (each fingertip's error
    against the true tip + the palm frames' origins apart + their turn apart times the
    tip's distance from the origin), plus the scales' difference times the palm-frame
    tip, plus each robot's own miss of its target. Measured (1000 frames): robot tips
    3.7 mm apart (median; 9.2 at most) in the MyoHand world, 9.9 (15.2) in the realistic
    world, where the marker fit's fingertip is 8.0 mm from the truth (the 6-DOF fit's
    1.7) and its palm frame 14.5 deg from the 6-DOF fit's; the bound never reached
    (6.4 and 17 mm to spare). The robot's moving joints follow the same course:
    correlation over 0.85 each (measured 0.97-0.998 and 0.89-0.99; a mirrored or
    reversed motion would be negative)."""
    sim, ms, marker_model, six = fitted_twice(world)
    bot, rmap = resolve("shadow", None, six.hand)
    pose = sim.session.test[0].slice(slice(0, FRAMES))
    markers = ms.session.test[0].slice(slice(0, FRAMES))
    rec, kin_m = with_hand(marker_model, markers, marker_kinematics(marker_model, markers)[0])
    res_m = retarget(marker_model, rec, bot, rmap, "tip", kin=kin_m)
    kin_6 = track_recording(six, pose, variants=("user_axis",)).kinematics
    res_6 = retarget(six, pose, bot, rmap, "tip", kin=kin_6)
    true = sim.truth.frames["test.csv"]["tip"]["index"][:FRAMES]
    tip_m = kin_m.motions["user_axis"]["index"].tip
    tip_6 = kin_6.motions["user_axis"]["index"].tip
    o_m, r_m = _palm_in_tracker(
        marker_model, person_palm(marker_model), hand_poses(marker_model, markers)
    )
    o_6, r_6 = _palm_in_tracker(six, person_palm(six), pose.pose(HAND_SENSOR))
    cos = (np.einsum("nij,nij->n", r_m, r_6) - 1) / 2
    turn = np.arccos(np.clip(cos, -1, 1))  # rad
    local_6 = np.einsum("nji,nj->ni", r_6, tip_6 - o_6)  # the 6-DOF fit's palm-frame tip
    s_m, s_6 = (setup(m, bot, rmap).scale["index"] for m in (marker_model, six))
    person = (
        np.linalg.norm(tip_m - true, axis=1)
        + np.linalg.norm(tip_6 - true, axis=1)
        + np.linalg.norm(o_m - o_6, axis=1)
        + turn * np.linalg.norm(tip_6 - o_6, axis=1)
    )
    miss = [np.linalg.norm(r.tips - r.targets, axis=2)[:, 0] for r in (res_m, res_6)]
    bound = s_m * person + abs(s_m - s_6) * np.linalg.norm(local_6, axis=1) + miss[0] + miss[1]
    apart = np.linalg.norm(res_m.tips - res_6.tips, axis=2)[:, 0]
    assert np.isfinite(apart).all()
    assert (apart <= bound + 1e-9).all(), np.max(apart - bound)
    moving = np.ptp(res_6.q, axis=0) > np.radians(10)
    assert moving.sum() >= 3
    for j in np.flatnonzero(moving):
        corr = np.corrcoef(res_m.q[:, j], res_6.q[:, j])[0, 1]
        assert corr > 0.85, (bot.joint_names[j], corr)


@functools.cache
def _files() -> dict[str, Path]:
    """A 6-DOF model, a marker model, a pose recording, a marker recording without one
    of the model's markers (the MyoHand subject's)."""
    sim, ms, marker_model, six = fitted_twice("myohand")
    root = Path(tempfile.mkdtemp(prefix="fingerfit-markers-offline-"))
    short = ms.session.test[0].slice(slice(0, 20))
    short.markers.pop("IND3_1")
    return {
        "six": save_model(six, root / "six_model.json"),
        "markers": save_model(marker_model, root / "marker_model.json"),
        "poses": _written(
            write_pose_csv, root / "poses.csv", sim.session.test[0].slice(slice(0, 20))
        ),
        "trc": write_markers(root / "test.trc", ms.session.test[0].slice(slice(0, 20)), units="mm"),
        "short": write_markers(root / "short.trc", short, units="mm"),
    }


def _written(write, path: Path, rec) -> Path:
    write(path, rec)
    return path


@pytest.mark.parametrize("command", ["retarget", "view", "angles"])
def test_the_other_kind_of_recording_is_refused_in_one_line(command: str, tmp_path: Path) -> None:
    """A 6-DOF model with a marker recording, a model fitted from markers with a pose
    recording, a marker recording without one of the model's markers, a model fitted
    from markers with ``--orthogonal``: one line naming the file (and the marker), exit
    2, nothing written."""
    f = _files()
    out = tmp_path / ("out.rrd" if command == "view" else "out.csv")
    tail = ["--save", str(out)] if command == "view" else ["-o", str(out)]

    def refused(model: Path, recording: Path) -> str:
        res = CliRunner().invoke(app, [command, str(model), str(recording), *tail])
        assert res.exit_code == 2, (res.output, repr(res.exception))
        lines = [x for x in res.output.splitlines() if x.strip()]
        assert len(lines) == 1, res.output
        assert not out.exists() and not out.with_suffix(".npz").exists()
        return lines[0]

    line = refused(f["six"], f["trc"])
    assert "test.trc: is a marker recording" in line and "fitted from 6-DOF sensors" in line
    line = refused(f["markers"], f["poses"])
    assert "poses.csv: is not a marker recording" in line and "fitted from markers" in line
    line = refused(f["markers"], f["short"])
    assert "short.trc" in line and "no marker IND3_1 of the model in the recording" in line
    if command != "angles":  # a marker model has its fitted axes only
        tail.append("--orthogonal")
        line = refused(f["markers"], f["trc"])
        assert "marker_model.json: was fitted from markers" in line and "--orthogonal" in line


def test_fit_jobs_fits_the_digits_in_worker_processes(tmp_path):
    """``fingerfit fit --jobs 2`` of a marker session: each digit fitted in a worker
    process, or one digit in two threads, the model the same as one process's; Ctrl-C ends it without a word from
    any process; a 6-DOF session refuses it in one line."""
    runner = CliRunner()
    sim = ["simulate", str(tmp_path), "--subjects", "1", "--fingers", "index,middle"]
    res = runner.invoke(app, [*sim, "--cycles", "2", "--markers", "todorov", "-q"])
    assert res.exit_code == 0, res.output
    (session,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    models = {}
    # The worker processes are started from a process of their own: this test process
    # (a pytest-xdist worker) keeps no pool's state for the tests after it.
    exe = Path(sys.executable).with_name("fingerfit")
    # Two digits on two cores: a worker process each; one digit: two threads.
    for jobs, fingers in (("1", "index,middle"), ("2", "index,middle"), ("2", "index")):
        out = tmp_path / f"jobs{jobs}{fingers}.json"
        cmd = [str(exe), "fit", str(session), "--jobs", jobs, "--fingers", fingers, "-q"]
        res = subprocess.run([*cmd, "-o", str(out)], capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stdout + res.stderr
        models[jobs, fingers] = load_model(out)
    one = models["1", "index,middle"]
    for jobs, fingers in (("2", "index,middle"), ("2", "index")):
        for d in fingers.split(","):
            for j in ("mp", "pip", "dip"):
                got = models[jobs, fingers].fingers[d].joints[j]
                np.testing.assert_array_equal(got.axis, one.fingers[d].joints[j].axis)
                np.testing.assert_array_equal(got.center, one.fingers[d].joints[j].center)
    # A terminal's Ctrl-C (the whole process group) once the workers run: no traceback
    # from any process, no model file.
    out = tmp_path / "interrupted.json"
    cmd = [str(exe), "fit", str(session), "--jobs", "2", "-q", "-o", str(out)]
    proc = subprocess.Popen(
        cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    deadline = time.monotonic() + 300  # a guard, not a measurement
    while proc.poll() is None and time.monotonic() < deadline:
        children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True)
        if len(children.stdout.split()) >= 2:  # the resource tracker and a worker at least
            break
        time.sleep(0.05)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    output = proc.communicate(timeout=300)[0]
    assert "Traceback" not in output, output
    if proc.returncode != 0:  # interrupted before it was done
        assert "interrupted" in output and not out.exists(), output
    six = tmp_path / "six"
    res = runner.invoke(app, ["simulate", str(six), "--subjects", "1", "--fingers", "index", "-q"])
    assert res.exit_code == 0, res.output
    (s6,) = [p for p in six.iterdir() if p.is_dir()]
    res = runner.invoke(app, ["fit", str(s6), "--jobs", "2", "-q"])
    assert res.exit_code != 0
    assert "only a marker session's digits" in res.output


def test_fit_chooses_a_marker_sessions_mp_axes_and_slide_on_the_command_line(tmp_path):
    """``fingerfit fit --mp-axes hinge --slide`` of a marker session: a hinge MP and every
    marker's slide estimated (a marker alone on its segment held at 0), in the model
    file; a bad choice and a 6-DOF session are refused in one line."""
    runner = CliRunner()
    sim = ["simulate", str(tmp_path / "m"), "--subjects", "1", "--fingers", "index"]
    res = runner.invoke(app, [*sim, "--cycles", "2", "--markers", "todorov", "-q"])
    assert res.exit_code == 0, res.output
    (session,) = (tmp_path / "m").iterdir()
    out = tmp_path / "hinge.json"
    cmd = ["fit", str(session), "--mp-axes", "hinge", "--slide", "-q", "-o", str(out)]
    res = runner.invoke(app, cmd)
    assert res.exit_code == 0, res.output
    model = load_model(out)
    assert [a.name for a in model.fingers["index"].axes("mp")] == ["mp"]
    slides = {k: np.linalg.norm(v[2]) for k, v in model.markers.items() if k.startswith("IND")}
    assert all(s > 0 for k, s in slides.items() if not k.startswith("IND3")), slides
    assert slides["IND3_1"] == 0.0  # alone on the distal phalanx
    res = runner.invoke(app, ["fit", str(session), "--mp-axes", "three", "-q"])
    assert res.exit_code != 0 and "--mp-axes" in res.output and "auto, hinge or two" in res.output
    six = tmp_path / "six"
    res = runner.invoke(app, ["simulate", str(six), "--subjects", "1", "--fingers", "index", "-q"])
    assert res.exit_code == 0, res.output
    (s6,) = six.iterdir()
    for option in (["--mp-axes", "two"], ["--slide"]):
        res = runner.invoke(app, ["fit", str(s6), *option, "-q"])
        assert res.exit_code != 0 and "only for a marker session" in res.output, res.output
