"""`fingerfit export` and `fingerfit angles --urdf-names`: files, errors, and replay.

The replay test drives the exported URDF in Pinocchio with the angles that
``fingerfit angles`` computed for a recording, places the ``hand`` root at the
recording's hand sensor pose, and requires the fingertips ``fingerfit angles``
wrote (mm, tracker frame) within 0.01 mm.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.errors import FingerfitError
from fingerfit.export import joint_names, robot_hand, trajectory_table
from fingerfit.io import read_pose_csv
from fingerfit.kinematics import FingerMotion, Kinematics
from fingerfit.model import JointModel, load_model, save_model, with_fixed_centres
from fingerfit.simulate import write_subject

from .conftest import subject

pin = pytest.importorskip("pinocchio")
mujoco = pytest.importorskip("mujoco")
pytest.importorskip("yourdfpy")

runner = CliRunner()


@pytest.fixture(scope="module")
def fitted(tmp_path_factory) -> Path:
    """A simulated session (index, middle) fitted by `fingerfit fit`; returns the session dir."""
    d = write_subject(
        subject("realistic", 4, ("index", "middle")), tmp_path_factory.mktemp("s") / "S"
    )
    res = runner.invoke(app, ["fit", str(d)])
    assert res.exit_code == 0, res.output
    return d


def _run(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def test_export_writes_urdf_and_mjcf(fitted: Path, tmp_path: Path) -> None:
    res = _run(
        "export", fitted / "model.json", "--urdf", tmp_path / "h.urdf", "--mjcf", tmp_path / "h.xml"
    )
    assert res.exit_code == 0, res.output
    res = _run(
        "export", fitted / "model.json", "--urdf", tmp_path / "o.urdf", "--variant", "orthogonal"
    )
    assert res.exit_code == 0, res.output
    model = load_model(fitted / "model.json")
    r0 = model.reference_poses["hand"][1]
    pu = pin.buildModelFromUrdf(str(tmp_path / "h.urdf"))
    po = pin.buildModelFromUrdf(str(tmp_path / "o.urdf"))
    mj = mujoco.MjModel.from_xml_path(str(tmp_path / "h.xml"))
    for f in ("index", "middle"):
        jm = model.fingers[f].joints["pip"]
        jid = pu.getJointId(f"{f}_pip")
        assert np.abs(pu.joints[jid].extract().axis - r0.T @ jm.axis).max() < 1e-12
        assert np.abs(po.joints[jid].extract().axis - r0.T @ jm.orthogonal_axis).max() < 1e-12
        assert np.abs(mj.joint(f"{f}_pip").axis - r0.T @ jm.axis).max() < 1e-12
    assert [mj.joint(i).name for i in range(mj.njnt)] == joint_names(model)


def test_angles_urdf_names_replays_in_pinocchio(fitted: Path, tmp_path: Path) -> None:
    model_path, rec_path = fitted / "model.json", fitted / "test.csv"
    res = _run(
        "angles", model_path, rec_path, "-o", tmp_path / "angles.csv",
        "--urdf-names", tmp_path / "traj.csv",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    res = _run("export", model_path, "--urdf", tmp_path / "hand.urdf")
    assert res.exit_code == 0, res.output

    model = load_model(model_path)
    angles = pd.read_csv(tmp_path / "angles.csv")
    traj = pd.read_csv(tmp_path / "traj.csv")
    assert list(traj.columns) == ["time", *joint_names(model)]
    assert np.array_equal(traj["time"], angles["time"])
    for name in joint_names(model):  # the same angles: deg in one file, rad in the other
        f, j = name.split("_", 1)
        assert np.allclose(np.radians(angles[f"{f}.{j}"]), traj[name], atol=1e-12, equal_nan=True)

    rec = read_pose_csv(rec_path, units=model.session_units)
    hand = rec.pose("hand")
    pm = pin.buildModelFromUrdf(str(tmp_path / "hand.urdf"))
    pd_ = pm.createData()
    assert sorted(pm.names[1:]) == sorted(joint_names(model))
    cols = [(pm.joints[pm.getJointId(n)].idx_q, n) for n in joint_names(model)]
    tips = {f: pm.getFrameId(f"{f}_tip") for f in model.fingers}
    values = traj[[n for _, n in cols]].to_numpy()
    idx = [i for i, _ in cols]
    worst, checked = 0.0, 0
    for k in range(len(traj)):
        if not (np.isfinite(values[k]).all() and np.isfinite(hand.position[k]).all()):
            continue
        q = pin.neutral(pm)
        q[idx] = values[k]
        pin.framesForwardKinematics(pm, pd_, q)
        for f, fid in tips.items():
            local_mm = 1000.0 * pd_.oMf[fid].translation
            tip = hand.rotation[k] @ local_mm + hand.position[k]
            ref = angles[[f"{f}.tip.x", f"{f}.tip.y", f"{f}.tip.z"]].to_numpy()[k]
            worst = max(worst, float(np.abs(tip - ref).max()))
        checked += 1
    print(f"\nPinocchio vs angles CSV: {checked} frames, max fingertip discrepancy {worst:.2e} mm")
    assert checked > 0.9 * len(traj)
    assert worst <= 0.01


def test_trajectory_abduction_columns() -> None:
    """Two-axis MP: the ab/adduction column comes first; kinematics without it are refused."""
    from tests.test_export import synthetic_model

    model = synthetic_model(2, abduction=True, fingers=("index",))
    n = 4
    mp = np.array([0.1, np.nan, 0.3, 0.4])
    base = {"mp": mp, "pip": np.full(n, 0.2), "dip": np.full(n, 0.3)}
    with_ab = {**base, "mp_abduction": np.full(n, -0.05)}
    kin = Kinematics(
        np.arange(n) / 100, {"user_axis": {"index": FingerMotion(with_ab, np.zeros((n, 3)))}}
    )
    t = trajectory_table(kin, model)
    assert list(t.columns) == ["time", "index_mp_abduction", "index_mp", "index_pip", "index_dip"]
    assert np.array_equal(t["index_mp_abduction"], np.full(n, -0.05))
    assert np.array_equal(t["index_mp"], mp, equal_nan=True)
    kin = Kinematics(kin.time, {"user_axis": {"index": FingerMotion(base, np.zeros((n, 3)))}})
    with pytest.raises(FingerfitError, match="no angle 'mp_abduction' of the index"):
        trajectory_table(kin, model)
    with pytest.raises(FingerfitError, match="variant"):
        trajectory_table(kin, model, "orthogonal")


def _one_error_line(res, *needles: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    text = " ".join(res.output.split())
    assert text.startswith("error:"), res.output
    for n in needles:
        assert n in text, res.output


def test_export_errors_leave_no_files(fitted: Path, tmp_path: Path) -> None:
    model = fitted / "model.json"
    urdf, mjcf = tmp_path / "a.urdf", tmp_path / "a.xml"
    _one_error_line(
        _run("export", model, "--urdf", urdf, "--mjcf", mjcf, "--variant", "tilted"), "--variant"
    )
    _one_error_line(_run("export", model), "--urdf, --mjcf and/or --osim")
    _one_error_line(_run("export", model, "--urdf", urdf, "--margin-deg", "-1"), "--margin-deg")
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    _one_error_line(_run("export", bad, "--urdf", urdf), "bad.json", "not valid JSON")
    doc = json.loads(model.read_text())
    del doc["fingers"]["index"]["joints"]["pip"]["axis"]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    _one_error_line(
        _run("export", tmp_path / "m.json", "--urdf", urdf), "fingers.index.joints.pip.axis"
    )
    blocker = tmp_path / "file"
    blocker.write_text("x")  # a file where a directory should be
    _one_error_line(
        _run("export", model, "--urdf", urdf, "--mjcf", blocker / "a.xml"), "cannot write"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json", "file", "m.json"]


def test_missing_robot_extra_is_one_line(fitted: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco -> ImportError
    res = _run("export", fitted / "model.json", "--mjcf", tmp_path / "a.xml")
    _one_error_line(res, "pip install fingerfit[robot]")
    assert not (tmp_path / "a.xml").exists()


@pytest.mark.skipif(
    "migration" not in JointModel.__dataclass_fields__, reason="models without migration"
)
def test_rolling_centre_is_refused(fitted: Path) -> None:
    model = load_model(fitted / "model.json")
    fm = model.fingers["index"]
    pip = dataclasses.replace(fm.joints["pip"], migration=np.array([0.5, 0.0, 0.0]))
    fm = dataclasses.replace(fm, joints={**fm.joints, "pip": pip})
    model = dataclasses.replace(model, fingers={**model.fingers, "index": fm})
    with pytest.raises(FingerfitError, match=r"fingers\.index\.joints\.pip\.migration"):
        robot_hand(model)


def test_rolling_model_exports_with_fixed_centres(fitted: Path, tmp_path: Path) -> None:
    model = load_model(fitted / "model.json")
    fm = model.fingers["index"]
    m = np.array([0.3, 0.0, -0.4])  # 0.5 mm/rad
    pip = dataclasses.replace(fm.joints["pip"], migration=m)
    fm = dataclasses.replace(fm, joints={**fm.joints, "pip": pip})
    model = dataclasses.replace(model, fingers={**model.fingers, "index": fm})
    save_model(model, tmp_path / "rolling.json")
    args = ["export", str(tmp_path / "rolling.json"), "--urdf", str(tmp_path / "r.urdf")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2 and "--fix-centres" in res.output
    assert not (tmp_path / "r.urdf").exists()
    res = CliRunner().invoke(app, [*args, "--fix-centres"])
    assert res.exit_code == 0, res.output
    half = 0.5 * np.radians(max(pip.quality.rom_deg))
    assert "index.pip: migrating centre fixed at mid-range" in res.output
    assert f"up to {half * 0.5:.2f} mm" in res.output
    fixed, _ = with_fixed_centres(model)
    np.testing.assert_allclose(fixed.fingers["index"].joints["pip"].center, pip.center + half * m)
    assert fixed.fingers["index"].joints["pip"].migration is None
    assert fixed.fingers["index"].joints["dip"] is model.fingers["index"].joints["dip"]
    robot_hand(fixed)  # exportable
