"""Joint-angle and hand-motion protocols of a simulated session (rad, mm, s).

* :func:`static` -- the reference recording: stretched posture, still hand;
* :func:`grasp` -- cylinder-grasp cycles with static holds, per-joint lags,
  amplitude scatter and a slowly moving hand (paper section 4);
* :func:`free` -- free motion off the grasp synergy (independent joints);
* target reaching is assembled in :mod:`.study` from :func:`min_jerk_path`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..transforms import FloatArray

ANGLE_KEYS = ("mp", "mp_abduction", "pip", "dip")
# Mean peak flexion of a 38 mm cylinder grasp (deg): MP, PIP, DIP.
GRASP_PEAK_DEG = np.array([62.0, 78.0, 48.0])


@dataclass
class Motion:
    """Time base, per-finger joint angles and hand motion of one recording.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Seconds.
    angles : dict[str, dict[str, ndarray]]
        finger -> ``mp``, ``mp_abduction``, ``pip``, ``dip`` -> ``(n,)`` rad.
    hand_rotation : ndarray, shape (n, 3, 3)
    hand_translation : ndarray, shape (n, 3)
        Hand motion relative to the reference posture (``p' = R p + t``, mm).
    """

    time: FloatArray
    angles: dict[str, dict[str, FloatArray]]
    hand_rotation: FloatArray
    hand_translation: FloatArray


def min_jerk(tau: FloatArray) -> FloatArray:
    """Minimum-jerk blend from 0 to 1 over ``tau`` in [0, 1] (clipped outside)."""
    t = np.clip(tau, 0.0, 1.0)
    return t * t * t * (10 - 15 * t + 6 * t * t)


def smooth_noise(rng: np.random.Generator, time: FloatArray, sd: float, f_max: float) -> FloatArray:
    """Band-limited random signal: a sum of random sinusoids below ``f_max`` Hz with SD ``sd``."""
    k = 12
    f = rng.uniform(0.05, f_max, k)
    ph = rng.uniform(0, 2 * np.pi, k)
    sig = np.sin(2 * np.pi * f[None, :] * time[:, None] + ph).sum(axis=1)
    return sig * sd / np.sqrt(k / 2)


def slow_hand_motion(
    rng: np.random.Generator, time: FloatArray, rot_deg: float, trans_mm: float, pivot: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Slow hand drift about the reference pose, turning about ``pivot (3,)`` (mm).

    Returns rotations ``(n, 3, 3)`` and translations ``(n, 3)`` mm of ``p' = R p + t``.
    """
    rv = np.column_stack([smooth_noise(rng, time, np.radians(rot_deg), 0.15) for _ in range(3)])
    tr = np.column_stack([smooth_noise(rng, time, trans_mm, 0.15) for _ in range(3)])
    r = Rotation.from_rotvec(rv).as_matrix()
    return r, pivot + tr - r @ pivot


def static(fingers: list[str], rate: float, duration: float) -> Motion:
    """Reference recording: all joint angles 0, the hand still at its reference pose."""
    time = np.arange(round(duration * rate)) / rate
    zero = np.zeros_like(time)
    angles = {f: dict.fromkeys(ANGLE_KEYS, zero) for f in fingers}
    return Motion(
        time, angles, np.broadcast_to(np.eye(3), (time.size, 3, 3)).copy(), np.zeros((time.size, 3))
    )


def grasp(
    rng: np.random.Generator,
    fingers: list[str],
    rate: float,
    *,
    cycles: int = 10,
    rom_scale: float = 1.0,
    abduction_coupling: FloatArray | None = None,
    abduction: bool = True,
    abduction_wander: tuple[float, float] = (np.radians(1.0), 0.3),
    pivot: FloatArray | None = None,
) -> Motion:
    """Cylinder-grasp cycles: open hold, flex, closed hold, extend.

    Each cycle lasts about 2 s; each joint follows a minimum-jerk profile with
    its own lag (MP leads, DIP lags by up to ~0.15 s) and its own amplitude
    scatter per cycle (~8 %); the MP ab/adducts with flexion by a subject-
    specific coupling. A faint tremor keeps the holds from being perfectly static.

    Parameters
    ----------
    rng : numpy Generator
    fingers : list of str
    rate : float
        Hz.
    cycles : int
    rom_scale : float
        Scales the peak flexion (1 = full cylinder grasp).
    abduction_coupling : ndarray, shape (n_fingers,), optional
        rad of ab/adduction per rad of MP flexion per finger.
    abduction : bool
        MP ab/adduction at all (the coupling plus a slow wander).
    abduction_wander : (float, float)
        SD (rad) and highest frequency (Hz) of the MP ab/adduction's wander independent of
        flexion (:func:`smooth_noise`; default about 1 deg below 0.3 Hz).
    pivot : ndarray, shape (3,), optional
        Point the hand turns about (mm); without it the hand does not move.
    """
    hold0 = rng.uniform(0.3, 0.45, cycles)
    flex = rng.uniform(0.55, 0.75, cycles)
    hold1 = rng.uniform(0.3, 0.5, cycles)
    ext = rng.uniform(0.55, 0.75, cycles)
    period = hold0 + flex + hold1 + ext
    starts = np.concatenate([[0.0], np.cumsum(period)])
    duration = starts[-1] + 0.5
    time = np.arange(round(duration * rate)) / rate
    if abduction_coupling is None:
        abduction_coupling = np.zeros(len(fingers))
    angles: dict[str, dict[str, FloatArray]] = {}
    for fi, finger in enumerate(fingers):
        peak = np.radians(GRASP_PEAK_DEG * rom_scale * rng.normal(1.0, 0.06, 3))
        lags = np.array([0.0, rng.uniform(0.02, 0.08), rng.uniform(0.06, 0.15)])
        out: dict[str, FloatArray] = {}
        for ji, j in enumerate(("mp", "pip", "dip")):
            amp = peak[ji] * rng.normal(1.0, 0.08, cycles)
            # Each joint runs the same cycle clock, delayed by its lag, so every
            # cycle starts and ends at zero flexion.
            lagged = time - lags[ji]
            cyc = np.clip(np.searchsorted(starts, lagged, side="right") - 1, 0, cycles - 1)
            local = lagged - starts[cyc] - hold0[cyc]
            up = min_jerk(local / flex[cyc])
            down = min_jerk((local - flex[cyc] - hold1[cyc]) / ext[cyc])
            theta = amp[cyc] * (up - down)
            tremor = smooth_noise(rng, time, np.radians(0.15), 2.0)
            out[j] = np.maximum(theta + tremor, 0.0)
        abd_rest = smooth_noise(rng, time, *abduction_wander)
        out["mp_abduction"] = (abduction_coupling[fi] * out["mp"] + abd_rest) * float(abduction)
        angles[finger] = out
    if pivot is not None:
        r, t = slow_hand_motion(rng, time, 6.0, 12.0, pivot)
    else:
        r, t = np.broadcast_to(np.eye(3), (time.size, 3, 3)).copy(), np.zeros((time.size, 3))
    return Motion(time, angles, r, t)


def free(
    rng: np.random.Generator,
    fingers: list[str],
    rate: float,
    *,
    duration: float = 20.0,
    abduction_coupling: FloatArray | None = None,
    abduction: bool = True,
    pivot: FloatArray | None = None,
) -> Motion:
    """Free motion off the grasp synergy: each joint wanders independently within its range.

    Ranges (deg): MP 0-75, PIP 0-95, DIP 0-65. The MP ab/adducts with flexion by
    the subject's coupling plus an independent wander of up to +/-4 deg (none
    when ``abduction`` is false).
    """
    time = np.arange(round(duration * rate)) / rate
    top = np.radians([75.0, 95.0, 65.0])
    angles: dict[str, dict[str, FloatArray]] = {}
    for fi, finger in enumerate(fingers):
        out = {}
        for ji, j in enumerate(("mp", "pip", "dip")):
            u = smooth_noise(rng, time, 1.0, 0.6)
            out[j] = top[ji] * 0.5 * (1 + np.tanh(u))
        k = 0.0 if abduction_coupling is None else abduction_coupling[fi]
        wander = np.radians(4.0) * np.tanh(smooth_noise(rng, time, 1.0, 0.4))
        out["mp_abduction"] = (k * out["mp"] + wander) * float(abduction)
        angles[finger] = out
    pivot = np.zeros(3) if pivot is None else pivot
    r, t = slow_hand_motion(rng, time, 8.0, 15.0, pivot)
    return Motion(time, angles, r, t)


def min_jerk_path(
    waypoints: FloatArray, hold: float, move: float, rate: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hold at each waypoint, move between them with minimum-jerk blends.

    Parameters
    ----------
    waypoints : ndarray, shape (m, d)
        Values to visit (any d, e.g. joint angles and hand pose parameters).
    hold, move : float
        Seconds held at each waypoint and spent moving between them.
    rate : float
        Hz.

    Returns
    -------
    time : ndarray, shape (n,)
    values : ndarray, shape (n, d)
    hold_intervals : ndarray, shape (m, 2)
        Start and end time (s) of each hold.
    """
    m = waypoints.shape[0]
    seg = hold + move
    duration = m * hold + (m - 1) * move
    time = np.arange(round(duration * rate) + 1) / rate
    k = np.clip((time // seg).astype(int), 0, m - 1)
    local = time - k * seg
    blend = min_jerk((local - hold) / move)
    nxt = np.minimum(k + 1, m - 1)
    values = waypoints[k] + blend[:, None] * (waypoints[nxt] - waypoints[k])
    holds = np.column_stack([np.arange(m) * seg, np.arange(m) * seg + hold])
    return time, values, holds
