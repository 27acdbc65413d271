"""The kinematics of a recording: each joint's angle from its two sensors, the tip and pad
through the digit's chain, carried by the hand sensor (see :mod:`fingerfit.kinematics`)."""

from __future__ import annotations

import numpy as np

from ..angles import (
    projection_angle,
    relative_rotation,
    twist_angle,
    two_axis_angles,
    two_axis_projection_angles,
)
from ..model import ANGLE_METHODS, VARIANTS, DigitModel, HandModel
from ..session import HAND_SENSOR, Recording
from ..transforms import FloatArray, rotate_about_lines
from .plan import KinematicsPlan
from .results import FingerMotion, Kinematics


def chain_points(
    finger: DigitModel,
    variant: str,
    angles: dict[str, FloatArray],
    points: FloatArray,
    depth: int = 3,
) -> FloatArray:
    """Move reference-posture points through a digit's joint rotations.

    Parameters
    ----------
    finger : DigitModel
    variant : {"user_axis", "orthogonal"}
    angles : dict
        Every axis of the first ``depth`` joints (flexion joints and, for two-axis
        joints, ``<joint>_abduction``) -> ``(n,)`` rad.
    points : ndarray, shape (3,) or (n, 3)
        Points on the segment distal to joint ``depth`` (tracker frame at the
        reference posture, mm); ``depth = 3`` for the distal phalanx.
    depth : int
        Number of joints (from the first) the points are carried by.

    Returns
    -------
    ndarray, shape (n, 3)
        The points with the hand at its reference pose (mm): turned about each axis
        through its centre (moved by ``theta * migration`` where the model has
        rolling-contact migration), distal axes first.
    """
    steps = []
    for jm in reversed(finger.chain(depth)):
        centre = jm.center
        if jm.migration is not None:
            centre = centre + np.multiply.outer(angles[jm.name], jm.migration)
        steps.append((centre, jm.axis_for(variant), angles[jm.name]))
    return rotate_about_lines(points, steps)


def carry_by_hand(
    model: HandModel, hand_rotation: FloatArray, hand_position: FloatArray, points: FloatArray
) -> FloatArray:
    """Carry reference-posture points ``(n, 3)`` by the hand sensor's motion (mm, tracker)."""
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = (points - p0) @ r0  # r0^T (p - p0), row-wise
    return np.einsum("nij,nj->ni", hand_rotation, local) + hand_position


def finger_angles(
    model: HandModel,
    finger: str,
    recording: Recording,
    variants: tuple[str, ...] = VARIANTS,
    method: str | None = None,
) -> dict[str, dict[str, FloatArray]]:
    """Joint angles of one digit under several model variants (sensor data read once).

    Parameters
    ----------
    model : HandModel
    finger : str
        Digit name.
    recording : Recording
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    method : {"projection", "swing_twist"}, optional
        Default: the model's ``angle_method``.

    Returns
    -------
    dict
        variant -> angle name (:meth:`~fingerfit.model.DigitModel.angle_names`) ->
        ``(n_frames,)`` rad; NaN where a sensor is missing. A two-axis joint
        ``Q = Rot(p, alpha) Rot(d, delta)`` (``p`` its proximal axis, ``d`` its distal one,
        :mod:`fingerfit.digits`) gives ``alpha`` and ``delta`` to the two axes' names.
    """
    method = method or model.angle_method
    if method not in ANGLE_METHODS:
        raise ValueError(f"unknown angle method '{method}' (have: {', '.join(ANGLE_METHODS)})")
    fm = model.fingers[finger]
    out: dict[str, dict[str, FloatArray]] = {v: {} for v in variants}
    for j, jm in fm.joints.items():
        parent, child = recording.pose(jm.parent), recording.pose(jm.child)
        pp, pr = model.reference_poses[jm.parent]
        cp, cr = model.reference_poses[jm.child]
        if method == "swing_twist":
            q = relative_rotation(parent.rotation, child.rotation, pr.T @ cr)
        else:
            r = np.einsum("ni,nij->nj", child.position - parent.position, parent.rotation)
            r0 = pr.T @ (cp - pp)
        for v in variants:
            if j not in fm.second_axes:
                c, a = model.in_parent(finger, j, v)
                if method == "swing_twist":
                    out[v][j] = twist_angle(q, a)
                else:
                    out[v][j] = projection_angle(
                        parent.rotation, parent.position, child.position, c, a, r0
                    )
                continue
            prox, dist = fm.axes(j)
            cb, b = model.in_parent(finger, prox.name, v)
            ca, a = model.in_parent(finger, dist.name, v)
            if method == "swing_twist":
                out[v][prox.name], out[v][dist.name] = two_axis_angles(q, a, b)
            else:
                out[v][prox.name], out[v][dist.name] = two_axis_projection_angles(
                    r, r0, ca, a, cb, b
                )
    # Column order: the flexion angles, then the ab/adductions.
    return {v: {k: d[k] for k in fm.angle_names()} for v, d in out.items()}


def joint_angles(
    model: HandModel,
    finger: str,
    recording: Recording,
    variant: str = "user_axis",
    method: str | None = None,
) -> dict[str, FloatArray]:
    """Joint angles ``(n_frames,)`` rad of digit ``finger`` over ``recording`` (one variant).

    Flexion and, for two-axis joints, ``<joint>_abduction``; computed by ``method``
    (default: the model's ``angle_method``). See :func:`finger_angles`.
    """
    return finger_angles(model, finger, recording, (variant,), method)[variant]


def compute_kinematics(
    model: HandModel,
    recording: Recording,
    variants: tuple[str, ...] = VARIANTS,
    fingers: list[str] | None = None,
) -> Kinematics:
    """Joint angles and fingertips of every frame, for each model variant.

    Parameters
    ----------
    model : HandModel
    recording : Recording
        Must hold the hand sensor and the three sensors of each finger.
    variants : tuple of str
    fingers : list of str, optional
        Default: every finger of the model.

    Returns
    -------
    Kinematics
        Frames with a missing sensor give NaN. Angles by the model's
        ``angle_method``.
    """
    fingers = fingers or list(model.fingers)
    if model.angle_method == "swing_twist" and recording.n_frames > 0:
        return KinematicsPlan(model, tuple(variants), fingers).run(recording)
    hand = recording.pose(HAND_SENSOR)
    motions: dict[str, dict[str, FingerMotion]] = {v: {} for v in variants}
    for f in fingers:
        fm = model.fingers[f]
        angles = finger_angles(model, f, recording, variants)
        for v in variants:
            tip, pad = (
                None
                if point is None
                else carry_by_hand(
                    model, hand.rotation, hand.position, chain_points(fm, v, angles[v], point)
                )
                for point in (fm.tip, fm.pad)
            )
            motions[v][f] = FingerMotion(angles[v], tip, pad)
    return Kinematics(recording.time, motions)
