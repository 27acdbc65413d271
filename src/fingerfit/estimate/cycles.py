"""Grasp-cycle extraction for one joint (paper section 3, Fig. 3).

The joint angle used for extraction is the geodesic angle of the child
sensor's orientation relative to the parent sensor, measured from the
reference posture: ``theta(k) = |rotvec(R(k) R_ref^T)|`` -- it needs no axis
yet. Its angular velocity (Savitzky-Golay derivative) separates movement
from the static holds and stretch periods; each excursion above half the
joint's range is one grasp cycle, and that cycle's movement period is the
set of its frames whose speed exceeds a threshold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from ..session import true_runs
from ..transforms import FloatArray, rotation_angle

SMOOTH_S = 0.1  # Savitzky-Golay window (s)
MIN_SPEED_DEG_S = 10.0  # a joint slower than this is static
SPEED_FRACTION = 0.15  # ... or slower than this fraction of its typical peak speed


@dataclass(frozen=True)
class Cycles:
    """Movement periods of one joint.

    Attributes
    ----------
    angle : ndarray, shape (n_frames,)
        Geodesic joint angle from the reference posture (rad); NaN where a sensor is missing.
    speed : ndarray, shape (n_frames,)
        Smoothed angular speed (rad/s).
    periods : list of ndarray
        Frame indices of each cycle's movement period (holds excluded).
    rom : ndarray, shape (n_cycles,)
        Range of motion of each cycle (rad).
    threshold : float
        Speed threshold used (rad/s).
    """

    angle: FloatArray
    speed: FloatArray
    periods: list[np.ndarray]
    rom: FloatArray
    threshold: float

    @property
    def count(self) -> int:
        return len(self.periods)


def period_labels(periods: list[np.ndarray]) -> np.ndarray:
    """Cycle index of every frame of ``periods`` in their concatenated order: ``(n,)`` int,
    ``n`` the total length (``np.concatenate(periods)`` gives the frames themselves)."""
    return np.concatenate([np.full(p.size, i) for i, p in enumerate(periods)])


def geodesic_angle(rotation: FloatArray, reference: FloatArray) -> FloatArray:
    """Angle ``(n,)`` rad of ``rotation (n, 3, 3)`` away from ``reference (3, 3)``."""
    return rotation_angle(rotation @ reference.T)


def extract_cycles(rotation: FloatArray, reference: FloatArray, rate_hz: float) -> Cycles:
    """Find the grasp cycles and their movement periods for one joint.

    Parameters
    ----------
    rotation : ndarray, shape (n_frames, 3, 3)
        Child-in-parent relative rotation per frame (NaN where missing).
    reference : ndarray, shape (3, 3)
        The same at the reference posture.
    rate_hz : float
        Sampling rate (Hz).

    Returns
    -------
    Cycles
        ``periods[i]`` holds the frames of cycle ``i`` whose angular speed exceeds
        ``max(10 deg/s, 0.15 x the 95th-percentile speed)``; frames with missing
        samples are never included.
    """
    angle = geodesic_angle(rotation, reference)
    ok = np.isfinite(angle)
    n = angle.size
    if ok.sum() < 10:
        return Cycles(angle, np.zeros(n), [], np.zeros(0), 0.0)
    frames = np.arange(n)
    filled = np.interp(frames, frames[ok], angle[ok])
    window = max(5, round(SMOOTH_S * rate_hz) | 1)  # odd
    if window > n:
        window = n if n % 2 else n - 1
    smooth = savgol_filter(filled, window, 3)
    speed = np.abs(savgol_filter(filled, window, 3, deriv=1)) * rate_hz
    threshold = max(np.radians(MIN_SPEED_DEG_S), SPEED_FRACTION * np.percentile(speed, 95))
    lo, hi = np.percentile(smooth, [5, 95])
    peaks = true_runs(smooth > lo + 0.5 * (hi - lo))
    if peaks.shape[0] == 0 or hi - lo <= 0:
        return Cycles(angle, speed, [], np.zeros(0), float(threshold))
    # Cycle i spans from midway after the previous excursion to midway before the next.
    bounds = np.concatenate([[0], (peaks[1:, 0] + peaks[:-1, 1]) // 2, [n]])
    moving = (speed > threshold) & ok
    periods, rom = [], []
    for i in range(peaks.shape[0]):
        a, b = bounds[i], bounds[i + 1]
        idx = a + np.flatnonzero(moving[a:b])
        # A cycle needs movement both into and out of its peak.
        if idx.size and idx.min() < peaks[i, 0] and idx.max() >= peaks[i, 1]:
            periods.append(idx)
            seg = smooth[a:b]
            rom.append(seg.max() - seg.min())
    return Cycles(angle, speed, periods, np.array(rom), float(threshold))
