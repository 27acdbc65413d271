"""MuJoCo MJCF export of a hand model (via ``mujoco.MjSpec``), metres and radians.

The body tree mirrors the URDF (:mod:`.urdf`): body ``hand`` (the hand sensor
frame at the reference posture) fixed to the world, one body per phalanx with a
hinge joint at its origin, and a **site** ``<finger>_tip`` at the fingertip
(a site, not a body, so MuJoCo never fuses it away).

Pitfalls handled (see ``docs/export.md``):

* MJCF angles default to degrees: the compiler is set to ``angle="radian"``.
* Every moving body has an explicit inertial (mass, centre of mass, full inertia
  tensor); MuJoCo rejects massless moving bodies and would otherwise infer
  inertia from geoms.
* ``MjSpec.to_xml`` writes numbers with 6 significant digits (about 1e-7 m of
  fingertip error on fitted models, more far from the hand sensor); body
  positions, joint axes and ranges, sites, inertials and capsule end points are
  rewritten with round-trip precision.
* MuJoCo quaternions are ``(w, x, y, z)``; none is needed, since every body frame
  is parallel to the hand frame (no body ``quat``) and capsules are given by
  ``fromto``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..extras import require
from ..model import HandModel
from .files import write_text
from .geometry import DEFAULT_MARGIN_DEG, HAND_LINK, RobotHand, robot_hand

FINGER_RGBA = (0.87, 0.72, 0.62, 1.0)
TIMESTEP_S = 1e-3


def _num(values) -> str:
    """Numbers with round-trip precision, space separated."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _full_inertia(i: np.ndarray) -> list[float]:
    """MuJoCo ``fullinertia`` order: ixx iyy izz ixy ixz iyz (URDF: ixx ixy ixz iyy iyz izz)."""
    return [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]


def _build_spec(hand: RobotHand, mujoco):
    spec = mujoco.MjSpec()
    spec.modelname = hand.name
    spec.compiler.degree = False  # MJCF's default is degrees
    spec.compiler.fusestatic = False
    spec.compiler.autolimits = True
    spec.option.timestep = TIMESTEP_S
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    bodies = {HAND_LINK: spec.worldbody.add_body(name=HAND_LINK)}
    for j, link in hand.chain():
        body = bodies[j.parent].add_body(name=link.name, pos=j.origin.tolist())
        bodies[link.name] = body
        body.explicitinertial = True
        body.mass = link.mass
        body.ipos = link.com.tolist()
        body.fullinertia = _full_inertia(link.inertia)
        body.add_joint(
            name=j.name,
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=j.axis.tolist(),
            range=[j.lower, j.upper],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            damping=j.damping,
        )
        if link.capsule is not None:
            body.add_geom(
                name=link.name,
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                fromto=np.concatenate(link.capsule).tolist(),
                size=[link.radius, 0.0, 0.0],
                rgba=list(FINGER_RGBA),
            )
    for finger in hand.fingers:
        bodies[finger.links[-1].name].add_site(
            name=finger.tip_name, pos=finger.tip.tolist(), size=[0.002, 0.0, 0.0]
        )
    return spec


def _restore_precision(xml: str, hand: RobotHand, comment: str) -> str:
    """Rewrite every kinematic and inertial number of ``to_xml`` with full precision."""
    root = ET.fromstring(xml)
    bodies = {b.get("name"): b for b in root.iter("body")}
    for j, link in hand.chain():
        body = bodies[link.name]
        body.set("pos", _num(j.origin))
        inertial = body.find("inertial")
        inertial.attrib.clear()
        inertial.attrib.update(
            pos=_num(link.com),
            mass=_num([link.mass]),
            fullinertia=_num(_full_inertia(link.inertia)),
        )
        joint = body.find("joint")
        joint.set("axis", _num(j.axis))
        joint.set("range", _num([j.lower, j.upper]))
        geom = body.find("geom")
        if geom is not None:
            for key in ("pos", "quat", "size"):
                geom.attrib.pop(key, None)
            geom.set("fromto", _num(np.concatenate(link.capsule)))
            geom.set("size", _num([link.radius]))
    for finger in hand.fingers:
        site = next(s for s in bodies[finger.links[-1].name].iter("site"))
        site.set("pos", _num(finger.tip))
    root.insert(0, ET.Comment(comment))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def mjcf_string(
    model: HandModel, variant: str = "user_axis", margin_deg: float = DEFAULT_MARGIN_DEG
) -> str:
    """The MJCF document of a hand model.

    Parameters
    ----------
    model : HandModel
        Tracker coordinates at the reference posture (mm).
    variant : {"user_axis", "orthogonal"}
        Fitted flexion axes, or the axes made perpendicular to the bones.
    margin_deg : float
        Joint-limit margin (deg), see :func:`fingerfit.export.geometry.joint_limits`.

    Returns
    -------
    str
        MJCF XML with ``<compiler angle="radian">``: metres, radians, kg; body
        ``hand`` = hand sensor frame at the reference posture, at the world origin.
        No body carries a quaternion (MuJoCo order would be ``w, x, y, z``).
        The string is checked to compile with MuJoCo.

    Raises
    ------
    FingerfitError
        Unknown variant or bad model (see :func:`~fingerfit.export.geometry.robot_hand`),
        or mujoco missing (``pip install fingerfit[robot]``).
    """
    mujoco = require("mujoco", "robot", "robot export")
    hand = robot_hand(model, variant, margin_deg)
    spec = _build_spec(hand, mujoco)
    spec.compile()
    comment = (
        f" fingerfit {model.version}: subject {model.subject}, {model.hand} hand, "
        f"variant {hand.variant}, joint-limit margin {hand.margin_deg:g} deg. "
        "Metres, radians, kg; body 'hand' = hand sensor frame at the reference posture. "
    )
    xml = _restore_precision(spec.to_xml(), hand, comment)
    mujoco.MjModel.from_xml_string(xml)  # the rewritten file must still compile
    return xml


def write_mjcf(
    model: HandModel,
    path: str | Path,
    variant: str = "user_axis",
    margin_deg: float = DEFAULT_MARGIN_DEG,
) -> Path:
    """Write the MJCF of a model atomically (see :func:`mjcf_string`).

    Parameters
    ----------
    model : HandModel
        Tracker coordinates at the reference posture (mm).
    path : str or Path
        Output file; metres, radians and kg inside.
    variant : {"user_axis", "orthogonal"}
    margin_deg : float
        Joint-limit margin (deg).

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        As :func:`mjcf_string`, or when ``path`` cannot be written (no file is left behind).
    """
    return write_text({Path(path): mjcf_string(model, variant, margin_deg)})[0]
