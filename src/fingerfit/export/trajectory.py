"""Recorded motion for robot software: joint angles per frame under the robot joint names.

The CSV has a column ``time`` (s) and one column per joint of the exported
URDF/MJCF, named like the joint (``<finger>_mp_abduction``, ``<finger>_mp``,
``<finger>_pip``, ``<finger>_dip``), in **radians**, in the joint order of the
robot files. Frames where an angle could not be computed are empty fields.
Setting these values as joint positions of the exported model, with the ``hand``
root placed at the recording's hand sensor pose, reproduces the fingertips that
``fingerfit angles`` writes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..kinematics import Kinematics
from ..model import HandModel
from .geometry import joint_names


def trajectory_table(kin: Kinematics, model: HandModel, variant: str = "user_axis") -> pd.DataFrame:
    """Joint-angle trajectory with robot joint names.

    Parameters
    ----------
    kin : Kinematics
        From :func:`fingerfit.kinematics.compute_kinematics` with ``model``.
    model : HandModel
    variant : {"user_axis", "orthogonal"}
        Must match the variant the URDF/MJCF was exported with.

    Returns
    -------
    DataFrame
        ``time`` (s, ``(n_frames,)``) and one column per robot joint (rad), in the
        order of :func:`~fingerfit.export.geometry.joint_names`; NaN where a sensor
        is missing.

    Raises
    ------
    FingerfitError
        If ``kin`` lacks the variant, a digit or an angle of the model.
    """
    if variant not in kin.motions:
        raise FingerfitError(f"the kinematics have no '{variant}' variant", field="variant")
    cols: dict[str, np.ndarray] = {"time": np.asarray(kin.time, dtype=float)}
    for name in joint_names(model):
        finger, kind = name.split("_", 1)
        motion = kin.motions[variant].get(finger)
        if motion is None:
            raise FingerfitError(f"the kinematics have no finger '{finger}'", field=finger)
        if kind not in motion.angles:
            raise FingerfitError(
                f"the kinematics have no angle '{kind}' of the {finger}", field=name
            )
        cols[name] = np.asarray(motion.angles[kind], dtype=float)
    return pd.DataFrame(cols)


def write_trajectory(
    path: str | Path, kin: Kinematics, model: HandModel, variant: str = "user_axis"
) -> Path:
    """Write :func:`trajectory_table` as CSV atomically (round-trip float precision), or as
    Parquet for a ``.parquet`` path (:func:`fingerfit.io.parquet.joints_meta`).

    Parameters
    ----------
    path : str or Path
    kin : Kinematics
    model : HandModel
    variant : {"user_axis", "orthogonal"}

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        As :func:`trajectory_table`, or when ``path`` cannot be written.
    """
    from ..io.parquet import joints_meta, write_table_file

    return write_table_file(Path(path), trajectory_table(kin, model, variant), joints_meta())
