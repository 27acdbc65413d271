"""The analytic Jacobians of the two-axis residual against central finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.estimate.twoaxis import _free_axes, _perpendicular_axes
from fingerfit.estimate.twoaxis_residual import (
    _skew_residual,
    direction_jacobian,
    skew_residual_jacobian,
)
from fingerfit.transforms import axis_angle_matrix, orthonormal_basis, unit


def _motion(seed: int, tilt: float, off_sd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations ``(300, 3, 3)`` of a two-axis joint with a rotation off the model, and its
    axes ``a``, ``b`` (``b`` tilted ``tilt`` rad towards ``a``)."""
    rng = np.random.default_rng(seed)
    a = unit(rng.normal(size=3))
    e = orthonormal_basis(a)
    b = unit(np.cos(tilt) * e[0] + np.sin(tilt) * a)
    beta, theta = rng.uniform(-0.5, 0.5, 300), rng.uniform(-1.6, 0.4, 300)
    off = Rotation.from_rotvec(rng.normal(0.0, off_sd, (300, 3))).as_matrix()
    return axis_angle_matrix(b, beta) @ axis_angle_matrix(a, theta) @ off, a, b


def _central(f, p: int, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``f(x) (m,)`` at ``x = 0`` over ``p`` parameters: ``(m, p)``."""
    return np.stack([(f(h * e) - f(-h * e)) / (2 * h) for e in np.eye(p)], axis=1)


@pytest.mark.parametrize(
    ("seed", "tilt", "off_sd"), [(1, 0.0, 0.05), (2, 0.3, 0.02), (3, -0.6, 0.2)]
)
def test_skew_residual_jacobian_matches_finite_differences(
    seed: int, tilt: float, off_sd: float
) -> None:
    q, a, b = _motion(seed, tilt, off_sd)
    # Off the true axes, so that every derivative is at work.
    a, b = unit(a + np.array([0.03, -0.02, 0.01])), unit(b + np.array([-0.02, 0.04, 0.02]))
    rng = np.random.default_rng(seed + 10)
    # Any tangent moves of the two axes, five parameters mixing both.
    ta, tb = orthonormal_basis(a)[:2], orthonormal_basis(b)[:2]
    ca, cb = rng.normal(size=(5, 2)), rng.normal(size=(5, 2))
    da, db = ca @ ta, cb @ tb

    def res(x: np.ndarray) -> np.ndarray:
        return _skew_residual(q, unit(a + x @ da), unit(b + x @ db)).ravel()

    want = _central(res, 5)
    r, got = skew_residual_jacobian(q, a, b, da, db)
    np.testing.assert_allclose(r, _skew_residual(q, a, b), rtol=0, atol=1e-14)
    assert got.shape == (300, 3, 5)
    scale = np.abs(want).max()
    assert scale > 0.1
    np.testing.assert_allclose(got.reshape(-1, 5), want, rtol=0, atol=1e-6 * scale)


def test_direction_jacobian_matches_finite_differences() -> None:
    q, a, b = _motion(4, 0.2, 0.05)
    sw = np.random.default_rng(5).uniform(0.5, 1.5, q.shape[0])
    r, jac, basis = direction_jacobian(q, a, b, sw)
    ta, tb = basis[:2], basis[2:]

    def res(z: np.ndarray) -> np.ndarray:
        aa, bb = unit(a + z[:2] @ ta), unit(b + z[2:] @ tb)
        return (_skew_residual(q, aa, bb) * sw[:, None]).ravel()

    np.testing.assert_allclose(r, res(np.zeros(4)), rtol=0, atol=1e-14)
    want = _central(res, 4)
    np.testing.assert_allclose(jac, want, rtol=0, atol=1e-6 * np.abs(want).max())


@pytest.mark.parametrize("stage", ["perpendicular", "free"])
def test_search_parametrisations_differentiate_right(stage: str) -> None:
    # The direction search's axes as functions of its parameters, and their derivatives,
    # carried into the residual's: the Jacobians least_squares is given.
    q, a, b = _motion(6, 0.1, 0.05)
    a0, b0 = unit(a + np.array([0.05, 0.02, -0.03])), unit(b + np.array([0.02, -0.05, 0.04]))
    ea, eb = orthonormal_basis(a0), orthonormal_basis(b0)
    x0 = np.array([0.04, -0.03, 0.2, -0.1])
    if stage == "perpendicular":
        x0 = x0[:3]

        def axes(x: np.ndarray) -> tuple:
            return _perpendicular_axes(x, a0, ea, b0)
    else:

        def axes(x: np.ndarray) -> tuple:
            return _free_axes(x, a0, ea, b0, eb)

    p = x0.size
    av, bv, da, db = axes(x0)
    assert da.shape == db.shape == (p, 3)
    np.testing.assert_allclose(da @ av, 0.0, atol=1e-15)  # moves keep them unit
    np.testing.assert_allclose(db @ bv, 0.0, atol=1e-15)
    if stage == "perpendicular":
        assert abs(av @ bv) < 1e-15
    want_dirs = _central(lambda d: np.concatenate(axes(x0 + d)[:2]), p)
    np.testing.assert_allclose(np.vstack([da.T, db.T]), want_dirs, rtol=0, atol=1e-8)
    want = _central(lambda d: _skew_residual(q, *axes(x0 + d)[:2]).ravel(), p)
    got = skew_residual_jacobian(q, av, bv, da, db)[1].reshape(-1, p)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
