"""How closely a robot digit copies the person's, up to scale and offset.

The person's and the robot's hands differ in size and in where their digits sit, so a
robot fingertip trajectory is compared with the person's after the best scale and
offset (least squares, no rotation): whatever remains is the shape of the motion the
robot could not copy, including a palm frame turned against the hand's anatomy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray


@dataclass(frozen=True)
class ScaleOffset:
    """``robot ≈ scale * person + offset``.

    Attributes
    ----------
    scale : float
        Robot length per person's length (mm/mm).
    offset : ndarray, shape (3,)
        mm, the robot's frame.
    rms_mm : float
        RMS distance (mm) of the robot's points from the scaled and offset person's.
    frames : int
        Frames with both points present (the others are left out).
    """

    scale: float
    offset: FloatArray
    rms_mm: float
    frames: int


def scale_offset_fit(person: FloatArray, robot: FloatArray) -> ScaleOffset:
    """Least-squares scale and offset taking the person's points onto the robot's.

    Parameters
    ----------
    person : ndarray, shape (n, 3)
        The person's point per frame (mm), in a frame whose axes correspond to the
        robot's (mirror it first when the hands differ).
    robot : ndarray, shape (n, 3)
        The robot's point per frame (mm).

    Returns
    -------
    ScaleOffset

    Raises
    ------
    FingerfitError
        Fewer than two frames with both points, or the person's point never moves.
    """
    person, robot = np.asarray(person, float), np.asarray(robot, float)
    ok = np.isfinite(person).all(axis=1) & np.isfinite(robot).all(axis=1)
    if ok.sum() < 2:
        raise FingerfitError("scale and offset need two frames with both points at least")
    p, r = person[ok], robot[ok]
    pc, rc = p - p.mean(axis=0), r - r.mean(axis=0)
    spread = float(np.sum(pc * pc))
    if spread == 0.0:
        raise FingerfitError("the person's point does not move: no scale to fit")
    scale = float(np.sum(pc * rc)) / spread
    offset = r.mean(axis=0) - scale * p.mean(axis=0)
    rms = float(np.sqrt(np.mean(np.sum((scale * p + offset - r) ** 2, axis=1))))
    return ScaleOffset(scale, offset, rms, int(ok.sum()))
