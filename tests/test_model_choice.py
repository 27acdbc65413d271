"""Hinge or two axes, chosen by held-out prediction from every cycle (:mod:`.choice`).

The truth is the simulator's: each test scores the fitted model's tips on the free-motion
recording against the true tips, and compares the default fit with the always-hinge
model (``method="robust"``) on the same session.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest

from fingerfit.digits import ABDUCTION_FIRST, FLEXION_FIRST
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.model import load_model, save_model
from fingerfit.simulate import SimConfig, SimulatedSubject, simulate_subject
from fingerfit.simulate.study import relative_truth_in_parent
from fingerfit.transforms import angle_between_axes

from .conftest import subject


def tip_error_mm(sim: SimulatedSubject, model, digit: str) -> float:
    """Mean tip error (mm) of ``digit`` over the free-motion recording, against the truth."""
    rec = sim.session.test[0]
    kin = compute_kinematics(model, rec, variants=("user_axis",), fingers=[digit])
    true = sim.truth.frames[rec.name]["tip"][digit]
    return float(np.mean(np.linalg.norm(kin.motions["user_axis"][digit].tip - true, axis=1)))


@functools.cache
def thumb_contact_subject() -> SimulatedSubject:
    # The thumb's MCP ab/adducts only in opposition and pinches: the robust hinge rejects
    # those cycles as inconsistent with the grasp's, so the evidence for the second axis
    # is in the cycles an outlier step would throw away.
    return simulate_subject(
        SimConfig(fingers=("thumb", "index"), thumb_mcp_abduction="contact"), 300
    )


def test_thumb_mcp_second_axis_seen_only_in_pinches_is_kept(tmp_path) -> None:
    sim = thumb_contact_subject()
    model = fit_session(sim.session, FitOptions())
    hinge = fit_session(sim.session, FitOptions(method="robust"))
    thumb = model.fingers["thumb"]
    assert "mcp" in thumb.second_axes
    choice = thumb.joints["mcp"].quality.model_choice
    assert choice["chosen"] == "two_axis"
    assert choice["held_out_two_axis_mm"] < choice["held_out_hinge_mm"]
    # The hinge rejects the cycles that carry the ab/adduction; with two axes they are
    # kept, and not called sensor slips.
    assert hinge.fingers["thumb"].joints["mcp"].quality.rejected_cycles
    quality = thumb.joints["mcp"].quality
    assert quality.rejected_cycles == []
    assert not any("sensor slip" in n for n in quality.notes)
    assert any("two axes explain them" in n for n in quality.notes)
    # Measured: 0.90 mm (two axes) vs 2.71 mm (the hinge the outlier step left).
    err, err_hinge = tip_error_mm(sim, model, "thumb"), tip_error_mm(sim, hinge, "thumb")
    assert err < 1.3, err
    assert err < 0.5 * err_hinge, (err, err_hinge)
    # The choice and its evidence are in model.json and survive a round trip.
    back = load_model(save_model(model, tmp_path / "model.json"))
    assert back.fingers["thumb"].joints["mcp"].quality.model_choice == choice
    doc = json.loads((tmp_path / "model.json").read_text())
    assert doc["fingers"]["thumb"]["joints"]["mcp"]["quality"]["model_choice"] == choice


def test_soft_tissue_second_axis_costs_no_fingertip_accuracy() -> None:
    # No MP ab/adduction: a second axis only follows the sensors' soft-tissue tilt. Whatever
    # the choice, the model must predict the fingertip as well as the hinge (within 5 %).
    sim = simulate_subject(SimConfig(abduction=False), 1618992604)
    err = tip_error_mm(sim, fit_session(sim.session, FitOptions()), "index")
    err_hinge = tip_error_mm(sim, fit_session(sim.session, FitOptions(method="robust")), "index")
    assert err <= 1.05 * err_hinge, (err, err_hinge)


def test_real_ab_adduction_keeps_the_second_axis() -> None:
    sim = subject("realistic", 2)
    model = fit_session(sim.session, FitOptions())
    assert "mp" in model.fingers["index"].second_axes
    # The simulator's MP ab/adducts proximally, as the finger's usual model does.
    assert model.fingers["index"].order("mp") == ABDUCTION_FIRST
    assert model.fingers["index"].joints["mp"].quality.model_choice["order"] == ABDUCTION_FIRST
    err = tip_error_mm(sim, model, "index")
    err_hinge = tip_error_mm(sim, fit_session(sim.session, FitOptions(method="robust")), "index")
    assert err < 0.9 * err_hinge, (err, err_hinge)


def test_exact_hinges_stay_hinges() -> None:
    # Exact data: both models predict to rounding; the hinge is kept and is exact.
    sim = simulate_subject(SimConfig.exact(fingers=("thumb", "index")), 11)
    model = fit_session(sim.session, FitOptions())
    assert "mcp" not in model.fingers["thumb"].second_axes
    assert "mp" not in model.fingers["index"].second_axes
    for digit, joint in (("thumb", "mcp"), ("index", "mp")):
        choice = model.fingers[digit].joints[joint].quality.model_choice
        assert choice["chosen"] == "hinge" and choice["held_out_hinge_mm"] < 1e-9
    assert tip_error_mm(sim, model, "thumb") < 1e-6


def _mp_axis_error_deg(sim: SimulatedSubject, model) -> float:
    true = relative_truth_in_parent(sim, "index", "mp")[1]
    return float(np.degrees(angle_between_axes(model.in_parent("index", "mp")[1], true)))


def test_myohand_mp_flexion_first_is_found_in_the_data(tmp_path) -> None:
    """MyoHand's MP turns about its flexion axis proximally (the OpenSim hand models'
    order). Fitted in the finger's usual order (ab/adduction proximal, 8dd570e) its
    flexion axis was 7.43 deg off on average over 20 hands (docs/simulator.md); the
    held-out cycles choose the order (1.15 deg there; 0.64 deg on this seed)."""
    pytest.importorskip("myo_sim")
    sim = simulate_subject(SimConfig(world="myohand", hand="right"), 1002)
    model = fit_session(sim.session, FitOptions())
    index = model.fingers["index"]
    choice = index.joints["mp"].quality.model_choice
    assert choice["chosen"] == "two_axis" and choice["order"] == FLEXION_FIRST
    assert index.order("mp") == FLEXION_FIRST
    assert [a.name for a in index.axes("mp")] == ["mp", "mp_abduction"]
    deg = _mp_axis_error_deg(sim, model)
    assert deg < 1.5, deg  # measured 0.64
    usual = fit_session(sim.session, FitOptions(method="robust"))  # one axis
    assert tip_error_mm(sim, model, "index") < tip_error_mm(sim, usual, "index")
    # The order is part of the model file.
    back = load_model(save_model(model, tmp_path / "model.json"))
    assert back.fingers["index"].axis_order == {"mp": FLEXION_FIRST}
    rec = sim.session.test[0]
    a = compute_kinematics(model, rec, variants=("user_axis",)).motions["user_axis"]["index"]
    b = compute_kinematics(back, rec, variants=("user_axis",)).motions["user_axis"]["index"]
    np.testing.assert_allclose(a.tip, b.tip, atol=1e-9)


def test_ab_adduction_coupled_to_flexion_keeps_the_second_axis() -> None:
    """MP ab/adduction that mostly follows flexion (6.5 +- 2 % of it) plus a slow 0.3 deg
    part out of step with the cycles: the rest test of HEAD 56e9747 rejected the second
    axis on every such subject (MP axis 1.9-5.4 deg off); the held-out choice keeps it
    (seed 5: MP axis 0.19 deg, against 5.68 deg for the hinge; tip 1.15 vs 1.65 mm)."""
    sim = simulate_subject(
        SimConfig(
            abduction_coupling=(-0.065, 0.02), abduction_wander_deg=0.3, abduction_wander_hz=0.08
        ),
        5,
    )
    model = fit_session(sim.session, FitOptions())
    hinge = fit_session(sim.session, FitOptions(method="robust"))
    assert "mp" in model.fingers["index"].second_axes
    assert _mp_axis_error_deg(sim, model) < 1.0
    assert _mp_axis_error_deg(sim, model) < 0.5 * _mp_axis_error_deg(sim, hinge)
    assert tip_error_mm(sim, model, "index") < 0.85 * tip_error_mm(sim, hinge, "index")
