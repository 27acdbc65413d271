"""Axis of rotation from the per-cycle centres (Tang et al. 2018, eq. 1).

``J(a) = sum_i |a x (c_i - e)|^2`` with ``e = mean(c_i)`` is minimised by the
principal eigenvector of the scatter matrix ``sum_i (c_i - e)(c_i - e)^T``:
a straight-line fit through the centres. It only works because the
untruncated centres spread along the axis (``docs/methods.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray, angle_between_axes, distance_point_to_line, unit
from .centre import CentreFit

# Below this spread (mm) the centres coincide: exact hinge data.
DEGENERATE_SPREAD_MM = 1e-6


@dataclass(frozen=True)
class AxisFit:
    """A fitted joint axis in the parent sensor frame.

    Attributes
    ----------
    point : ndarray, shape (3,)
        ``e``: a point on the axis (mm, parent sensor frame).
    direction : ndarray, shape (3,)
        Unit axis direction (parent sensor frame); sign not yet oriented.
    distances : ndarray, shape (n_cycles,)
        Distance of each cycle's centre to the axis (mm; paper Fig. 8).
    spread_mm : float
        RMS spread of the centres along the axis (mm).
    degenerate : bool
        True when the centres coincide (exact data): the direction then comes from
        the cycles' null vectors, which for an exact hinge are the axis itself.
    null_agreement_deg : float
        Angle between ``direction`` and the mean of the cycles' own null vectors
        (the rotation axis each cycle's motion shows). Large values mean the
        centres did not spread along the axis and the line fit is unreliable.
    """

    point: FloatArray
    direction: FloatArray
    distances: FloatArray
    spread_mm: float
    degenerate: bool
    null_agreement_deg: float


def line_through_centres(centres: list[CentreFit]) -> AxisFit:
    """The paper's axis: the least-squares line through the per-cycle centres.

    Parameters
    ----------
    centres : list of CentreFit
        One per grasp cycle (at least 2).

    Returns
    -------
    AxisFit
    """
    c = np.array([f.parent_point for f in centres])
    e = c.mean(axis=0)
    d = c - e
    w, v = np.linalg.eigh(d.T @ d)
    a = v[:, -1]
    spread = float(np.sqrt(w[-1] / len(centres)))
    degenerate = spread < DEGENERATE_SPREAD_MM
    null_axis = mean_null_axis(centres)
    if degenerate:
        a = null_axis
    agreement = float(np.degrees(angle_between_axes(a, null_axis)))
    return AxisFit(e, a, distance_point_to_line(c, e, a), spread, degenerate, agreement)


def mean_null_axis(centres: list[CentreFit]) -> FloatArray:
    """Mean of the cycles' null vectors (parent-frame part), sign-aligned, unit ``(3,)``."""
    nulls = np.array([unit(f.null_vector[:3]) for f in centres])
    nulls *= np.where(nulls @ nulls[0] < 0, -1.0, 1.0)[:, None]
    return unit(nulls.mean(axis=0))


def orient_flexion(direction: FloatArray, rotation_vectors: FloatArray) -> FloatArray:
    """Flip ``direction (3,)`` so flexion (motion away from the reference posture) is positive.

    Parameters
    ----------
    direction : ndarray, shape (3,)
        Axis in the parent sensor frame.
    rotation_vectors : ndarray, shape (n, 3)
        Rotation vectors of ``R(k) R_ref^T`` over movement frames (parent frame, rad).
    """
    s = np.nansum(rotation_vectors @ direction)
    return direction if s >= 0 else -direction
