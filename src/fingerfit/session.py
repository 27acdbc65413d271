"""In-memory session: recordings of sensor poses, landmarks and target events.

All lengths are millimetres and all positions are tracker coordinates,
whatever units the session files declare (the loader converts). Rotation
matrices map sensor coordinates into tracker coordinates. Arrays are
time-first. See ``docs/conventions.md`` and ``docs/formats.md``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .digits import DIGIT_NAMES, DIGITS, FINGER_JOINTS, FINGER_SEGMENTS
from .digits import FINGERS as FINGERS
from .digits import HAND_SENSOR as HAND_SENSOR
from .errors import FingerfitError, shown
from .transforms import FloatArray

FORMAT = "fingerfit.session/1"
# The fingers' segment and joint names (the thumb's are in ``digits.DIGITS["thumb"]``).
SEGMENTS = FINGER_SEGMENTS
JOINTS = FINGER_JOINTS
UNITS_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}

_FINGER = "(index|middle|ring|little)"
_SENSOR_RE = re.compile(
    rf"^(hand|stylus|{_FINGER}\.(proximal|middle|distal)|thumb\.(metacarpal|proximal|distal))$"
)
_SUBJECT_RE = re.compile(r"^[A-Za-z0-9_\-][A-Za-z0-9_.\-]{0,63}$")
#: Longest subject identifier (characters).
SUBJECT_ID_MAX = 64
_LANDMARK_RE = re.compile(
    rf"^({_FINGER}\.(mp|pip|dip|tip|pad)|thumb\.(cmc|mcp|ip|tip|pad)|target\.[A-Za-z0-9_\-]+)$"
)


def sensor_name(finger: str, segment: str) -> str:
    """Sensor name of a finger segment, e.g. ``index.proximal``."""
    return f"{finger}.{segment}"


def is_sensor_name(name: str) -> bool:
    """Whether ``name`` is a valid sensor name of the session format."""
    return bool(_SENSOR_RE.match(name))


def is_landmark_name(name: str) -> bool:
    """Whether ``name`` is a valid landmark name of the session format."""
    return bool(_LANDMARK_RE.match(name))


def check_subject_id(
    value: object, *, path: str | Path | None = None, field: str | None = "subject"
) -> str:
    """Check a subject identifier; it names folders and files, so it must be safe as one.

    Parameters
    ----------
    value : object
        The identifier (from ``session.toml``, ``--subject`` or a study list).
    path : str or Path, optional
        The file it came from, for the message.
    field : str, optional
        The field or option it came from, for the message.

    Returns
    -------
    str
        ``value``, unchanged: 1-64 characters from letters, digits, ``_``, ``.`` and
        ``-``, not starting with ``.`` (so never ``..``, a hidden name or a path).

    Raises
    ------
    FingerfitError
        Naming ``path`` and ``field`` and showing the value (escaped, shortened).
    """
    if not isinstance(value, str):
        raise FingerfitError(
            f"subject ID must be a string, not {type(value).__name__}", path=path, field=field
        )
    if not _SUBJECT_RE.fullmatch(value):
        raise FingerfitError(
            f"subject ID '{shown(value, 70)}' must be 1-{SUBJECT_ID_MAX} letters, digits, '_', '.' or '-', "
            "not starting with '.'",
            path=path,
            field=field,
        )
    return value


def true_runs(mask: np.ndarray) -> np.ndarray:
    """Start (inclusive) and end (exclusive) frame ``(m, 2)`` of every run of True in a 1-D mask."""
    d = np.diff(np.concatenate([[0], np.asarray(mask).astype(np.int8), [0]]))
    return np.column_stack([np.flatnonzero(d == 1), np.flatnonzero(d == -1)])


def joint_sensors(digit: str) -> dict[str, tuple[str, str]]:
    """(parent, child) sensor names of each joint of a digit, proximal to distal
    (``mp``, ``pip``, ``dip``; the thumb's ``cmc``, ``mcp``, ``ip``)."""
    return DIGITS[digit].joint_sensors()


def digit_sensors(digit: str) -> list[str]:
    """The hand sensor and the digit's three segment sensors, proximal to distal."""
    return DIGITS[digit].sensors()


@dataclass(frozen=True)
class PoseSeries:
    """Poses of one sensor over time.

    Attributes
    ----------
    position : ndarray, shape (n_frames, 3)
        Sensor origin in tracker coordinates (mm); NaN where missing.
    rotation : ndarray, shape (n_frames, 3, 3)
        Rotation matrix from sensor to tracker coordinates; NaN where missing.
    """

    position: FloatArray
    rotation: FloatArray

    def __post_init__(self) -> None:
        n = self.position.shape[0]
        if self.position.shape != (n, 3) or self.rotation.shape != (n, 3, 3):
            raise ValueError(
                f"PoseSeries needs position (n, 3) and rotation (n, 3, 3); got "
                f"{self.position.shape} and {self.rotation.shape}"
            )

    @property
    def n_frames(self) -> int:
        return int(self.position.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask ``(n_frames,)`` of frames with a complete sample."""
        # Column by column: NumPy's reductions over a short last axis go row by row.
        pos = np.isfinite(self.position)
        ok = pos[:, 0] & pos[:, 1]
        ok &= pos[:, 2]
        rot = np.isfinite(self.rotation).reshape(-1, 9)
        for j in range(9):
            ok &= rot[:, j]
        return ok

    def take(self, index: np.ndarray | slice) -> PoseSeries:
        """Frames selected by a slice, boolean mask or index array."""
        return PoseSeries(self.position[index], self.rotation[index])

    def mean(self) -> tuple[FloatArray, FloatArray]:
        """Mean pose over the valid frames: position ``(3,)`` mm, rotation ``(3, 3)``.

        The mean rotation is the chordal L2 mean (scipy ``Rotation.mean``).
        """
        ok = self.valid
        if not ok.any():
            raise ValueError("no valid samples to average")
        from scipy.spatial.transform import Rotation  # on use: importing it takes 0.2-0.3 s

        r = Rotation.from_matrix(self.rotation[ok]).mean().as_matrix()
        return self.position[ok].mean(axis=0), r


@dataclass
class Recording:
    """One recording: a common time base and a pose series per sensor.

    Attributes
    ----------
    name : str
        File name the recording came from (or will be written to).
    time : ndarray, shape (n_frames,)
        Seconds. Frames missing for every sensor appear with an interpolated
        time and NaN poses, so gaps stay visible.
    poses : dict[str, PoseSeries]
        Per sensor name.
    notes : list[str]
        Counts of anything repaired or treated as missing while reading.
    markers : dict[str, ndarray]
        Per marker label, its positions ``(n_frames, 3)`` in tracker (lab) coordinates,
        mm; NaN where the marker was not seen. Empty for a 6-DOF recording. Which
        segment carries which marker is the session's ``marker_map``.
    """

    name: str
    time: FloatArray
    poses: dict[str, PoseSeries]
    notes: list[str] = field(default_factory=list)
    markers: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def sensors(self) -> list[str]:
        return list(self.poses)

    def pose(self, sensor: str) -> PoseSeries:
        """Pose series of ``sensor``; a clear error if the recording lacks it."""
        try:
            return self.poses[sensor]
        except KeyError:
            raise FingerfitError(
                f"no samples for sensor '{sensor}' (has: {', '.join(self.poses) or 'none'})",
                path=self.name,
            ) from None

    def slice(self, index: np.ndarray | slice) -> Recording:
        """A recording of the selected frames of every sensor."""
        return Recording(
            self.name,
            self.time[index],
            {k: v.take(index) for k, v in self.poses.items()},
            list(self.notes),
            {k: v[index] for k, v in self.markers.items()},
        )


def concat_recordings(recordings: list[Recording]) -> Recording:
    """Recordings that follow one another (blocks of a stream) as one, frames in order.

    Parameters
    ----------
    recordings : list of Recording
        Non-empty; every one with the sensors and markers of the first (mm, tracker
        frame).

    Returns
    -------
    Recording
        The first's name; time ``(n,)`` s and per sensor positions ``(n, 3)`` mm and
        rotations ``(n, 3, 3)``, ``n`` the frames of all.
    """
    if len(recordings) == 1:
        return recordings[0]
    poses = {
        k: PoseSeries(
            np.concatenate([r.poses[k].position for r in recordings]),
            np.concatenate([r.poses[k].rotation for r in recordings]),
        )
        for k in recordings[0].poses
    }
    markers = {k: np.concatenate([r.markers[k] for r in recordings]) for k in recordings[0].markers}
    return Recording(
        recordings[0].name, np.concatenate([r.time for r in recordings]), poses, markers=markers
    )


@dataclass(frozen=True)
class TargetEvent:
    """The tip of digit ``finger`` touches something during [start, end] s.

    ``target`` is either a landmark's name after ``target.`` (the tip touches landmark
    ``target.<target>``) or a digit's name (a pinch: the pads of ``finger`` and of that
    digit touch).
    """

    recording: str
    finger: str
    target: str
    start: float
    end: float

    @property
    def is_pinch(self) -> bool:
        """Whether the event is a pinch of two digits (``target`` names a digit)."""
        return self.target in DIGIT_NAMES


@dataclass
class Session:
    """One subject's measurements (format ``fingerfit.session/1``).

    Attributes
    ----------
    subject : str
    hand : {"left", "right"}
    units : str
        Units declared by the files; arrays here are always mm.
    rate_hz : float
    fingers : list[str]
        Digits of the session: any of ``thumb``, ``index``, ``middle``, ``ring``, ``little``.
    reference : Recording
        Static recording at the stretched reference posture (all joint angles 0).
    grasp, targets, test : list[Recording]
    landmarks : dict[str, ndarray]
        Stylus-digitised points ``(3,)`` in tracker coordinates (mm), taken at the
        reference posture. May be empty in a marker session (its ``landmarks.csv`` is
        optional).
    events : list[TargetEvent]
    path : Path or None
        Directory the session was loaded from.
    files : tuple of Path
        Every file the session was read from (``session.toml``, recordings, landmarks,
        events, the marker map); no command may write onto one of them.
    marker_map : dict[str, tuple of str]
        For a marker session: per segment (``hand``, ``index.proximal``, ... the sensor
        names), the labels of the skin markers it carries, in the recordings'
        ``markers``. Empty for a 6-DOF session.
    landmark_sd : dict[str, float]
        Landmark name -> the digitised point's uncertainty (mm, the standard error of its
        stylus takes: ``landmarks.csv``'s ``sd``); landmarks without one are absent.
    """

    subject: str
    hand: str
    units: str
    rate_hz: float
    fingers: list[str]
    reference: Recording
    grasp: list[Recording]
    landmarks: dict[str, FloatArray]
    targets: list[Recording] = field(default_factory=list)
    test: list[Recording] = field(default_factory=list)
    events: list[TargetEvent] = field(default_factory=list)
    path: Path | None = None
    files: tuple[Path, ...] = ()
    marker_map: dict[str, tuple[str, ...]] = field(default_factory=dict)
    landmark_sd: dict[str, float] = field(default_factory=dict)

    def recordings(self) -> list[Recording]:
        """Every recording: reference, grasp, targets, test."""
        return [self.reference, *self.grasp, *self.targets, *self.test]

    def recording(self, name: str) -> Recording:
        """Recording by file name."""
        for rec in self.recordings():
            if rec.name == name:
                return rec
        raise FingerfitError(f"session has no recording '{name}'", path=self.path)

    def landmark(self, name: str) -> FloatArray:
        """Landmark position ``(3,)`` mm, tracker coordinates."""
        try:
            return self.landmarks[name]
        except KeyError:
            where = None if self.path is None else self.path / "landmarks.csv"
            raise FingerfitError(f"missing landmark '{name}'", path=where) from None
