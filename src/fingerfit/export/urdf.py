"""URDF export of a hand model (via yourdfpy), lengths in metres, angles in radians.

The root link ``hand`` is the hand sensor frame at the reference posture. Each
finger is a chain of revolute joints ``<finger>_mp_abduction`` (two-axis models),
``<finger>_mp``, ``<finger>_pip``, ``<finger>_dip`` with the fitted centres and
(tilted) axes, and a fixed link ``<finger>_tip`` at the fingertip. Link frames are
parallel to the hand frame at the reference posture (see :mod:`.geometry`), so
every joint origin has ``rpy = 0``.

The file also carries a ``<mujoco>`` extension element (ignored by other URDF
readers) so that MuJoCo keeps the fixed ``hand`` and ``<finger>_tip`` links
instead of fusing them into their parents.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..extras import require
from ..model import HandModel
from ..transforms import orthonormal_basis
from .files import write_text
from .geometry import (
    DEFAULT_MARGIN_DEG,
    EFFORT_NM,
    HAND_LINK,
    VELOCITY_RAD_S,
    RobotLink,
    robot_hand,
)

FINGER_RGBA = (0.87, 0.72, 0.62, 1.0)


def _pose(translation: np.ndarray, rotation: np.ndarray | None = None) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = translation
    if rotation is not None:
        t[:3, :3] = rotation
    return t


def _z_to(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix whose z column is the unit vector ``direction``."""
    return orthonormal_basis(direction).T


def _capsule_shapes(ydf, link: RobotLink) -> list[tuple[np.ndarray, object]]:
    """URDF has no capsule: a cylinder along the bone plus a sphere at each end."""
    if link.capsule is None:
        return []
    start, end = link.capsule
    d = end - start
    cyl = ydf.Geometry(cylinder=ydf.Cylinder(radius=link.radius, length=float(np.linalg.norm(d))))
    sphere = ydf.Geometry(sphere=ydf.Sphere(radius=link.radius))
    return [
        (_pose((start + end) / 2, _z_to(d)), cyl),
        (_pose(start), sphere),
        (_pose(end), sphere),
    ]


def _link(ydf, link: RobotLink):
    """A moving link: its inertial and capsule (visual and collision)."""
    shapes = _capsule_shapes(ydf, link)
    return ydf.Link(
        name=link.name,
        inertial=ydf.Inertial(origin=_pose(link.com), mass=link.mass, inertia=link.inertia),
        visuals=[
            ydf.Visual(origin=o, geometry=g, material=ydf.Material(name="finger"))
            for o, g in shapes
        ],
        collisions=[
            ydf.Collision(name=f"{link.name}_{i}", origin=o, geometry=g)
            for i, (o, g) in enumerate(shapes)
        ],
    )


def urdf_string(
    model: HandModel, variant: str = "user_axis", margin_deg: float = DEFAULT_MARGIN_DEG
) -> str:
    """The URDF document of a hand model.

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
        URDF XML: metres, radians, kg; root link ``hand`` = hand sensor frame at the
        reference posture. No quaternions appear (URDF uses roll-pitch-yaw; every
        joint origin has ``rpy = 0``).

    Raises
    ------
    FingerfitError
        Unknown variant or bad model (see :func:`~fingerfit.export.geometry.robot_hand`),
        or yourdfpy missing (``pip install fingerfit[robot]``).
    """
    ydf = require("yourdfpy", "robot", "robot export")
    from lxml import etree

    hand = robot_hand(model, variant, margin_deg)
    material = ydf.Material(name="finger", color=ydf.Color(rgba=np.array(FINGER_RGBA)))
    links = [ydf.Link(name=HAND_LINK)]
    joints = []
    for finger in hand.fingers:
        for j, link in finger.chain():
            links.append(_link(ydf, link))
            joints.append(
                ydf.Joint(
                    name=j.name,
                    type="revolute",
                    parent=j.parent,
                    child=j.child,
                    origin=_pose(j.origin),
                    axis=j.axis,
                    limit=ydf.Limit(
                        effort=EFFORT_NM, velocity=VELOCITY_RAD_S, lower=j.lower, upper=j.upper
                    ),
                    dynamics=ydf.Dynamics(damping=j.damping, friction=0.0),
                )
            )
        links.append(ydf.Link(name=finger.tip_name))
        joints.append(
            ydf.Joint(
                name=f"{finger.tip_name}_fixed",
                type="fixed",
                parent=finger.links[-1].name,
                child=finger.tip_name,
                origin=_pose(finger.tip),
            )
        )
    robot = ydf.Robot(name=hand.name, links=links, joints=joints, materials=[material])
    urdf = ydf.URDF(robot=robot, build_scene_graph=False, load_meshes=False)
    root = urdf.write_xml().getroot()
    root.insert(
        0,
        etree.Comment(
            f" fingerfit {model.version}: subject {model.subject}, {model.hand} hand, "
            f"variant {hand.variant}, joint-limit margin {hand.margin_deg:g} deg. "
            "Metres, radians, kg; root link 'hand' = hand sensor frame at the reference posture. "
        ),
    )
    # MuJoCo's URDF importer fuses fixed links into their parents by default.
    mj = etree.SubElement(root, "mujoco")
    etree.SubElement(mj, "compiler", attrib={"fusestatic": "false", "discardvisual": "true"})
    return etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="utf-8").decode()


def write_urdf(
    model: HandModel,
    path: str | Path,
    variant: str = "user_axis",
    margin_deg: float = DEFAULT_MARGIN_DEG,
) -> Path:
    """Write the URDF of a model atomically (see :func:`urdf_string`).

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
        As :func:`urdf_string`, or when ``path`` cannot be written (no file is left behind).
    """
    return write_text({Path(path): urdf_string(model, variant, margin_deg)})[0]
