"""Recorded motion for robot software: joint angles per frame under the robot joint names.

The CSV has a column ``time`` (s) and one column per joint of the exported
URDF/MJCF, named like the joint (``<finger>_mp_abduction``, ``<finger>_mp``,
``<finger>_pip``, ``<finger>_dip``), in **radians**, in the joint order of the
robot files. Frames where an angle could not be computed are empty fields.
Setting these values as joint positions of the exported model, with the ``hand``
root placed at the recording's hand sensor pose, reproduces the fingertips that
``fingerfit angles`` writes.

The OpenSim motion (``.mot``, :func:`coordinate_table`) holds the same angles in degrees
beside the hand's six coordinates (:func:`fingerfit.export.osim.hand_coordinates`), so
that it drives the exported ``.osim`` on its own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..kinematics import Kinematics
from ..model import HandModel
from ..session import HAND_SENSOR, Recording
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


def coordinate_table(kin: Kinematics, model: HandModel, recording: Recording) -> pd.DataFrame:
    """Every coordinate of the exported OpenSim model per frame (user-axis model).

    Parameters
    ----------
    kin : Kinematics
        From :func:`fingerfit.kinematics.compute_kinematics` with ``model`` and
        ``recording``.
    model : HandModel
    recording : Recording
        Its hand sensor's poses place the hand (mm, tracker frame).

    Returns
    -------
    DataFrame
        ``time`` (s), the hand's six coordinates (``hand_rx, hand_ry, hand_rz`` in degrees,
        ``hand_tx, hand_ty, hand_tz`` in metres, :func:`~fingerfit.export.osim.hand_coordinates`),
        then one column per joint (degrees) in the order of
        :func:`~fingerfit.export.geometry.joint_names`; ``(n_frames,)`` each, NaN where
        a sensor is missing (as the angles CSV leaves the field empty).

    Raises
    ------
    FingerfitError
        As :func:`trajectory_table`.
    """
    from .osim import HAND_COORDINATES, hand_coordinates

    joints = trajectory_table(kin, model)
    hand = recording.pose(HAND_SENSOR)
    values = hand_coordinates(model, hand.rotation, hand.position)
    values[:, :3] = np.degrees(values[:, :3])
    cols = {"time": joints["time"].to_numpy()}
    cols |= {name: values[:, k] for k, name in enumerate(HAND_COORDINATES)}
    cols |= {name: np.degrees(joints[name].to_numpy()) for name in joints.columns[1:]}
    return pd.DataFrame(cols)


def write_coordinates(
    path: str | Path, kin: Kinematics, model: HandModel, recording: Recording
) -> Path:
    """Write :func:`coordinate_table` as an OpenSim motion file (``.mot``) atomically
    (:func:`fingerfit.io.opensim.write_motion`).

    Parameters
    ----------
    path : str or Path
    kin : Kinematics
    model : HandModel
    recording : Recording

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        As :func:`trajectory_table`, or when ``path`` cannot be written.
    """
    from ..io.opensim import write_motion

    table = coordinate_table(kin, model, recording)
    return write_motion(path, table, name=f"fingerfit_{model.subject}_{model.hand}")
