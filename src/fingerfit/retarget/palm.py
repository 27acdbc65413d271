"""Palm frames of the person and the robot, digit anchors and per-digit scales.

**Person's palm frame** (fixed to the hand sensor, defined at the reference posture, the
stretched hand; tracker coordinates, mm) from the hand's anatomy, never from one joint
axis (:func:`person_palm`):

* ``x`` (distal) = the mean direction of the finger lines: each finger's least-squares
  line through its MP, PIP and DIP centres and its tip, pointing to the tip;
* ``y`` = the normal of the fingers' sagittal planes: the mean flexion axis of every
  joint of every finger (MP, PIP, DIP) made perpendicular to ``x`` (the planes the fit
  put the joint centres on), so on the side the flexion axes point to: radial for a
  right hand, ulnar for a left one (``docs/conventions.md``);
* ``z = x × y`` (dorsal); origin = the mean MP centre.

A frame moves with the hand sensor, so fingertips are expressed in it by undoing the hand
sensor's motion since the reference posture.

**Robot palm frame**: the map's ``palm`` frame at the neutral posture with ``x`` = the map's
``distal`` direction, ``z`` = its ``dorsal`` direction (made perpendicular), ``y = z × x``.

**Targets**: digit ``d``'s point ``P`` (person's palm frame, mm) becomes
``B_robot,d + s_d M (P - B_person,d)`` (robot palm frame, m), where ``B`` is the digit's
base (MP or thumb CMC centre; the robot's: the anchor of the map's ``base`` joint),
``s_d`` = the robot's chain length over the person's (base -> joints -> tip at the
neutral / reference posture), overridable per digit in the map, and ``M = diag(1, -1, 1)``
when the person's and the robot's hands differ (mirror), else the identity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..model import HandModel
from ..session import HAND_SENSOR, Recording
from ..transforms import FloatArray
from .maps import RobotMap
from .robots import Robot


@dataclass(frozen=True)
class Frame:
    """A palm frame: ``origin (3,)`` and ``rotation (3, 3)`` (columns x distal, y, z dorsal).

    ``evidence`` says what defined it (shown by ``fingerfit retarget``).
    """

    origin: FloatArray
    rotation: FloatArray
    evidence: str = ""


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _lines(points: FloatArray) -> FloatArray:
    """Unit directions ``(k, 3)`` of the least-squares lines through ``points (k, m, 3)``,
    each pointing from its first point towards its last."""
    centred = points - points.mean(axis=1, keepdims=True)
    d = np.linalg.svd(centred)[2][:, 0]
    sign = np.sign(np.einsum("ki,ki->k", d, points[:, -1] - points[:, 0]))
    return d * sign[:, None]


def _across(v: FloatArray, x: FloatArray) -> FloatArray:
    """``v (3,)`` made perpendicular to the unit ``x (3,)`` (not normalised)."""
    return v - (v @ x) * x


def person_palm(model: HandModel) -> Frame:
    """The person's palm frame at the reference posture (tracker coordinates, mm).

    Built from the fingers' anatomy (module docstring, ``docs/retargeting.md``): ``x`` =
    the mean finger line (least-squares line through the MP, PIP, DIP centres and the
    tip of each finger), ``y`` = the fingers' sagittal-plane normal (the mean flexion
    axis of all their joints made perpendicular to ``x``), ``z = x × y``. ``x`` fixes
    all but the roll about it, which ``y`` gives. An axis tilted about the dorsal axis
    (gaining a component along the finger) loses its tilt to the projection; one tilted
    about the finger line weighs ``1 / (3 k)`` (``k`` fingers). The MP centres' row is not
    used: its dorsal-palmar slope is the fitted centres' least certain coordinate and
    the metacarpal arch's (in simulated four-finger subjects it rolled the frame 2-6 deg,
    the flexion axes 0.5-0.7 deg). Nor is the thumb, which rests pronated beside the
    palm.

    Returns
    -------
    Frame
        ``origin (3,)`` = the mean MP centre (mm), ``rotation (3, 3)`` columns x, y, z,
        ``evidence`` naming the digits and the rule used.

    Raises
    ------
    FingerfitError
        When the model has no finger (a digit with an ``mp`` joint).
    """
    fingers = [f for f in model.fingers.values() if "mp" in f.joints]
    if not fingers:
        raise FingerfitError(
            "the model has no finger (a digit with an MP joint): the palm frame is defined "
            "by the fingers' lines and MP centres"
        )
    names = ", ".join(f.name for f in fingers)
    plural = "s" if len(fingers) > 1 else ""
    chains = np.array([[j.center for j in f.joints.values()] + [f.tip] for f in fingers])
    x = _unit(_lines(chains).mean(axis=0))
    flexion = np.mean([j.axis for f in fingers for j in f.joints.values()], axis=0)
    sagittal = _across(flexion, x)
    if np.linalg.norm(sagittal) < 0.1 * np.linalg.norm(flexion):
        raise FingerfitError(f"the flexion axes of {names} run along the fingers: no palm frame")
    y = _unit(sagittal)
    evidence = f"x: finger line{plural} ({names}); y: sagittal plane{plural} ({names})"
    centre = chains[:, 0].mean(axis=0)
    return Frame(centre, np.column_stack([x, y, np.cross(x, y)]), evidence)


def palm_in_hand_sensor(model: HandModel, palm: Frame) -> tuple[float, FloatArray]:
    """The person's palm frame seen from the hand sensor at the reference posture.

    Parameters
    ----------
    model : HandModel
        Holds the hand sensor's reference pose.
    palm : Frame
        From :func:`person_palm` (tracker coordinates).

    Returns
    -------
    angle : float
        Rotation angle (deg, 0-180) of ``R = R_hand^T R_palm``, the palm frame's axes in
        hand-sensor coordinates.
    euler : ndarray, shape (3,)
        ``(a, b, c)`` deg with ``R = Rz(c) Ry(b) Rx(a)`` (fixed axes x, y, z of the hand
        sensor).
    """
    r = Rotation.from_matrix(model.reference_poses[HAND_SENSOR][1].T @ palm.rotation)
    return float(np.degrees(r.magnitude())), r.as_euler("xyz", degrees=True)


def digit_base(model: HandModel, digit: str) -> FloatArray:
    """Centre ``(3,)`` of the digit's first joint (MP, thumb CMC), tracker frame, mm."""
    return next(iter(model.fingers[digit].joints.values())).center


def person_chain_length(model: HandModel, digit: str) -> float:
    """Base -> joint centres -> tip length of a digit at the reference posture (mm)."""
    fm = model.fingers[digit]
    pts = [j.center for j in fm.joints.values()] + [fm.tip]
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def in_palm(model: HandModel, palm: Frame, recording: Recording, points: FloatArray) -> FloatArray:
    """Points carried by the hand expressed in the person's palm frame.

    Parameters
    ----------
    model : HandModel
    palm : Frame
        From :func:`person_palm`.
    recording : Recording
        Holds the hand sensor (``hand``) for every frame.
    points : ndarray, shape (n, k, 3)
        Tracker coordinates (mm), frame ``i`` of the recording.

    Returns
    -------
    ndarray, shape (n, k, 3)
        Palm-frame coordinates (mm): ``R_palm^T (R_h0 R_h(t)^T (p - t_h(t)) + t_h0 - o)``.
    """
    hand = recording.pose(HAND_SENSOR)
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = np.einsum("nji,nkj->nki", hand.rotation, points - hand.position[:, None, :])
    ref = local @ r0.T + (p0 - palm.origin)
    return ref @ palm.rotation


def robot_palm(robot: Robot, rmap: RobotMap, q: FloatArray) -> Frame:
    """The robot's palm frame (robot world coordinates, m) at configuration ``q (nq,)``."""
    o, r = robot.pose(q, rmap.palm)
    x = rmap.distal
    z = _unit(_across(rmap.dorsal, x))
    return Frame(
        o, r @ np.column_stack([x, np.cross(z, x), z]), f"map: '{rmap.palm}' distal, dorsal"
    )


def robot_digit(
    robot: Robot, rmap: RobotMap, palm: Frame, q: FloatArray, digit: str
) -> tuple[FloatArray, float]:
    """A robot digit's base anchor ``(3,)`` (robot palm frame, m) and chain length (m).

    The chain runs from the map's ``base`` joint through the anchors of the joints between
    it and the tip frame (coincident anchors counted once) to the tip, at ``q (nq,)``.
    """
    dm = rmap.digits[digit]
    chain = robot.ancestors(dm.tip)
    base = robot.joint_names.index(dm.base)
    if base not in chain:
        raise FingerfitError(
            f"joint '{dm.base}' does not move the tip frame '{dm.tip}'",
            path=rmap.path,
            field=f"digits.{digit}.base",
        )
    anchors = robot.anchors(q)[chain[chain.index(base) :]]
    tip = robot.positions(q[None], [dm.tip])[0, 0]
    pts = np.vstack([anchors, tip])
    length = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    return (anchors[0] - palm.origin) @ palm.rotation, length
