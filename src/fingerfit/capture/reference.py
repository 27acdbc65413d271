"""The reference protocol: the stretched, still posture every angle is measured from,
and whether the hand held still while it was recorded (``docs/lab.md``, *Reference*).

Each digit sensor's motion is measured against the hand sensor (a finger that bends
changes the posture the angles are zero at); the hand sensor's own motion in the tracker
frame (a hand that slides blurs where the landmarks are carried to). Motion is the RMS
distance of the sensor's origin from its mean (mm) and the RMS angle from its mean
orientation (deg), each with the tracker's white noise taken out (from successive
differences, as a stylus take's spread: :func:`fingerfit.stylus.landmarks.window_spread`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..session import HAND_SENSOR, Recording
from ..stylus.landmarks import window_spread
from ..transforms import FloatArray

#: The most a sensor may move while the reference is recorded: RMS mm and RMS deg.
MAX_MOTION_MM = 1.0
MAX_MOTION_DEG = 1.0


@dataclass(frozen=True)
class SensorMotion:
    """How much one sensor moved during the reference recording.

    Attributes
    ----------
    sensor : str
    position_mm : float
        RMS distance from its mean position (white noise taken out), mm.
    rotation_deg : float
        RMS angle from its mean orientation (white noise taken out), deg.
    relative_to : str
        ``hand`` (a digit sensor, measured in the hand sensor's frame) or ``tracker``.
    """

    sensor: str
    position_mm: float
    rotation_deg: float
    relative_to: str

    @property
    def too_much(self) -> bool:
        return not (self.position_mm <= MAX_MOTION_MM and self.rotation_deg <= MAX_MOTION_DEG)


def _rotation_spread_deg(rot: FloatArray) -> float:
    """RMS angle (deg) of rotations ``(n, 3, 3)`` from their chordal mean, less white noise:
    the rotation vectors from the mean, treated as :func:`window_spread` treats points."""
    from scipy.spatial.transform import Rotation

    ok = np.isfinite(rot).reshape(-1, 9).all(axis=1)
    if ok.sum() < 3:
        return float("nan")
    r = Rotation.from_matrix(rot[ok])
    rv = (r.mean().inv() * r).as_rotvec()
    return float(np.degrees(window_spread(rv)))


def reference_motion(recording: Recording, sensors: list[str]) -> list[SensorMotion]:
    """How much each of ``sensors`` moved in ``recording`` (module docstring), hand first.

    Parameters
    ----------
    recording : Recording
        The reference recording (mm, tracker frame).
    sensors : list of str
        The session's sensors (``hand`` and the digits').
    """
    out: list[SensorMotion] = []
    hand = recording.poses.get(HAND_SENSOR)
    for s in sensors:
        pose = recording.poses.get(s)
        if pose is None:
            continue
        pos, rot = pose.position, pose.rotation
        relative = s != HAND_SENSOR and hand is not None
        if relative:
            assert hand is not None
            pos = np.einsum("nji,nj->ni", hand.rotation, pos - hand.position)
            rot = np.einsum("nji,njk->nik", hand.rotation, rot)
        out.append(
            SensorMotion(
                s, window_spread(pos), _rotation_spread_deg(rot), "hand" if relative else "tracker"
            )
        )
    return out
