"""Numerical stability of the fit: device precision must not move the model.

Each supported device stores poses with a finite precision: Liberty ASCII prints
positions with 3 decimals in its units (inches by default) and quaternions with 4
decimals (about 0.01 deg); Liberty binary and C3D store float32. Rounding a session to
that precision must move no joint axis by more than 0.2 deg and no centre by more than
0.2 mm -- or the fit must say, in the joint's quality notes, that the quantity is that
uncertain (``docs/methods.md``, "Numerical stability").

The subjects are the worst cases of the scan over ``SimConfig()`` seeds 0-20 and the
demo cohort (``simulate_cohort(SimConfig(), 5, 2018)``): seed 16 (before the fix the
ab/adduction axis turned by 61 deg and the MP centre moved by 0.61 mm under Liberty
ASCII rounding) and demo subjects 3 and 4 (the largest MP flexion-axis and
ab/adduction-axis movements after it).
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.shrink import MIN_DATA_SHARE, data_share
from fingerfit.model import HandModel
from fingerfit.session import Session
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.precision import DEVICES, device_rounded, round_rotations
from fingerfit.transforms import angle_between_axes, axis_angle_matrix, unit

MAX_AXIS_DEG = 0.2
MAX_CENTRE_MM = 0.2
# SimConfig() seed 16, and subjects 3 and 4 (S03, S04) of simulate_cohort(SimConfig(), 5, 2018).
SEEDS = {
    "seed 16": 16,
    "demo S03": int(np.random.SeedSequence(2018).spawn(5)[2].generate_state(1)[0]),
    "demo S04": int(np.random.SeedSequence(2018).spawn(5)[3].generate_state(1)[0]),
}


def _in_hand(model: HandModel, joint) -> tuple[np.ndarray, np.ndarray]:
    p, r = model.reference_poses[joint.parent]
    return r.T @ (joint.center - p), r.T @ joint.axis


def _fit(session: Session) -> HandModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_session(session, FitOptions())


@pytest.fixture(scope="module", params=list(SEEDS))
def subject_fit(request):
    sim = simulate_subject(SimConfig(targets=False, test=False), SEEDS[request.param])
    return request.param, sim.session, _fit(sim.session)


def _abduction_sd95(model: HandModel) -> float:
    """The 95 % half-width of the ab/adduction axis direction the MP quality notes state."""
    notes = " ".join(model.fingers["index"].joints["mp"].quality.notes)
    m = re.search(r"ab/adduction axis \+/-([0-9.]+) deg about it", notes)
    assert m, notes
    return float(m.group(1))


@pytest.mark.parametrize("device", DEVICES)
def test_device_precision_does_not_move_the_model(subject_fit, device) -> None:
    name, session, m0 = subject_fit
    m1 = _fit(device_rounded(session, device))
    f0, f1 = m0.fingers["index"], m1.fingers["index"]
    for j in ("mp", "pip", "dip"):
        c0, a0 = m0.in_parent("index", j)
        c1, a1 = m1.in_parent("index", j)
        deg = float(np.degrees(angle_between_axes(a0, a1)))
        mm = float(np.linalg.norm(c1 - c0))
        assert deg <= MAX_AXIS_DEG, (name, device, j, deg)
        assert mm <= MAX_CENTRE_MM, (name, device, j, mm)
    # The two-axis/one-axis choice does not flip.
    assert (f0.second_axes.get("mp") is None) == (f1.second_axes.get("mp") is None), (name, device)
    if f0.second_axes.get("mp") is None:
        return
    (p0, b0), (p1, b1) = (
        _in_hand(m0, f0.second_axes.get("mp")),
        _in_hand(m1, f1.second_axes.get("mp")),
    )
    mm = float(np.linalg.norm(p1 - p0))
    assert mm <= MAX_CENTRE_MM, (name, device, "ab/adduction point", mm)
    # The ab/adduction axis direction is seen through a few degrees of ab/adduction only:
    # it may move more than 0.2 deg only within the uncertainty the quality notes state.
    deg = float(np.degrees(angle_between_axes(b0, b1)))
    stated = min(_abduction_sd95(m0), _abduction_sd95(m1))
    assert deg <= max(MAX_AXIS_DEG, stated), (name, device, "ab/adduction axis", deg, stated)


def test_weakly_determined_parameters_are_held_and_reported(subject_fit) -> None:
    name, _, model = subject_fit
    fm = model.fingers["index"]
    assert fm.second_axes.get("mp") is not None, name
    notes = " ".join(fm.joints["mp"].quality.notes)
    # Realistic data do not determine the tilt of the ab/adduction axis towards the
    # flexion axis, nor the distance between the axes: held, and said so.
    assert "held perpendicular to the flexion axis (data weight 0 %)" in notes, notes
    assert "MP axes held intersecting (data weight 0 %)" in notes, notes
    c, a = model.in_parent("index", "mp")
    pb, b = _in_hand(model, fm.second_axes.get("mp"))
    assert abs(float(a @ b)) < 1e-9
    assert float(np.linalg.norm(np.cross(pb - c, a))) < 1e-4  # b's point lies on the MP axis
    assert "condition number" in notes


def test_data_share_is_smooth_and_monotone() -> None:
    sd = np.linspace(0.0, 10.0, 2001)
    w = np.array([data_share(s, 1.5) for s in sd])
    assert w[0] == 1.0 and data_share(1.5, 1.5) == pytest.approx(0.5)
    assert np.all(np.diff(w) <= 0.0)
    assert np.max(np.abs(np.diff(w))) < 0.01  # no step a small change could cross
    assert data_share(float("inf"), 1.5) == 0.0
    assert data_share(1.5 * (1 / MIN_DATA_SHARE) ** (1 / 6) * 1.01, 1.5) < MIN_DATA_SHARE


def test_liberty_ascii_rounding_is_the_printed_precision() -> None:
    rng = np.random.default_rng(0)
    r = axis_angle_matrix(unit(rng.normal(size=3)), rng.uniform(-3, 3, 200))
    for device, lo, hi in (("liberty-ascii", 1e-3, 0.02), ("liberty-binary", 0, 1e-4)):
        d = round_rotations(r, device)
        cos = (np.trace(d.transpose(0, 2, 1) @ r, axis1=1, axis2=2) - 1) / 2
        ang = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        # 4 decimals of a unit quaternion: about 0.01 deg; float32: far below.
        assert lo < ang.mean() < hi, (device, ang.mean())
