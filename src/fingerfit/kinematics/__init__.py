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
  two-axis joint ``Q = Rot(b, beta) Rot(a, theta)`` (``b`` the proximal axis, ``a``
  the distal one): ``beta`` turns ``a`` to ``Q a`` about ``b``, and ``theta`` is the
  twist of ``Rot(b, -beta) Q``.

Tip and pad: a product of exponentials at the reference posture. The point is
rotated about each axis of the digit from the distal one to the proximal one
(a finger: DIP, PIP, MP flexion, then the MP ab/adduction of a two-axis model;
the thumb: IP, MCP (ab/adduction, flexion), CMC ab/adduction, CMC flexion --
``docs/conventions.md``), each through its centre (moved by ``theta * migration``
where the model has rolling-contact migration), all in tracker coordinates at the
reference posture, and carried by the hand sensor's motion relative to its
reference pose.

Both run over whole recordings with NumPy; no per-frame Python loop. For a
``swing_twist`` model ``compute_kinematics`` computes the same numbers block by block
in cache (:class:`KinematicsPlan`, which a live stream prepares once; ``docs/performance.md``).
The angle maths of one joint are :mod:`fingerfit.angles`; their names are importable
from here too. Angles rad, lengths mm, tracker coordinates (``docs/conventions.md``).
"""

from ..angles import (
    projection_angle,
    relative_rotation,
    twist_angle,
    two_axis_angles,
    two_axis_projection_angles,
)
from .direct import (
    carry_by_hand,
    chain_points,
    compute_kinematics,
    finger_angles,
    joint_angles,
)
from .plan import BLOCK_FRAMES, KinematicsPlan
from .points import PointChain
from .results import FingerMotion, Kinematics, kinematics_table

__all__ = [
    "BLOCK_FRAMES",
    "FingerMotion",
    "Kinematics",
    "KinematicsPlan",
    "PointChain",
    "carry_by_hand",
    "chain_points",
    "compute_kinematics",
    "finger_angles",
    "joint_angles",
    "kinematics_table",
    "projection_angle",
    "relative_rotation",
    "twist_angle",
    "two_axis_angles",
    "two_axis_projection_angles",
]
