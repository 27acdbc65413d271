"""Thumb protocols of a simulated session: circumduction, opposition, pinches, and the
thumb's part of grasp, reaching and free motion (angles rad, times s, lengths mm).

Opposition and pinch postures come from a small least-squares inverse kinematics on
the true anatomy: the pulp **surfaces** touch, i.e. the pad centres of thumb and finger
end the sum of their pulp half-thicknesses apart, the two pulps facing each other
(tip pinch, opposition); in a key pinch the thumb's pulp lies on the radial side of
the index middle phalanx. The touch holds are exact (no tremor), so the pad distance
during a touch event is exact; the hand drifts slowly throughout (it moves the whole
hand, not the contact).

Every draw comes from the generator passed in (the session's thumb generator), never
from the fingers' stream: adding the thumb leaves the fingers' truth unchanged.

The inverse kinematics of one touch is :mod:`.touch`; its names are importable from here
too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray
from . import motion as mo
from .anatomy import FingerAnatomy
from .thumb import THUMB_KEYS, Pad, ThumbAnatomy, moved
from .touch import FACE_CONE_DEG as FACE_CONE_DEG
from .touch import FINGER_KEYS, key_pinch_site, solve_touch
from .touch import FINGER_LIMITS_DEG as FINGER_LIMITS_DEG
from .touch import INDEX_MIDDLE_HALF_WIDTH as INDEX_MIDDLE_HALF_WIDTH
from .touch import KEY_PINCH_PALMAR as KEY_PINCH_PALMAR
from .touch import THUMB_LIMITS_DEG as THUMB_LIMITS_DEG

#: Relaxed finger posture while the thumb works alone (deg).
FINGER_REST_DEG = {"mp": 10.0, "mp_abduction": 0.0, "pip": 12.0, "dip": 6.0}
#: Starting (prior) postures of opposition, per finger (deg).
OPPOSITION_THUMB_DEG = {
    "index": {"cmc": 25.0, "cmc_abduction": 30.0, "mcp": 15.0, "mcp_abduction": 0.0, "ip": 15.0},
    "middle": {"cmc": 35.0, "cmc_abduction": 35.0, "mcp": 20.0, "mcp_abduction": 0.0, "ip": 15.0},
    "ring": {"cmc": 45.0, "cmc_abduction": 40.0, "mcp": 25.0, "mcp_abduction": 0.0, "ip": 15.0},
    "little": {"cmc": 55.0, "cmc_abduction": 45.0, "mcp": 30.0, "mcp_abduction": 0.0, "ip": 15.0},
}
OPPOSITION_FINGER_DEG = {
    "index": {"mp": 40.0, "mp_abduction": 0.0, "pip": 40.0, "dip": 15.0},
    "middle": {"mp": 45.0, "mp_abduction": 0.0, "pip": 45.0, "dip": 15.0},
    "ring": {"mp": 50.0, "mp_abduction": 0.0, "pip": 50.0, "dip": 20.0},
    "little": {"mp": 55.0, "mp_abduction": 0.0, "pip": 50.0, "dip": 20.0},
}
#: Index posture of a key pinch (deg) and the prior thumb posture.
KEY_PINCH_INDEX_DEG = {"mp": 45.0, "mp_abduction": 0.0, "pip": 65.0, "dip": 35.0}
KEY_PINCH_THUMB_DEG = {
    "cmc": 5.0,
    "cmc_abduction": 15.0,
    "mcp": 15.0,
    "mcp_abduction": 0.0,
    "ip": 20.0,
}
#: Events start and end this long inside the exact hold (s).
EVENT_MARGIN = 0.15


@dataclass(frozen=True)
class Contact:
    """One touch of the thumb in a simulated recording.

    Attributes
    ----------
    kind : {"opposition", "tip_pinch", "key_pinch"}
    target : str
        The finger touched.
    start, end : float
        Event interval (s): inside the hold, where the contact is exact.
    gap : float
        Distance the contact keeps exactly during the event (mm): pad centre to pad
        centre (the sum of the pulp half-thicknesses) for opposition and tip pinch,
        thumb pad centre to the index middle phalanx's radial surface point (the thumb's
        pulp half-thickness) for a key pinch.
    """

    kind: str
    target: str
    start: float
    end: float
    gap: float

    @property
    def pad_to_pad(self) -> bool:
        """Whether the pads of thumb and ``target`` touch (an ``events.csv`` pinch row)."""
        return self.kind in ("opposition", "tip_pinch")


def _rad(d: dict[str, float]) -> dict[str, float]:
    return {k: float(np.radians(v)) for k, v in d.items()}


def _finger_rest(abduction: bool) -> dict[str, float]:
    r = _rad(FINGER_REST_DEG)
    r["mp_abduction"] = 0.0
    return r


def _assemble(
    rng: np.random.Generator,
    postures: list[dict[str, dict[str, float]]],
    digits: list[str],
    rate: float,
    pivot: FloatArray | None,
    hold: float = 1.0,
    move: float = 1.0,
) -> tuple[mo.Motion, FloatArray]:
    """Minimum-jerk path through whole-hand postures (digit -> key -> rad); hand drift."""
    keys = [(d, k) for d in digits for k in (THUMB_KEYS if d == "thumb" else FINGER_KEYS)]
    way = np.array([[p[d][k] for d, k in keys] for p in postures])
    time, values, holds = mo.min_jerk_path(way, hold=hold, move=move, rate=rate)
    angles: dict[str, dict[str, FloatArray]] = {d: {} for d in digits}
    for i, (d, k) in enumerate(keys):
        angles[d][k] = values[:, i].copy()
    return _with_hand(rng, time, angles, pivot), holds


def _with_hand(
    rng: np.random.Generator,
    time: FloatArray,
    angles: dict[str, dict[str, FloatArray]],
    pivot: FloatArray | None,
) -> mo.Motion:
    if pivot is None:
        r, t = np.broadcast_to(np.eye(3), (time.size, 3, 3)).copy(), np.zeros((time.size, 3))
    else:
        r, t = mo.slow_hand_motion(rng, time, 5.0, 10.0, pivot)
    return mo.Motion(time, angles, r, t)


def opposition(
    rng: np.random.Generator,
    thumb: ThumbAnatomy,
    fingers: dict[str, FingerAnatomy],
    pads: dict[str, Pad],
    rate: float,
    *,
    side: float,
    abduction: bool,
    mcp_abduction: bool,
    pivot: FloatArray | None = None,
) -> tuple[mo.Motion, list[Contact]]:
    """Opposition to each fingertip in turn: rest, touch (1 s hold), rest, ...

    The thumb's pad meets each finger's pad; the finger flexes to meet it. Fingers not
    involved stay at the relaxed posture.

    Returns
    -------
    motion : Motion
        ``angles`` for ``thumb`` and every finger of ``fingers``.
    contacts : list of Contact
        One per finger (kind ``opposition``).
    """
    digits = ["thumb", *fingers]
    rest = {f: _finger_rest(abduction) for f in fingers}
    rest["thumb"] = dict.fromkeys(THUMB_KEYS, 0.0)
    postures = [rest]
    gaps = []
    for f, anat in fingers.items():
        tp = _rad(OPPOSITION_THUMB_DEG[f])
        fp = _rad(OPPOSITION_FINGER_DEG[f])
        fp = {k: v + rng.normal(0, np.radians(3.0)) for k, v in fp.items()}
        ta, fa, _ = solve_touch(
            thumb,
            anat,
            pads[f],
            "pad",
            tp,
            fp,
            side=side,
            finger_abduction=abduction,
            mcp_abduction=mcp_abduction,
        )
        touch = {**rest, "thumb": ta, f: fa}
        postures += [touch, rest]
        gaps.append(thumb.pad.half_thickness + pads[f].half_thickness)
    motion, holds = _assemble(rng, postures, digits, rate, pivot)
    contacts = [
        Contact(
            "opposition",
            f,
            holds[2 * i + 1, 0] + EVENT_MARGIN,
            holds[2 * i + 1, 1] - EVENT_MARGIN,
            gaps[i],
        )
        for i, f in enumerate(fingers)
    ]
    return motion, contacts


def pinches(
    rng: np.random.Generator,
    thumb: ThumbAnatomy,
    fingers: dict[str, FingerAnatomy],
    pads: dict[str, Pad],
    rate: float,
    *,
    side: float,
    abduction: bool,
    mcp_abduction: bool,
    repeats: int = 3,
    pivot: FloatArray | None = None,
) -> tuple[mo.Motion, list[Contact]]:
    """Tip pinches (thumb and index pads) alternating with key pinches (thumb pulp on the
    radial side of the index middle phalanx), ``repeats`` of each, each from rest.

    Every repetition starts the solve from a prior posture scattered by 4 deg, so the
    pinch postures differ between repetitions. Needs ``index`` in ``fingers``.
    """
    index = fingers["index"]
    digits = ["thumb", *fingers]
    rest = {f: _finger_rest(abduction) for f in fingers}
    rest["thumb"] = dict.fromkeys(THUMB_KEYS, 0.0)
    postures = [rest]
    kinds: list[tuple[str, float]] = []
    for _ in range(repeats):
        for kind in ("tip_pinch", "key_pinch"):
            if kind == "tip_pinch":
                tp, fp, how = (
                    _rad(OPPOSITION_THUMB_DEG["index"]),
                    _rad(OPPOSITION_FINGER_DEG["index"]),
                    "pad",
                )
                gap = thumb.pad.half_thickness + pads["index"].half_thickness
            else:
                tp, fp, how = _rad(KEY_PINCH_THUMB_DEG), _rad(KEY_PINCH_INDEX_DEG), "key"
                gap = thumb.pad.half_thickness
            jitter = np.radians(4.0)
            tp = {k: v + rng.normal(0, jitter) for k, v in tp.items()}
            fp = {k: v + rng.normal(0, jitter) for k, v in fp.items()}
            if not abduction:
                fp["mp_abduction"] = 0.0
            ta, fa, _ = solve_touch(
                thumb,
                index,
                pads["index"],
                how,
                tp,
                fp,
                side=side,
                finger_abduction=abduction,
                mcp_abduction=mcp_abduction,
            )
            postures += [{**rest, "thumb": ta, "index": fa}, rest]
            kinds.append((kind, gap))
    motion, holds = _assemble(rng, postures, digits, rate, pivot)
    contacts = [
        Contact(
            kind,
            "index",
            holds[2 * i + 1, 0] + EVENT_MARGIN,
            holds[2 * i + 1, 1] - EVENT_MARGIN,
            gap,
        )
        for i, (kind, gap) in enumerate(kinds)
    ]
    return motion, contacts


def circumduction(
    rng: np.random.Generator,
    fingers: list[str],
    rate: float,
    *,
    cycles: int = 4,
    mcp_abduction: bool = True,
    abduction: bool = True,
    pivot: FloatArray | None = None,
) -> mo.Motion:
    """Thumb circumduction: the CMC circles (flexion ~ cos, palmar abduction ~ sin),
    about 3 s per circle, amplitudes 22-30 deg about a centre of ~15 deg; the MCP and IP
    flex and the MCP ab/adducts independently and slowly; the fingers rest, with a faint
    wander. The circle grows in and out over the first and last second.
    """
    period = rng.uniform(2.6, 3.4)
    duration = cycles * period + 1.0
    time = np.arange(round(duration * rate)) / rate
    env = mo.min_jerk(time / 1.0) * mo.min_jerk((duration - time) / 1.0)
    phase = 2 * np.pi * time / period + rng.uniform(0, 2 * np.pi)
    a_f, a_b = np.radians(rng.uniform(22.0, 30.0, 2))
    c_f, c_b = np.radians(rng.uniform(10.0, 20.0, 2))
    th: dict[str, FloatArray] = {
        "cmc": env * (c_f + a_f * np.cos(phase)),
        "cmc_abduction": env * (c_b + a_b * np.sin(phase)),
        "mcp": np.radians(12.0) * (1 + np.tanh(mo.smooth_noise(rng, time, 1.0, 0.3))) * env,
        "ip": np.radians(15.0) * (1 + np.tanh(mo.smooth_noise(rng, time, 1.0, 0.3))) * env,
    }
    wander = np.radians(6.0) * np.tanh(mo.smooth_noise(rng, time, 1.0, 0.3))
    th["mcp_abduction"] = wander * env * float(mcp_abduction)
    angles: dict[str, dict[str, FloatArray]] = {"thumb": {k: th[k] for k in THUMB_KEYS}}
    for f in fingers:
        angles[f] = _finger_wander(rng, time, abduction)
    return _with_hand(rng, time, angles, pivot)


def _finger_wander(
    rng: np.random.Generator, time: FloatArray, abduction: bool
) -> dict[str, FloatArray]:
    """Relaxed fingers: the rest posture with a faint slow wander (about 1 deg)."""
    rest = _rad(FINGER_REST_DEG)
    out = {}
    for k in FINGER_KEYS:
        w = mo.smooth_noise(rng, time, np.radians(1.0), 0.3)
        out[k] = rest[k] + w if k != "mp_abduction" else w * float(abduction)
    return out


def thumb_grasp(
    rng: np.random.Generator, time: FloatArray, clock: FloatArray, mcp_abduction: bool
) -> dict[str, FloatArray]:
    """The thumb's part of cylinder-grasp cycles, following the fingers' cycle.

    Parameters
    ----------
    time : ndarray, shape (n,)
        s.
    clock : ndarray, shape (n,)
        Grasp progress in [0, 1] (the fingers' normalised MP flexion).

    Peak angles (deg, assumption for a 38 mm cylinder; each scattered 8 % per subject):
    CMC flexion 15, CMC palmar abduction 30, MCP 25, MCP abduction 3, IP 30; each joint
    lags its own 0-0.12 s.
    """
    peak = np.radians([15.0, 30.0, 25.0, 3.0, 30.0]) * rng.normal(1.0, 0.08, 5)
    out = {}
    for i, k in enumerate(THUMB_KEYS):
        lag = rng.uniform(0.0, 0.12)
        c = np.interp(time - lag, time, clock)
        tremor = mo.smooth_noise(rng, time, np.radians(0.15), 2.0)
        out[k] = peak[i] * c + tremor
    out["mcp_abduction"] = out["mcp_abduction"] * float(mcp_abduction)
    return out


def thumb_free(
    rng: np.random.Generator, time: FloatArray, mcp_abduction: bool
) -> dict[str, FloatArray]:
    """Free thumb motion: every angle wanders independently within its range (deg):
    CMC -15..45, CMC abduction -10..45, MCP 0..50, MCP abduction -8..8, IP -10..70."""
    ranges = {
        "cmc": (-15.0, 45.0),
        "cmc_abduction": (-10.0, 45.0),
        "mcp": (0.0, 50.0),
        "mcp_abduction": (-8.0, 8.0),
        "ip": (-10.0, 70.0),
    }
    out = {}
    for k in THUMB_KEYS:
        lo, hi = np.radians(ranges[k])
        u = mo.smooth_noise(rng, time, 1.0, 0.5)
        out[k] = lo + (hi - lo) * 0.5 * (1 + np.tanh(u))
    out["mcp_abduction"] = out["mcp_abduction"] * float(mcp_abduction)
    return out


def thumb_hold(rng: np.random.Generator, time: FloatArray) -> dict[str, FloatArray]:
    """The thumb at a relaxed posture (5-15 deg at each joint) with a faint wander."""
    base = np.radians(rng.uniform(5.0, 15.0, len(THUMB_KEYS)))
    base[THUMB_KEYS.index("mcp_abduction")] = 0.0
    return {
        k: base[i] + mo.smooth_noise(rng, time, np.radians(0.5), 0.3)
        for i, k in enumerate(THUMB_KEYS)
    }


def pad_distance(
    thumb_distal: tuple[FloatArray, FloatArray],
    thumb: ThumbAnatomy,
    other: tuple[FloatArray, FloatArray],
    point: FloatArray,
) -> FloatArray:
    """Distance ``(n,)`` (mm) from the thumb's pad centre to a point ``(3,)`` of another
    segment (a pad centre, or the key-pinch site), both given at the reference posture
    and moved by their segments' motions ``(R (n, 3, 3), t (n, 3))``."""
    return np.linalg.norm(moved(thumb_distal, thumb.pad.centre) - moved(other, point), axis=1)


__all__ = [
    "Contact",
    "circumduction",
    "key_pinch_site",
    "opposition",
    "pad_distance",
    "pinches",
    "solve_touch",
    "thumb_free",
    "thumb_grasp",
    "thumb_hold",
]
