"""Joint angles and fingertip positions for every frame of a recording.

Two ways to get a joint angle from the two sensors of a joint (the model's
``angle_method``; ``docs/methods.md`` has the measurement that chose the default):

* ``projection`` (paper Fig. 6): the child sensor origin, expressed in the parent
  sensor frame, is projected on the plane normal to the joint axis; the angle
  is measured about the joint centre from its reference-posture projection.
  With ``p0`` the projected reference offset and ``u = a × p0`` this is
  ``theta = atan2(d·u, d·p0)``, ``d = r - c`` -- two dot products per frame.
* ``swing_twist``: the full relative orientation away from the reference
  posture, ``Q = R_p^T R_c R_ref^T`` (parent frame), is split into a twist about
  the joint axis ``a`` and a swing perpendicular to it; the angle is the twist,
  ``theta = 2 atan2(vee(Q - Q^T)·a, 1 + tr Q)`` (no quaternion needed): traces of
  ``Q``, one BLAS product over the whole recording. For a
  two-axis MP joint ``Q = Rot(b, beta) Rot(a, theta)``: ``beta`` turns ``a``
  to ``Q a`` about ``b``, and ``theta`` is the twist of ``Rot(b, -beta) Q``.

Fingertip: a product of exponentials at the reference posture. The tip point
is rotated about the DIP, then PIP, then MP axis (each through its centre --
moved by ``theta * migration`` where the model has rolling-contact migration --
all in tracker coordinates at the reference posture), then about the MP
ab/adduction axis of a two-axis model, and carried by the hand sensor's motion
relative to its reference pose.

Both run over whole recordings with NumPy; no per-frame Python loop.
Angles rad, lengths mm, tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .model import ANGLE_METHODS, VARIANTS, FingerModel, HandModel
from .session import HAND_SENSOR, JOINTS, UNITS_TO_MM, Recording
from .transforms import FloatArray, rotate_about_line, rotate_about_lines, skew

ABDUCTION = "mp_abduction"


@dataclass(frozen=True)
class FingerMotion:
    """One finger's kinematics under one model variant.

    Attributes
    ----------
    angles : dict[str, ndarray]
        ``mp``, ``pip``, ``dip`` -> ``(n_frames,)`` flexion angles (rad), then
        ``mp_abduction`` (rad, radial deviation positive) for a two-axis MP joint.
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


def relative_rotation(
    parent_rotation: FloatArray, child_rotation: FloatArray, reference: FloatArray
) -> FloatArray:
    """Rotation of the child away from the reference posture, in the parent sensor frame.

    Parameters
    ----------
    parent_rotation, child_rotation : ndarray, shape (n, 3, 3)
        Sensor -> tracker rotations.
    reference : ndarray, shape (3, 3)
        Child-in-parent rotation ``R_p^T R_c`` at the reference posture.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        ``Q = R_p^T R_c reference^T``: identity at the reference posture; for a
        hinge it is the rotation about the parent-frame axis by the joint angle.
    """
    g = np.matmul(np.swapaxes(parent_rotation, 1, 2), child_rotation)
    return (g.reshape(-1, 3) @ reference.T).reshape(g.shape)


# Swing-twist angles need only traces tr(Q C) for a few constant matrices C (and Q a):
# with Q flattened to (n, 9) each is one column of a single BLAS product.


def _traces(q: FloatArray, mats: FloatArray) -> FloatArray:
    """``tr(Q C_k)`` for ``q (n, 3, 3)`` and ``mats (k, 3, 3)``: ``(n, k)``."""
    n, k = q.shape[0], mats.shape[0]
    return q.reshape(n, 9) @ np.swapaxes(mats, 1, 2).reshape(k, 9).T


def _twist(tr_identity: FloatArray, tr_skew: FloatArray) -> FloatArray:
    """``2 atan2(tr(Q K_a^T), 1 + tr Q)``: the twist about ``a`` (rad)."""
    return 2.0 * np.arctan2(tr_skew, 1.0 + tr_identity)


def twist_angle(rotation: FloatArray, axis: FloatArray) -> FloatArray:
    """Twist angle of rotations about an axis (swing-twist decomposition).

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Rotations ``Q`` (e.g. from :func:`relative_rotation`).
    axis : ndarray, shape (3,)
        Unit axis ``a`` in the same frame.

    Returns
    -------
    ndarray, shape (n,)
        ``theta = 2 atan2(vee(Q - Q^T)·a, 1 + tr Q)`` (rad, in (-pi, pi]): the angle
        of the rotation about ``a`` that leaves a pure swing (a rotation about an
        axis perpendicular to ``a``) when removed. Exact for ``Q = Rot(a, theta)``.
    """
    t = _traces(rotation, np.stack([np.eye(3), skew(axis).T]))
    return _twist(t[:, 0], t[:, 1])


def two_axis_angles(
    rotation: FloatArray, flexion_axis: FloatArray, abduction_axis: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Angles of a two-axis joint ``Q = Rot(b, beta) Rot(a, theta)``.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Rotations ``Q`` away from the reference posture (parent frame).
    flexion_axis : ndarray, shape (3,)
        Unit flexion axis ``a`` (parent frame at the reference posture; carried by
        the ab/adduction).
    abduction_axis : ndarray, shape (3,)
        Unit ab/adduction axis ``b``, fixed in the parent frame, not parallel to ``a``.

    Returns
    -------
    beta, theta : ndarray, shape (n,)
        Ab/adduction and flexion (rad). ``beta`` is the angle about ``b`` from the
        part of ``a`` perpendicular to ``b`` to that of ``Q a`` (the flexion axis is
        all the ab/adduction moves); ``theta`` is the twist of ``Rot(b, -beta) Q``
        about ``a``. Exact when ``Q`` is of the two-axis form.
    """
    a, b = flexion_axis, abduction_axis
    n = rotation.shape[0]
    ap = a - (a @ b) * b
    # beta = atan2((Q a)·(b x ap), (Q a)·ap), and (Q a)·w = tr(Q a w^T). The twist needs
    # tr(X Rot(b, -beta) Q) = tr(Q X) - sin(beta) tr(Q X K_b) + (1 - cos(beta)) tr(Q X K_b^2)
    # for X = I and K_a^T. All ten traces come from one product.
    kb = skew(b)
    xs, ys = (np.eye(3), skew(a).T), (np.eye(3), kb, kb @ kb)
    mats = [np.outer(a, np.cross(b, ap)), np.outer(a, ap)] + [x @ y for x in xs for y in ys]
    t = _traces(rotation, np.stack(mats))
    beta = np.arctan2(t[:, 0], t[:, 1])
    t = t[:, 2:].reshape(n, 2, 3)
    s, c = np.sin(beta)[:, None], (1.0 - np.cos(beta))[:, None]
    tr = t[:, :, 0] - s * t[:, :, 1] + c * t[:, :, 2]
    return beta, _twist(tr[:, 0], tr[:, 1])


def _projected(r: FloatArray, centre: FloatArray, axis: FloatArray, r0: FloatArray) -> FloatArray:
    """Angle ``(n,)`` about the line (centre, axis) from ``r0 (3,)`` to points ``r (n, 3)``."""
    p0 = r0 - centre
    p0 = p0 - (p0 @ axis) * axis
    basis = np.column_stack([np.cross(axis, p0), p0])
    yx = (r - centre) @ basis
    return np.arctan2(yx[:, 0], yx[:, 1])


def two_axis_projection_angles(
    points: FloatArray,
    reference_point: FloatArray,
    flexion_point: FloatArray,
    flexion_axis: FloatArray,
    abduction_point: FloatArray,
    abduction_axis: FloatArray,
    iterations: int = 8,
) -> tuple[FloatArray, FloatArray]:
    """Two-axis joint angles from the child sensor origin alone (projection family).

    Solves ``r = Rot_b(beta) [Rot_a(theta) (r0 - c_a) + c_a - c_b] + c_b`` for
    ``(beta, theta)`` per frame by Gauss-Newton (vectorised over frames), started
    from the sequential projections about ``b`` and then ``a``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Child sensor origin in the parent sensor frame (mm).
    reference_point : ndarray, shape (3,)
        The same at the reference posture (mm).
    flexion_point, flexion_axis : ndarray, shape (3,)
        A point (mm) and the unit direction of the flexion axis (parent frame).
    abduction_point, abduction_axis : ndarray, shape (3,)
        The same for the ab/adduction axis.
    iterations : int
        Gauss-Newton steps.

    Returns
    -------
    beta, theta : ndarray, shape (n,)
        Ab/adduction and flexion (rad).
    """
    a, b, ca, cb = flexion_axis, abduction_axis, flexion_point, abduction_point
    beta = _projected(points, cb, b, reference_point)
    theta = _projected(rotate_about_line(points, cb, b, -beta), ca, a, reference_point)
    v = reference_point - ca
    for _ in range(iterations):
        rv = rotate_about_line(v, np.zeros(3), a, theta)  # (n, 3)
        f = rotate_about_line(rv + ca, cb, b, beta)
        jt = rotate_about_line(np.cross(a, rv), np.zeros(3), b, beta)
        jb = np.cross(b, f - cb)
        e = points - f
        g11, g12, g22 = (jt * jt).sum(1), (jt * jb).sum(1), (jb * jb).sum(1)
        r1, r2 = (jt * e).sum(1), (jb * e).sum(1)
        det = g11 * g22 - g12 * g12
        det = np.where(np.abs(det) > 1e-12, det, np.inf)
        theta = theta + (g22 * r1 - g12 * r2) / det
        beta = beta + (g11 * r2 - g12 * r1) / det
    return beta, theta


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
    steps = []
    for j in reversed(JOINTS[:depth]):
        jm = finger.joints[j]
        centre = jm.center
        if jm.migration is not None:
            centre = centre + np.multiply.outer(angles[j], jm.migration)
        steps.append((centre, jm.axis_for(variant), angles[j]))
    if finger.abduction is not None and depth > 0 and ABDUCTION in angles:
        ab = finger.abduction
        steps.append((ab.center, ab.axis, angles[ABDUCTION]))
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
    """Joint angles of one finger under several model variants (sensor data read once).

    Parameters
    ----------
    model : HandModel
    finger : str
    recording : Recording
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    method : {"projection", "swing_twist"}, optional
        Default: the model's ``angle_method``.

    Returns
    -------
    dict
        variant -> ``mp``, ``pip``, ``dip`` (and ``mp_abduction`` for a two-axis MP)
        -> ``(n_frames,)`` rad; NaN where a sensor is missing.
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
        two_axis = j == "mp" and fm.abduction is not None
        b = pr.T @ fm.abduction.axis if two_axis else None
        if method == "swing_twist":
            q = relative_rotation(parent.rotation, child.rotation, pr.T @ cr)
        else:
            r = np.einsum("ni,nij->nj", child.position - parent.position, parent.rotation)
            r0 = pr.T @ (cp - pp)
        for v in variants:
            c, a = model.in_parent(finger, j, v)
            if method == "swing_twist":
                if two_axis:
                    out[v][ABDUCTION], out[v][j] = two_axis_angles(q, a, b)
                else:
                    out[v][j] = twist_angle(q, a)
            elif two_axis:
                cb = pr.T @ (fm.abduction.center - pp)
                out[v][ABDUCTION], out[v][j] = two_axis_projection_angles(r, r0, c, a, cb, b)
            else:
                out[v][j] = projection_angle(
                    parent.rotation, parent.position, child.position, c, a, r0
                )
    # Column order: the three flexion angles, then the ab/adduction.
    return {v: {k: d[k] for k in (*JOINTS, ABDUCTION) if k in d} for v, d in out.items()}


def joint_angles(
    model: HandModel,
    finger: str,
    recording: Recording,
    variant: str = "user_axis",
    method: str | None = None,
) -> dict[str, FloatArray]:
    """Joint angles ``(n_frames,)`` rad of ``finger`` over ``recording`` (one variant).

    ``mp``, ``pip``, ``dip`` flexion and, for a two-axis MP joint, ``mp_abduction``;
    computed by ``method`` (default: the model's ``angle_method``). See
    :func:`finger_angles`.
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
    hand = recording.pose(HAND_SENSOR)
    motions: dict[str, dict[str, FingerMotion]] = {v: {} for v in variants}
    for f in fingers or list(model.fingers):
        angles = finger_angles(model, f, recording, variants)
        for v in variants:
            local = chain_points(model.fingers[f], v, angles[v], model.fingers[f].tip)
            tip = carry_by_hand(model, hand.rotation, hand.position, local)
            motions[v][f] = FingerMotion(angles[v], tip)
    return Kinematics(recording.time, motions)


def kinematics_table(kin: Kinematics, units: str = "mm") -> pd.DataFrame:
    """Angles CSV table: ``time``, ``<finger>.mp|pip|dip`` (deg), ``<finger>.mp_abduction``
    (deg, two-axis MP models only), ``<finger>.tip.x|y|z`` (``units``); the orthogonal
    variant's columns carry the prefix ``orthogonal.``."""
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
