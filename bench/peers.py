"""Adapters that run peer implementations on fingerfit's joint data (benchmark only).

Each adapter takes the same movement frames the fingerfit estimators use (the
grasp-cycle movement periods of one joint, parent and child sensor poses in
tracker coordinates) and returns the peer's axis and/or centre in the parent
sensor frame. The peers are imported from their installed packages; nothing of
theirs is copied.
"""

from __future__ import annotations

import logging

import numpy as np

from fingerfit.session import Recording
from fingerfit.transforms import FloatArray, transform_from_pr

try:  # biobuddy is an optional peer (extra "peers")
    from biobuddy.model_modifiers.joint_center_tool import Sara, Score
    from biobuddy.utils.linear_algebra import RotoTransMatrixTimeSeries

    logging.getLogger("biobuddy").setLevel(logging.WARNING)
    HAVE_BIOBUDDY = True
except ImportError:  # pragma: no cover - depends on the environment
    HAVE_BIOBUDDY = False


def _series(position: FloatArray, rotation: FloatArray) -> RotoTransMatrixTimeSeries:
    """biobuddy time series from poses ``(n, 3)`` mm and ``(n, 3, 3)``: 4 x 4 x n."""
    rt = np.moveaxis(transform_from_pr(position, rotation), 0, -1)
    return RotoTransMatrixTimeSeries.from_rt_matrix(np.ascontiguousarray(rt))


def joint_frames(
    recordings: list[Recording], parent: str, child: str, frames: np.ndarray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Parent and child poses (tracker frame) of the selected frames of concatenated recordings."""
    pp = np.concatenate([r.pose(parent).position for r in recordings])[frames]
    pr = np.concatenate([r.pose(parent).rotation for r in recordings])[frames]
    cp = np.concatenate([r.pose(child).position for r in recordings])[frames]
    cr = np.concatenate([r.pose(child).rotation for r in recordings])[frames]
    return pp, pr, cp, cr


def biobuddy_sara(
    parent_position: FloatArray,
    parent_rotation: FloatArray,
    child_position: FloatArray,
    child_rotation: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """biobuddy ``Sara.perform_algorithm`` (with its outlier removal).

    Returns
    -------
    axis, point : ndarray, shape (3,)
        Unit axis and its centre of rotation (the peer's pseudo-inverse point),
        both in the parent sensor frame (mm).
    """
    out = Sara.perform_algorithm(
        _series(parent_position, parent_rotation),
        _series(child_position, child_rotation),
        None,
        recursive_outlier_removal=True,
    )
    axis, point = np.asarray(out[1], float)[:3], np.asarray(out[4], float)[:3]
    return axis / np.linalg.norm(axis), point


def biobuddy_score(
    parent_position: FloatArray,
    parent_rotation: FloatArray,
    child_position: FloatArray,
    child_rotation: FloatArray,
) -> FloatArray:
    """biobuddy ``Score.perform_algorithm`` (with its outlier removal): centre ``(3,)`` mm,
    parent sensor frame."""
    out = Score.perform_algorithm(
        _series(parent_position, parent_rotation),
        _series(child_position, child_rotation),
        recursive_outlier_removal=True,
    )
    return np.asarray(out[1], float)[:3]
