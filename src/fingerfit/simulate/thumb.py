"""Simulated thumb anatomy, digit pads and the thumb's exact forward kinematics.

The thumb is a chain hand -> metacarpal -> proximal -> distal phalanx with joints
``cmc`` (two axes), ``mcp`` (two axes) and ``ip`` (hinge). In both two-axis joints the
flexion-extension axis is **proximal** (fixed in the parent: the trapezium, resp. the
metacarpal head) and the ab/adduction axis distal (in the base of the metacarpal, resp.
of the proximal phalanx; Hollister et al. 1992, 1995): relative to the reference
posture a segment moves by ``Rot(a, theta) Rot(b, beta)`` about the two *lines* (the
ab/adduction line is carried by the flexion). The two lines neither intersect nor
stand at right angles. Axes are fixed (no rolling contact, as Hollister found).

Thumb frame (``docs/conventions.md``, "Thumb"): at the reference posture x runs
distally along the straight thumb, z is the thumb's dorsal (nail) side, y = z x x.
Positive flexion turns the tip towards the pulp side (about ~ +y; at the CMC across
the palm towards the little finger); positive ab/adduction is palmar abduction (the
thumb moves away from the palm, about ~ ``side`` * z). A left hand is the mirror
image of a right one through the hand's x-z plane; mirrored motions have equal angles.

Lengths mm, angles rad, points and axes in tracker coordinates at the reference
posture. Literature sources and assumptions: ``docs/simulator.md`` ("Thumb").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..digits import THUMB_JOINTS
from ..transforms import (
    FloatArray,
    angle_between_axes,
    axis_angle_matrix,
    distance_between_lines,
    unit,
)
from .anatomy import BUCHHOLZ, INDEX_LENGTHS, compose, joint_transform

#: The thumb's angles (rad), in the order of the truth tables.
THUMB_KEYS = ("cmc", "cmc_abduction", "mcp", "mcp_abduction", "ip")

# Buchholz et al. 1992: thumb link lengths as fractions of hand length: metacarpal
# (CMC-MCP), proximal phalanx (MCP-IP), distal phalanx (IP-tip).
BUCHHOLZ_THUMB = np.array([0.251, 0.196, 0.158])
# Per-subject scatter of each link beyond the hand size (coefficient of variation;
# assumption, the size of the fingers' X-ray scatter).
THUMB_LENGTH_CV = 0.05
#: Hand length (mm) at which the finger links of :mod:`.anatomy` follow Buchholz:
#: the index proximal link 39.8 mm / 0.245.
NOMINAL_HAND_LENGTH = float(INDEX_LENGTHS[0] / BUCHHOLZ["index"][0])

# CMC flexion-extension axis point (in the trapezium), hand frame of a right hand
# relative to the middle-finger MP centre (mm, x distal, y radial, z dorsal), and its
# per-subject SD. Assumption from hand anatomy: radial of the index metacarpal base,
# palmar of the metacarpal plane.
CMC_POSITION = np.array([-62.0, 26.0, -10.0])
CMC_POSITION_SD = np.array([3.0, 3.0, 2.0])
# Rest direction of the straight thumb at the reference posture (deg): radial from the
# hand's x axis, palmar out of the metacarpal plane, and pronation about its own long
# axis relative to the fingers (nail facing radially). Assumptions (means, SDs).
THUMB_AZIMUTH_DEG = (25.0, 5.0)
THUMB_ELEVATION_DEG = (10.0, 4.0)
THUMB_PRONATION_DEG = (80.0, 8.0)

# CMC axes. Chang & Pollard 2008 (24 subjects, in vivo): mean separation of the
# flexion-extension and ab/adduction axes 4.6 mm, mean angle between them 87 deg;
# the axis directions deviated on average 9 deg (F/E) and 22 deg (A/A) from the mean
# direction (a mean deviation of an isotropic 2-D normal is SD * sqrt(pi/2)).
# Hollister et al. 1992: F/E axis in the trapezium, A/A axis in the metacarpal base,
# neither perpendicular to each other nor to the bone, not intersecting; the
# obliquity to the bone makes flexion and abduction pronate the metacarpal (the
# conjunct rotation of opposition). Obliquity magnitudes towards the bone: assumption.
CMC_OFFSET_MM = (4.6, 1.2)  # SD: assumption
CMC_ANGLE_DEG = (87.0, 4.0)  # SD: assumption
CMC_FE_DIRECTION_SD_DEG = 9.0 / np.sqrt(np.pi / 2)
CMC_AA_DIRECTION_SD_DEG = 22.0 / np.sqrt(np.pi / 2)
CMC_FE_OBLIQUITY_DEG = (15.0, 5.0)
CMC_AA_OBLIQUITY_DEG = (20.0, 6.0)
# MCP (Hollister et al. 1995): fixed F/E axis in the metacarpal head, A/A axis in the
# base of the proximal phalanx (between the sesamoids), neither perpendicular to the
# phalanges. Magnitudes are assumptions: F/E obliquity, angle and offset of the lines.
MCP_OBLIQUITY_DEG = (8.0, 4.0)
MCP_ANGLE_DEG = (85.0, 5.0)
MCP_OFFSET_MM = (3.0, 1.0)
# IP (Hollister et al. 1995): a hinge parallel to the flexion crease, oblique to the
# phalanx so that flexion adds ulnar deviation and pronation. Magnitude: assumption.
IP_OBLIQUITY_DEG = (7.0, 3.0)
# Dorsal depth of the joint landmarks above the axes (mm): CMC, MCP, IP (assumption).
THUMB_DORSAL_DEPTH = np.array([9.0, 8.0, 5.5])
THUMB_NAIL_HEIGHT = 3.0  # nail edge above the distal link axis (mm, assumption)

# Pads: the pulp centre lies palmar of the nail-edge tip by ``depth`` and ``proximal``
# mm proximal of it; the pulp surface is ``half`` mm further palmar (mean, SD; mm).
# Assumptions from fingertip anthropometry: pads touching leave the nail edges
# 12-18 mm apart (docs/simulator.md).
PAD_PARAMS = {
    "thumb": {"depth": (5.0, 0.4), "half": (4.0, 0.3), "proximal": (3.0, 0.5)},
    "index": {"depth": (4.0, 0.3), "half": (3.0, 0.3), "proximal": (3.0, 0.5)},
    "middle": {"depth": (4.0, 0.3), "half": (3.0, 0.3), "proximal": (3.0, 0.5)},
    "ring": {"depth": (3.8, 0.3), "half": (2.9, 0.3), "proximal": (3.0, 0.5)},
    "little": {"depth": (3.5, 0.3), "half": (2.7, 0.3), "proximal": (2.5, 0.5)},
}


@dataclass(frozen=True)
class Pad:
    """A digit's pulp at the reference posture (tracker coordinates, mm).

    Attributes
    ----------
    centre : ndarray, shape (3,)
        Pulp centre (moves with the distal segment).
    half_thickness : float
        Distance from the pulp centre to the pulp surface (mm): two pads touch when
        their centres are the sum of their half-thicknesses apart.
    depth, proximal : float
        The centre lies ``depth`` mm palmar and ``proximal`` mm proximal of the nail edge.
    surface : ndarray, shape (3,)
        The pulp's skin point below the centre (``half_thickness`` further palmar): the
        point a stylus digitises as the ``<digit>.pad`` landmark and the model's pad point.
    """

    centre: FloatArray
    half_thickness: float
    depth: float
    proximal: float
    surface: FloatArray


def sample_pad(rng: np.random.Generator, digit: str, tip: FloatArray, frame: FloatArray) -> Pad:
    """Draw a digit's pad below its nail-edge ``tip (3,)`` (digit ``frame`` columns x, y, z)."""
    p = PAD_PARAMS[digit]
    depth, half, prox = (max(rng.normal(*p[k]), 0.5) for k in ("depth", "half", "proximal"))
    centre = tip - depth * frame[:, 2] - prox * frame[:, 0]
    return Pad(centre, float(half), float(depth), float(prox), centre - half * frame[:, 2])


@dataclass(frozen=True)
class ThumbAnatomy:
    """True thumb geometry at the reference posture (tracker coordinates, mm).

    Attributes
    ----------
    name : str
        ``thumb``.
    axis_point : dict[str, ndarray]
        A point of each axis line ``cmc``, ``cmc_abduction``, ``mcp``,
        ``mcp_abduction``, ``ip`` (shape (3,)): for the flexion axes the joint centre,
        for an ab/adduction axis the point nearest its flexion axis.
    axis : dict[str, ndarray]
        Unit axis directions, same keys. Positive rotation = flexion (towards the pulp
        side), resp. palmar abduction.
    centre : ndarray, shape (3, 3)
        Joint centres CMC, MCP, IP (points of the flexion axes on the thumb's line).
    tip : ndarray, shape (3,)
        Nail-edge point (midpoint of the distal nail edge).
    pad : Pad
        Pulp centre and half-thickness.
    landmarks : dict[str, ndarray]
        True dorsal joint points ``cmc``, ``mcp``, ``ip``, the ``tip`` and the ``pad``
        (the pulp's skin point, :attr:`Pad.surface`).
    frame : ndarray, shape (3, 3)
        Columns x (distal), y, z (dorsal, nail side) of the thumb's anatomical frame.
    side : float
        +1 for a right hand, -1 for a left one.
    mcp_abduction : bool
        Whether the MCP has an ab/adduction axis (default). False: the MCP is a hinge
        (the MyoHand world); ``axis_point``/``axis["mcp_abduction"]`` then hold a
        placeholder line (through the MCP centre along the thumb's z) that never turns:
        every simulated ``mcp_abduction`` angle is 0.
    """

    name: str
    axis_point: dict[str, FloatArray]
    axis: dict[str, FloatArray]
    centre: FloatArray
    tip: FloatArray
    pad: Pad
    landmarks: dict[str, FloatArray]
    frame: FloatArray
    side: float
    mcp_abduction: bool = True

    @property
    def lengths(self) -> FloatArray:
        """Link lengths CMC-MCP, MCP-IP, IP-tip along the thumb (mm), shape (3,)."""
        pts = np.vstack([self.centre, self.tip])
        return np.linalg.norm(np.diff(pts, axis=0), axis=1)

    def offset(self, joint: str) -> float:
        """Shortest distance between a two-axis joint's lines (mm)."""
        second = f"{joint}_abduction"
        return distance_between_lines(
            self.axis_point[joint], self.axis[joint], self.axis_point[second], self.axis[second]
        )

    def axes_angle(self, joint: str) -> float:
        """Angle between a two-axis joint's axis lines (rad, in [0, pi/2])."""
        return float(angle_between_axes(self.axis[joint], self.axis[f"{joint}_abduction"]))


def _rot(axis: FloatArray, deg: float) -> FloatArray:
    return axis_angle_matrix(unit(axis), np.array([np.radians(deg)]))[0]


def _second_axis(
    rng: np.random.Generator,
    a: FloatArray,
    nominal: FloatArray,
    angle_deg: float,
    spread_deg: float,
) -> FloatArray:
    """A unit axis at ``angle_deg`` to ``a``, near ``nominal``, turned about ``a`` by N(0, spread)."""
    perp = unit(nominal - (nominal @ a) * a)
    perp = _rot(a, rng.normal(0.0, spread_deg)) @ perp
    g = np.radians(angle_deg)
    return unit(np.cos(g) * a + np.sin(g) * perp)


def _second_point(
    point_a: FloatArray, a: FloatArray, b: FloatArray, offset: float, distal: FloatArray
) -> FloatArray:
    """Point of the second line nearest the first: ``offset`` mm along the common normal, distally."""
    n = unit(np.cross(a, b))
    n = n if n @ distal >= 0 else -n
    return point_a + offset * n


def sample_thumb(
    rng: np.random.Generator,
    hand_length: float,
    side: str,
    *,
    hand_rotation: FloatArray,
    hand_origin: FloatArray,
    tilt_scale: float = 1.0,
) -> ThumbAnatomy:
    """Draw one subject's thumb.

    Parameters
    ----------
    rng : numpy Generator
        The thumb's own generator (the fingers' random stream is not touched).
    hand_length : float
        Hand length (mm) on the scale of :data:`NOMINAL_HAND_LENGTH` (the fingers' links
        follow Buchholz at that length).
    side : {"left", "right"}
    hand_rotation : ndarray, shape (3, 3)
        Hand anatomical frame (columns x distal, y = z x x, z dorsal) in tracker
        coordinates at the reference posture.
    hand_origin : ndarray, shape (3,)
        Middle-finger MP centre in tracker coordinates (mm).
    tilt_scale : float
        Scales every deviation of the axes from the thumb frame (0: CMC and MCP axes
        along y and z of the thumb, meeting at right angles; IP perpendicular to the
        bone). The offsets of the lines stay.

    Returns
    -------
    ThumbAnatomy
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', not {side!r}")
    scale = hand_length / NOMINAL_HAND_LENGTH
    lengths = BUCHHOLZ_THUMB * hand_length * (1.0 + rng.normal(0.0, THUMB_LENGTH_CV, 3))
    # Everything is built for a right hand in hand coordinates (x distal, y radial,
    # z dorsal), then mirrored for a left hand.
    cmc = CMC_POSITION * scale + rng.normal(0.0, CMC_POSITION_SD)
    az = np.radians(rng.normal(*THUMB_AZIMUTH_DEG))
    el = np.radians(rng.normal(*THUMB_ELEVATION_DEG))
    pron = rng.normal(*THUMB_PRONATION_DEG)
    x = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    z0 = unit(np.array([0.0, 0.0, 1.0]) - x[2] * x)
    # Pronation (right hand): the nail turns from dorsal towards radial.
    z = _rot(x, -pron) @ z0
    y = np.cross(z, x)
    frame = np.column_stack([x, y, z])
    t = tilt_scale

    def tilted(v: FloatArray, sd: float) -> FloatArray:
        # v turned by N(0, sd) about each of the two directions perpendicular to it.
        p1 = unit(np.cross(v, x if abs(v @ x) < 0.9 else z))
        p2 = np.cross(v, p1)
        return unit(_rot(p2, t * rng.normal(0.0, sd)) @ _rot(p1, t * rng.normal(0.0, sd)) @ v)

    centre = np.array([cmc, cmc + lengths[0] * x, cmc + (lengths[0] + lengths[1]) * x])
    axis: dict[str, FloatArray] = {}
    point: dict[str, FloatArray] = {}
    # CMC: F/E about ~y (across the palm), A/A about ~z (palmar abduction), distal line.
    # Both oblique towards the proximal bone direction (-x): +flexion and +abduction
    # pronate (about -x for a right hand).
    alpha = np.radians(t * rng.normal(*CMC_FE_OBLIQUITY_DEG))
    axis["cmc"] = tilted(np.cos(alpha) * y - np.sin(alpha) * x, CMC_FE_DIRECTION_SD_DEG)
    phi = np.radians(t * rng.normal(*CMC_AA_OBLIQUITY_DEG))
    gamma = 90.0 - t * (90.0 - rng.normal(*CMC_ANGLE_DEG))
    axis["cmc_abduction"] = _second_axis(
        rng, axis["cmc"], np.cos(phi) * z - np.sin(phi) * x, gamma, t * CMC_AA_DIRECTION_SD_DEG
    )
    point["cmc"] = centre[0]
    off = max(rng.normal(*CMC_OFFSET_MM), 1.5) * scale
    point["cmc_abduction"] = _second_point(centre[0], axis["cmc"], axis["cmc_abduction"], off, x)
    # MCP: oblique F/E axis, distal A/A line.
    obl = t * rng.normal(*MCP_OBLIQUITY_DEG)
    axis["mcp"] = tilted(_rot(z, obl) @ y, 3.0)
    gamma = 90.0 - t * (90.0 - rng.normal(*MCP_ANGLE_DEG))
    axis["mcp_abduction"] = _second_axis(rng, axis["mcp"], z, gamma, t * 8.0)
    point["mcp"] = centre[1]
    off = max(rng.normal(*MCP_OFFSET_MM), 1.0) * scale
    point["mcp_abduction"] = _second_point(centre[1], axis["mcp"], axis["mcp_abduction"], off, x)
    # IP: hinge oblique to the phalanx (gains a distal component: ulnar deviation).
    obl = t * rng.normal(*IP_OBLIQUITY_DEG)
    axis["ip"] = tilted(_rot(z, obl) @ y, 2.0)
    point["ip"] = centre[2]
    tip = centre[2] + lengths[2] * x + THUMB_NAIL_HEIGHT * z
    depth = THUMB_DORSAL_DEPTH * scale + rng.normal(0.0, 0.7, 3)
    landmarks = {j: centre[i] + depth[i] * z for i, j in enumerate(THUMB_JOINTS)}
    landmarks["tip"] = tip
    pad = sample_pad(rng, "thumb", tip, frame)
    landmarks["pad"] = pad.surface

    # Right-hand coordinates -> this hand (mirror y for a left hand) -> tracker.
    s = 1.0 if side == "right" else -1.0
    m = np.diag([1.0, s, 1.0])

    def pt(p: FloatArray) -> FloatArray:
        return hand_origin + hand_rotation @ (m @ p)

    def ax(v: FloatArray) -> FloatArray:
        # Axial vectors (rotation axes, y = z x x) mirror with -M: equal angles for
        # mirrored motions.
        return hand_rotation @ ((m @ v) * (1.0 if s > 0 else -1.0))

    frame_t = np.column_stack([hand_rotation @ (m @ x), ax(y), hand_rotation @ (m @ z)])
    pad_t = Pad(pt(pad.centre), pad.half_thickness, pad.depth, pad.proximal, pt(pad.surface))
    return ThumbAnatomy(
        "thumb",
        {k: pt(v) for k, v in point.items()},
        {k: ax(v) for k, v in axis.items()},
        np.array([pt(c) for c in centre]),
        pt(tip),
        pad_t,
        {k: pt(v) for k, v in landmarks.items()},
        frame_t,
        s,
    )


def thumb_segment_motions(
    thumb: ThumbAnatomy,
    angles: dict[str, FloatArray],
    hand_motion: tuple[FloatArray, FloatArray],
) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Motion of each thumb segment relative to the reference posture, per frame.

    ``metacarpal = hand * Rot(cmc line, theta) * Rot(cmc_abduction line, beta)``,
    ``proximal = metacarpal * Rot(mcp line, theta) * Rot(mcp_abduction line, beta)``,
    ``distal = proximal * Rot(ip line, theta)``: flexion proximal in both two-axis joints.

    Parameters
    ----------
    thumb : ThumbAnatomy
    angles : dict
        :data:`THUMB_KEYS` -> ``(n,)`` rad.
    hand_motion : (R (n, 3, 3), t (n, 3))
        Hand motion relative to its reference pose (tracker frame, mm).

    Returns
    -------
    dict
        ``hand``, ``metacarpal``, ``proximal``, ``distal`` -> ``(R (n, 3, 3), t (n, 3))``
        mapping a point at the reference posture to its position in each frame (mm).
    """
    out = {"hand": hand_motion}
    seg = hand_motion
    for name, keys in (
        ("metacarpal", ("cmc", "cmc_abduction")),
        ("proximal", ("mcp", "mcp_abduction")),
        ("distal", ("ip",)),
    ):
        for k in keys:
            seg = compose(seg, joint_transform(thumb.axis_point[k], thumb.axis[k], angles[k]))
        out[name] = seg
    return out


def moved(motion: tuple[FloatArray, FloatArray], point: FloatArray) -> FloatArray:
    """Positions ``(n, 3)`` of a reference-posture ``point (3,)`` under a motion ``(R, t)``."""
    r, t = motion
    return np.einsum("nij,j->ni", r, point) + t


__all__ = [
    "THUMB_KEYS",
    "Pad",
    "ThumbAnatomy",
    "moved",
    "sample_pad",
    "sample_thumb",
    "thumb_segment_motions",
]
