"""A simulated stylus: its pivot calibration recording and the stylus recording of a
landmark session (``fingerfit simulate --stylus-recordings``, ``docs/lab.md``).

The stylus is a sensor with its tip at ``tip_offset`` (sensor frame, mm): 90-160 mm along
the stylus, a millimetre or two off its line. Pivoting, its tip rests in a divot while
the stylus sweeps a cone (tilt ``cone_deg`` about the vertical, two to three turns of
azimuth, a slow roll about its own axis); digitising, the tip rests on each landmark for
:data:`HOLD_S`, is lifted :data:`LIFT_MM` and placed again. Both are seen through the
tracker's errors (the session's :class:`~.sensors.TrackerErrors`, or explicit white noise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..session import Recording
from ..transforms import FloatArray
from .motion import min_jerk, smooth_noise

#: Seconds the tip rests on a landmark per placement, lifted between placements, and
#: moving from one landmark to the next.
HOLD_S = 0.8
LIFT_S = 0.6
MOVE_S = 1.0
#: How far the tip is lifted between two placements (mm).
LIFT_MM = 25.0


@dataclass(frozen=True)
class Stylus:
    """A stylus: its tip in its sensor's frame, ``tip_offset`` ``(3,)`` mm."""

    tip_offset: FloatArray

    @classmethod
    def sample(cls, rng: np.random.Generator) -> Stylus:
        """A stylus 90-160 mm long, its tip up to ~2 mm off its line, in a randomly
        turned sensor frame."""
        length = rng.uniform(90.0, 160.0)
        local = np.array([0.0, 0.0, -length]) + rng.normal(0.0, 1.0, 3) * np.array([1, 1, 0])
        return cls(Rotation.random(random_state=rng).apply(local))

    def orientation(self, direction: FloatArray, roll: FloatArray) -> FloatArray:
        """Sensor -> tracker rotations ``(n, 3, 3)`` pointing the tip along ``direction``
        ``(n, 3)`` (unit, from the sensor to the tip) after ``roll`` ``(n,)`` rad about
        the stylus's own line."""
        u = self.tip_offset / np.linalg.norm(self.tip_offset)
        align = Rotation.align_vectors(np.array([[0.0, 0.0, -1.0]]), u[None])[0]
        spin = Rotation.from_rotvec(np.outer(roll, u))
        down = np.array([0.0, 0.0, -1.0])
        # The rotation taking straight down to each direction (its axis horizontal).
        axis = np.cross(down, direction)
        s = np.linalg.norm(axis, axis=1)
        angle = np.arctan2(s, direction @ down)
        rv = (
            np.where(s[:, None] > 1e-12, axis / np.maximum(s, 1e-12)[:, None], 0.0) * angle[:, None]
        )
        return (Rotation.from_rotvec(rv) * align * spin).as_matrix()

    def sensor_position(self, tip: FloatArray, rotation: FloatArray) -> FloatArray:
        """Sensor origins ``(n, 3)`` mm that put the tip at ``tip`` ``(n, 3)``."""
        return tip - np.einsum("nij,j->ni", rotation, self.tip_offset)


def white_noise(
    rng: np.random.Generator,
    position: FloatArray,
    rotation: FloatArray,
    position_sd_mm: float,
    orientation_sd_deg: float,
) -> tuple[FloatArray, FloatArray]:
    """Poses seen with white noise: ``position_sd_mm`` per axis, ``orientation_sd_deg``
    per axis of a small rotation (applied in the tracker frame)."""
    n = position.shape[0]
    pos = position + rng.normal(0.0, position_sd_mm, (n, 3))
    rv = rng.normal(0.0, np.radians(orientation_sd_deg), (n, 3))
    return pos, Rotation.from_rotvec(rv).as_matrix() @ rotation


def pivot_motion(
    rng: np.random.Generator,
    stylus: Stylus,
    pivot: FloatArray,
    rate_hz: float,
    *,
    duration_s: float = 10.0,
    cone_deg: float = 30.0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The stylus turned about its tip resting at ``pivot`` ``(3,)`` (tracker frame, mm).

    The stylus's line sweeps a cone: its tilt from the vertical varies between 40 % and
    100 % of ``cone_deg`` while its azimuth turns two to three times; it rolls up to
    about 30 deg about its own line.

    Returns
    -------
    time : ndarray, shape (n,)
        s.
    position : ndarray, shape (n, 3)
        True sensor origins, tracker frame, mm.
    rotation : ndarray, shape (n, 3, 3)
        True sensor -> tracker rotations.
    """
    time = np.arange(round(duration_s * rate_hz)) / rate_hz
    tau = time / max(duration_s, 1e-9)
    tilt = np.radians(cone_deg) * (0.7 + 0.3 * np.sin(2 * np.pi * rng.uniform(0.3, 0.6) * time))
    azimuth = 2 * np.pi * rng.uniform(2.0, 3.0) * tau + rng.uniform(0, 2 * np.pi)
    # From the tip to the sensor: up and out along the cone; the tip points the other way.
    up = np.column_stack(
        [np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)]
    )
    roll = smooth_noise(rng, time, np.radians(15.0), 0.3)
    rot = stylus.orientation(-up, roll)
    tip = np.broadcast_to(pivot, (time.size, 3))
    return time, stylus.sensor_position(tip, rot), rot


def digitising_motion(
    rng: np.random.Generator,
    stylus: Stylus,
    placements: FloatArray,
    from_above: FloatArray,
    rate_hz: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The stylus placed on points in turn, resting :data:`HOLD_S` on each.

    Parameters
    ----------
    placements : ndarray, shape (m, 3)
        Where the tip rests, in order (tracker frame, mm).
    from_above : ndarray of bool, shape (m,)
        The stylus comes from above (+z, a dorsal point) or from below (a palmar one).

    Returns
    -------
    time : ndarray, shape (n,)
        s.
    position, rotation : ndarray, shapes (n, 3), (n, 3, 3)
        True sensor poses (tracker frame, mm).
    holds : ndarray, shape (m, 2)
        Start and end (s) of each rest.
    """
    m = placements.shape[0]
    dt = 1.0 / rate_hz
    segs: list[FloatArray] = []
    holds = np.zeros((m, 2))
    t0 = 0.0
    # Tip path: lift off the previous point, arc over to the next, rest on it.
    lift = np.array([0.0, 0.0, LIFT_MM])
    prev = placements[0] + np.where(from_above[0], 1, -1) * lift
    for i in range(m):
        side = 1.0 if from_above[i] else -1.0
        start = prev
        end = placements[i]
        same = i > 0 and np.allclose(placements[i - 1], placements[i], atol=5.0)
        travel = LIFT_S if same else MOVE_S
        k = max(2, round(travel * rate_hz))
        tau = min_jerk(np.linspace(0, 1, k, endpoint=False))
        arc = np.sin(np.pi * np.linspace(0, 1, k, endpoint=False))[:, None] * side * lift
        segs.append(start + (end - start) * tau[:, None] + arc)
        h = max(2, round(HOLD_S * rate_hz))
        holds[i] = (t0 + k * dt, t0 + (k + h - 1) * dt)
        segs.append(np.broadcast_to(end, (h, 3)))
        t0 += (k + h) * dt
        prev = end + side * lift
    k = max(2, round(LIFT_S * rate_hz))
    tau = min_jerk(np.linspace(0, 1, k))
    segs.append(placements[-1] + tau[:, None] * (prev - placements[-1]))
    tip = np.concatenate(segs)
    time = np.arange(tip.shape[0]) * dt
    # The stylus leans 15-35 deg off the vertical, a slowly varying lean and roll.
    lean = np.radians(25.0) + smooth_noise(rng, time, np.radians(5.0), 0.2)
    az = rng.uniform(0, 2 * np.pi) + smooth_noise(rng, time, np.radians(20.0), 0.2)
    sides = np.ones(time.size)
    for i in range(m):  # the side of the point being approached or held
        sides[time >= (holds[i, 0] - (LIFT_S if i else MOVE_S))] = 1.0 if from_above[i] else -1.0
    up = np.column_stack([np.sin(lean) * np.cos(az), np.sin(lean) * np.sin(az), np.cos(lean)])
    up[:, 2] *= sides
    roll = smooth_noise(rng, time, np.radians(10.0), 0.2)
    rot = stylus.orientation(-up, roll)
    return time, stylus.sensor_position(tip, rot), rot, holds


#: Recordings of the stylus written beside a simulated session (not listed in it).
PIVOT_FILE = "stylus_pivot.csv"
LANDMARKS_RECORDING = "stylus_landmarks.csv"


@dataclass
class StylusSession:
    """The simulated stylus recordings of one subject and their truth.

    Attributes
    ----------
    pivot : Recording
        ``stylus_pivot.csv``: the ``stylus`` sensor turned about its tip in a divot.
    landmarks : Recording
        ``stylus_landmarks.csv``: the hand and digit sensors at the reference posture
        (the hand moved as a whole) and the stylus placed on each landmark in the order
        of :func:`fingerfit.stylus.landmarks.landmark_names`, :data:`~fingerfit.stylus.landmarks.TAKES`
        times each.
    truth : dict
        ``tip_offset_mm``, ``pivot_mm``, ``order`` (the landmarks in order), ``holds``
        (per landmark its placements' start and end, s), ``placements`` (per landmark
        where the tip rested, tracker frame at the reference posture, mm).
    """

    pivot: Recording
    landmarks: Recording
    truth: dict


def stylus_session(
    rng: np.random.Generator,
    *,
    landmarks: dict[str, FloatArray],
    landmark_sd: dict[str, float],
    order: list[str],
    pivot_point: FloatArray,
    hand_origin: FloatArray,
    rate_hz: float,
    run,
    apply_errors,
) -> StylusSession:
    """A stylus, its pivot recording and its landmark recording (module docstring).

    Parameters
    ----------
    landmarks : dict[str, ndarray]
        The session's landmarks ``(3,)`` (tracker frame at the reference posture, mm):
        the mean of each landmark's placements, as ``landmarks.csv`` gives them.
    landmark_sd : dict[str, float]
        Per landmark, the SD per axis (mm) of that mean: each placement scatters
        ``sqrt(TAKES)`` times more about it.
    order : list of str
        The landmarks to digitise, in order.
    pivot_point : ndarray, shape (3,)
        The divot (tracker frame, mm).
    hand_origin : ndarray, shape (3,)
        The hand moves as a whole about this point (mm) between the reference
        recording and the landmarks.
    run : callable
        ``run(time, rotation, translation, name, rng) -> Recording``: the subject's
        sensors at the reference posture, the hand moved by ``p' = R p + t`` (``(n, 3,
        3)``, ``(n, 3)`` mm) at times ``(n,)`` s.
    apply_errors : callable
        ``apply_errors(rng, position, rotation) -> (position, rotation)``: the
        tracker's errors.
    """
    from ..session import PoseSeries
    from ..stylus.landmarks import TAKES

    stylus = Stylus.sample(rng)
    time, pos, rot = pivot_motion(rng, stylus, pivot_point, rate_hz)
    pivot = Recording(PIVOT_FILE, time, {"stylus": PoseSeries(*apply_errors(rng, pos, rot))})
    # The hand rests a little elsewhere than in the reference recording.
    turn = Rotation.from_rotvec(rng.normal(0.0, np.radians(4.0), 3)).as_matrix()
    shift = hand_origin + rng.normal(0.0, 15.0, 3) - turn @ hand_origin
    placements, above, names = [], [], []
    for name in order:
        dev = rng.normal(0.0, landmark_sd[name] * np.sqrt(TAKES), (TAKES, 3))
        pts = landmarks[name] + dev - dev.mean(axis=0)
        names += [name] * TAKES
        placements.append(pts)
        above += [not name.endswith(".pad")] * TAKES
    ref_points = np.concatenate(placements)
    on_hand = np.array([not n.startswith("target.") for n in names])
    moved = np.where(on_hand[:, None], ref_points @ turn.T + shift, ref_points)
    t, spos, srot, holds = digitising_motion(rng, stylus, moved, np.array(above), rate_hz)
    rec = run(
        t,
        np.broadcast_to(turn, (t.size, 3, 3)).copy(),
        np.broadcast_to(shift, (t.size, 3)).copy(),
        LANDMARKS_RECORDING,
        rng,
    )
    rec.poses["stylus"] = PoseSeries(*apply_errors(rng, spos, srot))
    truth = {
        "tip_offset_mm": stylus.tip_offset.tolist(),
        "pivot_mm": np.asarray(pivot_point, dtype=float).tolist(),
        "order": list(order),
        "holds": {n: holds[i * TAKES : (i + 1) * TAKES].tolist() for i, n in enumerate(order)},
        "placements": {
            n: ref_points[i * TAKES : (i + 1) * TAKES].tolist() for i, n in enumerate(order)
        },
    }
    return StylusSession(pivot, rec, truth)
