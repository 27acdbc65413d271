"""The finger's sagittal plane from stylus landmarks, and joint centres on it.

Construction (documented in ``docs/methods.md``): the dorsal landmarks
``mp``, ``pip``, ``dip`` and ``tip`` of the stretched finger lie on a line in
the sagittal plane; the line through them (least squares) fixes the plane up to
a rotation about that line, which is fixed by making the plane normal the
mean fitted flexion axis made perpendicular to the line. Each joint centre is
where its fitted axis meets this plane (paper section 3; Tang et al. 2018 [13]).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray, unit


@dataclass(frozen=True)
class Plane:
    """A plane through ``point (3,)`` with unit ``normal (3,)`` (tracker, mm);
    ``direction (3,)`` is the in-plane finger direction (proximal -> distal)."""

    point: FloatArray
    normal: FloatArray
    direction: FloatArray


def sagittal_plane(landmarks: FloatArray, axes: FloatArray, finger: str = "") -> Plane:
    """Sagittal plane of a finger.

    Parameters
    ----------
    landmarks : ndarray, shape (m, 3)
        Dorsal landmarks from proximal to distal (MP, PIP, DIP, tip), mm.
    axes : ndarray, shape (k, 3)
        Fitted flexion axes, all oriented the same way (unit).

    Returns
    -------
    Plane
    """
    centroid = landmarks.mean(axis=0)
    _, _, vt = np.linalg.svd(landmarks - centroid)
    d = vt[0] if vt[0] @ (landmarks[-1] - landmarks[0]) > 0 else -vt[0]
    m = unit(axes.mean(axis=0))
    n = m - (m @ d) * d
    if np.linalg.norm(n) < 0.1:
        raise FingerfitError(
            f"{finger}: the fitted flexion axes run along the finger; no sagittal plane"
        )
    return Plane(centroid, unit(n), d)


def intersect(
    plane: Plane, point: FloatArray, direction: FloatArray, joint: str = ""
) -> FloatArray:
    """Where the line ``point + s * direction`` meets ``plane`` (mm); ``joint`` names it in errors."""
    den = plane.normal @ direction
    if abs(den) < 0.2:
        raise FingerfitError(
            f"{joint}: the fitted axis is within {np.degrees(np.arcsin(0.2)):.0f} deg of the sagittal plane; "
            "no reliable joint centre"
        )
    return point + (plane.normal @ (plane.point - point)) / den * direction
