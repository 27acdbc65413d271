"""What the model knows of its own fit, for tracking with fewer sensors (:mod:`fingerfit.track`).

The fit measures, on the session's calibration recordings, how far each sensor's pose
strays from the pose the fitted model predicts for it (sensor noise and soft-tissue
artefact, per sensor) and the range and speed of every joint angle. Tracking weighs each
sensor by its own spread, keeps angles softly inside the range the calibration showed and
expects no joint to move much faster than it did there (``docs/tracking.md``).

Units: mm for positions, degrees for angles and deg/s for speeds (as written in the model
file); :mod:`fingerfit.track` converts to radians.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SensorSpread:
    """A sensor's pose about the fitted model in the calibration recordings.

    The residual is the sensor's measured pose relative to the hand sensor minus the pose
    the model predicts from the joint angles of the same frame (both in tracker coordinates
    at the reference posture).

    Attributes
    ----------
    position_mm : float
        Per-axis RMS of the position residual (mm): ``sqrt(mean |e_p|^2 / 3)``.
    orientation_deg : float
        Per-axis RMS of the orientation residual (deg): ``sqrt(mean |e_r|^2 / 3)``, ``e_r``
        the rotation vector taking the predicted orientation to the measured one.
    frames : int
        Calibration frames the figures come from.
    """

    position_mm: float
    orientation_deg: float
    frames: int


@dataclass(frozen=True)
class AngleRange:
    """A joint angle in the calibration recordings.

    Attributes
    ----------
    low_deg, high_deg : float
        Its 0.5th and 99.5th percentiles (deg), widened to include 0 (the reference
        posture).
    speed_deg_s : float
        The 99th percentile of its speed (deg/s), from differences over about 25 ms.
    """

    low_deg: float
    high_deg: float
    speed_deg_s: float


@dataclass(frozen=True)
class TrackingStats:
    """The calibration statistics tracking needs (``"tracking"`` in the model file).

    Attributes
    ----------
    recordings : tuple of str
        The calibration recordings they were measured on (the session's grasp and thumb
        protocol recordings).
    frames : int
        Frames of those recordings in which the hand and every model sensor were present.
    sensors : dict[str, dict[str, SensorSpread]]
        Variant (``user_axis``, ``orthogonal``) -> sensor name -> its spread about that
        variant of the model. The hand sensor has none: every pose is taken relative to it.
    angles : dict[str, dict[str, dict[str, AngleRange]]]
        Variant -> digit -> angle name (``mp``, ``mp_abduction``, ...) -> its range.
    """

    recordings: tuple[str, ...]
    frames: int
    sensors: dict[str, dict[str, SensorSpread]]
    angles: dict[str, dict[str, dict[str, AngleRange]]]
