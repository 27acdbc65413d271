"""Saddle-joint (thumb CMC) estimator: known truth, both axis orders, refusals."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.estimate import SaddleFit, fit_saddle
from fingerfit.estimate.saddle import MIN_RANGE_DEG
from fingerfit.kinematics import two_axis_angles
from fingerfit.transforms import angle_between_axes, axis_angle_matrix, unit

from ._saddle_data import SaddleCase, make_case

ORDERS = ("flexion_first", "abduction_first")


@functools.cache
def case(seed: int, order: str, noise: float) -> SaddleCase:
    return make_case(seed, order=order, noise=noise, distortion=noise > 0)


@functools.cache
def fitted(seed: int, order: str, noise: float, guesses: bool = False) -> SaddleFit:
    c = case(seed, order, noise)
    kw = {}
    if guesses:
        # Rough guesses: each true axis turned by 20 deg.
        rng = np.random.default_rng(seed)
        kw = {
            "flexion_guess": _turned(c.flexion_axis, 20.0, rng),
            "abduction_guess": _turned(c.abduction_axis, 20.0, rng),
        }
    return fit_saddle(
        c.rotation, c.translation, c.reference_rotation, order=order, groups=c.groups, **kw
    )


def _turned(axis: np.ndarray, deg: float, rng: np.random.Generator) -> np.ndarray:
    perp = unit(np.cross(axis, rng.normal(size=3)))
    return axis_angle_matrix(perp, np.radians([deg]))[0] @ axis


def _deg(u: np.ndarray, v: np.ndarray) -> float:
    return float(np.degrees(angle_between_axes(u, v)))


def _rms_deg(x: np.ndarray) -> float:
    return float(np.degrees(np.sqrt(np.mean(x * x))))


def _sign(axis: np.ndarray, truth: np.ndarray) -> float:
    return 1.0 if axis @ truth > 0 else -1.0


@pytest.mark.parametrize("order", ORDERS)
def test_exact_data_give_the_true_saddle(order: str) -> None:
    c, f = case(3, order, 0.0), fitted(3, order, 0.0)
    # The synthetic geometry is a thumb CMC: axes 60-80 deg apart, lines 3-8 mm apart.
    assert 55 < _deg(c.flexion_axis, c.abduction_axis) < 85
    assert 3 <= abs(c.offset_mm) <= 8
    assert _deg(f.flexion_axis, c.flexion_axis) < 1e-6
    assert _deg(f.abduction_axis, c.abduction_axis) < 1e-6
    assert f.axis_angle_deg == pytest.approx(_deg(c.flexion_axis, c.abduction_axis), abs=1e-6)
    assert np.linalg.norm(f.flexion_point - c.flexion_point) < 1e-6
    assert np.linalg.norm(f.abduction_point - c.abduction_point) < 1e-6
    sf, sa = _sign(f.flexion_axis, c.flexion_axis), _sign(f.abduction_axis, c.abduction_axis)
    assert f.offset_mm == pytest.approx(sf * sa * c.offset_mm, abs=1e-6)
    assert _rms_deg(f.flexion_angle - sf * c.flexion_angle) < 1e-6
    assert _rms_deg(f.abduction_angle - sa * c.abduction_angle) < 1e-6
    assert f.rms_rotation_deg < 1e-6 and f.rms_position_mm < 1e-6
    assert f.offset_sd_mm < 1e-6 and f.flexion_sd_deg < 1e-6 and f.abduction_sd_deg < 1e-6
    assert f.clusters == 10
    # Thumb-like ranges were recorded and are reported.
    lo, hi = np.degrees(np.percentile(c.flexion_angle, [5, 95]))
    assert f.flexion_range_deg == pytest.approx(hi - lo, abs=1e-6)
    assert f.flexion_range_deg > 40 and f.abduction_range_deg > 30


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("seed", [0, 1])
def test_default_noise_axes_points_and_angles(order: str, seed: int) -> None:
    c, f = case(seed, order, 1.0), fitted(seed, order, 1.0, guesses=True)
    assert _deg(f.flexion_axis, c.flexion_axis) < 1.5
    assert _deg(f.abduction_axis, c.abduction_axis) < 1.5
    # Signed towards the guesses (within 20 deg of the truth): the truth's signs.
    assert f.flexion_axis @ c.flexion_axis > 0 and f.abduction_axis @ c.abduction_axis > 0
    assert abs(f.offset_mm - c.offset_mm) < 0.5
    assert np.linalg.norm(f.flexion_point - c.flexion_point) < 1.5
    assert np.linalg.norm(f.abduction_point - c.abduction_point) < 1.5
    assert _rms_deg(f.flexion_angle - c.flexion_angle) < 0.5
    assert _rms_deg(f.abduction_angle - c.abduction_angle) < 0.5
    # Liberty-like errors leave about a tenth of a degree and a few tenths of a mm.
    assert 0.02 < f.rms_rotation_deg < 0.5 and 0.05 < f.rms_position_mm < 1.0
    assert 0 < f.flexion_sd_deg < 1.0 and 0 < f.abduction_sd_deg < 1.0
    assert 0 < f.offset_sd_mm < 0.5


@pytest.mark.parametrize("order", ORDERS)
def test_angles_are_two_axis_angles_about_the_fitted_axes(order: str) -> None:
    c, f = case(0, order, 1.0), fitted(0, order, 1.0)
    q = c.rotation @ c.reference_rotation.T
    proximal, distal = two_axis_angles(q, f.distal_axis, f.proximal_axis)
    flex, abd = (proximal, distal) if order == "flexion_first" else (distal, proximal)
    np.testing.assert_allclose(f.flexion_angle, flex, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.abduction_angle, abd, rtol=0, atol=1e-12)
    if order == "flexion_first":
        np.testing.assert_array_equal(f.proximal_axis, f.flexion_axis)
    else:
        np.testing.assert_array_equal(f.proximal_axis, f.abduction_axis)


def test_signs_follow_the_guesses_and_the_offset_its_stated_direction() -> None:
    c = case(0, "flexion_first", 0.0)
    args = (c.rotation, c.translation, c.reference_rotation)
    base = fit_saddle(*args, flexion_guess=c.flexion_axis, abduction_guess=c.abduction_axis)
    flip = fit_saddle(*args, flexion_guess=-c.flexion_axis, abduction_guess=c.abduction_axis)
    np.testing.assert_allclose(base.flexion_axis, c.flexion_axis, atol=1e-9)
    np.testing.assert_allclose(flip.flexion_axis, -c.flexion_axis, atol=1e-9)
    np.testing.assert_allclose(flip.flexion_angle, -base.flexion_angle, atol=1e-9)
    np.testing.assert_allclose(flip.abduction_angle, base.abduction_angle, atol=1e-9)
    assert base.offset_mm == pytest.approx(c.offset_mm, abs=1e-6)
    assert flip.offset_mm == pytest.approx(-c.offset_mm, abs=1e-6)
    n = unit(np.cross(base.flexion_axis, base.abduction_axis))
    d = base.abduction_point - base.flexion_point
    assert d @ n == pytest.approx(base.offset_mm, abs=1e-9)
    assert np.linalg.norm(np.cross(d, n)) < 1e-9  # the common perpendicular


def test_the_proximal_axis_comes_from_the_data_and_a_wrong_order_is_refused() -> None:
    c = case(2, "flexion_first", 1.0)
    args = (c.rotation, c.translation, c.reference_rotation)
    # Without guesses the order names the axes: the data's proximal axis is "flexion".
    f = fit_saddle(*args, order="abduction_first")
    assert _deg(f.proximal_axis, c.flexion_axis) < 1.5
    with pytest.raises(
        FingerfitError, match=r"flexion-extension axis the proximal one.*abduction_first"
    ):
        fit_saddle(
            *args,
            order="abduction_first",
            flexion_guess=c.flexion_axis,
            abduction_guess=c.abduction_axis,
        )
    # Not strict: named by the order, the disagreement reported instead.
    g = fit_saddle(
        *args,
        order="abduction_first",
        flexion_guess=c.flexion_axis,
        abduction_guess=c.abduction_axis,
        strict_order=False,
    )
    swapped, named = g.guesses_swapped_deg
    assert swapped < 2.0 and named > 60.0, g.guesses_swapped_deg
    assert _deg(g.proximal_axis, c.flexion_axis) < 1.5
    assert fit_saddle(*args, flexion_guess=c.flexion_axis).guesses_swapped_deg is None


def _one_axis_case(abduction_amplitude_deg: float, seed: int = 1) -> SaddleCase:
    s = np.linspace(0.0, 1.0, 2400)
    flex = 10 + 30 * np.sin(2 * np.pi * 10 * s)  # -20..40 deg
    abd = 5 + abduction_amplitude_deg * np.sin(2 * np.pi * 7.3 * s + 1.0)
    return make_case(seed, flexion_deg=flex, abduction_deg=abd)


@pytest.mark.parametrize("amplitude", [0.0, 1.0, 3.5])
def test_a_motion_that_hardly_turns_the_second_axis_is_refused_naming_it(
    amplitude: float,
) -> None:
    c = _one_axis_case(amplitude)
    args = (c.rotation, c.translation, c.reference_rotation)
    with pytest.raises(FingerfitError) as err:
        fit_saddle(*args, flexion_guess=c.flexion_axis, abduction_guess=c.abduction_axis)
    msg = str(err.value)
    assert msg.startswith("the motion did not excite the ab/adduction axis (")
    assert "circumduction or opposition" in msg and "\n" not in msg
    # Without guesses the data cannot say which axis stayed still: no name, still refused.
    with pytest.raises(FingerfitError, match=r"one axis only|hardly turned"):
        fit_saddle(*args)


def test_enough_ab_adduction_is_fitted() -> None:
    c = _one_axis_case(6.0)  # ab/adduction spans about 12 deg
    f = fit_saddle(c.rotation, c.translation, c.reference_rotation)
    assert f.abduction_range_deg > MIN_RANGE_DEG
    assert _deg(f.flexion_axis, c.flexion_axis) < 1.5
    assert _deg(f.abduction_axis, c.abduction_axis) < 5.0


def test_an_ab_adduction_only_motion_names_the_flexion_axis() -> None:
    s = np.linspace(0.0, 1.0, 2400)
    c = make_case(
        4,
        flexion_deg=5 + 2 * np.sin(2 * np.pi * 7.3 * s),
        abduction_deg=15 + 25 * np.sin(2 * np.pi * 10 * s),
    )
    with pytest.raises(FingerfitError, match=r"^the motion did not excite the flexion-ext"):
        fit_saddle(
            c.rotation,
            c.translation,
            c.reference_rotation,
            flexion_guess=c.flexion_axis,
            abduction_guess=c.abduction_axis,
        )


def test_a_hinge_is_refused_not_fitted() -> None:
    rng = np.random.default_rng(7)
    n = 1200
    axis = unit(rng.normal(size=3))
    centre = rng.normal(0, 30, 3)
    theta = np.radians(60) * np.sin(np.linspace(0, 20 * np.pi, n))
    q = axis_angle_matrix(axis, theta)
    r_ref = axis_angle_matrix(unit(rng.normal(size=3)), np.array([0.7]))[0]
    t_ref = rng.normal(0, 30, 3)
    rot = q @ r_ref
    trans = np.einsum("nij,j->ni", q, t_ref - centre) + centre
    with pytest.raises(FingerfitError, match=r"one axis only \(the rotations spread 0\.0 deg"):
        fit_saddle(rot, trans, r_ref)


def test_bad_inputs_are_one_line_errors() -> None:
    c = case(0, "flexion_first", 0.0)
    args = (c.rotation, c.translation, c.reference_rotation)
    with pytest.raises(FingerfitError, match="order"):
        fit_saddle(*args, order="sideways")  # type: ignore[arg-type]
    bad = c.translation.copy()
    bad[5, 1] = np.nan
    with pytest.raises(FingerfitError, match="field 'translation': contains NaN"):
        fit_saddle(c.rotation, bad, c.reference_rotation)
    with pytest.raises(FingerfitError, match="field 'weights'"):
        fit_saddle(*args, weights=np.zeros(c.rotation.shape[0]))
    with pytest.raises(FingerfitError, match="field 'rotation': 10 frames"):
        fit_saddle(c.rotation[:10], c.translation[:10], c.reference_rotation)


def test_zero_weight_frames_do_not_count_and_one_cluster_gives_no_sd() -> None:
    c = case(5, "flexion_first", 0.0)
    rot, trans = c.rotation.copy(), c.translation.copy()
    bad = slice(300, 500)
    rot[bad] = axis_angle_matrix(unit(np.ones(3)), np.full(200, 0.5)) @ rot[bad]
    trans[bad] += 20.0
    w = np.ones(rot.shape[0])
    w[bad] = 0.0
    f = fit_saddle(rot, trans, c.reference_rotation, weights=w, groups=np.zeros(w.size))
    assert _deg(f.flexion_axis, c.flexion_axis) < 1e-6
    assert _deg(f.abduction_axis, c.abduction_axis) < 1e-6
    assert abs(abs(f.offset_mm) - abs(c.offset_mm)) < 1e-6
    assert f.clusters == 0 and np.isnan(f.offset_sd_mm) and np.isnan(f.flexion_sd_deg)
