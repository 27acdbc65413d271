"""Rigid fits of marker clusters never fail on garbled coordinates: those frames are NaN.

Found by ``tests/bad_inputs/test_fuzz_readers.py::test_fuzz_real_c3d`` (a C3D point value
overwritten with 1e30 made the SVD of the cross-covariance fail with a LinAlgError).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from fingerfit.io.rigid import fit_cluster


def test_overflowing_frame_is_not_fitted_and_the_others_are() -> None:
    shape = np.array([[0.0, 0, 0], [40, 0, 0], [0, 30, 0], [10, 10, 20]])
    rot = Rotation.random(5, random_state=1).as_matrix()
    markers = np.einsum("nij,mj->nmi", rot, shape) + np.arange(15.0).reshape(5, 1, 3)
    markers[2, 1, 0] = 1e300  # products overflow to inf
    markers[3, 0, 2] = -1e300
    fit = fit_cluster(markers, shape)
    assert np.isnan(fit.rotation[[2, 3]]).all() and np.isnan(fit.residual[[2, 3]]).all()
    ok = [0, 1, 4]
    np.testing.assert_allclose(fit.rotation[ok], rot[ok], atol=1e-12)
    assert np.all(fit.residual[ok] < 1e-9)
    # A shape that is not finite fits nothing, without an error.
    bad = shape.copy()
    bad[1, 0] = np.nan
    assert np.isnan(fit_cluster(markers, bad).rotation).all()
