"""The rest ab/adduction test (a two-axis diagnostic: ab/adduction varying independently of
flexion between cycles). The hinge/two-axis choice itself: ``tests/test_model_choice.py``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fingerfit.estimate.twoaxis import REST_SPREAD_CONFIDENCE, rest_abduction_test

CYCLES, PER_CYCLE = 10, 150


def _cycles(rest_sd_deg: float, noise_deg: float, seed: int = 0):
    """Grasp-like flexion (rad) and ab/adduction coupled to it, plus a rest value per cycle."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 1.0, PER_CYCLE)
    theta = np.tile(np.radians(60.0) * np.sin(np.pi * u) ** 2, CYCLES)
    groups = np.repeat(np.arange(CYCLES), PER_CYCLE)
    rest = np.radians(rest_sd_deg) * rng.normal(size=CYCLES)
    beta = -0.07 * theta + rest[groups] + np.radians(noise_deg) * rng.normal(size=theta.size)
    return beta, theta, groups, rest


def test_rest_spread_and_its_lower_bound_are_the_chi_square_ones() -> None:
    beta, theta, groups, rest = _cycles(0.5, 0.0)
    t = rest_abduction_test(beta, theta, groups, np.radians(0.1))
    # Noise-free lines: each cycle's intercept is exactly its rest value.
    assert t.cycles == CYCLES
    assert t.spread_deg == pytest.approx(np.degrees(np.std(rest, ddof=1)), rel=1e-9)
    factor = np.sqrt((CYCLES - 1) / chi2.ppf(REST_SPREAD_CONFIDENCE, CYCLES - 1))
    assert t.low_deg == pytest.approx(t.spread_deg * factor, rel=1e-12)
    assert t.passed


def test_ab_adduction_that_only_follows_flexion_is_no_second_axis() -> None:
    # Coupled ab/adduction (or soft-tissue artefact) alike in every cycle: rest spread is
    # only the noise's, far below the per-frame misfit.
    beta, theta, groups, _ = _cycles(0.0, 0.2)
    t = rest_abduction_test(beta, theta, groups, np.radians(0.2))
    assert t.spread_deg < 0.05
    assert not t.passed
    # The same with a rest value wandering by 0.5 deg SD between cycles passes.
    beta, theta, groups, _ = _cycles(0.5, 0.2)
    assert rest_abduction_test(beta, theta, groups, np.radians(0.2)).passed


def test_fewer_than_two_usable_cycles_fail() -> None:
    beta, theta, groups, _ = _cycles(0.5, 0.0)
    one = groups == 0
    t = rest_abduction_test(beta[one], theta[one], groups[one], 1e-3)
    assert t.cycles == 1 and not t.passed and np.isnan(t.low_deg)
    # A cycle without flexion has no intercept: it is left out.
    flat = np.where(groups == 1, 0.0, theta)
    assert rest_abduction_test(beta, flat, groups, 1e-3).cycles == CYCLES - 1
