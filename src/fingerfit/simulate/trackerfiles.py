"""A simulated subject's recordings written as the files real trackers produce.

``fingerfit simulate --format liberty-ascii|liberty-binary|c3d`` writes, per subject,
one tracker file per recording (``reference.<ext>``, ``grasp.<ext>``,
``targets.<ext>``, ``test.<ext>``) in the device's own layout, units and precision,
so that the real-data path (``fingerfit convert`` -> ``fingerfit session`` ->
``fingerfit fit``) can be tried without hardware. The stylus landmarks and the touch
events stay CSV (``landmarks.csv`` in mm, ``events.csv`` in s), as a lab's stylus
export would; the ground truth is written as for the CSV format (``truth.json``,
``truth/<recording>.csv``). See ``docs/simulator.md``.

Layouts (what the readers of :mod:`fingerfit.io.liberty` and :mod:`fingerfit.io.c3d`
read):

* **Liberty ASCII** (``.txt``): output list ``O*,2,7,9,1`` -- position (inches,
  3 decimals), quaternion ``w, x, y, z`` (4 decimals), frame count; one CR/LF line
  per station, stations in order within a frame.
* **Liberty binary** (``.bin``): the same items in ``LY`` records (8-byte header,
  little-endian float32 position in inches and quaternion, uint32 frame count).
* **C3D** (``.c3d``): one ROTATION channel (4x4 sensor -> tracker transform, mm)
  per sensor, float32 as ezc3d writes it, plus the sensor origins as points
  ``<LABEL>_ORIGIN`` (a C3D file needs points).

Stations: 1 = ``hand``, then three per finger in session order (proximal, middle,
distal): index 2-4, middle 5-7, ring 8-10, little 11-13; a ``stylus`` sensor would
come last. Frame counts (and C3D frames) start at 0, so time = frame / rate matches
the simulated time and the events.
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..digits import DIGIT_NAMES, DIGITS
from ..errors import FingerfitError
from ..io.atomic import atomic_path, staged_directory
from ..io.liberty import LibertyRecords, write_liberty_ascii, write_liberty_binary
from ..io.sessiondir import EVENTS_FILE, LANDMARKS_FILE, write_events, write_landmarks
from ..session import HAND_SENSOR, UNITS_TO_MM, Recording, sensor_name
from ..transforms import quat_wxyz_from_matrix
from .truth import SimulatedSubject, write_truth

#: Tracker formats ``fingerfit simulate --format`` can write (besides ``csv``).
TRACKER_FORMATS = ("liberty-ascii", "liberty-binary", "c3d")
#: File extension per format.
EXTENSIONS = {"liberty-ascii": ".txt", "liberty-binary": ".bin", "c3d": ".c3d"}
#: ``fingerfit convert --from`` value per format.
CONVERT_FROM = {"liberty-ascii": "liberty", "liberty-binary": "liberty-binary", "c3d": "c3d"}
#: Liberty output list written (device codes of the ``O`` command; 1 = CR/LF, no data).
LIBERTY_ITEM_CODES = "2,7,9,1"
#: The data items of :data:`LIBERTY_ITEM_CODES`, in stream order.
LIBERTY_ITEMS = ("position", "quaternion", "frame")
#: Liberty position units (the device default).
LIBERTY_UNITS = "in"
#: C3D ``POINT:UNITS`` (also the units of the ROTATION translations).
C3D_UNITS = "mm"
#: Most stations a Liberty can have.
LIBERTY_MAX_STATIONS = 16
#: Sub-folders (of the subject folder) the printed commands write to.
CONVERTED_DIR = "csv"
SESSION_DIR = "session"
_SEGMENT_LABEL = {"metacarpal": "MC", "proximal": "PROX", "middle": "MID", "distal": "DIST"}


def sensor_order(sensors: Sequence[str]) -> list[str]:
    """Sensors in station order: ``hand``, the thumb's metacarpal/proximal/distal, each
    finger's proximal/middle/distal, ``stylus``.

    Parameters
    ----------
    sensors : sequence of str
        Session sensor names.

    Returns
    -------
    list of str
        The same names, ordered by digit (:data:`~fingerfit.digits.DIGIT_NAMES`) and segment.
    """
    canonical = [HAND_SENSOR] + [sensor_name(d, s) for d in DIGIT_NAMES for s in DIGITS[d].segments]
    canonical.append("stylus")
    rank = {name: i for i, name in enumerate(canonical)}
    return sorted(sensors, key=lambda s: rank.get(s, len(rank)))


def station_map(sensors: Sequence[str]) -> dict[int, str]:
    """Liberty station number (1..) -> sensor name, in :func:`sensor_order`.

    Parameters
    ----------
    sensors : sequence of str
        Session sensor names.

    Returns
    -------
    dict[int, str]
        ``{1: "hand", 2: "index.proximal", 3: "index.middle", 4: "index.distal", ...}``.

    Raises
    ------
    FingerfitError
        More sensors than a Liberty has stations (16).
    """
    order = sensor_order(sensors)
    if len(order) > LIBERTY_MAX_STATIONS:
        raise FingerfitError(
            f"{len(order)} sensors, but a Liberty has at most {LIBERTY_MAX_STATIONS} stations",
            field="--fingers",
        )
    return {i + 1: s for i, s in enumerate(order)}


def c3d_label(sensor: str) -> str:
    """C3D ROTATION channel label of a sensor: ``hand`` -> ``HAND``, ``index.proximal`` ->
    ``INDEX_PROX``, ``thumb.metacarpal`` -> ``THUMB_MC``."""
    if "." in sensor:
        finger, segment = sensor.split(".", 1)
        return f"{finger.upper()}_{_SEGMENT_LABEL.get(segment, segment.upper())}"
    return sensor.upper()


def map_option(mapping: Mapping[int | str, str]) -> str:
    """``fingerfit convert --map`` value of a station/channel -> sensor mapping.

    Parameters
    ----------
    mapping : mapping int or str -> str

    Returns
    -------
    str
        ``"1=hand,2=index.proximal,..."``.
    """
    return ",".join(f"{k}={v}" for k, v in mapping.items())


def liberty_records(
    recording: Recording, stations: Mapping[int, str], rate_hz: float
) -> LibertyRecords:
    """One recording as Liberty station records (position, quaternion, frame count).

    Parameters
    ----------
    recording : Recording
        Positions mm, tracker frame; rotations sensor -> tracker; time s.
    stations : mapping int -> str
        Station number -> sensor name; every sensor must be in the recording.
    rate_hz : float
        Frame rate; frame count = ``round(time * rate_hz)``.

    Returns
    -------
    LibertyRecords
        Records frame-major, stations ascending within a frame; ``position``
        ``(n, 3)`` inches, ``quaternion`` ``(n, 4)`` **w, x, y, z**, ``frame`` ``(n,)``.
        Samples missing (NaN) in the recording have no record, as when a sensor
        drops out; the frame count still shows the gap.
    """
    numbers = np.array(list(stations), dtype=np.int64)
    names = list(stations.values())
    n, m = recording.n_frames, len(names)
    pos = np.stack([recording.poses[s].position for s in names], axis=1)  # (n, m, 3) mm
    rot = np.stack([recording.poses[s].rotation for s in names], axis=1)  # (n, m, 3, 3)
    quat = quat_wxyz_from_matrix(rot.reshape(-1, 3, 3)).reshape(n, m, 4)
    frame = np.rint(recording.time * rate_hz).astype(np.int64)
    ok = np.isfinite(pos).all(axis=2) & np.isfinite(quat).all(axis=2)  # (n, m)
    fr, st = np.nonzero(ok)  # frame-major, station-minor
    return LibertyRecords(
        items=LIBERTY_ITEMS,
        station=numbers[st],
        values={
            "position": pos[fr, st] / UNITS_TO_MM[LIBERTY_UNITS],
            "quaternion": quat[fr, st],
            "frame": frame[fr].astype(float),
        },
        indicator=np.full(fr.size, "", dtype=str),
        where=np.arange(1, fr.size + 1),
    )


def require_ezc3d():
    """The ``ezc3d`` module, or a one-line error saying how to install it."""
    from ..extras import require

    return require("ezc3d", "c3d", "writing C3D files", field="--format")


def write_c3d_recording(
    path: str | Path, recording: Recording, labels: Mapping[str, str], rate_hz: float
) -> Path:
    """Write a recording as a C3D file of ROTATION channels, atomically.

    Parameters
    ----------
    path : str or Path
    recording : Recording
        Positions mm, rotations sensor -> tracker.
    labels : mapping str -> str
        Channel label -> sensor name, in channel order.
    rate_hz : float
        ``POINT:RATE`` and ``ROTATION:RATE`` (the first frame is 0).

    Returns
    -------
    Path
        The file: per channel a 4x4 transform per frame (sensor -> tracker, translation
        in mm; ezc3d stores float32), NaN where a sample is missing, and the sensor
        origins as points ``<label>_ORIGIN`` (mm).
    """
    ezc3d = require_ezc3d()
    path = Path(path)
    names = list(labels.values())
    n, m = recording.n_frames, len(names)
    pos = np.stack([recording.poses[s].position for s in names], axis=1)  # (n, m, 3)
    rot = np.stack([recording.poses[s].rotation for s in names], axis=1)  # (n, m, 3, 3)
    mat = np.zeros((n, m, 4, 4))
    mat[..., :3, :3] = rot
    mat[..., :3, 3] = pos
    mat[..., 3, 3] = 1.0
    points = np.ones((4, m, n))
    points[:3] = np.transpose(pos, (2, 1, 0))
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(rate_hz)]
    c["parameters"]["POINT"]["UNITS"]["value"] = [C3D_UNITS]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"{lb}_ORIGIN" for lb in labels)
    c["data"]["points"] = points
    c["data"]["rotations"] = np.transpose(mat, (2, 3, 1, 0))  # (4, 4, channel, frame)
    c.add_parameter("ROTATION", "LABELS", list(labels))
    c.add_parameter("ROTATION", "RATE", [float(rate_hz)])
    c.add_parameter("ROTATION", "USED", [m])
    # ezc3d appends ".c3d" to a name not ending in it: the temporary name must end in it.
    with atomic_path(path, suffix=".part.c3d") as tmp:
        c.write(str(tmp))
    return path


@dataclass(frozen=True)
class TrackerFiles:
    """What :func:`write_tracker_subject` wrote and how to turn it into a session.

    Attributes
    ----------
    directory : Path
        The subject folder.
    fmt : str
        One of :data:`TRACKER_FORMATS`.
    files : dict[str, Path]
        Recording name (``grasp.csv``) -> tracker file written.
    mapping : dict
        Station number (Liberty) or channel label (C3D) -> sensor name.
    commands : list of str
        Shell commands (``fingerfit convert`` per recording, ``fingerfit session``,
        ``fingerfit fit``), paths as given in ``directory``, quoted for a POSIX shell.
    """

    directory: Path
    fmt: str
    files: dict[str, Path]
    mapping: dict
    commands: list[str]


def _write_csv_extras(sim: SimulatedSubject, directory: Path) -> None:
    """landmarks.csv (mm), events.csv (s), truth.json and truth/<recording>.csv."""
    session = sim.session
    write_landmarks(directory / LANDMARKS_FILE, session.landmarks, session.units)
    if session.events:
        write_events(directory / EVENTS_FILE, session.events)
    write_truth(sim, directory)


def session_commands(
    sim: SimulatedSubject, directory: Path, fmt: str, files: Mapping[str, Path], mapping: Mapping
) -> list[str]:
    """The ``fingerfit convert`` / ``session`` / ``fit`` commands for one subject.

    Parameters
    ----------
    sim : SimulatedSubject
    directory : Path
        Subject folder as the user named it (the commands use these paths).
    fmt : str
        One of :data:`TRACKER_FORMATS`.
    files : mapping str -> Path
        Recording name -> tracker file.
    mapping : mapping
        Station number or channel label -> sensor name.

    Returns
    -------
    list of str
        One shell command per line; the converted pose CSVs go to
        ``directory/csv/<recording>.csv`` (mm), the session to ``directory/session``.
    """
    s = sim.session
    q = shlex.quote
    csv_dir = directory / CONVERTED_DIR
    cmds = []
    for name, src in files.items():
        args = ["fingerfit", "convert", q(str(src)), "-o", q(str(csv_dir / name))]
        args += ["--from", CONVERT_FROM[fmt]]
        if fmt != "c3d":
            args += ["--items", LIBERTY_ITEM_CODES, "--units", LIBERTY_UNITS]
            args += ["--rate", f"{s.rate_hz:g}"]
        args += ["--map", q(map_option(mapping))]
        cmds.append(" ".join(args))
    args = ["fingerfit", "session", q(str(directory / SESSION_DIR)), "--subject", q(s.subject)]
    args += ["--hand", s.hand, "--units", "mm", "--rate", f"{s.rate_hz:g}"]
    args += ["--fingers", ",".join(s.fingers)]
    args += ["--reference", q(str(csv_dir / s.reference.name))]
    for kind, recs in (("grasp", s.grasp), ("targets", s.targets), ("test", s.test)):
        for r in recs:
            args += [f"--{kind}", q(str(csv_dir / r.name))]
    args += ["--landmarks", q(str(directory / LANDMARKS_FILE))]
    if s.events:
        args += ["--events", q(str(directory / EVENTS_FILE))]
    cmds.append(" ".join(args))
    cmds.append(f"fingerfit fit {q(str(directory / SESSION_DIR))}")
    return cmds


def write_tracker_subject(
    sim: SimulatedSubject, directory: str | Path, fmt: str, *, overwrite: bool = False
) -> TrackerFiles:
    """Write a simulated subject as tracker files plus landmarks, events and truth.

    Parameters
    ----------
    sim : SimulatedSubject
        Session arrays in mm, tracker frame.
    directory : str or Path
        Subject folder. It is built in a hidden sibling and appears complete or not at
        all (:func:`~fingerfit.io.atomic.staged_directory`).
    fmt : {"liberty-ascii", "liberty-binary", "c3d"}
    overwrite : bool
        Replace an existing non-empty ``directory`` (else refused).

    Returns
    -------
    TrackerFiles
        The files, the station/channel map and the commands that build the session.

    Raises
    ------
    FingerfitError
        Unknown format, ezc3d missing for C3D, more sensors than Liberty stations, a
        recording lacking a sensor, ``directory`` a file or not empty (without
        ``overwrite``), or a file that cannot be written (naming it).
    """
    if fmt not in TRACKER_FORMATS:
        raise FingerfitError(
            f"unknown tracker format '{fmt}' (use {', '.join(TRACKER_FORMATS)})", field="--format"
        )
    directory = Path(directory)
    s = sim.session
    sensors = s.reference.sensors
    for rec in s.recordings():
        if sorted(rec.sensors) != sorted(sensors):
            raise FingerfitError(
                f"sensors {', '.join(rec.sensors)} differ from the reference's "
                f"({', '.join(sensors)})",
                path=rec.name,
            )
    stations = station_map(sensors)
    if fmt == "c3d":
        require_ezc3d()
        mapping: dict = {c3d_label(n): n for n in stations.values()}
    else:
        mapping = dict(stations)
    names = {rec.name: Path(rec.name).stem + EXTENSIONS[fmt] for rec in s.recordings()}
    with staged_directory(directory, overwrite=overwrite) as tmp:
        for rec in s.recordings():
            path = tmp / names[rec.name]
            if fmt == "c3d":
                write_c3d_recording(path, rec, mapping, s.rate_hz)
            else:
                records = liberty_records(rec, stations, s.rate_hz)
                writer = write_liberty_ascii if fmt == "liberty-ascii" else write_liberty_binary
                writer(path, records)
        _write_csv_extras(sim, tmp)
    files = {rec: directory / name for rec, name in names.items()}
    return TrackerFiles(
        directory, fmt, files, mapping, session_commands(sim, directory, fmt, files, mapping)
    )


__all__ = [
    "TRACKER_FORMATS",
    "TrackerFiles",
    "c3d_label",
    "liberty_records",
    "require_ezc3d",
    "session_commands",
    "station_map",
    "write_c3d_recording",
    "write_tracker_subject",
]
