"""Evaluation of the whole hand: every thumb axis, tip, pad and angle against truth, pinch
tip distances and pad gaps, and events the model cannot evaluate (listed, never dropped).

Exact subject (noise-free, rigid sensors, pure hinges, thumb + index): the fitted thumb
chain equals the truth to 1e-6 mm / 1e-6 deg. Realistic subject: loose bounds measured on
this subject (thumb tip 1.6 mm user-axis vs 7.0 mm orthogonal on ``test.csv``; pinch
tip-distance error 0.3-1.3 mm user-axis, depending on the simulator's pinch postures).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.evaluate.fingertip import (
    count_skipped,
    evaluate_targets,
    sensor_carried,
    skipped_events,
)
from fingerfit.evaluate.pinch import PINCH_COLUMNS, evaluate_pinches
from fingerfit.evaluate.subject import _angle_errors, evaluate_subject, thumb_geometry
from fingerfit.evaluate.summary import summarize_study
from fingerfit.evaluate.truth import axis_errors, load_truth
from fingerfit.io.sessiondir import load_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.simulate import write_subject

from .conftest import subject

HAND = ("thumb", "index")


@functools.cache
def _written(kind: str, seed: int, root: str):
    """A simulated thumb + index subject written with its truth, loaded back and fitted
    (the exact one by the study: its SubjectResult is the fourth item)."""
    from pathlib import Path

    path = write_subject(subject(kind, seed, HAND), Path(root) / f"{kind}{seed}")
    session = load_session(path)
    if kind == "exact":
        res = evaluate_subject(session, FitOptions())
        return session, res.model, res.truth, res
    return session, fit_session(session), load_truth(path), None


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("thumb_eval"))


@pytest.fixture(scope="module")
def exact(root):
    return _written("exact", 11, root)


@pytest.fixture(scope="module")
def realistic(root):
    return _written("realistic", 2, root)


def test_exact_thumb_axes_equal_truth(exact) -> None:
    _session, model, truth, _res = exact
    ax = axis_errors(model, truth, "thumb")
    assert list(ax["joint"]) == ["cmc", "cmc_abduction", "mcp", "ip"]  # exact: MCP a hinge
    assert ax["axis_error_deg"].max() < 1e-6
    assert ax["centre_to_axis_mm"].max() < 1e-6
    # The fingers' rows are still their three flexion joints.
    assert list(axis_errors(model, truth, "index")["joint"]) == ["mp", "pip", "dip"]
    geo = thumb_geometry(_subject_stub(exact))
    row = geo.set_index("joint").loc["cmc"]
    assert row["true_axis_offset_mm"] > 1.0  # the CMC axes do not intersect
    assert abs(row["axis_offset_mm"] - row["true_axis_offset_mm"]) < 1e-6
    assert abs(row["axes_angle_deg"] - row["true_axes_angle_deg"]) < 1e-6


def _subject_stub(data):
    """The fields of a SubjectResult thumb_geometry reads."""
    session, model, truth, _res = data
    return type("S", (), {"subject": session.subject, "model": model, "truth": truth})()


def _moves_off_model(truth, recording: str, digit: str, model) -> bool:
    """Whether the true digit turns about an axis the model does not have in a recording
    (the exact simulator's target recording lets the thumb's MCP ab/adduction wander
    while the exact fit, rightly, makes the MCP a hinge)."""
    names = set(model.fingers[digit].angle_names())
    true = truth.angles[recording][digit]
    return any(np.abs(a).max() > 1e-9 for k, a in true.items() if k not in names)


def test_exact_thumb_tips_pads_and_angles_equal_truth(exact) -> None:
    session, model, truth, _res = exact
    checked = set()
    for rec in session.recordings()[1:]:
        kin = compute_kinematics(model, rec)
        for d in HAND:
            if _moves_off_model(truth, rec.name, d, model):
                continue
            checked.add((rec.name, d))
            m = kin.motions["user_axis"][d]
            assert np.abs(m.tip - truth.tips[rec.name][d]).max() < 1e-6, (rec.name, d)
            # The pads come from the pinch holds, not the digitised skin point: the exact
            # chain carries them as the distal sensor does.
            carried = sensor_carried(model, d, rec, model.fingers[d].pad)
            assert np.abs(m.pad - carried).max() < 1e-6, (rec.name, d)
            rows = _angle_errors(session.subject, d, rec.name, "user_axis", m.angles, truth)
            assert {r[3] for r in rows} == set(m.angles)  # every angle scored
            assert max(r[5] for r in rows) < 1e-6 and max(r[6] for r in rows) < 1e-6
        # The orthogonal thumb is not the true one: the comparison can fail.
        ortho = kin.motions["orthogonal"]["thumb"].tip
        if rec.name == "test.csv":
            assert np.nanmean(np.linalg.norm(ortho - truth.tips[rec.name]["thumb"], axis=1)) > 1
    for name in ("grasp.csv", "thumb_circumduction.csv", "thumb_opposition.csv", "pinch.csv"):
        assert (name, "thumb") in checked and (name, "index") in checked
    assert ("test.csv", "thumb") in checked


def test_exact_pinch_distances_equal_truth(exact) -> None:
    session, model, truth, _res = exact
    pin = evaluate_pinches(model, session, truth)
    assert list(pin.columns) == PINCH_COLUMNS
    n_events = sum(e.is_pinch for e in session.events)
    assert n_events >= 2 and len(pin) == 3 * n_events
    assert set(pin["kind"]) >= {"tip_pinch", "opposition"}
    for src in ("reference", "user_axis"):
        g = pin[pin["source"] == src]
        assert g["tip_distance_error_mm"].max() < 1e-6
        assert (g["tip_distance_mm"] - g["true_tip_distance_mm"]).abs().max() < 1e-6
        # Pads fitted to the exact holds meet (the digitised skin points do not).
        assert g["pad_gap_mm"].max() < 0.2 < g["true_pad_gap_mm"].min()
    # Nail-edge tips stay 12-18 mm apart while the pads touch.
    assert pin["true_tip_distance_mm"].between(10, 20).all()
    assert pin.loc[pin["source"] == "orthogonal", "tip_distance_error_mm"].mean() > 0.1


def test_realistic_thumb_tip_and_pinch_errors_are_bounded(realistic) -> None:
    session, model, truth, _res = realistic
    kin = compute_kinematics(model, session.recording("test.csv"), fingers=["thumb"])
    err = {
        v: np.nanmean(
            np.linalg.norm(kin.motions[v]["thumb"].tip - truth.tips["test.csv"]["thumb"], axis=1)
        )
        for v in ("user_axis", "orthogonal")
    }
    assert err["user_axis"] < 2.5  # measured 1.6
    assert err["user_axis"] < 0.5 * err["orthogonal"]  # measured 1.6 vs 7.0
    pin = evaluate_pinches(model, session, truth)
    tip = pin[pin["kind"] == "tip_pinch"].groupby("source")["tip_distance_error_mm"].mean()
    assert tip["user_axis"] < 2.5  # measured 0.3-1.3 (one subject; simulator versions)
    assert tip["reference"] < 2.5
    ax = axis_errors(model, truth, "thumb").set_index("joint")["axis_error_deg"]
    assert ax["cmc"] < 6 and ax["cmc_abduction"] < 6 and ax["ip"] < 6  # measured 1.9, 2.0, 1.0


def test_real_session_reports_the_model_pad_gap_alone(realistic) -> None:
    session, model, _truth, _res = realistic
    pin = evaluate_pinches(model, session, None)
    assert len(pin) and pin["tip_distance_error_mm"].isna().all()
    assert pin["true_pad_gap_mm"].isna().all() and pin["true_tip_distance_mm"].isna().all()
    assert np.isfinite(pin["pad_gap_mm"]).all() and np.isfinite(pin["tip_distance_mm"]).all()


def test_events_of_a_missing_digit_are_skipped_with_a_reason(exact) -> None:
    session, model, truth, _res = exact
    fingers = {k: v for k, v in model.fingers.items() if k != "thumb"}
    no_thumb = dataclasses.replace(model, fingers=fingers)
    skipped = skipped_events(no_thumb, session)
    pinches = [e for e in session.events if e.is_pinch]
    assert len(skipped) == len(pinches) > 0
    assert all("the model has no digit 'thumb'" in s["reason"] for s in skipped)
    assert evaluate_pinches(no_thumb, session, truth).empty
    # Target touches by the index are still evaluated; pinches are not target touches.
    t = evaluate_targets(model, session)
    assert set(t["finger"]) == {"index"} and not t["target"].isin(HAND).any()
    assert skipped_events(model, session) == []


def test_study_summary_has_thumb_pinch_and_skipped_events(exact) -> None:
    session, model, _truth, res = exact
    fingers = {k: v for k, v in res.model.fingers.items() if k != "thumb"}
    lacking = dataclasses.replace(
        res,
        subject="S99",
        skipped_events=tuple(skipped_events(dataclasses.replace(model, fingers=fingers), session)),
    )
    summary, tables = summarize_study([res, lacking], FitOptions())
    assert summary["thumb"]["truth_axes"]["cmc_abduction"]["axis_error_deg"]["max"] < 1e-6
    assert summary["thumb"]["truth_tip"]["test.csv"]["user_axis"]["mean_mm"] < 1e-6
    pn = summary["pinch"]["per_source"]["user_axis"]
    assert pn["tip_distance_error"]["mean_mm"] < 1e-6 and pn["tip_distance_error"]["n"] > 0
    assert summary["truth"]["angle_error_deg"]["thumb"]["cmc_abduction"]["user_axis"]["mean"] < 1e-6
    assert set(tables) >= {"pinch", "truth_angles", "thumb_geometry"}
    events = [s for s in summary["skipped"] if s["statistic"].startswith("events.S99.")]
    assert len(events) == sum(e.is_pinch for e in session.events)
    # The paper's headline is the four fingers'; the thumb has its own.
    assert set(tables["max_flexion"]["finger"]) == {"thumb", "index"}
    n_index = int((tables["max_flexion"]["finger"] == "index").sum())
    assert summary["max_flexion"]["user_axis"]["n"] == n_index
    assert summary["thumb"]["max_flexion"]["user_axis"]["n"] > 0


def test_a_target_touch_of_a_missing_digit_is_counted(exact) -> None:
    session, model, _truth, _res = exact
    touch = next(e for e in session.events if not e.is_pinch)
    lone = dataclasses.replace(session, events=[dataclasses.replace(touch, finger="middle")])
    assert evaluate_targets(model, lone).empty
    skipped = skipped_events(model, lone)
    assert [s["kind"] for s in skipped] == ["target"]
    assert "the model has no digit 'middle'" in skipped[0]["reason"]
    assert count_skipped(skipped) == {"target_touches": 1, "pinches": 0}
    assert count_skipped(skipped_events(model, session)) == {"target_touches": 0, "pinches": 0}


def test_study_counts_and_reports_the_events_not_evaluated(exact, tmp_path, monkeypatch) -> None:
    """A model without the index: its target touches and every pinch (thumb with index)
    are counted in summary.json, the report and fingerfit study's warnings."""
    from typer.testing import CliRunner

    from fingerfit.cli import app
    from fingerfit.evaluate import StudyResult
    from fingerfit.evaluate.report_sections import _problems

    session, model, _truth, res = exact
    fingers = {k: v for k, v in res.model.fingers.items() if k != "index"}
    skipped = skipped_events(dataclasses.replace(model, fingers=fingers), session)
    lacking = dataclasses.replace(res, subject="S99", skipped_events=tuple(skipped))
    touches = sum(e.finger == "index" and not e.is_pinch for e in session.events)
    pinches = sum(e.is_pinch for e in session.events)
    assert touches > 1 and pinches > 1
    counts = {"target_touches": touches, "pinches": pinches}
    summary, tables = summarize_study([res, lacking], FitOptions())
    assert summary["events_not_evaluated"] == {**counts, "per_subject": {"S99": counts}}
    assert "events_not_evaluated" not in summarize_study([res], FitOptions())[0]
    result = StudyResult([res, lacking], summary, tables, tmp_path, report=tmp_path / "r.html")
    html = "".join(_problems(result))
    assert f"{touches} target touches and {pinches} pinches were not evaluated" in html
    assert f"<li>S99: {touches} target touches and {pinches} pinches</li>" in html
    assert "not evaluated" not in "".join(_problems(dataclasses.replace(result, summary={})))
    monkeypatch.setattr("fingerfit.evaluate.run_study", lambda *_a, **_k: result)
    out = CliRunner().invoke(app, ["study", str(session.path), "--out", str(tmp_path / "o")])
    assert out.exit_code == 0, out.output
    assert (
        f"warning: S99: {touches} target touch(es) and {pinches} pinch(es) not evaluated: "
        "the model lacks their digit" in " ".join(out.output.split())
    )


def test_thumb_only_study(tmp_path) -> None:
    """A session of the thumb alone: no Fig. 10 (the fingers'), the thumb's own section."""
    from fingerfit.evaluate import run_study

    path = write_subject(subject("exact", 5, ("thumb",)), tmp_path / "T05")
    res = run_study([path], tmp_path / "out", FitOptions())
    assert set(res.figures) == {"fig08", "fig09_S01", "thumb"}
    sm = res.summary
    assert sm["max_flexion"]["user_axis"]["n"] == 0
    assert sm["thumb"]["max_flexion"]["user_axis"]["n"] > 0
    assert sm["thumb"]["truth_tip"]["test.csv"]["user_axis"]["mean_mm"] < 1e-6
    html = res.report.read_text()
    assert "No finger in this study" in html and "id=thumb" in html
