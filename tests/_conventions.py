"""Pose series as a file written in another quaternion convention would read
(``tests/test_plausibility.py`` and ``bench/plausibility_conventions.py``)."""

from __future__ import annotations

import numpy as np

from fingerfit.session import PoseSeries
from fingerfit.transforms import matrix_from_quat_wxyz, quat_wxyz_from_matrix

#: The conventions :func:`as_written` knows.
KINDS = ("conjugated", "xyzw")


def as_written(series: PoseSeries, kind: str) -> PoseSeries:
    """The series as read from a file written in another quaternion convention.

    Parameters
    ----------
    series : PoseSeries
        Poses as they are.
    kind : {"conjugated", "xyzw"}
        The file's quaternions conjugated, or in ``x, y, z, w`` order, and read as
        ``w, x, y, z``.

    Returns
    -------
    PoseSeries
        Same positions; the rotations as misread.
    """
    q = quat_wxyz_from_matrix(series.rotation)
    if kind == "conjugated":
        q = q * np.array([1.0, -1, -1, -1])
    elif kind == "xyzw":
        q = q[:, [1, 2, 3, 0]]
    return PoseSeries(series.position, matrix_from_quat_wxyz(q))
