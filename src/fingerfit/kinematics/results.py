"""What the kinematics of a recording are: per model variant and digit, the joint angles,
tip and pad of every frame (:class:`Kinematics`), and the angles table they make.
Angles rad, lengths mm, tracker coordinates (``docs/conventions.md``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..session import UNITS_TO_MM
from ..transforms import FloatArray


@dataclass(frozen=True)
class FingerMotion:
    """One digit's kinematics under one model variant.

    Attributes
    ----------
    angles : dict[str, ndarray]
        Flexion joints (``mp``, ``pip``, ``dip``; the thumb's ``cmc``, ``mcp``, ``ip``)
        -> ``(n_frames,)`` angles (rad), then ``<joint>_abduction`` (rad) of each
        two-axis joint (:meth:`~fingerfit.model.DigitModel.angle_names`).
    tip : ndarray, shape (n_frames, 3)
        Tip (nail-edge point) in tracker coordinates (mm).
    pad : ndarray, shape (n_frames, 3) or None
        Pad point (on the pulp's skin, ``docs/conventions.md``) in tracker coordinates
        (mm); ``None`` for a model without pads.
    """

    angles: dict[str, FloatArray]
    tip: FloatArray
    pad: FloatArray | None = None


@dataclass(frozen=True)
class Kinematics:
    """Angles and fingertips of a recording.

    Attributes
    ----------
    time : ndarray, shape (n_frames,)
        Seconds.
    motions : dict[str, dict[str, FingerMotion]]
        variant (``user_axis``, ``orthogonal``) -> digit -> motion.
    """

    time: FloatArray
    motions: dict[str, dict[str, FingerMotion]]


def kinematics_table(kin: Kinematics, units: str = "mm") -> pd.DataFrame:
    """Angles CSV table: ``time``, per digit its angles ``<digit>.<joint>`` (deg; flexion
    joints, then ``<joint>_abduction`` of two-axis joints), ``<digit>.tip.x|y|z`` and,
    for models with pads, ``<digit>.pad.x|y|z`` (``units``); the orthogonal variant's
    columns carry the prefix ``orthogonal.``."""
    scale = UNITS_TO_MM[units]
    names = ["time"]
    for v, fingers in kin.motions.items():
        prefix = "" if v == "user_axis" else f"{v}."
        for f, m in fingers.items():
            names += [f"{prefix}{f}.{j}" for j in m.angles]
            for point, xyz in (("tip", m.tip), ("pad", m.pad)):
                if xyz is not None:
                    names += [f"{prefix}{f}.{point}.{c}" for c in "xyz"]
    # One (columns, frames) array filled column by column: the frame wraps it as its one
    # block, without stacking the columns again (a third of the table's time at 500,000
    # frames).
    values = np.empty((len(names), len(kin.time)))
    values[0] = kin.time
    k = 1
    for fingers in kin.motions.values():
        for m in fingers.values():
            for a in m.angles.values():
                np.degrees(a, out=values[k])
                k += 1
            for xyz in (m.tip, m.pad):
                if xyz is not None:
                    np.divide(xyz.T, scale, out=values[k : k + 3])
                    k += 3
    return pd.DataFrame(values.T, columns=names, copy=False)
