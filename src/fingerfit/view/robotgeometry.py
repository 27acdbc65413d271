"""A robot hand's own geometry for the view: the visual shapes of its MuJoCo (MJCF) or URDF
model, each fixed to a link, and every link's pose per configuration.

The hand: the links from the robot map's palm frame down (a forearm, a wrist, a floor or
a target beside the hand in the same file are left out).

* **MJCF** (MuJoCo, the model :attr:`fingerfit.retarget.Robot.mujoco_model` compiled): the
  bodies below the palm's, and their geoms that MuJoCo's viewer shows by default (groups
  0, 1 and 2: visual geoms; collision geoms are usually group 3 or more) and that are not
  transparent; meshes (the compiled vertices and faces), boxes, spheres, ellipsoids,
  capsules and cylinders; the colour of the geom or of its material.
* **URDF** (Pinocchio, ``pinocchio.buildGeomFromUrdf``, its ``<visual>`` elements;
  ``package://`` paths resolved against the URDF file's parent folders): every visual
  of a link below the palm's joint, fixed to its link (a link joined by a fixed joint is
  its own entity still), with the URDF's colour.

Units and frames: metres, each shape in its link's frame (its pose there given), each
link's pose in the robot's world frame (rotation link -> world). A link's pose for a
batch of configurations is one forward kinematics per configuration (MuJoCo's
``mj_kinematics`` or Pinocchio's ``framesForwardKinematics``, a few microseconds each).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray

#: MuJoCo geom groups its viewer shows by default (the rest: collision geoms, hidden).
VISIBLE_GROUPS = (0, 1, 2)
#: MuJoCo's default geom colour: a geom with a material and this colour takes the material's.
_MUJOCO_DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)


@dataclass
class Visual:
    """One visual shape of a link.

    Attributes
    ----------
    link : int
        Index into :attr:`RobotGeometry.links`.
    name : str
        The geom's or visual's name (an index where it has none).
    translation : ndarray, shape (3,)
        Its origin in the link's frame (m).
    rotation : ndarray, shape (3, 3)
        Its axes in the link's frame (shape -> link).
    kind : {"mesh", "box", "sphere", "ellipsoid", "capsule", "cylinder"}
    size : ndarray, shape (3,)
        m: a box's half sizes; a sphere's or ellipsoid's radii; a capsule's or cylinder's
        radius, half length (along its z) and 0; zeros for a mesh.
    vertices : ndarray, shape (v, 3), optional
        A mesh's vertices (m, shape frame).
    triangles : ndarray, shape (t, 3), optional
        A mesh's triangles (vertex indices, counter-clockwise seen from outside).
    rgba : ndarray, shape (4,)
        Colour, 0-1.
    """

    link: int
    name: str
    translation: FloatArray
    rotation: FloatArray
    kind: str
    size: FloatArray
    rgba: FloatArray
    vertices: FloatArray | None = None
    triangles: np.ndarray | None = None


class RobotGeometry:
    """A robot hand's links and their visual shapes (module docstring).

    Attributes
    ----------
    links : list of str
        The links (MJCF bodies, URDF links) that carry a shape.
    visuals : list of Visual
    """

    def __init__(self, links: list[str], visuals: list[Visual], poser: Any) -> None:
        self.links = links
        self.visuals = visuals
        self._poser = poser

    def link_poses(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Every link's pose for a batch of configurations.

        Parameters
        ----------
        q : ndarray, shape (n, nq)
            Joint values (rad; m for a slide joint), the robot's configuration order.

        Returns
        -------
        translation : ndarray, shape (n, L, 3)
            Link origins (m, robot world frame).
        rotation : ndarray, shape (n, L, 3, 3)
            Link axes (link -> world).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n, k = q.shape[0], len(self.links)
        pos, rot = np.empty((n, k, 3)), np.empty((n, k, 3, 3))
        for i in range(n):
            pos[i], rot[i] = self._poser(q[i])
        return pos, rot


def robot_geometry(robot, palm: str) -> RobotGeometry:
    """The visual geometry of a loaded robot's hand (:func:`fingerfit.retarget.resolve`).

    Parameters
    ----------
    robot : fingerfit.retarget.Robot
        An MJCF (``.xml``) or URDF (``.urdf``) robot.
    palm : str
        The robot map's palm frame: the links from it down are drawn.

    Returns
    -------
    RobotGeometry
        Possibly without a shape (a robot file without visual geometry).

    Raises
    ------
    FingerfitError
        A URDF whose visual meshes cannot be loaded, or whose joints are not the robot's.
    """
    if robot.mujoco_model is not None:
        return _mujoco_geometry(robot.mujoco_model, palm)
    return _urdf_geometry(Path(robot.path), tuple(robot.joint_names), palm)


def _mujoco_geometry(m, palm: str) -> RobotGeometry:
    import mujoco

    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, palm)
    top = (
        int(m.site_bodyid[site])
        if site >= 0
        else mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, palm)
    )

    def below(b: int) -> bool:
        while b > 0 and b != top:
            b = int(m.body_parentid[b])
        return b == top

    bodies = [b for b in range(1, m.nbody) if below(b)]
    shapes = {
        int(mujoco.mjtGeom.mjGEOM_MESH): "mesh",
        int(mujoco.mjtGeom.mjGEOM_BOX): "box",
        int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
        int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
        int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
        int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    }
    index = {b: i for i, b in enumerate(bodies)}
    visuals, used = [], []
    for g in range(m.ngeom):
        b, kind = int(m.geom_bodyid[g]), shapes.get(int(m.geom_type[g]))
        rgba = np.array(m.geom_rgba[g], dtype=float)
        mat = int(m.geom_matid[g])
        if mat >= 0 and np.allclose(rgba, _MUJOCO_DEFAULT_RGBA):
            rgba = np.array(m.mat_rgba[mat], dtype=float)
        if b not in index or kind is None or int(m.geom_group[g]) not in VISIBLE_GROUPS:
            continue
        if rgba[3] <= 0:
            continue
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, np.asarray(m.geom_quat[g], dtype=float))
        size = np.array(m.geom_size[g], dtype=float)
        verts = tris = None
        if kind == "mesh":
            mesh = int(m.geom_dataid[g])
            v0, nv = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
            f0, nf = int(m.mesh_faceadr[mesh]), int(m.mesh_facenum[mesh])
            verts = np.array(m.mesh_vert[v0 : v0 + nv], dtype=float)
            tris = np.array(m.mesh_face[f0 : f0 + nf], dtype=np.int64)
            size = np.zeros(3)
        elif kind in ("capsule", "cylinder"):
            size = np.array([size[0], size[1], 0.0])
        elif kind == "sphere":
            size = np.full(3, size[0])
        name = m.geom(g).name or f"geom{g}"
        visuals.append(
            Visual(
                index[b],
                name,
                np.array(m.geom_pos[g]),
                rot.reshape(3, 3),
                kind,
                size,
                rgba,
                verts,
                tris,
            )
        )
        used.append(b)
    keep = sorted(set(used))
    renumber = {index[b]: i for i, b in enumerate(keep)}
    for v in visuals:
        v.link = renumber[v.link]
    data = mujoco.MjData(m)
    ids = np.array(keep, dtype=int)

    def poses(q: FloatArray) -> tuple[FloatArray, FloatArray]:
        data.qpos[:] = q
        mujoco.mj_kinematics(m, data)
        return data.xpos[ids], data.xmat[ids].reshape(-1, 3, 3)

    return RobotGeometry([m.body(b).name for b in keep], visuals, poses)


def _urdf_geometry(path: Path, joint_names: tuple[str, ...], palm: str) -> RobotGeometry:
    from ..retarget.robots import require

    pin = require("pinocchio")
    model = pin.buildModelFromUrdf(str(path))
    order = sorted(range(1, model.njoints), key=lambda j: model.joints[j].idx_q)
    if tuple(model.names[j] for j in order) != joint_names:
        raise FingerfitError("its joints are not those of the robot loaded", path=path)
    top = int(model.frames[model.getFrameId(palm)].parentJoint)

    def below(j: int) -> bool:
        while j > 0 and j != top:
            j = int(model.parents[j])
        return j == top

    try:  # package:// paths: a folder above the URDF holds the package
        geom = pin.buildGeomFromUrdf(
            model, str(path), pin.GeometryType.VISUAL, package_dirs=[str(p) for p in path.parents]
        )
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise FingerfitError(f"cannot load its visual geometry: {first}", path=path) from None
    frames: list[int] = []
    visuals = []
    for i, obj in enumerate(geom.geometryObjects):
        shape = _coal_shape(obj.geometry)
        if shape is None or not below(int(obj.parentJoint)):
            continue
        f = int(obj.parentFrame)
        if f not in frames:
            frames.append(f)
        # the visual's placement is given in its joint's frame; its link's frame sits there too
        local = model.frames[f].placement.inverse() * obj.placement
        kind, size, verts, tris = shape
        if verts is not None:
            verts = verts * np.asarray(obj.meshScale, dtype=float)
        rgba = np.asarray(obj.meshColor, dtype=float)
        visuals.append(
            Visual(
                frames.index(f),
                obj.name or f"visual{i}",
                np.array(local.translation),
                np.array(local.rotation),
                kind,
                size,
                rgba,
                verts,
                tris,
            )
        )
    data = model.createData()

    def poses(q: FloatArray) -> tuple[FloatArray, FloatArray]:
        pin.framesForwardKinematics(model, data, q)
        placed = [data.oMf[f] for f in frames]
        return (
            np.array([p.translation for p in placed]).reshape(-1, 3),
            np.array([p.rotation for p in placed]).reshape(-1, 3, 3),
        )

    return RobotGeometry([model.frames[f].name for f in frames], visuals, poses)


def _coal_shape(g) -> tuple[str, FloatArray, FloatArray | None, np.ndarray | None] | None:
    """``(kind, size, vertices, triangles)`` of a Coal collision shape, or None for a
    shape the view does not draw (a plane, a height field, an octree)."""
    name = type(g).__name__
    if name.startswith("BVHModel"):
        verts = np.asarray(g.vertices(), dtype=float)
        tris = np.array(
            [[t[0], t[1], t[2]] for t in (g.tri_indices(i) for i in range(g.num_tris))],
            dtype=np.int64,
        ).reshape(-1, 3)
        return "mesh", np.zeros(3), verts, tris
    if name == "Box":
        return "box", np.asarray(g.halfSide, dtype=float), None, None
    if name == "Sphere":
        return "sphere", np.full(3, float(g.radius)), None, None
    if name == "Ellipsoid":
        return "ellipsoid", np.asarray(g.radii, dtype=float), None, None
    if name in ("Capsule", "Cylinder"):
        size = np.array([float(g.radius), float(g.halfLength), 0.0])
        return name.lower(), size, None, None
    return None


def vertex_normals(vertices: FloatArray, triangles: np.ndarray) -> FloatArray:
    """Unit normals ``(v, 3)`` of a mesh's vertices: the area-weighted mean of the normals
    of the triangles that share each (a vertex in no triangle: z)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # length: twice the triangle's area
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, triangles[:, k], face)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    unit = np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)
    unit[norm[:, 0] == 0] = (0.0, 0.0, 1.0)
    return unit
