"""`fingerfit angles` and `fingerfit stream` with fewer sensors than phalanges.

`angles` solves the frames with a missing sensor (absent from the file, or left out with
--sensors) and says so (`<digit>.ik_rms_mm`, the summary), refuses a layout that cannot
determine a joint in one line naming it; `stream` keeps sending solved values, not held
ones, through a sensor that vanishes for two seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fingerfit.io import write_pose_csv
from fingerfit.kinematics import compute_kinematics, kinematics_table
from fingerfit.live.sources import ReplaySource
from fingerfit.live.stream import Streamer, channels_of, run
from fingerfit.model import load_model
from fingerfit.session import PoseSeries, Recording

from ._live import SOLVED_DEG, FakeLsl, Logged, angles_of, fitted, short_recording
from .bad_inputs._cli import refused
from .bad_inputs._cli import run as cli

REDUCED = "hand,index.proximal,index.distal"


def _angles(tmp_path: Path, *args: str) -> pd.DataFrame:
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "rec.csv", short_recording(480))
    out = tmp_path / "angles.csv"
    res = cli("angles", model_path, csv, "-o", out, "-q", *args)
    assert res.exit_code == 0, res.output
    return pd.read_csv(out), res.output


def test_angles_of_every_sensor_are_unchanged_and_say_nothing_was_solved(tmp_path) -> None:
    got, output = _angles(tmp_path)
    model = load_model(fitted()[1])
    want = kinematics_table(compute_kinematics(model, short_recording(480)), model.session_units)
    pd.testing.assert_frame_equal(got[list(want.columns)], want, check_exact=False, atol=1e-9)
    assert list(got.columns) == [*want.columns, "index.ik_rms_mm"]  # the one new column
    assert got["index.ik_rms_mm"].isna().all() and "solved by the model" not in output


def test_angles_with_sensors_left_out_are_solved_and_reported(tmp_path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    got, output = _angles(tmp_path / "a", "--sensors", REDUCED, "--uncertainty")
    full, _ = _angles(tmp_path / "b")
    assert "480 frames solved by the model (index)" in output
    assert "index: median SD (deg)" in output
    rms = got["index.ik_rms_mm"]
    assert rms.notna().all() and 0.05 < rms.median() < 5.0  # mm: the sensors' spread
    for k in ("mp", "pip", "dip"):
        diff = got[f"index.{k}"] - full[f"index.{k}"]
        assert np.sqrt((diff**2).mean()) < 4.0, k  # deg, from the model, not from sensors
        sd = got[f"index.{k}.sd"]
        assert sd.notna().all() and (sd > 0).all()
    # The split of PIP and DIP comes from the distal sensor's position alone: less sure
    # than the MP, which the proximal sensor gives.
    assert got["index.pip.sd"].median() > 5 * got["index.mp.sd"].median()
    assert np.isfinite(got[["index.tip.x", "index.tip.y", "index.tip.z"]].to_numpy()).all()


@pytest.mark.parametrize(
    ("sensors", "fragments"),
    [
        ("hand,index.proximal,index.middle", ["index dip: not determined", "index.distal would"]),
        ("index.proximal,index.middle,index.distal", ["no 'hand' sensor"]),
        ("hand,index.tip", ["--sensors", "index.tip", "has:"]),
    ],
)
def test_angles_refuses_a_layout_that_cannot_determine_a_joint(tmp_path, sensors, fragments):
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "rec.csv", short_recording(48))
    out = tmp_path / "angles.csv"
    res = cli("angles", model_path, csv, "-o", out, "--sensors", sensors)
    refused(res, *fragments)
    assert not out.exists()


def test_stream_solves_a_sensor_that_vanishes_for_two_seconds() -> None:
    """The robot lane keeps sending values that agree with the offline solution, and none
    are held; its source channel says the model solved them."""
    model = load_model(fitted()[1])
    rec = short_recording(960)
    poses = dict(rec.poses)
    p = poses["index.middle"]
    pos, rot = p.position.copy(), p.rotation.copy()
    gone = slice(240, 720)  # 2 s at 240 Hz
    pos[gone], rot[gone] = np.nan, np.nan
    poses["index.middle"] = PoseSeries(pos, rot)
    rec = Recording(rec.name, rec.time, poses)
    lsl = FakeLsl()
    streamer = Streamer(model, lsl=lsl, max_age=10.0)  # no frame too old: every one is sent
    source = Logged(ReplaySource(rec, 4.0))
    s = run(source, streamer, status=False)
    assert s.received == 960 and s.invalid == 480 and s.held == 0
    arrivals = np.concatenate(source.blocks_seen)
    sent = np.searchsorted(arrivals, np.concatenate(lsl.arrival))
    ch = channels_of(model, compute_kinematics(model, rec.slice(slice(0, 2)), ("user_axis",)))
    angles = np.vstack(lsl.angles)
    code = np.vstack(lsl.source)[:, ch.digits.index("index")]
    inside = (sent >= 240) & (sent < 720)
    np.testing.assert_array_equal(code, inside.astype(float))
    table, solved = angles_of(model, rec)
    cols = [ch.angle_labels.index(f"index.{k}") for k in ("pip", "dip")]
    want = table[[ch.angle_labels[c] for c in cols]].to_numpy()[sent]
    diff = angles[:, cols] - want
    assert np.abs(diff[~inside]).max() < 1e-9
    assert np.abs(diff[inside]).max() < 5 * SOLVED_DEG
    assert np.sqrt((diff[inside] ** 2).mean()) < SOLVED_DEG
    # Not held: the solved angles follow the finger from frame to frame.
    moving = np.abs(np.diff(angles[inside][:, cols], axis=0)).max(axis=1)
    assert (moving > 0).mean() > 0.99
    assert solved[gone].all()


def test_a_reduced_layout_in_the_wrong_units_is_refused(tmp_path) -> None:
    """The hand and the distal sensor share no joint, so no pivot check applies; the
    residual of the model's solution says the recording does not fit (read as cm, a
    recording in mm is ten times too large)."""
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "rec.csv", short_recording(96))
    out = tmp_path / "angles.csv"
    args = ("angles", model_path, csv, "-o", out, "--sensors", "hand,index.distal")
    refused(cli(*args, "--units", "cm"), "the sensors do not fit the model", "--units")
    assert not out.exists()
    res = cli(*args, "--units", "cm", "--force", "-q")
    assert res.exit_code == 0 and "continued with --force" in res.output
    assert cli(*args, "-q").exit_code == 0  # the right units: it fits
