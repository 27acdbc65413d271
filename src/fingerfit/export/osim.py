"""OpenSim export of a hand model (``.osim``, OpenSim 4 document), metres and radians.

The model a biomechanics lab opens in OpenSim, built from the chain description of
:mod:`.geometry` that the URDF and MJCF writers read too:

* **ground** is the tracker frame (m). Its vertical is unknown to fingerfit, so gravity
  is 0 (set ``<gravity>`` to your tracker's down for a forward simulation).
* **hand**: the hand sensor's frame, on the 6-DOF joint ``ground_hand`` whose parent
  frame is the hand's reference orientation. Its coordinates: ``hand_rx``, ``hand_ry``,
  ``hand_rz`` (rad), the hand's rotation from its reference orientation as body-fixed
  X-Y-Z angles about the reference hand-sensor axes, ``R_hand = R_h0 Rx Ry Rz``
  (:func:`hand_coordinates`; singular only 90 deg about y away from the reference), and
  ``hand_tx``, ``hand_ty``, ``hand_tz`` (m), the hand sensor's origin in the tracker
  frame. Default values: the reference posture.
* One body per phalanx (and the thumb's metacarpal), named like the URDF links, its frame
  parallel to the hand's with the origin at the centre of the joint that moves it; one
  ``CustomJoint`` per axis, its coordinate named like the URDF joint (``index_mp``,
  ``thumb_cmc_abduction``, ...) turning about the fitted (tilted) axis through that
  centre. A two-axis joint's axes do not meet: between them sits a massless body
  ``<digit>_<axis>_link``.
* Coordinate ranges: the calibration's range of motion widened by the margin
  (:func:`~.geometry.joint_limits`), not clamped (IK follows a recording beyond them).
* Masses: the capsules of :mod:`.geometry` (density 1100 kg/m^3), the palm by
  :func:`~.geometry.palm_link`.
* Each sensor is a ``PhysicalOffsetFrame`` ``<segment>_imu`` (:func:`~fingerfit.io.opensim.frame_name`)
  on its body at its reference pose; each also has a marker of that name at its origin.
  Markers ``<digit>_tip`` and ``<digit>_pad`` sit on the distal body; the session's
  stylus landmarks, when given (:func:`landmark_markers`), are markers too.

No element needs a quaternion: frame orientations are OpenSim's body-fixed X-Y-Z angles
(rad). Numbers are written with round-trip precision. See ``docs/export.md``, *OpenSim*.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..io.opensim import frame_name
from ..model import HandModel
from ..session import HAND_SENSOR
from ..transforms import FloatArray, orthonormal_basis
from .files import write_text
from .geometry import (
    DEFAULT_MARGIN_DEG,
    HAND_LINK,
    RobotHand,
    RobotLink,
    robot_hand,
    to_hand_frame,
)

#: OpenSim document version written (OpenSim 4.6).
DOCUMENT_VERSION = "40600"
#: The hand's six coordinates: rotations (rad) then translations (m).
HAND_COORDINATES = ("hand_rx", "hand_ry", "hand_rz", "hand_tx", "hand_ty", "hand_tz")
#: Range of the hand's translations (m, each way) and rotations (rad).
HAND_REACH_M = 10.0
HAND_TURN_RAD = float(np.pi)
BONE_RGB = (0.87, 0.72, 0.62)


def _num(values) -> str:
    """Numbers with round-trip precision, space separated."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _angles(rotation: FloatArray) -> FloatArray:
    """OpenSim's frame orientation: body-fixed X-Y-Z angles (rad) of a rotation ``(3, 3)``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # gimbal lock: still the same rotation
        return Rotation.from_matrix(rotation).as_euler("XYZ")


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _offset_frame(
    parent: ET.Element, name: str, of: str, translation: FloatArray, rotation: FloatArray
) -> ET.Element:
    frame = _sub(parent, "PhysicalOffsetFrame", name=name)
    _sub(frame, "socket_parent", of)
    _sub(frame, "translation", _num(translation))
    _sub(frame, "orientation", _num(_angles(rotation)))
    return frame


def _inertial(body: ET.Element, link: RobotLink, massless: bool = False) -> None:
    i = link.inertia
    _sub(body, "mass", _num([0.0 if massless else link.mass]))
    _sub(body, "mass_center", _num(np.zeros(3) if massless else link.com))
    six = np.zeros(6) if massless else [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
    _sub(body, "inertia", _num(six))


def _bone(components: ET.Element, link: RobotLink) -> None:
    """The capsule's cylinder (its axis along the bone: OpenSim cylinders run along y)."""
    start, end = link.capsule
    e1, e2, d = orthonormal_basis(end - start)  # right-handed, d along the bone
    frame = _offset_frame(
        components, f"{link.name}_bone", "..", (start + end) / 2, np.column_stack([e2, d, e1])
    )
    geometry = _sub(frame, "attached_geometry")
    cylinder = _sub(geometry, "Cylinder", name=f"{link.name}_capsule")
    _sub(cylinder, "socket_frame", "..")
    _sub(_sub(cylinder, "Appearance"), "color", _num(BONE_RGB))
    _sub(cylinder, "radius", _num([link.radius]))
    _sub(cylinder, "half_height", _num([np.linalg.norm(end - start) / 2]))


def _coordinate(parent: ET.Element, name: str, lo: float, hi: float, default: float = 0.0) -> None:
    c = _sub(parent, "Coordinate", name=name)
    _sub(c, "default_value", _num([default]))
    _sub(c, "range", _num([lo, hi]))
    _sub(c, "clamped", "false")
    _sub(c, "locked", "false")


def _transform(
    joint: ET.Element,
    rotations: list[tuple[FloatArray, str | None]],
    translations: list[tuple[FloatArray, str | None]],
) -> None:
    """A ``SpatialTransform``: three rotation then three translation axes, each driven by
    its coordinate (``LinearFunction`` 1, 0) or held at 0 (``Constant``)."""
    st = _sub(joint, "SpatialTransform")
    for kind, axes in (("rotation", rotations), ("translation", translations)):
        for k, (axis, coordinate) in enumerate(axes, start=1):
            ta = _sub(st, "TransformAxis", name=f"{kind}{k}")
            _sub(ta, "coordinates", coordinate or "")
            _sub(ta, "axis", _num(axis))
            if coordinate is None:
                _sub(_sub(ta, "Constant", name="function"), "value", "0")
            else:
                _sub(_sub(ta, "LinearFunction", name="function"), "coefficients", "1 0")


def _path(link: str) -> str:
    """A body's path in the model (``ground`` is no body)."""
    return "/ground" if link == "ground" else f"/bodyset/{link}"


def hand_coordinates(model: HandModel, rotation: FloatArray, position: FloatArray) -> FloatArray:
    """The values of the hand's six coordinates for hand sensor poses.

    Parameters
    ----------
    model : HandModel
        Its hand sensor's reference pose ``(t_h0 mm, R_h0)``.
    rotation : ndarray, shape (n, 3, 3)
        Hand sensor -> tracker.
    position : ndarray, shape (n, 3)
        Hand sensor origin, tracker frame (mm).

    Returns
    -------
    ndarray, shape (n, 6)
        ``hand_rx, hand_ry, hand_rz`` (rad): body-fixed X-Y-Z angles of ``R_h0^T R``;
        ``hand_tx, hand_ty, hand_tz`` (m): ``position / 1000``. NaN rows where the pose is
        missing.
    """
    rotation = np.asarray(rotation, dtype=float).reshape(-1, 3, 3)
    out = np.full((rotation.shape[0], 6), np.nan)
    ok = np.isfinite(rotation).all(axis=(1, 2)) & np.isfinite(position).all(axis=1)
    r0 = np.asarray(model.reference_poses[HAND_SENSOR][1], dtype=float)
    if ok.any():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            out[ok, :3] = Rotation.from_matrix(r0.T @ rotation[ok]).as_euler("XYZ")
        out[ok, 3:] = np.asarray(position, dtype=float)[ok] / 1000.0
    return out


def landmark_markers(
    model: HandModel, hand: RobotHand, landmarks: dict[str, FloatArray]
) -> tuple[list[tuple[str, str, FloatArray]], list[str]]:
    """The session's landmarks as markers of the exported model.

    Parameters
    ----------
    model : HandModel
    hand : RobotHand
        Its chain description.
    landmarks : dict[str, ndarray]
        Name -> position ``(3,)``, tracker coordinates at the reference posture (mm), as
        :func:`fingerfit.io.read_landmarks` gives them.

    Returns
    -------
    markers : list of (name, body, location)
        A dorsal joint landmark ``<digit>.<joint>`` becomes ``<digit>_<joint>_dorsal`` on
        the joint's parent segment (the bone whose head it lies over: the hand for the MP
        and the CMC); a target ``target.<label>`` becomes ``target_<label>`` on ground;
        ``location`` in the body's frame (m).
    skipped : list of str
        Landmarks not made markers: ``<digit>.tip`` and ``<digit>.pad`` (the model's
        ``<digit>_tip`` and ``<digit>_pad`` are those points), and those of digits the
        model does not have.
    """
    origins = {HAND_LINK: np.zeros(3), **{j.child: j.centre for j, _ in hand.chain()}}
    parent = {j.name: j.parent for j, _ in hand.chain()}
    markers, skipped = [], []
    for name, p in landmarks.items():
        head, _, tail = name.partition(".")
        if head == "target":
            markers.append((f"target_{tail}", "ground", np.asarray(p, dtype=float) / 1000.0))
            continue
        fm = model.fingers.get(head)
        if fm is None or tail not in fm.joints:
            skipped.append(name)
            continue
        # the first axis of the joint: its parent is the segment before the joint
        link = parent[f"{head}_{fm.axes(tail)[0].name}"]
        location = to_hand_frame(model, p) - origins[link]
        markers.append((f"{head}_{tail}_dorsal", link, location))
    return markers, skipped


def _model_element(
    model: HandModel, hand: RobotHand, landmarks: list[tuple[str, str, FloatArray]]
) -> ET.Element:
    t0, r0 = (np.asarray(v, dtype=float) for v in model.reference_poses[HAND_SENSOR])
    doc = ET.Element("OpenSimDocument", Version=DOCUMENT_VERSION)
    m = _sub(doc, "Model", name=hand.name)
    _sub(
        m,
        "credits",
        f"fingerfit {model.version}: subject {model.subject}, {model.hand} hand, method "
        f"{model.method}, variant {hand.variant}, joint-limit margin {hand.margin_deg:g} deg",
    )
    _sub(m, "length_units", "meters")
    _sub(m, "force_units", "N")
    _sub(m, "gravity", "0 0 0")
    _sub(m, "Ground", name="ground")

    bodies = _sub(_sub(m, "BodySet", name="bodyset"), "objects")
    components: dict[str, ET.Element] = {}
    for link, massless in [(hand.palm, False)] + [
        (link, link.capsule is None) for _, link in hand.chain()
    ]:
        body = _sub(bodies, "Body", name=link.name)
        components[link.name] = _sub(body, "components")
        _inertial(body, link, massless)
        if link.capsule is not None:
            _bone(components[link.name], link)
    for sensor in hand.sensors:
        _offset_frame(
            components[sensor.link], frame_name(sensor.name), "..", sensor.position, sensor.rotation
        )

    joints = _sub(_sub(m, "JointSet", name="jointset"), "objects")
    ground = _sub(joints, "CustomJoint", name="ground_hand")
    _sub(ground, "socket_parent_frame", "ground_offset")
    _sub(ground, "socket_child_frame", _path(HAND_LINK))
    coords = _sub(ground, "coordinates")
    for name in HAND_COORDINATES[:3]:
        _coordinate(coords, name, -HAND_TURN_RAD, HAND_TURN_RAD)
    for name, value in zip(HAND_COORDINATES[3:], t0 / 1000.0, strict=True):
        _coordinate(coords, name, -HAND_REACH_M, HAND_REACH_M, float(value))
    _offset_frame(_sub(ground, "frames"), "ground_offset", "/ground", np.zeros(3), r0)
    names = iter(HAND_COORDINATES)
    _transform(
        ground,
        [(e, next(names)) for e in np.eye(3)],
        [(r0.T[:, k], next(names)) for k in range(3)],  # tracker axes, in the parent frame
    )
    for j, _ in hand.chain():
        joint = _sub(joints, "CustomJoint", name=j.name)
        _sub(joint, "socket_parent_frame", f"{j.parent}_offset")
        _sub(joint, "socket_child_frame", _path(j.child))
        _coordinate(_sub(joint, "coordinates"), j.name, j.lower, j.upper)
        _offset_frame(
            _sub(joint, "frames"), f"{j.parent}_offset", _path(j.parent), j.origin, np.eye(3)
        )
        e1, e2, _ = orthonormal_basis(j.axis)  # the two unused axes: any independent ones
        _transform(
            joint, [(j.axis, j.name), (e1, None), (e2, None)], [(e, None) for e in np.eye(3)]
        )

    markers = _sub(_sub(m, "MarkerSet", name="markerset"), "objects")

    def marker(name: str, link: str, location: FloatArray) -> None:
        el = _sub(markers, "Marker", name=name)
        _sub(el, "socket_parent_frame", _path(link))
        _sub(el, "location", _num(location))

    for finger in hand.fingers:
        distal = finger.links[-1].name
        marker(finger.tip_name, distal, finger.tip)
        if finger.pad is not None:
            marker(finger.pad_name, distal, finger.pad)
    for sensor in hand.sensors:
        marker(frame_name(sensor.name), sensor.link, sensor.position)
    for name, link, location in landmarks:
        marker(name, link, location)
    return doc


def osim_string(
    model: HandModel,
    variant: str = "user_axis",
    margin_deg: float = DEFAULT_MARGIN_DEG,
    landmarks: dict[str, FloatArray] | None = None,
) -> str:
    """The OpenSim model document of a hand model.

    Parameters
    ----------
    model : HandModel
        Tracker coordinates at the reference posture (mm).
    variant : {"user_axis", "orthogonal"}
        Fitted flexion axes, or the axes made perpendicular to the bones.
    margin_deg : float
        Joint-limit margin (deg), see :func:`fingerfit.export.geometry.joint_limits`.
    landmarks : dict[str, ndarray], optional
        The session's stylus landmarks (tracker coordinates at the reference posture, mm),
        made markers by :func:`landmark_markers`.

    Returns
    -------
    str
        The ``.osim`` XML (OpenSim 4.6 document): metres, radians, kg; ground = the
        tracker frame; the hand on a 6-DOF joint (:func:`hand_coordinates`).

    Raises
    ------
    FingerfitError
        Unknown variant or bad model (see :func:`~fingerfit.export.geometry.robot_hand`).
    """
    hand = robot_hand(model, variant, margin_deg)
    markers = landmark_markers(model, hand, landmarks or {})[0]
    doc = _model_element(model, hand, markers)
    doc.insert(
        0,
        ET.Comment(
            f" fingerfit {model.version}: subject {model.subject}, {model.hand} hand. "
            "Metres, radians, kg. Ground = the tracker frame (gravity 0: its vertical is "
            "not known); body 'hand' = the hand sensor frame; sensors = frames <segment>_imu. "
        ),
    )
    ET.indent(doc, space="\t")
    return '<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(doc, encoding="unicode") + "\n"


def write_osim(
    model: HandModel,
    path: str | Path,
    variant: str = "user_axis",
    margin_deg: float = DEFAULT_MARGIN_DEG,
    landmarks: dict[str, FloatArray] | None = None,
) -> Path:
    """Write the OpenSim model of a hand model atomically (see :func:`osim_string`).

    Parameters
    ----------
    model : HandModel
    path : str or Path
        Output ``.osim`` file.
    variant : {"user_axis", "orthogonal"}
    margin_deg : float
        Joint-limit margin (deg).
    landmarks : dict[str, ndarray], optional
        Stylus landmarks (mm, tracker, reference posture) to add as markers.

    Returns
    -------
    Path

    Raises
    ------
    FingerfitError
        As :func:`osim_string`, or when ``path`` cannot be written (no file is left behind).
    """
    return write_text({Path(path): osim_string(model, variant, margin_deg, landmarks)})[0]
