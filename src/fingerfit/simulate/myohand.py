"""An independent ground-truth world: the fingers of the MyoHand model (``--world myohand``).

MyoHand (package ``myo-sim``, Apache-2.0; MyoHub, derived from OpenSim hand models) is a
right hand whose kinematic tree, joint positions and tilted axes were authored by
others. This module loads it with MuJoCo, reads every finger joint's world anchor and
axis, the phalanx bodies' poses and the fingertip sites at the all-zero posture, and
turns them into fingerfit's true finger geometry
(:class:`~fingerfit.simulate.anatomy.FingerAnatomy`) in tracker coordinates, so that the
default simulator's protocols, sensors, tracker errors and truth files run unchanged on
it (:func:`fingerfit.simulate.study.simulate_subject` with ``SimConfig(world="myohand")``).

Order of the MP axes: MyoHand lists ``mcp<k>_flexion`` before ``mcp<k>_abduction`` in one
body, so in MuJoCo the flexion is the **proximal** rotation and the ab/adduction axis
turns with the flexion: ``FingerAnatomy.order = ("mp", "mp_abduction")`` (the default
world has the opposite order). The forward kinematics is the product of exponentials of
:func:`~fingerfit.simulate.anatomy.segment_motions` in that order, about the zero-posture
world anchors and axes; it reproduces MuJoCo's body poses (``tests/test_myohand_world.py``).

Frames and units: MyoHand is in metres in MuJoCo's world frame (``mj_*`` names below);
everything this module returns is in **mm**, and either in that world frame (``mj``) or
in tracker coordinates at the reference posture. The hand anatomical frame
(``docs/conventions.md``: x distal, z dorsal, y = z x x, radial for the right hand) is
built from MyoHand's own geometry (:func:`reference_geometry`). Angles are rad, oriented
as fingerfit's (flexion positive about ~+y, MP ab/adduction positive radially about ~+z);
``sign`` maps them to MuJoCo's ``qpos``.

The thumb (:func:`sample_thumb`): MyoHand's ``cmc_flexion`` and ``cmc_abduction`` share
the metacarpal body ``firstmc_r`` (flexion listed first, so **proximal**, as fingerfit's
thumb convention; the two lines meet at the body origin), ``mp_flexion`` and
``ip_flexion`` are hinges: MyoHand's thumb has **no MCP ab/adduction**, so in this world
the thumb's MCP is a hinge (:attr:`~fingerfit.simulate.thumb.ThumbAnatomy.mcp_abduction`
False, every ``mcp_abduction`` angle 0). The thumb is expressed as the default world's
:class:`~fingerfit.simulate.thumb.ThumbAnatomy`, so its protocols (circumduction,
opposition, pinches solved by :mod:`.contact`) and truth run unchanged on it.

Scope: right hand only; the thumb and the four fingers. Sources and the population
model: ``docs/simulator.md``, "The MyoHand world".
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..extras import require
from ..transforms import FloatArray, unit
from .anatomy import DORSAL_DEPTH, FingerAnatomy
from .thumb import THUMB_DORSAL_DEPTH, ThumbAnatomy, sample_pad

#: fingerfit's MP axis order of a MyoHand finger: flexion proximal.
ORDER = ("mp", "mp_abduction")
#: The finger digits this world simulates.
FINGERS = ("index", "middle", "ring", "little")
#: Joint names per finger, fingerfit order ``mp``, ``mp_abduction``, ``pip``, ``dip``
#: (MyoHand spells some with, some without ``_r``: both are tried).
JOINT_NAMES = {
    f: (f"mcp{k}_flexion", f"mcp{k}_abduction", f"pm{k}_flexion", f"md{k}_flexion")
    for f, k in zip(FINGERS, (2, 3, 4, 5), strict=True)
}
#: Phalanx bodies per finger: proximal, middle, distal.
SEGMENT_BODIES = {
    f: (f"{k}proxph_r", f"midph{k}_r", f"distph{k}_r")
    for f, k in zip(FINGERS, (2, 3, 4, 5), strict=True)
}
#: MyoHand's fingertip site on each distal phalanx (on the distal bone's line).
TIP_SITES = {"index": "IFtip_r", "middle": "MFtip_r", "ring": "RFtip_r", "little": "LFtip_r"}
#: The thumb's joints, fingerfit order ``cmc``, ``cmc_abduction``, ``mcp``, ``ip`` (no MCP
#: ab/adduction in MyoHand).
THUMB_JOINT_NAMES = ("cmc_flexion", "cmc_abduction", "mp_flexion", "ip_flexion")
#: fingerfit's names of those joints' angles.
THUMB_KEYS = ("cmc", "cmc_abduction", "mcp", "ip")
#: The thumb's bodies: metacarpal, proximal, distal phalanx.
THUMB_BODIES = ("firstmc_r", "proximal_thumb_r", "distal_thumb_r")
#: MyoHand's thumb tip site on the distal phalanx (on the distal bone's line).
THUMB_TIP_SITE = "THtip_r"
#: Per-subject scatter: link length factor SD, axis rotation SD per component (deg).
LENGTH_SD = 0.04
AXIS_SD_DEG = 3.0


def _myo_sim() -> Any:
    return require("myo_sim", "myohand", "the MyoHand world", field="--world")


def _mujoco() -> Any:
    return require("mujoco", "myohand", "the MyoHand world", field="--world")


def model_xml() -> str:
    """The MJCF that loads MyoHand: the ``myo-sim`` wheel's right arm-and-hand chain
    (``models/arm/assets/myoarm_r_chain.xml``) with its assets (meshes), in a world body.

    Returns
    -------
    str
        MJCF text with absolute include paths (load with ``mujoco.MjModel.from_xml_string``).
    """
    root = Path(_myo_sim().__file__).resolve().parent / "models"
    assets = root / "arm" / "assets"
    return (
        '<mujoco model="fingerfit-myohand">'
        f'<include file="{assets / "myoarm_r_assets.xml"}"/>'
        f'<compiler meshdir="{root}" texturedir="{root}"/>'
        f'<worldbody><include file="{assets / "myoarm_r_chain.xml"}"/></worldbody>'
        "</mujoco>"
    )


@functools.lru_cache(maxsize=1)
def load_model() -> Any:
    """MyoHand as a compiled ``mujoco.MjModel`` (cached; about 0.2 s the first time).

    Raises
    ------
    FingerfitError
        Without ``myo-sim`` or ``mujoco``: one line naming ``pip install fingerfit[myohand]``.
    """
    return _mujoco().MjModel.from_xml_string(model_xml())


def joint_id(model: Any, name: str) -> int:
    """MuJoCo id of joint ``name`` or ``name + "_r"``."""
    mujoco = _mujoco()
    for n in (name, f"{name}_r"):
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)
        if i >= 0:
            return int(i)
    raise FingerfitError(f"MyoHand has no joint {name!r} (nor {name}_r)", field="--world")


@dataclass(frozen=True)
class MyoFinger:
    """One MyoHand finger at the all-zero posture (MuJoCo world frame, mm).

    The thumb is held in the same form, its joints ``cmc``, ``cmc_abduction``, ``mcp``,
    ``ip`` in place of ``mp``, ``mp_abduction``, ``pip``, ``dip`` (the two CMC axes share
    the metacarpal body's origin as the MP's two axes share the proximal phalanx's).

    Attributes
    ----------
    name : str
        ``index``, ``middle``, ``ring``, ``little`` or ``thumb``.
    joints : tuple of str
        MuJoCo joint names, fingerfit order ``mp``, ``mp_abduction``, ``pip``, ``dip``
        (thumb: :data:`THUMB_JOINT_NAMES`).
    qpos : ndarray, shape (4,), int
        Their ``qpos`` addresses.
    sign : ndarray, shape (4,)
        +1 or -1: ``qpos = sign * angle`` (fingerfit's angle orientation).
    anchor : ndarray, shape (4, 3)
        World joint anchors ``xanchor`` (mm), same order.
    axis : ndarray, shape (4, 3)
        World unit axes ``sign * xaxis``: flexion towards the hand's +y (right-hand rule
        curls palmar), ab/adduction towards +z (positive = radial deviation).
    body_position : ndarray, shape (3, 3)
        ``xpos`` of the proximal, middle, distal phalanx bodies (mm) (thumb: metacarpal,
        proximal, distal).
    body_rotation : ndarray, shape (3, 3, 3)
        Their ``xmat`` (body -> world).
    tip : ndarray, shape (3,)
        The fingertip site (:data:`TIP_SITES`, thumb :data:`THUMB_TIP_SITE`) position (mm).
    """

    name: str
    joints: tuple[str, ...]
    qpos: np.ndarray
    sign: FloatArray
    anchor: FloatArray
    axis: FloatArray
    body_position: FloatArray
    body_rotation: FloatArray
    tip: FloatArray


@dataclass(frozen=True)
class MyoHandReference:
    """MyoHand's fingers at the all-zero posture and its hand frame (MuJoCo world, mm).

    Attributes
    ----------
    fingers : dict[str, MyoFinger]
    origin : ndarray, shape (3,)
        Middle-finger MCP anchor (mm): the hand origin, as in the default world.
    frame : ndarray, shape (3, 3)
        Columns x (MCP3 -> middle fingertip), y (radial: the index side), z (dorsal) of the
        hand anatomical frame in MuJoCo world coordinates.
    thumb : MyoFinger
        The thumb (:data:`THUMB_JOINT_NAMES`, :data:`THUMB_BODIES`, :data:`THUMB_TIP_SITE`);
        axes oriented as fingerfit's thumb angles: positive flexion moves the tip ulnarly
        (across the palm, towards the little finger), positive CMC ab/adduction palmarly
        (palmar abduction). MyoHand's own signs are the opposite for the three flexions
        (``sign`` -1) and agree for the ab/adduction.
    """

    fingers: dict[str, MyoFinger]
    origin: FloatArray
    frame: FloatArray
    thumb: MyoFinger

    def link_angles_deg(self, finger: str) -> FloatArray:
        """Angles (deg) between successive links MCP-PIP, PIP-DIP, DIP-tip of ``finger`` at
        the zero posture, signed positive for flexion: how far zero is from stretched
        (``thumb``: the links CMC-MCP, MCP-IP, IP-tip).

        Returns
        -------
        ndarray, shape (2,)
            PIP and DIP angles (thumb: MCP and IP).
        """
        f = self.thumb if finger == "thumb" else self.fingers[finger]
        pts = np.vstack([f.anchor[[0, 2, 3]], f.tip])
        d = unit(np.diff(pts, axis=0))
        out = []
        for i in (1, 2):
            a = f.axis[i]  # flexion axis at the joint between link i-1 and link i
            s = np.dot(np.cross(d[i - 1], d[i]), a)
            out.append(np.degrees(np.arctan2(s, np.dot(d[i - 1], d[i]))))
        return np.array(out)


def reference_geometry(model: Any | None = None) -> MyoHandReference:
    """Read MyoHand at the all-zero posture: joint anchors and axes, bodies, tip sites.

    Every joint of the model is set to 0 (``qpos0`` of MyoHand's hinges is 0), then
    ``mj_kinematics`` runs. The hand frame: x from the middle MCP anchor to the middle
    fingertip site, y the index MCP minus the little MCP made perpendicular to x, z = x x y
    (dorsal for a right hand; checked: the middle MCP flexion axis lies along +y). The
    thumb's axes are oriented by the motion of its tip site: ``axis x (tip - anchor)``
    towards the hand's -y (ulnar) for a flexion, towards -z (palmar) for the CMC
    ab/adduction.

    Parameters
    ----------
    model : mujoco.MjModel, optional
        Defaults to :func:`load_model`.

    Returns
    -------
    MyoHandReference
    """
    mujoco = _mujoco()
    model = load_model() if model is None else model
    data = mujoco.MjData(model)
    data.qpos[:] = 0.0
    mujoco.mj_kinematics(model, data)
    raw = {}
    chains = {f: (JOINT_NAMES[f], SEGMENT_BODIES[f], TIP_SITES[f]) for f in FINGERS}
    chains["thumb"] = (THUMB_JOINT_NAMES, THUMB_BODIES, THUMB_TIP_SITE)
    for f, (joint_names, body_names, site) in chains.items():
        ids = [joint_id(model, n) for n in joint_names]
        if np.any(model.jnt_pos[ids] != 0.0):
            raise FingerfitError(f"MyoHand's {f} joints are not at their body origins")
        bodies = [model.body(b).id for b in body_names]
        raw[f] = (
            ids,
            1000.0 * data.xanchor[ids],
            data.xaxis[ids].copy(),
            1000.0 * data.xpos[bodies],
            data.xmat[bodies].reshape(3, 3, 3).copy(),
            1000.0 * data.site(site).xpos.copy(),
        )
    origin = raw["middle"][1][0]
    x = unit(raw["middle"][5] - origin)
    y = raw["index"][1][0] - raw["little"][1][0]
    y = unit(y - np.dot(y, x) * x)
    frame = np.column_stack([x, y, np.cross(x, y)])
    fingers = {}
    for f, (ids, anchor, axis, bpos, brot, tip) in raw.items():
        if f == "thumb":
            # Orient by the tip's motion: flexion ulnar (-y), ab/adduction palmar (-z).
            toward = -frame[:, [1, 2, 1, 1]].T
            sign = np.sign(np.einsum("ij,ij->i", np.cross(axis, tip - anchor), toward))
        else:
            # Orient each axis as fingerfit's angles: flexion about ~+y, ab/adduction ~+z.
            ref = np.array([frame[:, 1], frame[:, 2], frame[:, 1], frame[:, 1]])
            sign = np.sign(np.einsum("ij,ij->i", axis, ref))
        fingers[f] = MyoFinger(
            f,
            tuple(model.joint(i).name for i in ids),
            np.array([model.jnt_qposadr[i] for i in ids]),
            sign,
            anchor,
            sign[:, None] * axis,
            bpos,
            brot,
            tip,
        )
    if np.dot(fingers["middle"].axis[0], frame[:, 1]) < 0.9:
        raise FingerfitError("MyoHand's middle MCP flexion axis is not along the hand's y")
    thumb = fingers.pop("thumb")
    return MyoHandReference(fingers, origin, frame, thumb)


@dataclass(frozen=True)
class MyoHandSubject:
    """One subject's MyoHand: the reference hand scaled, its links and axes perturbed.

    All in the MuJoCo world frame before placement (mm, rad).

    Attributes
    ----------
    scale : float
        Whole-hand size factor (the subject size factor of the default world, N(1, 0.06)).
    length_factor : dict[str, ndarray]
        Per finger ``(3,)``: factors of the links MCP-PIP, PIP-DIP, DIP-tip site, N(1, 0.04)
        (``thumb``: CMC-MCP, MCP-IP, IP-tip site; added by :func:`sample_thumb`).
    axis_rotation : dict[str, ndarray]
        Per finger ``(4, 3)``: rotation vectors (rad, MuJoCo world) turning each zero-posture
        axis (``mp``, ``mp_abduction``, ``pip``, ``dip``; ``thumb``: ``cmc``,
        ``cmc_abduction``, ``mcp``, ``ip``), N(0, 3 deg x tilt_scale) per component.
    placement : ndarray, shape (3, 3)
        Rotation of MuJoCo world coordinates into tracker coordinates
        (``hand_rotation @ reference.frame.T``); the scaled middle MCP anchor goes to the
        hand origin.
    """

    scale: float
    length_factor: dict[str, FloatArray]
    axis_rotation: dict[str, FloatArray]
    placement: FloatArray

    def document(self) -> dict:
        """JSON-ready parameters (``truth.json`` ``myohand``)."""
        return {
            "scale": self.scale,
            "length_factor": {f: v.tolist() for f, v in self.length_factor.items()},
            "axis_rotation_rad": {f: v.tolist() for f, v in self.axis_rotation.items()},
            "placement": self.placement.tolist(),
        }


def check_config(hand: str) -> None:
    """Refuse, in one line naming the option, what the MyoHand world cannot simulate
    (``hand``: the simulated hand, ``left`` or ``right``).

    Raises
    ------
    FingerfitError
        A left hand, or ``myo-sim``/``mujoco`` missing.
    """
    if hand != "right":
        raise FingerfitError("the MyoHand world is a right hand: use --hand right", field="--hand")
    _myo_sim()
    _mujoco()


def sample_fingers(
    rng: np.random.Generator,
    names: list[str],
    *,
    hand_scale: float,
    hand_rotation: FloatArray,
    hand_origin: FloatArray,
    tilt_scale: float = 1.0,
    reference: MyoHandReference | None = None,
) -> tuple[dict[str, FingerAnatomy], MyoHandSubject]:
    """Draw one subject's MyoHand fingers and place them in tracker coordinates.

    Per finger (in ``names`` order) the link factors ``(3,)`` then the axis rotation
    vectors ``(4, 3)`` are drawn from ``rng``, then the dorsal landmark depths ``(3,)``.

    Parameters
    ----------
    rng : numpy Generator
    names : list of str
        Fingers (subset of :data:`FINGERS`).
    hand_scale : float
        Subject size factor (scales the whole hand about the middle MCP).
    hand_rotation : ndarray, shape (3, 3)
        Hand anatomical frame in tracker coordinates at the reference posture.
    hand_origin : ndarray, shape (3,)
        Where the middle MCP anchor goes (tracker, mm).
    tilt_scale : float
        Scales the per-subject axis rotations (0: MyoHand's axes exactly).
    reference : MyoHandReference, optional
        Defaults to :func:`reference_geometry` of :func:`load_model`.

    Returns
    -------
    fingers : dict[str, FingerAnatomy]
        Tracker coordinates at the reference posture (mm); ``order`` flexion first,
        ``rolling`` zero (MyoHand's axes are fixed), ``tip`` the fingertip site,
        landmarks ``mp|pip|dip`` dorsal of the anchors by the default depths x size,
        ``tip`` the tip site.
    subject : MyoHandSubject
    """
    ref = reference_geometry() if reference is None else reference
    placement = hand_rotation @ ref.frame.T
    lengths: dict[str, FloatArray] = {}
    rotations: dict[str, FloatArray] = {}
    fingers: dict[str, FingerAnatomy] = {}
    for f in names:
        lengths[f] = rng.normal(1.0, LENGTH_SD, 3)
        rotations[f] = rng.normal(0.0, np.radians(AXIS_SD_DEG) * tilt_scale, (4, 3))
        anchor, axis, tip = subject_geometry(
            ref.fingers[f], ref.origin, hand_scale, lengths[f], rotations[f]
        )
        # MuJoCo world (mm, origin at the scaled middle MCP) -> tracker.
        centre = anchor[[0, 2, 3]] @ placement.T + hand_origin
        axis_t = axis @ placement.T
        tip_t = placement @ tip + hand_origin
        x = unit(tip_t - centre[0])
        z = hand_rotation[:, 2] - np.dot(hand_rotation[:, 2], x) * x
        z = unit(z)
        frame = np.column_stack([x, np.cross(z, x), z])
        depth = DORSAL_DEPTH * hand_scale + rng.normal(0, 0.7, 3)
        landmarks = {j: centre[i] + depth[i] * z for i, j in enumerate(("mp", "pip", "dip"))}
        landmarks["tip"] = tip_t.copy()
        fingers[f] = FingerAnatomy(
            f,
            centre,
            axis_t[[0, 2, 3]],
            centre[0].copy(),
            axis_t[1],
            np.zeros((3, 3)),
            tip_t,
            landmarks,
            frame,
            order=ORDER,
        )
    return fingers, MyoHandSubject(hand_scale, lengths, rotations, placement)


def sample_thumb(
    rng: np.random.Generator,
    subject: MyoHandSubject,
    *,
    hand_origin: FloatArray,
    tilt_scale: float = 1.0,
    reference: MyoHandReference | None = None,
) -> ThumbAnatomy:
    """Draw one subject's MyoHand thumb and place it in tracker coordinates.

    The thumb is scaled with the hand (``subject.scale`` about the middle MCP) and
    perturbed as the fingers are: the links CMC-MCP, MCP-IP, IP-tip site each x N(1, 0.04),
    the four axes (``cmc``, ``cmc_abduction``, ``mcp``, ``ip``) each turned by a rotation
    vector N(0, 3 deg x ``tilt_scale``) per component. Drawn from ``rng`` in this order:
    link factors ``(3,)``, axis rotations ``(4, 3)``, landmark depths ``(3,)``, the pad
    (:func:`~fingerfit.simulate.thumb.sample_pad`). The draws are recorded in
    ``subject.length_factor["thumb"]`` and ``subject.axis_rotation["thumb"]``.

    Parameters
    ----------
    rng : numpy Generator
        The thumb's own generator (the fingers' stream is not touched).
    subject : MyoHandSubject
        The subject's hand (scale, placement) from :func:`sample_fingers`.
    hand_origin : ndarray, shape (3,)
        Where the middle MCP anchor goes (tracker, mm).
    tilt_scale : float
        Scales the axis rotations (0: MyoHand's axes exactly).
    reference : MyoHandReference, optional
        Defaults to :func:`reference_geometry` of :func:`load_model`.

    Returns
    -------
    ThumbAnatomy
        Tracker coordinates at the reference posture (MyoHand's zero posture, the thumb
        straight to within 2.1 deg), mm. ``axis_point``: the CMC anchor for both CMC axes
        (MyoHand's lines intersect), the MCP and IP anchors; ``mcp_abduction`` False (a
        hinge MCP; its placeholder line never turns). ``centre``: the CMC, MCP, IP anchors;
        ``tip``: the tip site; ``frame``: x from the CMC anchor to the tip site, y the IP
        flexion axis made perpendicular to x, z = x x y (the nail side: positive flexion
        turns the tip towards -z); landmarks ``cmc|mcp|ip`` dorsal of the anchors by the
        default world's depths x size (+- 0.7 mm); the pad from the tip site and frame as
        the default world's (:func:`~fingerfit.simulate.thumb.sample_pad`).
    """
    ref = reference_geometry() if reference is None else reference
    lengths = rng.normal(1.0, LENGTH_SD, 3)
    rotations = rng.normal(0.0, np.radians(AXIS_SD_DEG) * tilt_scale, (4, 3))
    anchor, axis, tip = subject_geometry(ref.thumb, ref.origin, subject.scale, lengths, rotations)
    place = subject.placement
    anchor_t = anchor @ place.T + hand_origin
    axis_t = axis @ place.T
    tip_t = place @ tip + hand_origin
    centre = anchor_t[[0, 2, 3]]
    x = unit(tip_t - centre[0])
    y = unit(axis_t[3] - np.dot(axis_t[3], x) * x)
    z = np.cross(x, y)
    frame = np.column_stack([x, y, z])
    depth = THUMB_DORSAL_DEPTH * subject.scale + rng.normal(0.0, 0.7, 3)
    landmarks = {j: centre[i] + depth[i] * z for i, j in enumerate(("cmc", "mcp", "ip"))}
    landmarks["tip"] = tip_t.copy()
    pad = sample_pad(rng, "thumb", tip_t, frame)
    landmarks["pad"] = pad.surface
    subject.length_factor["thumb"] = lengths
    subject.axis_rotation["thumb"] = rotations
    points = dict(zip(THUMB_KEYS, anchor_t, strict=True))
    axes = dict(zip(THUMB_KEYS, axis_t, strict=True))
    return ThumbAnatomy(
        "thumb",
        {**points, "mcp_abduction": anchor_t[2].copy()},
        {**axes, "mcp_abduction": z.copy()},
        centre,
        tip_t,
        pad,
        landmarks,
        frame,
        1.0,
        mcp_abduction=False,
    )


def subject_geometry(
    finger: MyoFinger,
    origin: FloatArray,
    scale: float,
    length_factor: FloatArray,
    axis_rotation: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A finger's (or the thumb's) zero-posture geometry scaled and perturbed (MuJoCo
    world axes, mm).

    The hand is scaled by ``scale`` about ``origin``; then each link (MCP -> PIP -> DIP ->
    tip site) is stretched by its factor, the more distal points following rigidly; each
    axis is turned by its rotation vector.

    Parameters
    ----------
    finger : MyoFinger
    origin : ndarray, shape (3,)
        The middle MCP anchor (mm); the result is relative to it.
    scale : float
    length_factor : ndarray, shape (3,)
    axis_rotation : ndarray, shape (4, 3)
        Rotation vectors (rad) for ``mp``, ``mp_abduction``, ``pip``, ``dip``.

    Returns
    -------
    anchor : ndarray, shape (4, 3)
        Joint anchors relative to the scaled middle MCP (mm).
    axis : ndarray, shape (4, 3)
        Unit axes (oriented as :attr:`MyoFinger.axis`).
    tip : ndarray, shape (3,)
    """
    pts = scale * (np.vstack([finger.anchor[[0, 2, 3]], finger.tip]) - origin)
    links = np.diff(pts, axis=0) * length_factor[:, None]
    pts = pts[0] + np.vstack([np.zeros(3), np.cumsum(links, axis=0)])
    anchor = pts[[0, 0, 1, 2]]
    axis = unit(Rotation.from_rotvec(axis_rotation).apply(finger.axis))
    return anchor, axis, pts[3]


def mujoco_qpos(model: Any, reference: MyoHandReference, angles: dict) -> FloatArray:
    """MuJoCo ``qpos`` of fingerfit joint angles (every other joint 0).

    Parameters
    ----------
    model : mujoco.MjModel
    reference : MyoHandReference
    angles : dict
        finger -> ``mp``, ``mp_abduction``, ``pip``, ``dip`` -> float (rad); ``thumb`` ->
        ``cmc``, ``cmc_abduction``, ``mcp``, ``ip`` (an ``mcp_abduction`` must be 0: the
        thumb's MCP is a hinge in MyoHand).

    Returns
    -------
    ndarray, shape (model.nq,)

    Raises
    ------
    FingerfitError
        A thumb ``mcp_abduction`` other than 0.
    """
    q = np.zeros(model.nq)
    for f, ang in angles.items():
        if f == "thumb":
            if ang.get("mcp_abduction", 0.0) != 0.0:
                raise FingerfitError("MyoHand's thumb MCP has no ab/adduction: it must be 0")
            mf, keys = reference.thumb, THUMB_KEYS
        else:
            mf, keys = reference.fingers[f], ("mp", "mp_abduction", "pip", "dip")
        for k, key in enumerate(keys):
            q[mf.qpos[k]] = mf.sign[k] * ang[key]
    return q


__all__ = [
    "FINGERS",
    "ORDER",
    "THUMB_BODIES",
    "THUMB_JOINT_NAMES",
    "THUMB_KEYS",
    "THUMB_TIP_SITE",
    "MyoFinger",
    "MyoHandReference",
    "MyoHandSubject",
    "check_config",
    "load_model",
    "mujoco_qpos",
    "reference_geometry",
    "sample_fingers",
    "sample_thumb",
    "subject_geometry",
]
