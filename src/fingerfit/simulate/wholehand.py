"""The thumb's part of a simulated session: its anatomy, sensors, recordings and truth.

:func:`setup` draws the thumb (when the session has one) and every digit's pad from the
thumb's own generator (seeded from ``(seed, "thumb")``), so the fingers' random stream,
and with it their truth, is the same with or without the thumb. :mod:`.study` calls the
helpers here to add the thumb to each recording and to the truth.

Recordings the thumb adds (all listed under ``grasp`` in ``session.toml``):
``thumb_circumduction.csv`` (always), ``thumb_opposition.csv`` (with at least one
finger: opposition to each fingertip, every digit moving) and ``pinch.csv`` (with the
index: tip and key pinches). The thumb also moves in ``grasp.csv`` (with the fingers'
grasp cycle), ``targets.csv`` (held) and ``test.csv`` (free motion).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..digits import THUMB_JOINTS, THUMB_SEGMENTS
from ..transforms import FloatArray
from . import contact as ct
from . import motion as mo
from . import myohand as mh
from .anatomy import FingerAnatomy
from .sensors import SensorMount, TrackerErrors, mount, sensor_poses
from .thumb import (
    NOMINAL_HAND_LENGTH,
    THUMB_KEYS,
    Pad,
    ThumbAnatomy,
    moved,
    sample_pad,
    sample_thumb,
    thumb_segment_motions,
)

#: Second entry of the thumb generator's seed (``"thum"`` in ASCII).
THUMB_STREAM = 0x7468756D
#: Dorsal height of the thumb sensors above the thumb's line (mm): metacarpal,
#: proximal, distal (on the nail).
THUMB_SENSOR_HEIGHT = np.array([9.0, 7.0, 5.0])
THUMB_SENSOR_STA = np.array([1.2, 1.0, 0.3])
#: Joints whose angles drive each thumb sensor's skin sliding.
THUMB_ADJACENT = {"metacarpal": ("cmc", "mcp"), "proximal": ("mcp", "ip"), "distal": ("ip", None)}
CIRCUMDUCTION = "thumb_circumduction.csv"
OPPOSITION = "thumb_opposition.csv"
PINCH = "pinch.csv"


def thumb_generator(seed: int) -> np.random.Generator:
    """The thumb's generator of a session simulated with ``seed`` (independent stream)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), THUMB_STREAM]))


@dataclass
class ThumbSetup:
    """What the thumb adds to one simulated subject.

    Attributes
    ----------
    rng : numpy Generator
        The thumb's generator (anatomy, pads, mounts, protocols, its tracker noise).
    thumb : ThumbAnatomy or None
        None when the session has no thumb.
    pads : dict[str, Pad]
        Every digit's pad (pulp centre and half-thickness), thumb included when present.
    mounts : dict[str, SensorMount]
        The thumb's sensors ``thumb.metacarpal|proximal|distal``.
    side : float
        +1 right hand, -1 left.
    """

    rng: np.random.Generator
    thumb: ThumbAnatomy | None
    pads: dict[str, Pad]
    mounts: dict[str, SensorMount] = field(default_factory=dict)
    side: float = 1.0


def setup(
    seed: int,
    *,
    with_thumb: bool,
    hand: str,
    fingers: dict[str, FingerAnatomy],
    hand_rotation: FloatArray,
    hand_origin: FloatArray,
    hand_scale: float,
    tilt_scale: float,
    sta: float,
    myohand: mh.MyoHandSubject | None = None,
) -> ThumbSetup:
    """Draw the thumb (if ``with_thumb``), its sensor mounts and every digit's pad.

    With ``myohand`` (the MyoHand world) the thumb is MyoHand's
    (:func:`.myohand.sample_thumb`, a hinge MCP), otherwise the default world's.
    """
    rng = thumb_generator(seed)
    thumb = None
    pads: dict[str, Pad] = {}
    mounts: dict[str, SensorMount] = {}
    if with_thumb and myohand is not None:
        thumb = mh.sample_thumb(rng, myohand, hand_origin=hand_origin, tilt_scale=tilt_scale)
        pads["thumb"] = thumb.pad
    elif with_thumb:
        thumb = sample_thumb(
            rng,
            NOMINAL_HAND_LENGTH * hand_scale,
            hand,
            hand_rotation=hand_rotation,
            hand_origin=hand_origin,
            tilt_scale=tilt_scale,
        )
        pads["thumb"] = thumb.pad
    for f, anat in fingers.items():
        pads[f] = sample_pad(rng, f, anat.tip, anat.frame)
    if thumb is not None:
        pts = np.vstack([thumb.centre, thumb.tip])
        for i, s in enumerate(THUMB_SEGMENTS):
            site = 0.5 * (pts[i] + pts[i + 1]) + THUMB_SENSOR_HEIGHT[i] * thumb.frame[:, 2]
            mounts[f"thumb.{s}"] = mount(
                rng,
                f"thumb.{s}",
                site,
                thumb.frame,
                offset_sd=np.array([2.0, 1.5, 0.5]),
                sta=THUMB_SENSOR_STA[i] * sta,
            )
    return ThumbSetup(rng, thumb, pads, mounts, 1.0 if hand == "right" else -1.0)


def run_thumb(
    ts: ThumbSetup,
    angles: dict[str, FloatArray],
    hand: tuple[FloatArray, FloatArray],
    tracker: TrackerErrors,
) -> tuple[dict[str, tuple[FloatArray, FloatArray]], dict]:
    """Move the thumb: measured sensor poses and truth of one recording.

    Returns
    -------
    measured : dict
        ``thumb.<segment>`` -> measured ``(position (n, 3), rotation (n, 3, 3))``.
    truth : dict
        ``tip`` ``(n, 3)``, ``pad`` ``(n, 3)``, ``sensors`` (noise-free poses) and
        ``motions`` (segment motions ``(R, t)``), keyed like the fingers' truth.
    """
    assert ts.thumb is not None
    seg = thumb_segment_motions(ts.thumb, angles, hand)
    zero = np.zeros(angles["cmc"].shape[0])
    out: dict = {
        "tip": moved(seg["distal"], ts.thumb.tip),
        "pad": moved(seg["distal"], ts.thumb.pad.centre),
        "sensors": {},
        "motions": {},
    }
    measured = {}
    for s in THUMB_SEGMENTS:
        a, b = THUMB_ADJACENT[s]
        name = f"thumb.{s}"
        p, r = sensor_poses(ts.mounts[name], seg[s], (angles[a], zero if b is None else angles[b]))
        out["sensors"][name] = (p, r)
        out["motions"][name] = seg[s]
        measured[name] = tracker.apply(ts.rng, p, r)
    return measured, out


def static_angles(n: int) -> dict[str, FloatArray]:
    """The thumb at the reference posture (every angle 0) for ``n`` frames."""
    return {k: np.zeros(n) for k in THUMB_KEYS}


def grasp_angles(
    ts: ThumbSetup, motion: mo.Motion, fingers: list[str], mcp_abduction: bool
) -> dict[str, FloatArray]:
    """The thumb's grasp, on the clock of the fingers' grasp cycle in ``motion`` (the MCP
    ab/adduction only with ``mcp_abduction`` and a thumb that has one)."""
    assert ts.thumb is not None
    mp = np.mean([motion.angles[f]["mp"] for f in fingers], axis=0)
    clock = np.clip(mp / max(float(mp.max()), 1e-9), 0.0, 1.0)
    mcp_abduction = mcp_abduction and ts.thumb.mcp_abduction
    return ct.thumb_grasp(ts.rng, motion.time, clock, mcp_abduction)


def protocols(
    ts: ThumbSetup,
    fingers: dict[str, FingerAnatomy],
    rate: float,
    *,
    abduction: bool,
    pivot: FloatArray,
    circumduction_mcp_abduction: bool | None = None,
) -> list[tuple[str, mo.Motion, list[ct.Contact]]]:
    """The thumb's calibration recordings: circumduction, opposition, pinches.

    ``circumduction_mcp_abduction`` (default: ``abduction``) switches the MCP's
    ab/adduction in circumduction alone (opposition and pinches follow ``abduction``).
    A thumb without MCP ab/adduction (:attr:`ThumbAnatomy.mcp_abduction` False) never
    ab/adducts its MCP (the touches are solved without it).

    Returns
    -------
    list of (name, Motion, contacts)
        Every digit of the session moves in each (the fingers relaxed in circumduction).
    """
    assert ts.thumb is not None
    has_mcp = ts.thumb.mcp_abduction
    out: list[tuple[str, mo.Motion, list[ct.Contact]]] = [
        (
            CIRCUMDUCTION,
            ct.circumduction(
                ts.rng,
                list(fingers),
                rate,
                mcp_abduction=has_mcp
                and (
                    abduction
                    if circumduction_mcp_abduction is None
                    else circumduction_mcp_abduction
                ),
                abduction=abduction,
                pivot=pivot,
            ),
            [],
        )
    ]
    kw = dict(side=ts.side, abduction=abduction, mcp_abduction=abduction and has_mcp, pivot=pivot)
    if fingers:
        m, c = ct.opposition(ts.rng, ts.thumb, fingers, ts.pads, rate, **kw)
        out.append((OPPOSITION, m, c))
    if "index" in fingers:
        m, c = ct.pinches(ts.rng, ts.thumb, fingers, ts.pads, rate, **kw)
        out.append((PINCH, m, c))
    return out


def contact_truth(
    ts: ThumbSetup,
    fingers: dict[str, FingerAnatomy],
    recording: str,
    contacts: list[ct.Contact],
    frames: dict,
) -> list[dict]:
    """Truth of each touch: the intended gap and the true distances during the event (mm).

    ``distance_*``: pad centre to pad centre (tip pinch, opposition), or thumb pad centre
    to the key-pinch site on the index middle phalanx; ``tip_distance_*``: nail edge to
    nail edge.
    """
    assert ts.thumb is not None
    time = frames["time"]
    out = []
    for c in contacts:
        sel = (time >= c.start) & (time <= c.end)
        if c.pad_to_pad:
            d = np.linalg.norm(frames["pad"]["thumb"][sel] - frames["pad"][c.target][sel], axis=1)
        else:
            site, _ = ct.key_pinch_site(fingers[c.target], ts.side)
            mid = frames["motions"][f"{c.target}.middle"]
            d = np.linalg.norm(
                frames["pad"]["thumb"][sel] - moved((mid[0][sel], mid[1][sel]), site), axis=1
            )
        tips = np.linalg.norm(frames["tip"]["thumb"][sel] - frames["tip"][c.target][sel], axis=1)
        out.append(
            {
                "recording": recording,
                "kind": c.kind,
                "digit": "thumb",
                "target": c.target,
                "start": c.start,
                "end": c.end,
                "in_events_csv": c.pad_to_pad,
                "gap_mm": c.gap,
                "distance_min_mm": float(d.min()),
                "distance_max_mm": float(d.max()),
                "tip_distance_min_mm": float(tips.min()),
                "tip_distance_max_mm": float(tips.max()),
            }
        )
    return out


def thumb_document(th: ThumbAnatomy, ref_sensor: dict[str, tuple[FloatArray, FloatArray]]) -> dict:
    """The thumb's entry of ``truth.json`` (tracker coordinates at the reference posture,
    and each axis in its parent sensor frame ``*_in_parent``)."""
    parents = {
        "cmc": "hand",
        "cmc_abduction": "hand",
        "mcp": "thumb.metacarpal",
        "mcp_abduction": "thumb.metacarpal",
        "ip": "thumb.proximal",
    }
    joints = {}
    # A hinge MCP (MyoHand) has no ab/adduction line: none is written.
    two = ("cmc", "mcp") if th.mcp_abduction else ("cmc",)
    for k in THUMB_KEYS:
        if k == "mcp_abduction" and not th.mcp_abduction:
            continue
        pp, pr = ref_sensor[parents[k]]
        joints[k] = {
            "center": th.axis_point[k].tolist(),
            "axis": th.axis[k].tolist(),
            "parent_sensor": parents[k],
            "center_in_parent": (pr.T @ (th.axis_point[k] - pp)).tolist(),
            "axis_in_parent": (pr.T @ th.axis[k]).tolist(),
        }
    return {
        "joints": joints,
        "axis_order": {j: [j, f"{j}_abduction"] for j in two},
        "axis_offset_mm": {j: th.offset(j) for j in two},
        "axes_angle_deg": {j: float(np.degrees(th.axes_angle(j))) for j in two},
        "segment_lengths": dict(zip(THUMB_SEGMENTS, th.lengths.tolist(), strict=True)),
        "joint_centers": dict(zip(THUMB_JOINTS, th.centre.tolist(), strict=True)),
        "frame": th.frame.tolist(),
        "tip": th.tip.tolist(),
        "landmarks": {k: v.tolist() for k, v in th.landmarks.items()},
    }


__all__ = [
    "ThumbSetup",
    "contact_truth",
    "grasp_angles",
    "protocols",
    "run_thumb",
    "setup",
    "static_angles",
    "thumb_document",
    "thumb_generator",
]
