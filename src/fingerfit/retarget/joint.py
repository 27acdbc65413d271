"""The ``joint`` method: the person's joint angles copied to robot joints through the map.

``q[robot] = sign * scale * angle + offset`` for every human joint the map names and the
model has; every other joint keeps its held (neutral) value; then limits and couplings
(:meth:`fingerfit.retarget.limits.Limits.project` without sweeps: each coupling's driver
is clipped to the range its driven joint can follow, then the driven joint to its band).
The baseline robot-hand labs use.
"""

from __future__ import annotations

import numpy as np

from ..transforms import FloatArray
from .limits import Limits
from .maps import RobotMap


def copy_angles(
    angles: dict[str, dict[str, FloatArray]],
    rmap: RobotMap,
    joint_names: tuple[str, ...],
    hold: FloatArray,
    limits: Limits,
) -> tuple[FloatArray, int]:
    """Robot joint trajectory from human joint angles.

    Parameters
    ----------
    angles : dict
        digit -> human joint (``mp``, ``pip``, ``mp_abduction``, ``cmc``, ...) -> ``(n,)`` rad.
    rmap : RobotMap
    joint_names : tuple of str
        The robot's joints (``nq``).
    hold : ndarray, shape (nq,)
        Values of joints no human joint drives (rad).
    limits : Limits

    Returns
    -------
    q : ndarray, shape (n, nq)
        rad, within limits and couplings.
    held : int
        Frames where some mapped angle was missing (NaN) and the previous frame's value
        was kept (the first frames: the held value).
    """
    idx = {n: i for i, n in enumerate(joint_names)}
    n = len(next(iter(next(iter(angles.values())).values()))) if angles else 0
    q = np.tile(hold, (n, 1))
    missing = np.zeros(n, dtype=bool)
    for digit, dm in rmap.digits.items():
        for human, link in dm.joints.items():
            a = angles.get(digit, {}).get(human)
            if a is None:
                continue
            col = link.sign * link.scale * np.asarray(a, dtype=float) + link.offset
            bad = ~np.isfinite(col)
            missing |= bad
            if bad.any():  # forward fill: the robot keeps its last commanded value
                valid = np.where(bad, 0, np.arange(n))
                np.maximum.accumulate(valid, out=valid)
                col = np.where(bad & ~np.isfinite(col[valid]), hold[idx[link.robot]], col[valid])
            q[:, idx[link.robot]] = col
    return limits.project(q, sweeps=0), int(missing.sum())
