"""Joint angles and fingertip positions for every frame of a recording.

* Joint angle (paper Fig. 6): the child sensor origin, expressed in the parent
  sensor frame, is projected on the plane normal to the joint axis; the angle
  is measured about the joint centre from its reference-posture projection.
  With ``p0`` the projected reference offset and ``u = a × p0`` this is
  ``theta = atan2(d·u, d·p0)``, ``d = r - c`` -- two dot products per frame.
* Fingertip: a product of exponentials at the reference posture. The tip point
  is rotated about the DIP, then PIP, then MP axis (each through its centre,
  all in tracker coordinates at the reference posture) and carried by the hand
  sensor's motion relative to its reference pose.

Both run over whole recordings with NumPy; no per-frame Python loop.
Angles rad, lengths mm, tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .model import VARIANTS, FingerModel, HandModel
from .session import HAND_SENSOR, JOINTS, UNITS_TO_MM, Recording
from .transforms import FloatArray, rotate_about_line


@dataclass(frozen=True)
class FingerMotion:
    """One finger's kinematics under one model variant.

    Attributes
    ----------
    angles : dict[str, ndarray]
        ``mp``, ``pip``, ``dip`` -> ``(n_frames,)`` flexion angles (rad).
    tip : ndarray, shape (n_frames, 3)
        Fingertip in tracker coordinates (mm).
    """

    angles: dict[str, FloatArray]
    tip: FloatArray


@dataclass(frozen=True)
class Kinematics:
    """Angles and fingertips of a recording.

    Attributes
    ----------
    time : ndarray, shape (n_frames,)
        Seconds.
    motions : dict[str, dict[str, FingerMotion]]
        variant (``user_axis``, ``orthogonal``) -> finger -> motion.
    """

    time: FloatArray
    motions: dict[str, dict[str, FingerMotion]]


def projection_angle(
    parent_rotation: FloatArray,
    parent_position: FloatArray,
    child_position: FloatArray,
    centre: FloatArray,
    axis: FloatArray,
    reference_offset: FloatArray,
) -> FloatArray:
    """Joint angle by the paper's projection method (Fig. 6).

    Parameters
    ----------
    parent_rotation : ndarray, shape (n, 3, 3)
        Parent sensor rotations (sensor -> tracker).
    parent_position, child_position : ndarray, shape (n, 3)
        Parent and child sensor origins, tracker coordinates (mm).
    centre, axis : ndarray, shape (3,)
        Joint centre (mm) and unit axis in the **parent sensor frame**.
    reference_offset : ndarray, shape (3,)
        Child sensor origin in the parent frame at the reference posture (mm).

    Returns
    -------
    ndarray, shape (n,)
        Angle about ``axis`` (rad, right-hand rule), 0 at the reference posture.
    """
    p0 = reference_offset - centre
    p0 = p0 - (p0 @ axis) * axis
    basis = np.column_stack([np.cross(axis, p0), p0])  # (3, 2): u, p0
    # r = R^T (t_c - t_p) is the child origin in the parent frame; d = r - c.
    r = np.einsum("ni,nij->nj", child_position - parent_position, parent_rotation)
    yx = r @ basis
    yx -= centre @ basis
    return np.arctan2(yx[:, 0], yx[:, 1])


def chain_points(
    finger: FingerModel,
    variant: str,
    angles: dict[str, FloatArray],
    points: FloatArray,
    depth: int = 3,
) -> FloatArray:
    """Move reference-posture points through the finger's joint rotations.

    Parameters
    ----------
    finger : FingerModel
    variant : {"user_axis", "orthogonal"}
    angles : dict
        ``mp``, ``pip``, ``dip`` (and ``mp_abduction`` for two-axis models) -> ``(n,)`` rad.
    points : ndarray, shape (3,) or (n, 3)
        Points on the segment distal to joint ``depth`` (tracker frame at the
        reference posture, mm); ``depth = 3`` for the distal phalanx.
    depth : int
        Number of joints (from the MP) the points are carried by.

    Returns
    -------
    ndarray, shape (n, 3)
        The points with the hand at its reference pose (mm).
    """
    p = points
    for j in reversed(JOINTS[:depth]):
        jm = finger.joints[j]
        p = rotate_about_line(p, jm.center, jm.axis_for(variant), angles[j])
    if finger.abduction is not None and depth > 0 and "mp_abduction" in angles:
        ab = finger.abduction
        p = rotate_about_line(p, ab.center, ab.axis, angles["mp_abduction"])
    return np.asarray(p)


def carry_by_hand(
    model: HandModel, hand_rotation: FloatArray, hand_position: FloatArray, points: FloatArray
) -> FloatArray:
    """Carry reference-posture points ``(n, 3)`` by the hand sensor's motion (mm, tracker)."""
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = (points - p0) @ r0  # r0^T (p - p0), row-wise
    return np.einsum("nij,nj->ni", hand_rotation, local) + hand_position


def joint_angles(
    model: HandModel, finger: str, recording: Recording, variant: str = "user_axis"
) -> dict[str, FloatArray]:
    """Flexion angles ``(n_frames,)`` rad of each joint of ``finger`` over ``recording``."""
    out = {}
    for j, jm in model.fingers[finger].joints.items():
        parent, child = recording.pose(jm.parent), recording.pose(jm.child)
        c, a = model.in_parent(finger, j, variant)
        pp, pr = model.reference_poses[jm.parent]
        cp, _ = model.reference_poses[jm.child]
        out[j] = projection_angle(
            parent.rotation, parent.position, child.position, c, a, pr.T @ (cp - pp)
        )
    return out


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
        Frames with a missing sensor give NaN.
    """
    hand = recording.pose(HAND_SENSOR)
    motions: dict[str, dict[str, FingerMotion]] = {}
    for v in variants:
        motions[v] = {}
        for f in fingers or list(model.fingers):
            ang = joint_angles(model, f, recording, v)
            local = chain_points(model.fingers[f], v, ang, model.fingers[f].tip)
            tip = carry_by_hand(model, hand.rotation, hand.position, local)
            motions[v][f] = FingerMotion(ang, tip)
    return Kinematics(recording.time, motions)


def kinematics_table(kin: Kinematics, units: str = "mm") -> pd.DataFrame:
    """Angles CSV table: ``time``, ``<finger>.<joint>`` (deg), ``<finger>.tip.x|y|z`` (``units``);
    the orthogonal variant's columns carry the prefix ``orthogonal.``."""
    scale = UNITS_TO_MM[units]
    cols: dict[str, FloatArray] = {"time": kin.time}
    for v, fingers in kin.motions.items():
        prefix = "" if v == "user_axis" else f"{v}."
        for f, m in fingers.items():
            for j, a in m.angles.items():
                cols[f"{prefix}{f}.{j}"] = np.degrees(a)
            for i, c in enumerate("xyz"):
                cols[f"{prefix}{f}.tip.{c}"] = m.tip[:, i] / scale
    return pd.DataFrame(cols)
