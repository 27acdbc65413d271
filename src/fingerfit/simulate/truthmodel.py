"""A :class:`~fingerfit.model.HandModel` built from a simulated subject's ground truth.

Driving the true model with the simulated (noisy) sensors gives the fingertip
error no estimator of the model can beat on that data: what is left comes from
the sensors (tracker noise, field distortion, soft-tissue artefact) and from the
angle method, not from the fitted geometry (``docs/accuracy.md``).
"""

from __future__ import annotations

import numpy as np

from ..model import HandModel, JointModel, JointQuality, assemble_digit
from ..session import HAND_SENSOR, JOINTS, joint_sensors, sensor_name
from .study import SimulatedSubject


def truth_model(
    sim: SimulatedSubject,
    *,
    angle_method: str = "swing_twist",
    two_axis: bool = True,
    migration: bool = True,
) -> HandModel:
    """The true hand model of a simulated subject.

    Parameters
    ----------
    sim : SimulatedSubject
    angle_method : {"swing_twist", "projection"}
        Angle method recorded in the model.
    two_axis : bool
        Include the true MP ab/adduction axis (when the subject has one).
    migration : bool
        Include the true rolling-contact migration of the centres.

    Returns
    -------
    HandModel
        True joint centres, axes (tracker coordinates at the reference posture,
        mm), fingertip and, as reference sensor poses, the true sensor mountings
        (before artefact and tracker error), so that every joint is exact in its
        parent sensor frame.
    """
    truth = sim.truth
    quality = JointQuality(0, [], [], [], 0.0, [], notes=["ground truth"])
    fingers = {}
    for f, anat in truth.fingers.items():
        joints = {
            j: (parent, child, anat.centre[i], anat.axis[i], quality)
            for i, (j, (parent, child)) in enumerate(joint_sensors(f).items())
        }
        second_axes = {}
        if two_axis and truth.config.abduction:
            second_axes["mp"] = JointModel(
                "mp_abduction",
                HAND_SENSOR,
                sensor_name(f, "proximal"),
                anat.abduction_point,
                anat.abduction_axis,
                anat.abduction_axis,
                quality,
            )
        rolling = {}
        if migration and np.any(anat.rolling):
            rolling = {j: anat.rolling[i] for i, j in enumerate(JOINTS)}
        fingers[f] = assemble_digit(f, joints, anat.tip, second_axes, rolling)
    poses = {name: (m.position, m.rotation) for name, m in truth.mounts.items()}
    return HandModel(
        subject=sim.session.subject,
        hand=sim.session.hand,
        session_units="mm",
        method="truth",
        reference_poses=poses,
        fingers=fingers,
        angle_method=angle_method,
    )


__all__ = ["truth_model"]
