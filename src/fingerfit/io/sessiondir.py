"""Session directories (format ``fingerfit.session/1``): load and save.

Layout (see ``docs/formats.md``)::

    session.toml      format, subject, hand, units, rate_hz, fingers, [recordings]
    reference.csv     static recording at the stretched reference posture
    landmarks.csv     name,x,y,z (stylus points at the reference posture)
    grasp*.csv ...    pose recordings (canonical pose CSV)
    events.csv        optional: recording,finger,target,start,end
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..session import (
    FINGERS,
    FORMAT,
    HAND_SENSOR,
    SEGMENTS,
    UNITS_TO_MM,
    Recording,
    Session,
    TargetEvent,
    is_landmark_name,
    sensor_name,
)
from .atomic import atomic_write
from .posecsv import read_pose_csv, write_pose_csv

SESSION_FILE = "session.toml"
LANDMARKS_FILE = "landmarks.csv"
EVENTS_FILE = "events.csv"
EVENTS_HEADER = ("recording", "finger", "target", "start", "end")


def _require(table: dict, key: str, kind: type | tuple[type, ...], path: Path, where: str = ""):
    if key not in table:
        raise FingerfitError("missing", path=path, field=f"{where}{key}")
    value = table[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise FingerfitError(f"wrong type {type(value).__name__}", path=path, field=f"{where}{key}")
    return value


def _file_list(value, path: Path, key: str) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise FingerfitError("must be a file name or a list of file names", path=path, field=key)
    return value


def read_landmarks(path: str | Path, units: str = "mm") -> dict[str, np.ndarray]:
    """Read ``name,x,y,z`` landmarks; returns positions ``(3,)`` in mm, tracker frame."""
    path = Path(path)
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
    except FileNotFoundError:
        raise FingerfitError("file not found", path=path) from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise FingerfitError(f"not a valid CSV ({str(exc).splitlines()[0]})", path=path) from None
    if tuple(df.columns) != ("name", "x", "y", "z"):
        raise FingerfitError(
            f"header must be 'name,x,y,z', found '{','.join(df.columns)}'", path=path, line=1
        )
    out: dict[str, np.ndarray] = {}
    for i, row in enumerate(df.itertuples(index=False), start=2):
        name = str(row.name)
        if not is_landmark_name(name):
            raise FingerfitError(f"unknown landmark name '{name}'", path=path, line=i, field="name")
        if name in out:
            raise FingerfitError(f"landmark '{name}' given twice", path=path, line=i, field="name")
        try:
            xyz = np.array([float(row.x), float(row.y), float(row.z)])
        except ValueError:
            raise FingerfitError("coordinates must be numbers", path=path, line=i) from None
        if not np.isfinite(xyz).all():
            raise FingerfitError("coordinates must be finite numbers", path=path, line=i)
        out[name] = xyz * UNITS_TO_MM[units]
    return out


def read_events(path: Path) -> list[TargetEvent]:
    """Read ``recording,finger,target,start,end`` touch events (seconds)."""
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
    except FileNotFoundError:
        raise FingerfitError("file not found", path=path) from None
    if tuple(df.columns) != EVENTS_HEADER:
        raise FingerfitError(f"header must be '{','.join(EVENTS_HEADER)}'", path=path, line=1)
    events = []
    for i, row in enumerate(df.itertuples(index=False), start=2):
        try:
            start, end = float(row.start), float(row.end)
        except ValueError:
            raise FingerfitError("start and end must be numbers (s)", path=path, line=i) from None
        if not (math.isfinite(start) and math.isfinite(end) and end > start):
            raise FingerfitError("need finite start < end", path=path, line=i)
        if row.finger not in FINGERS:
            raise FingerfitError(
                f"unknown finger '{row.finger}'", path=path, line=i, field="finger"
            )
        events.append(TargetEvent(row.recording, row.finger, row.target, start, end))
    return events


def load_session(directory: str | Path) -> Session:
    """Load and validate a session directory.

    Parameters
    ----------
    directory : str or Path
        Folder holding ``session.toml`` and the files it names.

    Returns
    -------
    Session
        Recordings and landmarks in mm, tracker coordinates.

    Raises
    ------
    FingerfitError
        One line naming the file and the line or field at fault.
    """
    directory = Path(directory)
    meta_path = directory / SESSION_FILE
    if not meta_path.is_file():
        raise FingerfitError(f"not a session directory (no {SESSION_FILE})", path=directory)
    try:
        meta = tomllib.loads(meta_path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"at line (\d+)", str(exc))
        line = int(found.group(1)) if found else None
        raise FingerfitError(
            f"invalid TOML ({str(exc).split(' (at')[0]})", path=meta_path, line=line
        ) from None
    fmt = _require(meta, "format", str, meta_path)
    if fmt != FORMAT:
        raise FingerfitError(
            f"unsupported format '{fmt}' (expected '{FORMAT}')", path=meta_path, field="format"
        )
    subject = _require(meta, "subject", str, meta_path)
    hand = _require(meta, "hand", str, meta_path)
    if hand not in ("left", "right"):
        raise FingerfitError(
            f"must be 'left' or 'right', not '{hand}'", path=meta_path, field="hand"
        )
    units = _require(meta, "units", str, meta_path)
    if units not in UNITS_TO_MM:
        raise FingerfitError(
            f"must be one of {', '.join(UNITS_TO_MM)}, not '{units}'", path=meta_path, field="units"
        )
    rate = float(_require(meta, "rate_hz", (int, float), meta_path))
    if not rate > 0:
        raise FingerfitError("must be positive", path=meta_path, field="rate_hz")
    fingers = _require(meta, "fingers", list, meta_path)
    if not fingers or any(f not in FINGERS for f in fingers) or len(set(fingers)) != len(fingers):
        raise FingerfitError(
            f"must be a non-empty list of distinct names from {', '.join(FINGERS)}",
            path=meta_path,
            field="fingers",
        )
    recs = _require(meta, "recordings", dict, meta_path)

    def load(name: str, key: str) -> Recording:
        f = directory / name
        if not f.is_file():
            raise FingerfitError(
                f"names a file that does not exist: '{name}'",
                path=meta_path,
                field=f"recordings.{key}",
            )
        return read_pose_csv(f, units=units, rate_hz=rate)

    reference = load(_require(recs, "reference", str, meta_path, "recordings."), "reference")
    grasp_names = _file_list(
        _require(recs, "grasp", (str, list), meta_path, "recordings."),
        meta_path,
        "recordings.grasp",
    )
    if not grasp_names:
        raise FingerfitError(
            "needs at least one grasp recording", path=meta_path, field="recordings.grasp"
        )
    grasp = [load(n, "grasp") for n in grasp_names]
    targets = [
        load(n, "targets")
        for n in _file_list(recs.get("targets", []), meta_path, "recordings.targets")
    ]
    test = [load(n, "test") for n in _file_list(recs.get("test", []), meta_path, "recordings.test")]
    landmarks = read_landmarks(directory / LANDMARKS_FILE, units)
    events = []
    if "events" in recs:
        events = read_events(directory / _require(recs, "events", str, meta_path, "recordings."))
    session = Session(
        subject=subject,
        hand=hand,
        units=units,
        rate_hz=rate,
        fingers=list(fingers),
        reference=reference,
        grasp=grasp,
        landmarks=landmarks,
        targets=targets,
        test=test,
        events=events,
        path=directory,
    )
    _check_complete(session)
    return session


def _check_complete(session: Session) -> None:
    """Every listed finger has its sensors in the reference and grasp recordings and its landmarks."""
    assert session.path is not None
    for finger in session.fingers:
        needed = [HAND_SENSOR] + [sensor_name(finger, s) for s in SEGMENTS]
        for rec in [session.reference, *session.grasp]:
            for s in needed:
                if s not in rec.poses or not rec.poses[s].valid.any():
                    raise FingerfitError(
                        f"no samples for sensor '{s}' (finger '{finger}' is listed in {SESSION_FILE})",
                        path=session.path / rec.name,
                    )
        for lm in ("mp", "pip", "dip", "tip"):
            if f"{finger}.{lm}" not in session.landmarks:
                raise FingerfitError(
                    f"missing landmark '{finger}.{lm}' (finger '{finger}' is listed in {SESSION_FILE})",
                    path=session.path / LANDMARKS_FILE,
                )
    names = {r.name for r in session.recordings()}
    for ev in session.events:
        if ev.recording not in names:
            raise FingerfitError(
                f"event names unknown recording '{ev.recording}'", path=session.path / "events.csv"
            )
        if f"target.{ev.target}" not in session.landmarks:
            raise FingerfitError(
                f"event names target '{ev.target}' with no landmark 'target.{ev.target}'",
                path=session.path / "events.csv",
            )


def _toml_list(names: list[str]) -> str:
    return "[" + ", ".join(json.dumps(n) for n in names) + "]"


def write_session_toml(session: Session, directory: str | Path) -> Path:
    """Write ``session.toml`` naming the session's recordings (files are not written).

    ``events = "events.csv"`` is listed when the session has events.
    """
    lines = [
        f'format = "{FORMAT}"',
        f"subject = {json.dumps(session.subject)}",
        f'hand = "{session.hand}"',
        f'units = "{session.units}"',
        f"rate_hz = {float(session.rate_hz)!r}",
        f"fingers = {_toml_list(session.fingers)}",
        "",
        "[recordings]",
        f"reference = {json.dumps(session.reference.name)}",
        f"grasp = {_toml_list([r.name for r in session.grasp])}",
    ]
    if session.targets:
        lines.append(f"targets = {_toml_list([r.name for r in session.targets])}")
    if session.test:
        lines.append(f"test = {_toml_list([r.name for r in session.test])}")
    if session.events:
        lines.append(f'events = "{EVENTS_FILE}"')
    path = Path(directory) / SESSION_FILE
    with atomic_write(path) as fh:
        fh.write("\n".join(lines) + "\n")
    return path


def save_session(session: Session, directory: str | Path) -> Path:
    """Write a session directory in format ``fingerfit.session/1``.

    Parameters
    ----------
    session : Session
        Arrays in mm; files are written in ``session.units``.
    directory : str or Path
        Created if needed; existing files of the same names are replaced.

    Returns
    -------
    Path
        The directory.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    scale = UNITS_TO_MM[session.units]
    for rec in session.recordings():
        write_pose_csv(directory / rec.name, rec, units=session.units)
    lm = pd.DataFrame(
        [(k, *(v / scale)) for k, v in session.landmarks.items()], columns=["name", "x", "y", "z"]
    )
    with atomic_write(directory / LANDMARKS_FILE, newline="") as fh:
        lm.to_csv(fh, index=False, lineterminator="\n")
    if session.events:
        ev = pd.DataFrame([e.__dict__ for e in session.events], columns=list(EVENTS_HEADER))
        with atomic_write(directory / EVENTS_FILE, newline="") as fh:
            ev.to_csv(fh, index=False, lineterminator="\n")
    write_session_toml(session, directory)
    return directory
