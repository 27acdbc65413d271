"""One touch of the thumb solved on the true anatomy: a small least-squares inverse
kinematics (:func:`solve_touch`) in which the pulp **surfaces** touch (pad centres the
sum of their half-thicknesses apart, the two pulps facing each other), or, in a key
pinch, the thumb's pulp lies on the radial side of the index middle phalanx
(:func:`key_pinch_site`); joint limits as bounds. :mod:`.contact` builds the thumb's
protocols from these postures (angles rad, lengths mm)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..transforms import FloatArray
from . import motion as mo
from .anatomy import FingerAnatomy, joint_transform
from .thumb import THUMB_KEYS, Pad, ThumbAnatomy

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
