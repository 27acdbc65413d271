"""The calibration statistics tracking needs, measured when the model is fitted.

Driven by its own angles (the direct computation, every sensor present), the model
predicts each sensor's pose relative to the hand sensor; what the sensor really did differs
by the tracker's noise and the skin's motion over the bone. The spread of that difference,
per sensor, is the weight tracking gives the sensor (:class:`~fingerfit.model.SensorSpread`);
the angles' range and speed bound and link the frames (:class:`~fingerfit.model.AngleRange`).
"""

from __future__ import annotations

import math

import numpy as np

from ..kinematics import compute_kinematics
from ..model import VARIANTS, AngleRange, HandModel, SensorSpread, TrackingStats
from ..session import HAND_SENSOR, Recording
from ..transforms import FloatArray
from .chains import Chains
from .solver import BLOCK, Observed, observe

#: Percentiles of an angle kept as its calibration range.
RANGE_PERCENTILES = (0.5, 99.5)
#: Percentile of an angle's speed kept as its calibration speed.
SPEED_PERCENTILE = 99.0
#: Seconds over which a speed is measured (differences of frames this far apart).
SPEED_SPAN_S = 0.025
#: Smallest spreads kept (mm, deg): a noise-free simulation must not give infinite weights.
MIN_POSITION_MM = 1e-3
MIN_ORIENTATION_DEG = 1e-3
#: Smallest speed kept (deg/s).
MIN_SPEED_DEG_S = 1.0


def chain_angles(chains: Chains, angles: dict[str, dict[str, dict[str, FloatArray]]]) -> FloatArray:
    """Angles by name -> the stacked levels ``(D, L, n)`` rad (padding 0; frames last).

    ``angles`` is variant -> digit -> angle name -> ``(n,)`` rad
    (:attr:`fingerfit.kinematics.Kinematics.motions`' angles)."""
    first = next(iter(next(iter(angles.values())).values()))
    n = next(iter(first.values())).shape[0]
    q = np.zeros((chains.size, chains.L, n))
    for i, (v, d) in enumerate(chains.keys):
        for k, name in enumerate(chains.names[i]):
            q[i, k] = angles[v][d][name]
    return q


def residuals(chains: Chains, obs: Observed, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each sensor's pose minus the one the chains predict at ``q (D, L, n)``.

    Returns
    -------
    position : ndarray, shape (D, S, n)
        Length of the position residual (mm); NaN where the sensor or an angle is missing.
    orientation : ndarray, shape (D, S, n)
        Angle of the orientation residual (rad); NaN likewise.
    """
    n = q.shape[-1]
    pos = np.full(obs.present.shape, np.nan)
    rot = np.full(obs.present.shape, np.nan)
    for s in range(0, n, BLOCK):
        e = min(n, s + BLOCK)
        qs = q[..., s:e]
        pose = chains.pose(np.nan_to_num(qs))
        ok = obs.present[..., s:e] & np.isfinite(qs).all(axis=1)[:, None, :]
        d = obs.position[..., s:e] - pose.sensor_position
        pos[..., s:e] = np.where(ok, np.sqrt((d * d).sum(axis=2)), np.nan)
        # tr(R A^T) of the measured and predicted segment rotations.
        tr = (obs.rotation[..., s:e] * pose.segment_rotation).sum(axis=(2, 3))
        cos = np.clip((tr - 1.0) / 2.0, -1.0, 1.0)
        rot[..., s:e] = np.where(ok, np.arccos(cos), np.nan)
    return pos, rot


def tracking_statistics(model: HandModel, recordings: list[Recording]) -> TrackingStats:
    """Each sensor's spread about the model and each angle's range and speed.

    Parameters
    ----------
    model : HandModel
        The fitted model.
    recordings : list of Recording
        The calibration recordings (a session's grasp and thumb protocol recordings: every
        model sensor present, mm, tracker coordinates).

    Returns
    -------
    TrackingStats
        Per variant: the per-axis RMS of every sensor's position (mm) and orientation (deg)
        residual over the frames where the hand and the digit's sensors are present, and
        every angle's range (percentiles :data:`RANGE_PERCENTILES`, widened to include 0)
        and speed (percentile :data:`SPEED_PERCENTILE` of differences over
        :data:`SPEED_SPAN_S`).
    """
    digits = list(model.fingers)
    chains = Chains(model, VARIANTS, digits)
    sq_pos = np.zeros((chains.size, 3))
    sq_rot = np.zeros((chains.size, 3))
    count = np.zeros((chains.size, 3), dtype=np.int64)
    values: dict[tuple[int, int], list[FloatArray]] = {}
    speeds: dict[tuple[int, int], list[FloatArray]] = {}
    frames = 0
    used = []
    sensors = [HAND_SENSOR, *{s for row in chains.sensors for s in row}]
    for rec in recordings:
        if rec.n_frames == 0 or any(s not in rec.poses for s in sensors):
            continue
        used.append(rec.name)
        kin = compute_kinematics(model, rec, VARIANTS, digits)
        angles = {v: {d: m.angles for d, m in kin.motions[v].items()} for v in VARIANTS}
        q = chain_angles(chains, angles)
        hand = rec.pose(HAND_SENSOR)
        obs = observe(
            chains,
            hand.position,
            hand.rotation,
            {s: rec.poses[s].position for s in rec.poses},
            {s: rec.poses[s].rotation for s in rec.poses},
        )
        pos, rot = residuals(chains, obs, q)
        whole = np.isfinite(pos).all(axis=1) & np.isfinite(rot).all(axis=1)  # (D, n)
        frames += int(np.count_nonzero(whole.all(axis=0)))
        for i in range(chains.size):
            ok = whole[i]
            sq_pos[i] += (pos[i][:, ok] ** 2).sum(axis=1)
            sq_rot[i] += (rot[i][:, ok] ** 2).sum(axis=1)
            count[i] += int(np.count_nonzero(ok))
        span = max(1, round(SPEED_SPAN_S / max(float(np.median(np.diff(rec.time))), 1e-9)))
        dt = rec.time[span:] - rec.time[:-span]
        for i in range(chains.size):
            for k in range(chains.levels[i]):
                x = q[i, k]
                values.setdefault((i, k), []).append(x[np.isfinite(x)])
                if rec.n_frames > span:
                    v = np.abs(x[span:] - x[:-span]) / dt
                    speeds.setdefault((i, k), []).append(v[np.isfinite(v)])
    out_sensors: dict[str, dict[str, SensorSpread]] = {v: {} for v in VARIANTS}
    out_angles: dict[str, dict[str, dict[str, AngleRange]]] = {
        v: {d: {} for d in digits} for v in VARIANTS
    }
    for i, (v, d) in enumerate(chains.keys):
        for s, name in enumerate(chains.sensors[i]):
            c = int(count[i, s])
            p = math.sqrt(sq_pos[i, s] / (3 * c)) if c else math.nan
            r = math.degrees(math.sqrt(sq_rot[i, s] / (3 * c))) if c else math.nan
            out_sensors[v][name] = SensorSpread(
                max(p, MIN_POSITION_MM), max(r, MIN_ORIENTATION_DEG), c
            )
        for k, name in enumerate(chains.names[i]):
            x = np.concatenate(values.get((i, k), [np.zeros(0)]))
            sp = np.concatenate(speeds.get((i, k), [np.zeros(0)]))
            lo, hi = np.percentile(x, RANGE_PERCENTILES) if x.size else (0.0, 0.0)
            speed = float(np.percentile(sp, SPEED_PERCENTILE)) if sp.size else 0.0
            out_angles[v][d][name] = AngleRange(
                min(0.0, math.degrees(lo)),
                max(0.0, math.degrees(hi)),
                max(math.degrees(speed), MIN_SPEED_DEG_S),
            )
    if not used or frames == 0:
        raise ValueError("no calibration recording with every model sensor")
    return TrackingStats(tuple(used), frames, out_sensors, out_angles)
