"""The ``joint`` method: the person's joint angles copied to robot joints through the map.

``q[robot] = sign * scale * angle + offset`` for every human joint the map names and the
model has; every other joint keeps its held (neutral) value; then limits and couplings
(:meth:`fingerfit.retarget.limits.Limits.project` without sweeps: each coupling's driver
is clipped to the range its driven joint can follow, then the driven joint to its band).
The baseline robot-hand labs use.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..transforms import FloatArray
from .limits import Limits
from .maps import RobotMap


class AngleCopy:
    """The ``joint`` method with the map's links prepared once; a missing angle keeps its value.

    Its state (each link's last value) carries from one call to the next, so calls over
    blocks of frames as they arrive give the joints of one call over all of them.

    Parameters
    ----------
    rmap : RobotMap
    joint_names : tuple of str
        The robot's joints (``nq``).
    hold : ndarray, shape (nq,)
        Values of joints no human joint drives, and of a driven one before its angle was
        ever seen (rad).
    limits : Limits
    angles : iterable of (str, str)
        The (digit, human joint) angles the caller will give; map links to others are
        left out (their robot joints keep ``hold``).
    """

    def __init__(
        self,
        rmap: RobotMap,
        joint_names: tuple[str, ...],
        hold: FloatArray,
        limits: Limits,
        angles: Iterable[tuple[str, str]],
    ) -> None:
        have = set(angles)
        idx = {n: i for i, n in enumerate(joint_names)}
        links = [
            (d, h, link)
            for d, dm in rmap.digits.items()
            for h, link in dm.joints.items()
            if (d, h) in have
        ]
        #: The (digit, human joint) of each column :meth:`__call__` takes, in order.
        self.keys = [(d, h) for d, h, _ in links]
        self.cols = np.array([idx[link.robot] for _, _, link in links], dtype=int)
        self.gain = np.array([link.sign * link.scale for _, _, link in links])
        self.offset = np.array([link.offset for _, _, link in links])
        self.hold, self.limits = hold, limits
        self.last = hold[self.cols].astype(float)

    def __call__(self, angles: FloatArray) -> tuple[FloatArray, int]:
        """Robot joints from a block of human angles.

        Parameters
        ----------
        angles : ndarray, shape (n, k)
            rad, one column per :attr:`keys` entry; NaN where missing.

        Returns
        -------
        q : ndarray, shape (n, nq)
            rad, within limits and couplings.
        held : int
            Frames where some angle was missing and its link kept its last value (before
            any value: ``hold``).
        """
        col = angles * self.gain + self.offset
        bad = ~np.isfinite(col)
        held = int(bad.any(axis=1).sum())
        if held:  # forward fill, column by column, from the last value of the last call
            n = len(col)
            rows = np.where(bad, -1, np.arange(n)[:, None])
            np.maximum.accumulate(rows, axis=0, out=rows)
            col = np.where(rows >= 0, col[np.maximum(rows, 0), np.arange(col.shape[1])], self.last)
        if len(col):
            self.last = col[-1].copy()
        q = np.tile(self.hold, (len(col), 1))
        q[:, self.cols] = col
        return self.limits.project(q, sweeps=0), held


def copy_angles(
    angles: dict[str, dict[str, FloatArray]],
    rmap: RobotMap,
    joint_names: tuple[str, ...],
    hold: FloatArray,
    limits: Limits,
) -> tuple[FloatArray, int]:
    """Robot joint trajectory from human joint angles (one :class:`AngleCopy` call).

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
    keys = [(d, h) for d, per in angles.items() for h in per]
    copy = AngleCopy(rmap, joint_names, hold, limits, keys)
    n = len(next(iter(next(iter(angles.values())).values()))) if angles else 0
    a = np.empty((n, len(copy.keys)))
    for i, (d, h) in enumerate(copy.keys):
        a[:, i] = angles[d][h]
    return copy(a)
