"""``fingerfit view``: the .rrd it writes, read back with Rerun's own reader."""

from __future__ import annotations

import sys
import warnings
from collections import defaultdict

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.evaluate.truth import load_truth
from fingerfit.kinematics import compute_kinematics
from fingerfit.model import save_model
from fingerfit.simulate import write_subject

from .conftest import subject

DIGITS = ("thumb", "index", "middle")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated session folder (with its truth), its fitted model and the grasp file."""
    from fingerfit.estimate import fit_session

    sub = subject("realistic", 2, DIGITS)
    folder = write_subject(sub, tmp_path_factory.mktemp("view") / "S01")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    path = save_model(model, folder / "model.json")
    return model, sub, folder, path


def _read(path):
    """Entity -> component -> list of (frame, value) of the temporal rows; static rows apart."""
    from rerun.chunk import RrdReader

    rows: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    static: dict[str, set] = defaultdict(set)
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n not in ("rerun.controls.RowId", "time")]
        if chunk.is_static:
            static[chunk.entity_path] |= set(names)
            continue
        frames = batch.column("frame").to_pylist()
        for name in names:
            if name != "frame":
                rows[chunk.entity_path][name] += list(
                    zip(frames, batch.column(name).to_pylist(), strict=True)
                )
        rows[chunk.entity_path]["frame"] += frames
    return rows, static


def test_view_save_writes_every_entity_once_per_frame(simulated, tmp_path):
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    model, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    out = tmp_path / "v" / "grasp.rrd"
    r = CliRunner().invoke(
        app,
        ["view", str(model_path), str(grasp), "--robot", "shadow", "--save", str(out), "-q"],
    )
    assert r.exit_code == 0, r.output
    assert out.is_file() and not list(out.parent.glob(".*part*"))
    rows, static = _read(out)
    rec = sub.session.grasp[0]
    n = rec.n_frames
    expected = [
        "/person/skeleton",
        "/person/joints",
        "/person/axes",
        "/person/tips",
        "/person/pads",
        "/person/orthogonal/tips",
        "/sensors",
        "/truth/tips",
        "/robot/skeleton",
        "/robot/joints",
        "/robot/tips",
    ]
    expected += [f"/angles/{d}/{a}" for d in DIGITS for a in model.fingers[d].angle_names()]
    assert set(expected) <= set(rows), sorted(set(expected) - set(rows))
    for entity in rows:
        assert sorted(rows[entity]["frame"]) == list(range(n)), entity  # one point per frame
    # The tips, in float64 beside the float32 positions, are compute_kinematics' own.
    kin = compute_kinematics(model, rec)
    tips = np.stack([kin.motions["user_axis"][d].tip for d in model.fingers], axis=1)
    got = np.array([v for _, v in sorted(rows["/person/tips"]["tip_mm"])]).reshape(n, -1, 3)
    np.testing.assert_allclose(got, tips, rtol=0, atol=1e-6)
    shown = np.array([v for _, v in sorted(rows["/person/tips"]["Points3D:positions"])])
    np.testing.assert_allclose(shown, tips, rtol=0, atol=1e-3)  # float32 in the viewer
    # The angles in degrees, the truth's tips as written by the simulator.
    pip = np.array([v[0] for _, v in sorted(rows["/angles/index/pip"]["Scalars:scalars"])])
    np.testing.assert_allclose(
        pip, np.degrees(kin.motions["user_axis"]["index"].angles["pip"]), atol=1e-9
    )
    truth = np.array([v for _, v in sorted(rows["/truth/tips"]["Points3D:positions"])])
    written = load_truth(folder).tips[rec.name]
    np.testing.assert_allclose(truth, np.stack([written[d] for d in DIGITS], axis=1), atol=1e-3)
    assert "Points3D:labels" in static["/person/tips"]


def test_skeleton_is_rigid_and_starts_at_the_model(simulated):
    """The distal segment keeps its length; frame by frame the skeleton ends at the tip."""
    from fingerfit.view import hand_scene

    model, sub, _, _ = simulated
    rec = sub.session.grasp[0]
    scene = hand_scene(model, rec)
    for k, d in enumerate(scene.digits):
        fm = model.fingers[d]
        last = list(fm.joints)[-1]
        if fm.joints[last].migration is not None:
            continue
        length = np.linalg.norm(fm.tip - fm.joints[last].center)
        tip = scene.kinematics.motions["user_axis"][d].tip
        np.testing.assert_allclose(
            np.linalg.norm(tip - scene.centres[:, k, 2], axis=1), length, atol=1e-9
        )
    assert scene.axis_origins.shape == (rec.n_frames, len(scene.axes), 3)
    assert {kind for _, _, kind in scene.axes} == {"flexion", "abduction"}


def test_missing_rerun_is_one_line_naming_the_extra(simulated, tmp_path, monkeypatch):
    _, sub, folder, model_path = simulated
    monkeypatch.setitem(sys.modules, "rerun", None)
    grasp = folder / sub.session.grasp[0].name
    r = CliRunner().invoke(
        app, ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.rrd")]
    )
    assert r.exit_code == 2
    assert "pip install fingerfit[view]" in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "v.rrd").exists()


def test_save_must_be_an_rrd_and_map_needs_a_robot(simulated, tmp_path):
    _, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    r = CliRunner().invoke(
        app, ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.txt")]
    )
    assert r.exit_code == 2 and "--save" in r.output
    r = CliRunner().invoke(
        app,
        ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.rrd"), "--map", "m.toml"],
    )
    assert r.exit_code == 2 and "needs --robot" in r.output
