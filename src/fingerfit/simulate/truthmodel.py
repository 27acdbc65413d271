"""A :class:`~fingerfit.model.HandModel` built from a simulated subject's ground truth.

Driving the true model with the simulated (noisy) sensors gives the fingertip
error no estimator of the model can beat on that data: what is left comes from
the sensors (tracker noise, field distortion, soft-tissue artefact) and from the
angle method, not from the fitted geometry (``docs/accuracy.md``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..digits import DIGITS, FLEXION_FIRST, second_axis
from ..model import DigitModel, HandModel, JointModel, JointQuality, assemble_digit
from ..session import HAND_SENSOR, JOINTS, joint_sensors, sensor_name
from .thumb import ThumbAnatomy
from .truth import SimulatedSubject


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
        Include the true MP ab/adduction axis (when the subject has one) and the thumb's
        MCP ab/adduction axis (when it moves); the thumb's CMC always has both axes.
    migration : bool
        Include the true rolling-contact migration of the centres.

    Returns
    -------
    HandModel
        True joint centres, axes (tracker coordinates at the reference posture,
        mm), fingertip and, as reference sensor poses, the true sensor mountings
        (before artefact and tracker error), so that every joint is exact in its
        parent sensor frame. A MyoHand finger keeps its MP order (flexion proximal to
        ab/adduction, :attr:`~fingerfit.model.DigitModel.axis_order`); MyoHand's thumb
        (CMC flexion proximal, as fingerfit's thumb; a hinge MCP) is represented exactly.
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
        pad = truth.pads[f].surface if f in truth.pads else None
        fingers[f] = assemble_digit(f, joints, anat.tip, second_axes, rolling, pad)
        if second_axes and anat.order[0] == "mp":
            fingers[f] = replace(fingers[f], axis_order={"mp": FLEXION_FIRST})
    if truth.thumb is not None:
        # A hinge thumb MCP (MyoHand) has no second axis to include.
        mcp_two = two_axis and truth.config.abduction and truth.thumb.mcp_abduction
        fingers = {"thumb": _thumb_model(truth.thumb, quality, mcp_two), **fingers}
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


def _thumb_model(thumb: ThumbAnatomy, quality: JointQuality, two_axis: bool) -> DigitModel:
    """The thumb's true DigitModel: CMC two-axis always, MCP two-axis with ``two_axis``
    and the subject's MCP ab/adduction moving; the pad is the pulp's skin point."""
    sensors = DIGITS["thumb"].joint_sensors()
    joints = {
        j: (*sensors[j], thumb.axis_point[j], thumb.axis[j], quality)
        for j in DIGITS["thumb"].joints
    }
    second = {}
    for j in DIGITS["thumb"].second_axes:
        if j == "cmc" or two_axis:
            k = second_axis(j)
            second[j] = JointModel(
                k, *sensors[j], thumb.axis_point[k], thumb.axis[k], thumb.axis[k], quality
            )
    return assemble_digit("thumb", joints, thumb.tip, second, None, thumb.pad.surface)


__all__ = ["truth_model"]
