"""The digit chains of a hand model in robot terms: links, joints, limits, inertials,
the sensors' frames and the points the digits carry.

The one description of the chain that every writer reads (URDF, MJCF, OpenSim, and the
trajectory writers' joint names): the chain is walked here only, so the files cannot
disagree.

Frames and units
----------------
Everything here is expressed in the **hand sensor frame at the reference
posture**, in **metres** (kilograms, radians):

    p_hand = R_h0^T (p_tracker - t_h0) / 1000,

with ``(R_h0, t_h0)`` the hand sensor's reference pose (``R`` sensor -> tracker,
``t`` mm). Every link frame is **parallel to the hand frame** at the reference
posture and has its origin at the centre of the joint that moves it. Hence a
joint's origin in its parent link is the difference of the two joint centres
(no rotation, ``rpy = 0``), its axis is the fitted axis expressed in the hand
frame (the same vector in the parent and child link frames at ``q = 0``), and
the chain ``T(c1) Rot(a1, q1) T(c2 - c1) Rot(a2, q2) ...`` equals the product of
exponentials of :func:`fingerfit.kinematics.chain_points` exactly. A two-axis joint
gets an intermediate link between its two axes, proximal axis first: a finger's MP
ab/adduction then flexion; the thumb's CMC (and a two-axis MCP) flexion then
ab/adduction, with the fitted offset between the two lines kept.

Joint limits
------------
Flexion joints: ``[-margin, max(rom_deg) + margin]``; ab/adduction axes
(``<joint>_abduction``) and the thumb's CMC flexion: ``±(max(rom_deg) + margin)``
(their sign can go either way). ``rom_deg`` is the
per-cycle range of motion recorded in the model's :class:`~fingerfit.model.JointQuality`;
angles are 0 at the reference (stretched) posture and flexion is positive.
Without a recorded range, anatomical defaults (:data:`DEFAULT_RANGE_DEG`) are
used. See ``docs/export.md``.

Masses
------
Each phalanx (and the thumb's metacarpal) is a solid capsule of density :data:`DENSITY`
from its joint centre to the next (the distal one to the tip), its radius a fraction of
the digit's proximal segment length (:data:`RADIUS_FRACTION`). The palm (the hand link,
which only a model with a free hand needs: OpenSim) is the fingers' metacarpals by the
same rule (:func:`palm_link`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..model import VARIANTS, HandModel, JointModel
from ..session import HAND_SENSOR
from ..transforms import FloatArray

HAND_LINK = "hand"
DEFAULT_MARGIN_DEG = 10.0
#: Ranges (deg) used when a joint has no recorded range of motion.
DEFAULT_RANGE_DEG = {
    "mp_abduction": (-30.0, 30.0),
    "mp": (-30.0, 90.0),
    "pip": (-10.0, 110.0),
    "dip": (-20.0, 90.0),
    "cmc": (-40.0, 40.0),
    "cmc_abduction": (-40.0, 40.0),
    "mcp": (-20.0, 70.0),
    "mcp_abduction": (-20.0, 20.0),
    "ip": (-20.0, 90.0),
}
#: Joints whose angle can go either way from the reference posture (symmetric limits).
SYMMETRIC = ("mp_abduction", "cmc", "cmc_abduction", "mcp_abduction")
#: Soft tissue and bone, kg/m^3.
DENSITY = 1100.0
#: Capsule radius of each segment as a fraction of the proximal segment length.
RADIUS_FRACTION = {"metacarpal": 0.2, "proximal": 0.17, "middle": 0.15, "distal": 0.13}
#: Viscous joint damping, N m s/rad.
DAMPING = {
    "mp_abduction": 0.005,
    "mp": 0.005,
    "pip": 0.003,
    "dip": 0.002,
    "cmc": 0.008,
    "cmc_abduction": 0.008,
    "mcp": 0.005,
    "mcp_abduction": 0.005,
    "ip": 0.003,
}
#: Joint effort (N m) and velocity (rad/s) limits required by URDF.
EFFORT_NM = 2.0
VELOCITY_RAD_S = 20.0
#: The abduction gimbal link is massless in reality; simulators need a mass.
GIMBAL_MASS_KG = 5e-4
GIMBAL_RADIUS_M = 0.005


@dataclass(frozen=True)
class RobotJoint:
    """One revolute joint of a finger chain.

    Attributes
    ----------
    name : str
        ``<finger>_mp_abduction``, ``<finger>_mp``, ``<finger>_pip`` or ``<finger>_dip``.
    kind : str
        ``mp_abduction``, ``mp``, ``pip`` or ``dip``.
    parent, child : str
        Link names.
    centre : ndarray, shape (3,)
        Joint centre, hand frame at the reference posture (m).
    origin : ndarray, shape (3,)
        Joint frame origin in the parent link frame (m); rotation identity.
    axis : ndarray, shape (3,)
        Unit axis, hand frame (= parent and child link frames at q = 0).
    lower, upper : float
        Joint limits (rad).
    damping : float
        Viscous damping (N m s/rad).
    """

    name: str
    kind: str
    parent: str
    child: str
    centre: FloatArray
    origin: FloatArray
    axis: FloatArray
    lower: float
    upper: float
    damping: float


@dataclass(frozen=True)
class RobotLink:
    """A moving link: capsule geometry and inertial, in its own frame (m, kg).

    Attributes
    ----------
    name : str
    capsule : tuple of ndarray or None
        Capsule segment end points ``(start (3,), end (3,))`` in the link frame (m);
        ``None`` for the abduction gimbal (no geometry).
    radius : float
        Capsule radius (m); for the gimbal, the radius of its nominal sphere.
    mass : float
        kg.
    com : ndarray, shape (3,)
        Centre of mass in the link frame (m).
    inertia : ndarray, shape (3, 3)
        Inertia tensor about ``com`` in link-frame axes (kg m^2).
    """

    name: str
    capsule: tuple[FloatArray, FloatArray] | None
    radius: float
    mass: float
    com: FloatArray
    inertia: FloatArray


@dataclass(frozen=True)
class RobotFinger:
    """One finger chain, proximal to distal.

    Attributes
    ----------
    name : str
    joints : tuple of RobotJoint
        Ab/adduction (two-axis models only), MP, PIP, DIP; ``joints[k].child`` is
        ``links[k].name``.
    links : tuple of RobotLink
    tip : ndarray, shape (3,)
        Fingertip in the distal link frame (m).
    tip_name : str
        ``<finger>_tip`` (URDF link, MJCF site, OpenSim marker).
    pad : ndarray, shape (3,) or None
        Pad point in the distal link frame (m); ``None`` for a model without pads.
    pad_name : str
        ``<finger>_pad`` (OpenSim marker).
    """

    name: str
    joints: tuple[RobotJoint, ...]
    links: tuple[RobotLink, ...]
    tip: FloatArray
    tip_name: str
    pad: FloatArray | None = None
    pad_name: str = ""

    def chain(self) -> list[tuple[RobotJoint, RobotLink]]:
        """Each joint with the link it moves, proximal to distal."""
        return list(zip(self.joints, self.links, strict=True))


@dataclass(frozen=True)
class RobotSensor:
    """A tracker sensor fixed on a link: its frame at the reference posture.

    Attributes
    ----------
    name : str
        The sensor (``hand``, ``index.proximal``, ...).
    link : str
        The link that carries it.
    position : ndarray, shape (3,)
        Sensor origin in the link frame (m).
    rotation : ndarray, shape (3, 3)
        Sensor -> link frame (columns: the sensor's axes in link coordinates).
    """

    name: str
    link: str
    position: FloatArray
    rotation: FloatArray


@dataclass(frozen=True)
class RobotHand:
    """All finger chains of a model, rooted at the ``hand`` link (hand sensor frame).

    Attributes
    ----------
    name : str
        Robot / model name.
    variant : {"user_axis", "orthogonal"}
    margin_deg : float
        Joint-limit margin (deg).
    fingers : tuple of RobotFinger
    sensors : tuple of RobotSensor
        The hand sensor (on ``hand``, at its origin) and every segment sensor.
    palm : RobotLink
        The hand link's mass and inertia (:func:`palm_link`), for a model whose hand is
        free; the URDF and MJCF fix the hand to the world and leave it without.
    """

    name: str
    variant: str
    margin_deg: float
    fingers: tuple[RobotFinger, ...]
    sensors: tuple[RobotSensor, ...] = ()
    palm: RobotLink | None = None

    @property
    def joints(self) -> list[RobotJoint]:
        """Every joint, finger by finger, proximal to distal."""
        return [j for f in self.fingers for j in f.joints]

    def chain(self) -> list[tuple[RobotJoint, RobotLink]]:
        """Every joint with the link it moves, finger by finger, proximal to distal: the
        order every writer builds its tree in (``joint.parent`` is ``hand`` or the link
        of the pair before)."""
        return [pair for f in self.fingers for pair in f.chain()]


def to_hand_frame(model: HandModel, points: FloatArray) -> FloatArray:
    """Tracker points at the reference posture (mm) -> hand sensor frame (m).

    Parameters
    ----------
    model : HandModel
    points : ndarray, shape (..., 3)
        Tracker coordinates at the reference posture (mm).

    Returns
    -------
    ndarray, shape (..., 3)
        ``R_h0^T (p - t_h0) / 1000`` (m).
    """
    t0, r0 = _hand_pose(model)
    return ((np.asarray(points, dtype=float) - t0) @ r0) / 1000.0


def joint_limits(joint: JointModel, kind: str, margin_deg: float) -> tuple[float, float]:
    """Lower and upper limit (rad) of a joint from its recorded range of motion.

    Parameters
    ----------
    joint : JointModel
        ``joint.quality.rom_deg`` holds per-cycle ranges of motion (deg).
    kind : str
        The joint or axis name (a key of :data:`DEFAULT_RANGE_DEG`).
    margin_deg : float
        Added on both sides (deg).

    Returns
    -------
    (float, float)
        Flexion: ``(-margin, max ROM + margin)``; :data:`SYMMETRIC` joints:
        ``±(max ROM + margin)``;
        :data:`DEFAULT_RANGE_DEG` widened by the margin if no finite ROM is recorded (rad).
    """
    rom = np.asarray(joint.quality.rom_deg, dtype=float)
    rom = rom[np.isfinite(rom) & (rom > 0)]
    if rom.size == 0:
        lo, hi = DEFAULT_RANGE_DEG[kind]
        lo, hi = lo - margin_deg, hi + margin_deg
    elif kind in SYMMETRIC:
        hi = float(rom.max()) + margin_deg
        lo = -hi
    else:
        lo, hi = -margin_deg, float(rom.max()) + margin_deg
    return math.radians(lo), math.radians(hi)


def joint_names(model: HandModel) -> list[str]:
    """Robot joint names of a model, digit by digit, proximal to distal.

    Parameters
    ----------
    model : HandModel

    Returns
    -------
    list of str
        ``<digit>_<axis>`` for every axis proximal to distal, e.g. ``index_mp_abduction``
        (two-axis MP), ``index_mp``, ``index_pip``, ``index_dip``; ``thumb_cmc``,
        ``thumb_cmc_abduction``, ``thumb_mcp``, ``thumb_ip`` -- the order of
        :attr:`RobotHand.joints`, of the joints in the URDF/MJCF files and of the
        columns of the ``--urdf-names`` trajectory.
    """
    return [f"{f}_{jm.name}" for f, fm in model.fingers.items() for jm in fm.chain()]


def capsule_inertial(
    start: FloatArray, end: FloatArray, radius: float, density: float = DENSITY
) -> tuple[float, FloatArray, FloatArray]:
    """Mass, centre of mass and inertia tensor of a solid capsule.

    Parameters
    ----------
    start, end : ndarray, shape (3,)
        Segment end points (m); the capsule is the set of points within ``radius``.
    radius : float
        m.
    density : float
        kg/m^3.

    Returns
    -------
    mass : float
        kg.
    com : ndarray, shape (3,)
        The segment midpoint (m).
    inertia : ndarray, shape (3, 3)
        About ``com``, in the axes of ``start``/``end`` (kg m^2).
    """
    d = np.asarray(end, dtype=float) - np.asarray(start, dtype=float)
    h = float(np.linalg.norm(d))
    u = d / h
    m_cyl = density * math.pi * radius**2 * h
    m_sph = density * 4.0 / 3.0 * math.pi * radius**3  # both hemispheres
    i_axial = m_cyl * radius**2 / 2 + m_sph * 2 * radius**2 / 5
    i_perp = m_cyl * (h**2 / 12 + radius**2 / 4) + m_sph * (
        2 * radius**2 / 5 + h**2 / 4 + 3 * h * radius / 8
    )
    uu = np.outer(u, u)
    inertia = i_perp * (np.eye(3) - uu) + i_axial * uu
    return m_cyl + m_sph, (np.asarray(start) + np.asarray(end)) / 2, inertia


def robot_hand(
    model: HandModel, variant: str = "user_axis", margin_deg: float = DEFAULT_MARGIN_DEG
) -> RobotHand:
    """The robot description of a model: every finger chain in the hand frame (m).

    Parameters
    ----------
    model : HandModel
        Geometry in tracker coordinates at the reference posture (mm).
    variant : {"user_axis", "orthogonal"}
        Fitted (tilted) axes, or the axes made perpendicular to the bones (a second
        axis also perpendicular to the orthogonal flexion axis; ``docs/export.md``).
    margin_deg : float
        Joint-limit margin (deg, >= 0), see :func:`joint_limits`.

    Returns
    -------
    RobotHand

    Raises
    ------
    FingerfitError
        Unknown variant, negative margin, no ``hand`` reference pose, or a
        degenerate segment (joint centres coinciding).
    """
    if variant not in VARIANTS:
        raise FingerfitError(
            f"must be one of {', '.join(VARIANTS)}, not '{variant}'", field="variant"
        )
    if not (math.isfinite(margin_deg) and margin_deg >= 0):
        raise FingerfitError("must be a non-negative number of degrees", field="margin_deg")
    _hand_pose(model)
    r0 = model.reference_poses[HAND_SENSOR][1]
    fingers = []
    sensors = [_sensor(model, HAND_SENSOR, HAND_LINK, np.zeros(3))]
    for fname, fm in model.fingers.items():
        names = list(fm.joints)
        centres = to_hand_frame(model, np.stack([fm.joints[j].center for j in names] + [fm.tip]))
        prox_len = float(np.linalg.norm(centres[1] - centres[0]))
        for jm in fm.chain():
            if jm.migration is not None and np.any(np.asarray(jm.migration) != 0):
                raise FingerfitError(
                    "rolling-contact centre migration cannot be exported as a fixed "
                    "revolute joint; export with --fix-centres to fix each centre at its "
                    "mid-range position",
                    field=f"fingers.{fname}.joints.{jm.name}.migration_mm_per_rad",
                )
        joints, links = [], []
        parent, parent_origin = HAND_LINK, np.zeros(3)
        for i, j in enumerate(names):
            axes = fm.axes(j)
            for k, jm in enumerate(axes):
                last = k == len(axes) - 1
                seg = fm.segments[i]
                # The link between two axes is named after the proximal one.
                child = f"{fname}_{seg}" if last else f"{fname}_{jm.name}_link"
                centre = to_hand_frame(model, jm.center)
                a = r0.T @ np.asarray(jm.axis_for(variant), dtype=float)
                lo, hi = joint_limits(jm, jm.name, margin_deg)
                joints.append(
                    RobotJoint(
                        f"{fname}_{jm.name}",
                        jm.name,
                        parent,
                        child,
                        centre,
                        centre - parent_origin,
                        a / np.linalg.norm(a),
                        lo,
                        hi,
                        DAMPING[jm.name],
                    )
                )
                if not last:
                    links.append(_gimbal(child))
                else:
                    end = centres[i + 1] - centre
                    if np.linalg.norm(end) < 1e-4:
                        raise FingerfitError(
                            "segment shorter than 0.1 mm (joint centres coincide)",
                            field=f"fingers.{fname}.segment_lengths.{seg}",
                        )
                    radius = RADIUS_FRACTION[seg] * prox_len
                    mass, com, inertia = capsule_inertial(np.zeros(3), end, radius)
                    links.append(RobotLink(child, (np.zeros(3), end), radius, mass, com, inertia))
                parent, parent_origin = child, centre
            sensors.append(_sensor(model, fm.joints[j].child, child, centre))
        tip = centres[3] - parent_origin
        pad = None if fm.pad is None else to_hand_frame(model, fm.pad) - parent_origin
        fingers.append(
            RobotFinger(
                fname, tuple(joints), tuple(links), tip, f"{fname}_tip", pad, f"{fname}_pad"
            )
        )
    name = f"fingerfit_{model.subject}_{model.hand}"
    return RobotHand(
        name, variant, float(margin_deg), tuple(fingers), tuple(sensors), palm_link(model)
    )


def palm_link(model: HandModel) -> RobotLink:
    """The hand link's mass and inertia from the digits' segment lengths.

    The palm is taken as the metacarpals of the fingers in the model, each a solid
    capsule of density :data:`DENSITY` (:func:`capsule_inertial`) collinear with the
    finger's proximal phalanx at the reference posture (the stretched hand), from its MP
    centre proximally. Its length is the proximal phalanx's scaled by the Buchholz et al.
    (1992) ratio of the finger's metacarpal to its proximal phalanx
    (:data:`~fingerfit.estimate.plausibility.bounds.SEGMENT_FRACTION`, e.g. index
    0.463 / 0.245), its radius ``RADIUS_FRACTION["metacarpal"]`` of the proximal phalanx
    (the thumb metacarpal's rule). A model without a finger gets one such capsule
    proximal of the thumb's CMC centre, along the thumb's metacarpal, as long as an index
    metacarpal of the hand length the thumb's segments give.

    Parameters
    ----------
    model : HandModel

    Returns
    -------
    RobotLink
        Named ``hand``, without geometry (``capsule`` None, ``radius`` 0): mass (kg),
        centre of mass (m) and inertia about it (kg m^2), hand frame.
    """
    from ..estimate.plausibility.bounds import SEGMENT_FRACTION  # the estimate package: lazily

    parts = []
    for fname, fm in model.fingers.items():
        if fname == "thumb":
            continue
        base, proximal = fm.joints["mp"].center, fm.joints["pip"].center
        fraction = SEGMENT_FRACTION[fname]
        length = fm.segment_lengths["proximal"] * fraction["metacarpal"] / fraction["proximal"]
        parts.append((base, base - proximal, length, fm.segment_lengths["proximal"]))
    if not parts:
        fm = model.fingers["thumb"]
        fraction = SEGMENT_FRACTION["thumb"]
        hand_length = np.mean([fm.segment_lengths[s] / fraction[s] for s in fm.segments])
        base = fm.joints["cmc"].center
        parts.append(
            (
                base,
                base - fm.joints["mcp"].center,
                SEGMENT_FRACTION["index"]["metacarpal"] * hand_length,
                SEGMENT_FRACTION["index"]["proximal"] * hand_length,
            )
        )
    masses, coms, inertias = [], [], []
    for base, direction, length, proximal_length in parts:
        start = to_hand_frame(model, base)
        end = start + to_hand_frame_vector(model, direction) / np.linalg.norm(direction) * (
            length / 1000.0
        )
        radius = RADIUS_FRACTION["metacarpal"] * proximal_length / 1000.0
        mass, com, inertia = capsule_inertial(start, end, radius)
        masses.append(mass)
        coms.append(com)
        inertias.append(inertia)
    mass = float(sum(masses))
    com = np.average(coms, axis=0, weights=masses)
    inertia = sum(
        i + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
        for m, c, i in zip(masses, coms, inertias, strict=True)
        for d in [c - com]
    )
    return RobotLink(HAND_LINK, None, 0.0, mass, com, inertia)


def to_hand_frame_vector(model: HandModel, vectors: FloatArray) -> FloatArray:
    """Tracker directions ``(..., 3)`` at the reference posture -> hand sensor frame (same
    units, not translated): ``R_h0^T v``."""
    return np.asarray(vectors, dtype=float) @ _hand_pose(model)[1]


def _sensor(model: HandModel, sensor: str, link: str, link_origin: FloatArray) -> RobotSensor:
    """A sensor's reference pose in the frame of ``link`` (origin ``link_origin``, hand
    frame, m; parallel to the hand frame)."""
    t, r = model.reference_poses[sensor]
    return RobotSensor(
        sensor,
        link,
        to_hand_frame(model, t) - link_origin,
        _hand_pose(model)[1].T @ np.asarray(r, dtype=float),
    )


def _gimbal(name: str) -> RobotLink:
    """The massless-in-reality link between the two axes of a joint (a small sphere)."""
    i = 2.0 / 5.0 * GIMBAL_MASS_KG * GIMBAL_RADIUS_M**2
    return RobotLink(name, None, GIMBAL_RADIUS_M, GIMBAL_MASS_KG, np.zeros(3), i * np.eye(3))


def _hand_pose(model: HandModel) -> tuple[FloatArray, FloatArray]:
    if HAND_SENSOR not in model.reference_poses:
        raise FingerfitError(
            "the model has no hand sensor pose", field=f"reference_poses.{HAND_SENSOR}"
        )
    t0, r0 = model.reference_poses[HAND_SENSOR]
    return np.asarray(t0, dtype=float), np.asarray(r0, dtype=float)
