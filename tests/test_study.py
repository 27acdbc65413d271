"""The study: statistics against hand-computed values, the evaluation against truth, the report."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.estimate import FitOptions
from fingerfit.evaluate import run_study
from fingerfit.evaluate.stats import (
    independent_ttest,
    paired_ttest,
    reduction_percent,
    summarize,
    two_way_anova,
)
from fingerfit.simulate import SimConfig, simulate_cohort, write_subject


def test_summary_and_reduction_by_hand() -> None:
    s = summarize([1.0, 2.0, 3.0, 4.0, np.nan])
    assert (s.mean, s.n) == (2.5, 4)
    assert s.sd == pytest.approx(np.sqrt(5 / 3))
    assert reduction_percent(2.6, 4.7) == pytest.approx(44.68085, abs=1e-4)


def _p_two_sided_df4(t: float) -> float:
    """Closed-form Student t with 4 df: CDF = 1/2 + (3/8) u (1 - u^2/12), u = t / sqrt(1 + t^2/4)."""
    u = abs(t) / np.sqrt(1 + t * t / 4)
    return 2 * (1 - (0.5 + 3 / 8 * u * (1 - u * u / 12)))


def test_t_tests_by_hand() -> None:
    # d = a - b = [-1, 0, -1, -1, -2]: mean -1, SD sqrt(0.5); t = -1 / (sqrt(0.5)/sqrt(5)).
    t = paired_ttest([1, 2, 3, 4, 5], [2, 2, 4, 5, 7])
    assert t.t == pytest.approx(-np.sqrt(10))
    assert t.df == 4 and t.p == pytest.approx(_p_two_sided_df4(np.sqrt(10)), rel=1e-9)
    # Means 2 and 5, pooled variance 1: t = -3 / sqrt(2/3).
    t = independent_ttest([1, 2, 3], [4, 5, 6])
    assert t.t == pytest.approx(-3 / np.sqrt(2 / 3))
    assert t.df == 4 and t.p == pytest.approx(_p_two_sided_df4(3 / np.sqrt(2 / 3)), rel=1e-9)


def test_two_way_anova_by_hand() -> None:
    # Balanced 2x2, two replicates: SS_A = 18, SS_B = 72, SS_AB = 8, SS_E = 8 (df 4, MSE 2).
    data = pd.DataFrame(
        {
            "y": [1, 3, 5, 7, 2, 4, 10, 12],
            "model": ["u", "u", "u", "u", "o", "o", "o", "o"],
            "target": ["t1", "t1", "t2", "t2", "t1", "t1", "t2", "t2"],
        }
    )
    table = two_way_anova(data, "y", "model", "target")
    assert table.loc["C(model)", "sum_sq"] == pytest.approx(18)
    assert table.loc["C(target)", "sum_sq"] == pytest.approx(72)
    assert table.loc["C(model):C(target)", "sum_sq"] == pytest.approx(8)
    assert table.loc["Residual", "sum_sq"] == pytest.approx(8)
    assert table.loc["C(model)", "F"] == pytest.approx(9)
    assert table.loc["C(model):C(target)", "F"] == pytest.approx(4)


@pytest.fixture(scope="module")
def exact_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("exact")
    dirs = [
        write_subject(s, root / s.session.subject) for s in simulate_cohort(SimConfig.exact(), 2, 5)
    ]
    return run_study(dirs, root / "out", FitOptions(method="tang2018"))


def test_evaluation_is_exact_on_noise_free_data(exact_study) -> None:
    """With exact data the user-axis model, the distal-sensor reference and the stylus targets all
    coincide, so every error the study reports for them is zero; the orthogonal model's is not."""
    sm = exact_study.summary
    assert sm["max_flexion"]["user_axis"]["mean_mm"] < 1e-6
    assert sm["targets"]["user_axis"]["mean_mm"] < 1e-6
    assert sm["targets"]["reference"]["mean_mm"] < 1e-6
    assert sm["max_flexion"]["orthogonal"]["mean_mm"] > 0.5
    assert sm["truth"]["axis_error_deg"]["pip"]["max"] < 1e-6
    flex = exact_study.tables["max_flexion"]
    assert (flex.groupby("subject").size() == 10).all()  # one maximal flexion per grasp cycle


@pytest.fixture(scope="module")
def realistic_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("real")
    dirs = [write_subject(s, root / s.session.subject) for s in simulate_cohort(SimConfig(), 3, 8)]
    return run_study(dirs, root / "out", FitOptions(method="tang2018"))


def test_realistic_study_outputs(realistic_study) -> None:
    out = realistic_study.out_dir
    sm = json.loads((out / "summary.json").read_text())
    for key in ("targets", "max_flexion"):
        h = sm[key]
        assert h["user_axis"]["mean_mm"] < h["orthogonal"]["mean_mm"]
        assert h["reduction_percent"] == pytest.approx(
            100 * (1 - h["user_axis"]["mean_mm"] / h["orthogonal"]["mean_mm"])
        )
        assert {"mean_mm", "sd_mm"} <= set(h["user_axis"]) and "sd_reduction_percent" in h
    targets = pd.read_csv(out / "targets.csv")
    assert len(targets) == 3 * 7 * 3  # subjects x targets x sources
    user = targets[targets.source == "user_axis"].error_mm
    assert sm["targets"]["user_axis"]["mean_mm"] == pytest.approx(user.mean())
    assert set(sm["axis_quality"]["per_joint"]) == {"mp", "pip", "dip"}
    assert "C(model):C(target)" in sm["targets"]["anova_model_x_target"]
    for name in (
        "fig08_axis_quality.png",
        "fig10_max_flexion.png",
        "fig11_target_offsets.png",
        "fig12_target_errors.png",
        "truth_fingertip.png",
        "axis_quality.csv",
        "models/S01.json",
    ):
        assert (out / name).stat().st_size > 0, name
    report = (out / "report.html").read_text()
    assert report.count("data:image/png;base64,") >= 5  # Figs. 8, 10-12, truth
    for s in sm["subjects"]:  # each subject's Fig. 9: linked, the file beside it
        assert f'src="fig09_trajectories_{s}.png"' in report
        assert (out / f"fig09_trajectories_{s}.png").stat().st_size > 0
    assert 'id="model-data"' in report or "id='model-data'" in report


def test_report_renders_in_headless_chromium(realistic_study, tmp_path) -> None:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip(
            "Debian chromium is not installed (make test installs it when apt-get is available)"
        )
    shot = tmp_path / "report.png"
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--window-size=1200,3000",
        f"--screenshot={shot}",
        (realistic_study.out_dir / "report.html").as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    img = mpimg.imread(shot)[..., :3]
    assert img.shape[0] >= 1000
    non_white = np.mean(img.min(axis=2) < 0.9)
    assert non_white > 0.05, non_white  # text, tables and figures, not a blank page
    assert img.std() > 0.05


def test_cli_demo(tmp_path) -> None:
    res = CliRunner().invoke(
        app, ["demo", "--out", str(tmp_path / "d"), "--subjects", "2", "--method", "tang2018"]
    )
    assert res.exit_code == 0, res.output
    assert "report:" in res.output and (tmp_path / "d" / "study" / "report.html").is_file()
    assert "targets" in res.output and "paper" in res.output
    # The sessions as summary.json names them: beside the study, not in the staging folder
    # the demo was written into before it was renamed into place.
    study = tmp_path / "d" / "study"
    sessions = json.loads((study / "summary.json").read_text())["sessions"]
    assert {k: v["path"] for k, v in sessions.items()} == {
        "S01": "../sessions/S01",
        "S02": "../sessions/S02",
    }
    assert all((study / v["path"] / "session.toml").is_file() for v in sessions.values())


def test_summary_names_sessions_from_the_study_folder(tmp_path, monkeypatch) -> None:
    from fingerfit.evaluate.summary import summary_path

    monkeypatch.chdir(tmp_path)
    assert summary_path(Path("c100/S01"), Path("out")) == "../c100/S01"
    # Not beside the study folder: absolute (a path relative to where it ran means nothing).
    assert summary_path(Path("c100/S01"), Path("runs/out")) == str(Path.cwd() / "c100/S01")
    assert summary_path(tmp_path / "a" / "S01", Path("out")) == "../a/S01"
    outside = Path("/nonexistent-data/S01")
    assert summary_path(outside, tmp_path / "out") == str(outside)
    assert summary_path(Path("c100/S01"), None) == "c100/S01"
    assert summary_path(None, Path("out")) is None
