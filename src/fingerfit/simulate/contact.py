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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..transforms import FloatArray
from . import motion as mo
from .anatomy import FingerAnatomy, joint_transform
from .thumb import THUMB_KEYS, Pad, ThumbAnatomy, moved

FINGER_KEYS = mo.ANGLE_KEYS
#: Joint limits of the inverse kinematics (deg).
THUMB_LIMITS_DEG = {
    "cmc": (-30.0, 70.0),
    "cmc_abduction": (-20.0, 70.0),
    "mcp": (-10.0, 70.0),
    "mcp_abduction": (-15.0, 15.0),
    "ip": (-15.0, 85.0),
}
FINGER_LIMITS_DEG = {
    "mp": (0.0, 90.0),
    "mp_abduction": (-20.0, 20.0),
    "pip": (0.0, 100.0),
    "dip": (0.0, 80.0),
}
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
#: Half-width of the index middle phalanx (mm; its radial surface, assumption) and how
#: far palmar of the phalanx axis the key-pinch contact lies.
INDEX_MIDDLE_HALF_WIDTH = 8.0
KEY_PINCH_PALMAR = 1.5
# Weights of the inverse kinematics: contact distance (per mm), facing (per unit),
# nail-edge distance outside 13.5-16.5 mm (per mm), posture prior (per rad).
_W_DIST, _W_FACE, _W_TIP, _W_PRIOR = 30.0, 30.0, 100.0, 3.0
#: The line of contact must leave each pulp within this angle of its palmar normal (deg):
#: the pulp is rounded, a touch anywhere on it within the cone is a pad touch.
FACE_CONE_DEG = 40.0
_FACE_COS = float(np.cos(np.radians(FACE_CONE_DEG)))
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


def key_pinch_site(finger: FingerAnatomy, side: float) -> tuple[FloatArray, FloatArray]:
    """Key-pinch contact point ``(3,)`` on the radial side of a middle phalanx and its
    outward unit normal ``(3,)`` (reference posture, tracker frame, mm)."""
    _, y, z = finger.frame.T
    radial = side * y
    point = (
        0.5 * (finger.centre[1] + finger.centre[2])
        + INDEX_MIDDLE_HALF_WIDTH * radial
        - KEY_PINCH_PALMAR * z
    )
    return point, radial


def _hinge(x: FloatArray) -> FloatArray:
    """Smooth ``max(0, x)`` (within 0.005 of it), so the solver converges quickly."""
    return 0.5 * (x + np.sqrt(x * x + 1e-4))


def _chain(
    lines: list[tuple[FloatArray, FloatArray, FloatArray | None]], angles: FloatArray
) -> list[tuple[FloatArray, FloatArray]]:
    """Cumulative motions ``(R (b, 3, 3), t (b, 3))`` of rotations about ``lines``
    (centre, axis, rolling) by ``angles (b, len(lines))``, for a batch of b postures."""
    b = angles.shape[0]
    r, t = np.broadcast_to(np.eye(3), (b, 3, 3)), np.zeros((b, 3))
    out = []
    for j, (c, a, roll) in enumerate(lines):
        rj, tj = joint_transform(c, a, angles[:, j], roll)
        r, t = r @ rj, np.einsum("nij,nj->ni", r, tj) + t
        out.append((r, t))
    return out


def solve_touch(
    thumb: ThumbAnatomy,
    finger: FingerAnatomy,
    finger_pad: Pad,
    kind: str,
    thumb_prior: dict[str, float],
    finger_prior: dict[str, float],
    *,
    side: float,
    finger_abduction: bool,
    mcp_abduction: bool,
) -> tuple[dict[str, float], dict[str, float], float]:
    """Thumb (and finger) posture of one touch, by least squares.

    Residuals: the contact distance (pad centre to pad centre = the sum of the pulp
    half-thicknesses; for a key pinch the thumb pad centre to the site on the radial
    side of the middle phalanx = the thumb's half-thickness), weighted to converge to
    ~1e-12 mm by a final Gauss-Newton polish; softly, the line of contact within
    :data:`FACE_CONE_DEG` of each pulp's palmar normal (of the side's normal in a key
    pinch), the nail edges of a pad touch 13.5-16.5 mm apart, and the posture near
    ``*_prior``; joint limits as bounds.

    Parameters
    ----------
    thumb, finger : anatomy
    finger_pad : Pad
        The finger's pulp (pad touches).
    kind : {"pad", "key"}
        Pads touching (tip pinch, opposition), or the thumb's pulp on the radial side of
        the finger's middle phalanx (key pinch; the finger keeps ``finger_prior``).
    thumb_prior, finger_prior : dict
        Starting postures (rad) the solution stays near.
    side : float
        +1 right hand, -1 left.
    finger_abduction, mcp_abduction : bool
        Whether the finger's MP ab/adduction and the thumb's MCP ab/adduction may move.

    Returns
    -------
    thumb_angles, finger_angles : dict[str, float]
        rad, every key of :data:`~.thumb.THUMB_KEYS`, resp. the finger keys.
    error : float
        Contact distance minus the intended one (mm) after the solve.
    """
    t_keys = tuple(k for k in THUMB_KEYS if mcp_abduction or k != "mcp_abduction")
    if kind == "pad":
        f_keys = tuple(k for k in FINGER_KEYS if finger_abduction or k != "mp_abduction")
    else:
        f_keys = ()
    fixed = {("thumb", k): 0.0 for k in THUMB_KEYS if k not in t_keys}
    for k in FINGER_KEYS:
        if k not in f_keys:
            fixed[("finger", k)] = (
                finger_prior[k] if (k != "mp_abduction" or finger_abduction) else 0.0
            )
    free = [("thumb", k) for k in t_keys] + [("finger", k) for k in f_keys]
    limits = {**THUMB_LIMITS_DEG, **FINGER_LIMITS_DEG}
    lo = np.radians([limits[k][0] for _, k in free])
    hi = np.radians([limits[k][1] for _, k in free])
    prior = {("thumb", k): v for k, v in thumb_prior.items()}
    prior.update({("finger", k): v for k, v in finger_prior.items()})
    q0 = np.clip(np.array([prior[f] for f in free]), lo + 1e-9, hi - 1e-9)
    h_t = thumb.pad.half_thickness
    if kind == "pad":
        gap = h_t + finger_pad.half_thickness
    else:
        gap = h_t
        site, normal = key_pinch_site(finger, side)
    z_t, z_f = thumb.frame[:, 2], finger.frame[:, 2]
    t_lines = [(thumb.axis_point[k], thumb.axis[k], None) for k in THUMB_KEYS]
    # The finger's chain in its MP order (proximal first): ab/adduction first in the
    # default world, flexion first in the MyoHand world (FingerAnatomy.order).
    ab_line = (finger.abduction_point, finger.abduction_axis, None)
    flexion = [(finger.centre[i], finger.axis[i], finger.rolling[i]) for i in range(3)]
    if finger.order[0] == "mp_abduction":
        f_lines = [ab_line, *flexion]
        f_order: tuple[str, ...] = ("mp_abduction", "mp", "pip", "dip")
    else:
        f_lines = [flexion[0], ab_line, *flexion[1:]]
        f_order = ("mp", "mp_abduction", "pip", "dip")
    slots = [("thumb", k) for k in THUMB_KEYS] + [("finger", k) for k in f_order]
    base = np.array([fixed.get(sl, 0.0) for sl in slots])
    where = np.array([slots.index(f) for f in free])

    def split(q: FloatArray) -> tuple[dict[str, float], dict[str, float]]:
        val = base.copy()
        val[where] = q
        return (
            {k: float(val[i]) for i, k in enumerate(THUMB_KEYS)},
            {k: float(val[5 + f_order.index(k)]) for k in FINGER_KEYS},
        )

    def residuals(qs: FloatArray) -> FloatArray:
        """Residuals ``(b, m)`` of a batch of free-angle vectors ``qs (b, n_free)``."""
        val = np.repeat(base[None], qs.shape[0], axis=0)
        val[:, where] = qs
        rt, tt = _chain(t_lines, val[:, :5])[-1]
        pt = rt @ thumb.pad.centre + tt
        segs = _chain(f_lines, val[:, 5:])
        if kind == "pad":
            rf, tf = segs[3]
            pf = rf @ finger_pad.centre + tf
            nf = rf @ z_f  # the finger pulp faces -z: the thumb lies along -nf
            tip_gap = np.linalg.norm((rt @ thumb.tip + tt) - (rf @ finger.tip + tf), axis=1)
            tips = np.column_stack([_hinge(13.5 - tip_gap), _hinge(tip_gap - 16.5)])
        else:
            rf, tf = segs[2]
            pf = rf @ site + tf
            nf = -(rf @ normal)  # the side faces +normal: the thumb lies along +normal
            tips = np.zeros((qs.shape[0], 2))
        d = pf - pt
        dist = np.linalg.norm(d, axis=1)
        u = d / dist[:, None]
        face_t = _hinge(_FACE_COS + np.einsum("ni,ni->n", rt @ z_t, u))
        face_f = _hinge(_FACE_COS - np.einsum("ni,ni->n", nf, u))
        return np.column_stack(
            [
                _W_DIST * (dist - gap),
                _W_FACE * face_t,
                _W_FACE * face_f,
                _W_TIP * tips,
                _W_PRIOR * (qs - q0),
            ]
        )

    step = 1e-7

    def residual(q: FloatArray) -> FloatArray:
        return residuals(q[None])[0]

    def jacobian(q: FloatArray) -> FloatArray:
        # Forward differences, every column from one batched evaluation.
        r = residuals(np.vstack([q, q + step * np.eye(q.size)]))
        return ((r[1:] - r[0]) / step).T

    def solve(start: FloatArray) -> FloatArray:
        # 150 evaluations settle the soft terms well enough; only where the nail edges
        # are still under 13 mm apart does the solve go on (to convergence).
        sol = least_squares(
            residual, start, jac=jacobian, bounds=(lo, hi), method="trf", max_nfev=150
        )
        if kind == "pad" and sol.status == 0 and np.max(np.abs(sol.fun[3:5])) > 0.5 * _W_TIP:
            sol = least_squares(residual, sol.x, jac=jacobian, bounds=(lo, hi), method="trf")
        # Polish the contact distance alone to ~1e-12 mm: minimal-norm Gauss-Newton steps
        # on the joints not at a limit (the soft terms barely change over such a step).
        q = sol.x.copy()
        inner = (q > lo + 1e-6) & (q < hi - 1e-6)
        for _ in range(8):
            r0 = residual(q)[0] / _W_DIST
            if abs(r0) < 1e-12:
                break
            grad = jacobian(q)[0] / _W_DIST * inner
            q = np.clip(q - r0 * grad / (grad @ grad), lo, hi)
        return q

    def tip_gap(q: FloatArray) -> float:
        ta, fa = split(q)
        rt, tt = _chain(t_lines, np.array([[ta[k] for k in THUMB_KEYS]]))[-1]
        rf, tf = _chain(f_lines, np.array([[fa[k] for k in f_order]]))[-1]
        return float(np.linalg.norm((rt @ thumb.tip + tt) - (rf @ finger.tip + tf)))

    # A local minimum with the nail edges outside 12.5-17.5 mm is left for another start
    # near the prior (a fixed sequence, so the result stays deterministic).
    q = solve(q0)
    if kind == "pad":
        restarts = np.random.default_rng(len(free)).normal(0.0, np.radians(8.0), (6, q0.size))
        best, margin = q, 0.0
        for jitter in (None, *restarts):
            if jitter is not None:
                q = solve(np.clip(q0 + jitter, lo + 1e-9, hi - 1e-9))
            g = tip_gap(q)
            m = min(g - 12.5, 17.5 - g)
            if m >= 0.0:
                best = q
                break
            if jitter is None or m > margin:
                best, margin = q, m
        q = best
    ta, fa = split(q)
    err = float(residual(q)[0] / _W_DIST)
    return ta, fa, err


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
