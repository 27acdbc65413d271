"""The stylus: pivot calibration against simulated truth, ``stylus.json`` and
``fingerfit stylus``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.errors import FingerfitError
from fingerfit.io.posewrite import write_pose_csv
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate.stylus import Stylus, pivot_motion, white_noise
from fingerfit.stylus import STYLUS_FORMAT, fit_pivot, read_stylus
from fingerfit.stylus.pivot import MAX_TIP_CI_MM


def _pivot(seed: int, cone: float, noise: tuple[float, float] | None = (0.25, 0.1)):
    rng = np.random.default_rng(seed)
    stylus = Stylus.sample(rng)
    pivot = rng.normal(0.0, 150.0, 3)
    t, pos, rot = pivot_motion(rng, stylus, pivot, 240.0, cone_deg=cone)
    if noise is not None:
        pos, rot = white_noise(rng, pos, rot, *noise)
    return stylus, pivot, t, pos, rot


def test_noise_free_pivot_gives_the_tip_and_the_divot_exactly():
    stylus, pivot, _, pos, rot = _pivot(1, 30.0, None)
    fit = fit_pivot(pos, rot)
    np.testing.assert_allclose(fit.tip_offset_mm, stylus.tip_offset, atol=1e-6)
    np.testing.assert_allclose(fit.pivot_mm, pivot, atol=1e-6)
    assert fit.rms_mm < 1e-6
    assert fit.n_frames == pos.shape[0]


@pytest.mark.parametrize(("seed", "cone"), [(2, 25.0), (3, 40.0)])
def test_liberty_noise_pivot_within_the_targets(seed, cone):
    stylus, pivot, _, pos, rot = _pivot(seed, cone)
    fit = fit_pivot(pos, rot)
    assert np.linalg.norm(fit.tip_offset_mm - stylus.tip_offset) < 0.3
    assert np.linalg.norm(fit.pivot_mm - pivot) < 0.5
    assert 0.3 < fit.rms_mm < 0.8  # 0.25 mm and 0.1 deg at ~100 mm, per axis
    # The reported uncertainty covers the error it claims to.
    assert np.linalg.norm(fit.tip_offset_mm - stylus.tip_offset) < max(fit.tip_ci_mm, 0.1)
    assert fit.rotation_span_deg > cone  # the cone's width and the roll


def test_a_one_degree_wiggle_is_refused_though_the_roll_spans_tens_of_degrees():
    _, _, _, pos, rot = _pivot(4, 1.0)
    with pytest.raises(FingerfitError, match=r"do not determine the tip: \+/-") as exc:
        fit_pivot(pos, rot)
    assert f"over {MAX_TIP_CI_MM:g} mm" in str(exc.value)
    assert "\n" not in str(exc.value)


def test_outlier_frames_are_down_weighted():
    stylus, _, _, pos, rot = _pivot(5, 30.0)
    bad = np.arange(100, 2400, 97)
    pos = pos.copy()
    pos[bad] += 25.0  # a slipped tip, a distorted sample
    fit = fit_pivot(pos, rot)
    assert fit.downweighted >= bad.size
    assert np.linalg.norm(fit.tip_offset_mm - stylus.tip_offset) < 0.3


def test_missing_frames_are_left_out():
    stylus, _, _, pos, rot = _pivot(6, 30.0)
    pos, rot = pos.copy(), rot.copy()
    pos[::5] = np.nan
    fit = fit_pivot(pos, rot)
    assert fit.n_frames == pos.shape[0] - pos[::5].shape[0]
    assert np.linalg.norm(fit.tip_offset_mm - stylus.tip_offset) < 0.3


def _write(tmp_path, pos, rot, t, name="pivot.csv", sensor="stylus"):
    return write_pose_csv(tmp_path / name, Recording(name, t, {sensor: PoseSeries(pos, rot)}))


def test_cli_writes_stylus_json(tmp_path):
    stylus, _, t, pos, rot = _pivot(7, 35.0)
    path = _write(tmp_path, pos, rot, t)
    out = tmp_path / "stylus.json"
    r = CliRunner().invoke(app, ["stylus", str(path), "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["format"] == STYLUS_FORMAT and doc["sensor"] == "stylus"
    assert set(doc) >= {"tip_offset_mm", "pivot_mm", "rms_mm", "rotation_span_deg", "n_frames"}
    assert np.linalg.norm(np.array(doc["tip_offset_mm"]) - stylus.tip_offset) < 0.3
    assert doc["n_frames"] == t.size
    cal = read_stylus(out)
    np.testing.assert_allclose(cal.tip_offset_mm, doc["tip_offset_mm"])
    # Existing output: refused without --overwrite.
    r = CliRunner().invoke(app, ["stylus", str(path), "-o", str(out)])
    assert r.exit_code == 2 and "exists" in r.output


def test_cli_refuses_a_wiggle_in_one_line_and_writes_nothing(tmp_path):
    _, _, t, pos, rot = _pivot(8, 1.0)
    path = _write(tmp_path, pos, rot, t)
    out = tmp_path / "stylus.json"
    r = CliRunner().invoke(app, ["stylus", str(path), "-o", str(out)])
    assert r.exit_code == 2
    assert "do not determine the tip" in r.output and str(path) in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_maker_offset_and_its_refusals(tmp_path):
    out = tmp_path / "s.json"
    r = CliRunner().invoke(app, ["stylus", "--tip-offset", "0,0,-120.5", "-o", str(out)])
    assert r.exit_code == 0, r.output
    cal = read_stylus(out)
    np.testing.assert_allclose(cal.tip_offset_mm, [0, 0, -120.5])
    assert cal.pivot_mm is None and np.isnan(cal.rms_mm)
    for args, words in [
        (["--tip-offset", "0,0,-12.05"], None),  # fine: 12 mm
        (["--tip-offset", "0,0,-1.2"], "not a stylus's"),  # cm given as mm
        (["--tip-offset", "0,0"], "three numbers"),
        ([], "one of them"),
    ]:
        r = CliRunner().invoke(
            app, ["stylus", *args, "-o", str(tmp_path / "t.json"), "--overwrite"]
        )
        if words is None:
            assert r.exit_code == 0, r.output
        else:
            assert r.exit_code == 2 and words in r.output, r.output


def test_cli_names_a_missing_sensor(tmp_path):
    _, _, t, pos, rot = _pivot(9, 30.0)
    path = _write(tmp_path, pos, rot, t, sensor="hand")
    r = CliRunner().invoke(app, ["stylus", str(path), "-o", str(tmp_path / "s.json")])
    assert r.exit_code == 2 and "no sensor 'stylus' (has: hand)" in r.output


@pytest.mark.parametrize(
    ("doc", "field"),
    [
        ({"format": "x"}, "format"),
        ({"format": STYLUS_FORMAT, "sensor": "stylus", "tip_offset_mm": [0, 0]}, "tip_offset_mm"),
        ({"format": STYLUS_FORMAT, "sensor": "", "tip_offset_mm": [0, 0, 100]}, "sensor"),
        (
            {"format": STYLUS_FORMAT, "sensor": "stylus", "tip_offset_mm": [0, 0, 0.1]},
            "tip_offset_mm",
        ),
    ],
)
def test_bad_stylus_files_name_the_field(tmp_path, doc, field):
    path = tmp_path / "stylus.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FingerfitError) as exc:
        read_stylus(path)
    assert exc.value.field == field and str(path) in str(exc.value)
