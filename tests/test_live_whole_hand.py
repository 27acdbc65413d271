"""`fingerfit stream` with a model that has a thumb: picked up with no code change."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fingerfit.export.geometry import joint_names
from fingerfit.export.trajectory import trajectory_table
from fingerfit.io import write_pose_csv
from fingerfit.kinematics import compute_kinematics, kinematics_table
from fingerfit.live.stream import block_values, channels_of, model_sensors
from fingerfit.model import save_model

from .bad_inputs._cli import run
from .conftest import subject

HAND = ("thumb", "index")  # the subject test_export and test_thumb_fit use (cached once)


@pytest.fixture(scope="module")
def whole_hand(tmp_path_factory):
    try:
        sim = subject("exact", 3, HAND)
    except (KeyError, ValueError):
        pytest.skip("the simulator has no thumb")
    from fingerfit.simulate.truthmodel import truth_model

    model = truth_model(sim)
    d = tmp_path_factory.mktemp("hand")
    rec = sim.session.test[0].slice(slice(0, 96))
    return model, save_model(model, d / "model.json"), rec, write_pose_csv(d / "rec.csv", rec)


def test_whole_hand_channels_and_values(whole_hand) -> None:
    model, _, rec, _ = whole_hand
    kin = compute_kinematics(model, rec, ("user_axis",))
    ch = channels_of(model, kin)
    assert ch.digits == list(HAND)
    assert {"thumb.cmc", "thumb.mcp", "thumb.ip"} <= set(ch.angle_labels)
    assert ch.joint_names == joint_names(model) and "thumb_cmc" in ch.joint_names
    sensors = model_sensors(model)
    assert sensors[0] == "hand" and "thumb.metacarpal" in sensors
    v = block_values(kin, ch, rec, sensors, "tracker")
    table = kinematics_table(kin)
    np.testing.assert_array_equal(v.angles, table[ch.angle_labels].to_numpy())
    np.testing.assert_array_equal(v.tips, table[ch.tip_labels].to_numpy())
    traj = trajectory_table(kin, model)
    np.testing.assert_array_equal(v.joints, traj[ch.joint_names].to_numpy())
    assert v.valid.all()


def test_whole_hand_stream_record_equals_angles(whole_hand, tmp_path: Path) -> None:
    _, model_path, _, csv = whole_hand
    res = run("angles", model_path, csv, "-o", tmp_path / "angles.csv", "-q")
    assert res.exit_code == 0, res.output
    res = run(
        "stream", model_path, "--source", f"replay:{csv}@20", "--record", tmp_path / "live.csv",
        "-q",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    want = pd.read_csv(tmp_path / "angles.csv")
    got = pd.read_csv(tmp_path / "live.csv")
    assert "thumb.cmc" in got.columns and len(got) == 96
    pd.testing.assert_frame_equal(got, want, check_exact=False, rtol=0, atol=1e-9)
