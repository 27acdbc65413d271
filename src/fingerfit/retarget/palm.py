"""Palm frames of the person and the robot, digit anchors and per-digit scales.

**Person's palm frame** (fixed to the hand sensor, defined at the reference posture, the
stretched hand): ``y`` = the mean MP flexion axis of the fingers (radial for a right hand,
ulnar for a left one, ``docs/conventions.md``), ``x`` (distal) = the mean fingertip-minus-MP
direction made perpendicular to ``y``, ``z = x × y`` (dorsal); origin = the mean MP centre.
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

from ..errors import FingerfitError
from ..model import HandModel
from ..session import HAND_SENSOR, Recording
from ..transforms import FloatArray
from .maps import RobotMap
from .robots import Robot


@dataclass(frozen=True)
class Frame:
    """A palm frame: ``origin (3,)`` and ``rotation (3, 3)`` (columns x distal, y, z dorsal)."""

    origin: FloatArray
    rotation: FloatArray


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v)


def person_palm(model: HandModel) -> Frame:
    """The person's palm frame at the reference posture (tracker coordinates, mm).

    Raises
    ------
    FingerfitError
        When the model has no finger (a digit with an ``mp`` joint).
    """
    fingers = [f for f in model.fingers.values() if "mp" in f.joints]
    if not fingers:
        raise FingerfitError("the model has no finger with an MP joint to define the palm frame")
    y = _unit(np.mean([f.joints["mp"].axis for f in fingers], axis=0))
    centres = np.array([f.joints["mp"].center for f in fingers])
    distal = np.mean([_unit(f.tip - f.joints["mp"].center) for f in fingers], axis=0)
    x = _unit(distal - (distal @ y) * y)
    z = np.cross(x, y)
    return Frame(centres.mean(axis=0), np.column_stack([x, y, z]))


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
    z = _unit(rmap.dorsal - (rmap.dorsal @ x) * x)
    return Frame(o, r @ np.column_stack([x, np.cross(z, x), z]))


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
