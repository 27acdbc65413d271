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
    cols: dict[str, FloatArray] = {"time": kin.time}
    for v, fingers in kin.motions.items():
        prefix = "" if v == "user_axis" else f"{v}."
        for f, m in fingers.items():
            for j, a in m.angles.items():
                cols[f"{prefix}{f}.{j}"] = np.degrees(a)
            for point, xyz in (("tip", m.tip), ("pad", m.pad)):
                if xyz is not None:
                    for i, c in enumerate("xyz"):
                        cols[f"{prefix}{f}.{point}.{c}"] = xyz[:, i] / scale
    return pd.DataFrame(cols)
