"""Rotation conversions against scipy's ``Rotation``: quaternions from matrices, rotation
angles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit import transforms
from fingerfit.transforms import (
    matrix_from_quat_wxyz,
    quat_wxyz_columns,
    quat_wxyz_from_matrix,
    rotation_angle,
    rotation_vector,
)


def _scipy_wxyz(matrix: np.ndarray) -> np.ndarray:
    xyzw = Rotation.from_matrix(matrix).as_quat()  # scipy: scalar last
    wxyz = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    return wxyz * np.where(wxyz[:, :1] < 0, -1.0, 1.0)


def test_quat_from_matrix_is_scipys_to_rounding_on_every_branch():
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(400, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        [
            rng.uniform(0, np.pi, 100),  # any
            rng.uniform(0, 1e-9, 100),  # near identity: w largest
            np.pi - rng.uniform(0, 1e-9, 100),  # near 180 degrees: x, y or z largest
            np.full(100, np.pi),  # w = 0 exactly
        ]
    )
    m = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    m = np.concatenate([m, Rotation.random(5000, random_state=8).as_matrix()])
    got = quat_wxyz_from_matrix(m)
    assert np.abs(got - _scipy_wxyz(m)).max() <= 4.5e-16
    assert (got[:, 0] >= 0).all()
    assert np.abs(np.linalg.norm(got, axis=1) - 1).max() <= 4.5e-16
    assert np.abs(matrix_from_quat_wxyz(got) - m).max() <= 2e-15
    # every branch of the method was taken
    d = np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], np.trace(m, axis1=1, axis2=2)])
    assert set(np.argmax(d, axis=0).tolist()) == {0, 1, 2, 3}


def test_quat_from_matrix_nan_rows_single_and_reflections():
    m = Rotation.random(4, random_state=2).as_matrix()
    m[1, 0, 2] = np.nan
    m[2, 1, 1] = np.inf
    got = quat_wxyz_from_matrix(m)
    assert np.isnan(got[[1, 2]]).all() and np.isfinite(got[[0, 3]]).all()
    assert np.array_equal(quat_wxyz_from_matrix(m[3]), got[3])
    assert np.array_equal(quat_wxyz_from_matrix(np.eye(3)), [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"non-positive determinant .* rotation matrix 1"):
        quat_wxyz_from_matrix(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])]))


def _markley_plain(m: np.ndarray) -> np.ndarray:
    """Markley's method written plainly on ``(n, 3, 3)`` (np.argmax, np.choose,
    np.linalg.norm): the numbers :func:`quat_wxyz_from_matrix` must give bit for bit."""
    r = [[m[:, a, b] for b in range(3)] for a in range(3)]
    trace = r[0][0] + r[1][1] + r[2][2]
    choice = np.argmax(np.stack([r[0][0], r[1][1], r[2][2], trace]), axis=0)
    big = [1 - trace + 2 * r[k][k] for k in range(3)]
    wx, wy, wz = r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]
    xy, xz, yz = r[1][0] + r[0][1], r[2][0] + r[0][2], r[2][1] + r[1][2]
    out = np.stack(
        [
            np.choose(choice, [wx, wy, wz, 1 + trace]),
            np.choose(choice, [big[0], xy, xz, wx]),
            np.choose(choice, [xy, big[1], yz, wy]),
            np.choose(choice, [xz, yz, big[2], wz]),
        ],
        axis=1,
    )
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    out *= np.where(out[:, :1] < 0, -1.0, 1.0)
    out[~np.isfinite(m).all(axis=(1, 2))] = np.nan
    return out


def test_quat_from_matrix_is_the_plain_method_bit_for_bit(monkeypatch) -> None:
    """The blocked, gathered conversion gives the plain formula's bits on every branch,
    ties (the first largest diagonal entry wins, as np.argmax), signed zeros, NaN rows and
    matrices only near a rotation; :func:`quat_wxyz_columns` is its transpose, and an
    error names the matrix by its index in the whole array across blocks."""
    monkeypatch.setattr(transforms, "_QUAT_BLOCK", 37)
    rng = np.random.default_rng(3)
    m = Rotation.random(1000, random_state=4).as_matrix()
    m[::3] += rng.normal(0, 1e-7, m[::3].shape)  # not quite orthonormal
    m[::5] *= rng.uniform(0.5, 2.0, (m[::5].shape[0], 1, 1))
    m[1] = np.eye(3)
    m[2] = np.diag([1.0, -1.0, -1.0])
    m[3] = np.diag([-1.0, 1.0, -1.0])
    m[4] = np.diag([-1.0, -1.0, 1.0])
    m[5] = np.diag([0.5, 0.5, 0.5])  # ties between the diagonal entries
    m[6] = np.diag([0.2, 0.7, 0.7])
    m[7] = np.where(np.eye(3) > 0, 1.0, -0.0)  # signed zeros
    m[8, 1, 2] = np.nan
    m[9, 0, 0] = -np.inf
    m[10] = np.nan
    with np.errstate(invalid="ignore"):
        want = _markley_plain(m)
    got = quat_wxyz_from_matrix(m)
    assert got.flags.c_contiguous
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    assert np.array_equal(quat_wxyz_columns(m).view(np.int64), want.T.view(np.int64))
    assert np.array_equal(quat_wxyz_from_matrix(m[6]).view(np.int64), want[6].view(np.int64))
    assert quat_wxyz_from_matrix(m[:0]).shape == (0, 4)
    m[200] = np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match=r"rotation matrix 200$"):
        quat_wxyz_from_matrix(m)


def test_rotation_angle_is_the_rotation_vectors_norm_from_0_to_pi_and_nan_safe():
    rng = np.random.default_rng(11)
    axes = rng.normal(size=(300, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        [
            rng.uniform(0, np.pi, 100),
            rng.uniform(0, 1e-8, 100),  # near identity
            np.pi - rng.uniform(0, 1e-8, 100),  # near a half turn: the trace alone loses it
        ]
    )
    m = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    got = rotation_angle(m)
    assert np.abs(got - angles).max() <= 2e-15
    rv = np.linalg.norm(rotation_vector(m[:100]), axis=1)
    assert np.abs(got[:100] - rv).max() <= 2e-15
    m[[3, 150], [1, 2], [2, 0]] = np.nan  # one NaN element in two matrices
    got = rotation_angle(m)
    assert np.isnan(got[[3, 150]]).all()
    assert np.isfinite(np.delete(got, [3, 150])).all()


def test_cross3_and_stacked_orthonormal_bases_give_numpys_bits():
    from fingerfit.transforms import cross3, orthonormal_basis

    rng = np.random.default_rng(12)
    u, v = rng.normal(size=(2, 200, 3)) * rng.uniform(1e-3, 1e3, (2, 200, 1))
    for x, y in zip(u, v, strict=True):
        np.testing.assert_array_equal(cross3(x, y), np.cross(x, y))
    stacked = orthonormal_basis(u)
    assert stacked.shape == (200, 3, 3)
    np.testing.assert_array_equal(stacked, np.stack([orthonormal_basis(x) for x in u]))
    # Right-handed and orthonormal, the last row the unit axis.
    np.testing.assert_allclose(
        stacked @ np.swapaxes(stacked, 1, 2), np.broadcast_to(np.eye(3), (200, 3, 3)), atol=1e-15
    )
    np.testing.assert_allclose(np.linalg.det(stacked), 1.0, atol=1e-14)
    np.testing.assert_allclose(
        stacked[:, 2], u / np.linalg.norm(u, axis=1, keepdims=True), atol=1e-16
    )


def test_stacked_axis_angle_matrices_and_skews_give_one_at_a_times_bits():
    from fingerfit.transforms import axis_angle_matrix, skew, unit

    rng = np.random.default_rng(13)
    axes = unit(rng.normal(size=(7, 3)))
    angles = rng.uniform(-3.0, 3.0, (7, 50))
    stacked = axis_angle_matrix(axes, angles)
    assert stacked.shape == (7, 50, 3, 3)
    want = np.stack([axis_angle_matrix(a, t) for a, t in zip(axes, angles, strict=True)])
    np.testing.assert_array_equal(stacked, want)
    np.testing.assert_array_equal(skew(axes), np.stack([skew(a) for a in axes]))
    v = rng.normal(size=3)
    np.testing.assert_allclose(skew(axes) @ v, np.cross(axes, v), atol=1e-15)
