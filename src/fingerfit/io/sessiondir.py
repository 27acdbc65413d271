"""Session directories (format ``fingerfit.session/1``): load and save.

Layout (see ``docs/formats.md``)::

    session.toml      format, subject, hand, units, rate_hz, fingers, [markers,] [recordings]
    reference.csv     static recording at the stretched reference posture
    landmarks.csv     name,x,y,z (stylus points at the reference posture)
    grasp*.csv ...    pose recordings (canonical pose CSV)
    events.csv        optional: recording,finger,target,start,end

A marker session (``markers = "markers.toml"``) holds marker recordings (``.trc``,
``.tsv``, ``.c3d``) instead, and its landmarks are optional (:mod:`.markers.session`).
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import io
import json
import math
import os
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np
import pandas as pd

from ..digits import DIGIT_NAMES, DIGITS
from ..errors import FingerfitError, shown
from ..session import (
    FORMAT,
    UNITS_TO_MM,
    Recording,
    Session,
    TargetEvent,
    check_subject_id,
    digit_sensors,
    is_landmark_name,
)
from ..transforms import FloatArray
from .atomic import atomic_write
from .hygiene import MAX_RATE_HZ, implausible_message, implausible_rows
from .markers import read_marker_recording
from .markers.markermap import MAP_FILE, read_marker_map, write_marker_map
from .markers.session import check_marker_session, check_recording_kind, trc_named
from .opensim import write_markers
from .posecsv import check_field_counts, read_pose_csv
from .posewrite import write_pose_csv
from .textfile import read_bytes, read_toml

SESSION_FILE = "session.toml"
LANDMARKS_FILE = "landmarks.csv"
EVENTS_FILE = "events.csv"
EVENTS_HEADER = ("recording", "finger", "target", "start", "end")


#: Keys of ``session.toml``: top level and ``[recordings]``.
TOP_KEYS = ("format", "subject", "hand", "units", "rate_hz", "fingers", "markers", "recordings")
RECORDING_KEYS = ("reference", "grasp", "targets", "test", "events")


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


def _check_keys(
    table: dict, allowed: tuple[str, ...], path: Path, where: str, prefix: str = ""
) -> None:
    """Refuse unknown keys, suggesting the closest known one (``difflib``)."""
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f", did you mean '{close[0]}'?" if close else f" (known: {', '.join(allowed)})"
            raise FingerfitError(
                f"unknown key '{shown(key)}' in {where}{hint}",
                path=path,
                field=prefix + shown(key),
            )


def session_file(directory: Path, name: object, meta_path: Path, field: str) -> Path:
    """The file a ``session.toml`` field names, contained in the session folder.

    Parameters
    ----------
    directory : Path
        The session folder.
    name : object
        The field's value: a path relative to the folder, e.g. ``"grasp.csv"`` or
        ``"raw/grasp.csv"``.
    meta_path : Path
        ``session.toml``, for messages.
    field : str
        The field, for messages (e.g. ``recordings.grasp``).

    Returns
    -------
    Path
        ``directory / name``; an existing regular file whose real path (symlinks
        resolved) lies inside the folder. The file is not opened.

    Raises
    ------
    FingerfitError
        Naming ``meta_path`` and ``field``: not a string, empty, control characters,
        an absolute path, a ``..`` component, a path or symlink resolving outside the
        folder, or no such regular file.
    """
    if not isinstance(name, str) or not name.strip():
        raise FingerfitError("must be a non-empty file name", path=meta_path, field=field)
    if any(ord(c) < 32 or ord(c) == 127 for c in name):
        raise FingerfitError(
            f"'{shown(name)}' contains control characters", path=meta_path, field=field
        )
    rel = PurePosixPath(name.replace("\\", "/"))
    if rel.is_absolute() or PureWindowsPath(name).drive:
        raise FingerfitError(
            f"'{shown(name)}' is an absolute path; name a file inside the session folder "
            "(a path relative to it)",
            path=meta_path,
            field=field,
        )
    if ".." in rel.parts:
        raise FingerfitError(
            f"'{shown(name)}' leaves the session folder ('..'); name a file inside it",
            path=meta_path,
            field=field,
        )
    f = directory / name
    try:
        root = directory.resolve(strict=True)
        real = f.resolve()
    except (OSError, RuntimeError) as exc:  # symlink loops, unreadable folders
        raise FingerfitError(
            f"cannot resolve '{shown(name)}' ({type(exc).__name__})", path=meta_path, field=field
        ) from None
    if not real.is_relative_to(root):
        raise FingerfitError(
            f"'{shown(name)}' is a link to a file outside the session folder; copy the file in",
            path=meta_path,
            field=field,
        )
    if not f.is_file():
        what = "is not a regular file" if f.exists() else "names a file that does not exist"
        raise FingerfitError(f"{what}: '{shown(name)}'", path=meta_path, field=field)
    return f


def _read_small_csv(path: Path, header: tuple[str, ...]) -> pd.DataFrame:
    """A small text table with an exact header; every line has ``len(header)`` fields.

    Returns the table as strings; row ``i`` is file line ``i + 2``.
    """
    raw = read_bytes(path)
    first = raw.split(b"\n", 1)[0].decode("utf-8", "replace").strip().lstrip("\ufeff")
    cols = tuple(h.strip() for h in first.split(","))
    if cols != header:
        raise FingerfitError(
            f"header must be '{','.join(header)}', found '{shown(first, 80)}'", path=path, line=1
        )
    n = check_field_counts(raw, path, len(header))
    if n == 0:
        return pd.DataFrame(columns=list(header), dtype=str)
    df = pd.read_csv(
        io.BytesIO(raw),
        dtype=str,
        keep_default_na=False,
        quoting=csv.QUOTE_NONE,
        encoding="utf-8",
        skip_blank_lines=True,
    )
    df.columns = list(header)
    return df.apply(lambda c: c.str.strip())


def _number(text: str, path: Path, line: int, field: str, what: str) -> float:
    """A finite number from a field's text, else an error naming the line and field."""
    try:
        if "_" in text:
            raise ValueError
        v = float(text)
    except ValueError:
        raise FingerfitError(
            f"{what} must be a number, not '{shown(text)}'", path=path, line=line, field=field
        ) from None
    if not math.isfinite(v):
        raise FingerfitError(
            f"{what} must be a finite number, not '{shown(text)}'",
            path=path,
            line=line,
            field=field,
        )
    return v


def read_landmarks(path: str | Path, units: str = "mm") -> dict[str, np.ndarray]:
    """Read a ``name,x,y,z`` landmarks CSV.

    Parameters
    ----------
    path : str or Path
    units : str
        Units of ``x,y,z`` in the file.

    Returns
    -------
    dict[str, ndarray]
        Landmark name -> position ``(3,)`` in mm, tracker coordinates.

    Raises
    ------
    FingerfitError
        Naming the file and line: header, field count, unknown or repeated name,
        a coordinate that is not a finite number.
    """
    path = Path(path)
    df = _read_small_csv(path, ("name", "x", "y", "z"))
    out: dict[str, np.ndarray] = {}
    for i, row in enumerate(df.itertuples(index=False), start=2):
        name = str(row.name)
        if not is_landmark_name(name):
            raise FingerfitError(
                f"unknown landmark name '{shown(name)}'", path=path, line=i, field="name"
            )
        if name in out:
            raise FingerfitError(f"landmark '{name}' given twice", path=path, line=i, field="name")
        xyz = np.array(
            [_number(v, path, i, k, "coordinate") for k, v in zip("xyz", row[1:], strict=True)]
        )
        if implausible_rows(xyz[None], UNITS_TO_MM[units]).size:
            big = float(xyz[np.argmax(np.abs(xyz))]) * UNITS_TO_MM[units]
            raise FingerfitError(implausible_message(big), path=path, line=i)
        out[name] = xyz * UNITS_TO_MM[units]
    return out


def read_events(path: str | Path) -> list[TargetEvent]:
    """Read ``recording,finger,target,start,end`` touch events.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of TargetEvent
        ``start`` and ``end`` in seconds (finite, ``start < end``).

    Raises
    ------
    FingerfitError
        Naming the file and line: header, field count, a time that is not a finite
        number, ``end <= start``, an unknown finger.
    """
    path = Path(path)
    df = _read_small_csv(path, EVENTS_HEADER)
    events = []
    for i, row in enumerate(df.itertuples(index=False), start=2):
        start = _number(row.start, path, i, "start", "start and end (s)")
        end = _number(row.end, path, i, "end", "start and end (s)")
        if not end > start:
            raise FingerfitError(
                f"need start < end, got {start:g} and {end:g} s", path=path, line=i
            )
        if row.finger not in DIGIT_NAMES:
            raise FingerfitError(
                f"unknown digit '{shown(row.finger)}' (expected one of {', '.join(DIGIT_NAMES)})",
                path=path,
                line=i,
                field="finger",
            )
        if row.target == row.finger:
            raise FingerfitError(
                f"digit '{row.finger}' cannot pinch itself", path=path, line=i, field="target"
            )
        events.append(TargetEvent(row.recording, row.finger, row.target, start, end))
    return events


def match_event_recordings(events: list[TargetEvent], names: list[str]) -> list[TargetEvent]:
    """Events naming a recording by another extension, renamed to the session's file.

    An event's ``recording`` that is no recording's name but has the stem of exactly
    one (``targets.csv`` for a session converted to ``targets.parquet``) names that
    recording; any other name is left for the session's check to refuse.

    Parameters
    ----------
    events : list of TargetEvent
    names : list of str
        The file names of the session's recordings.

    Returns
    -------
    list of TargetEvent
    """
    stems: dict[str, list[str]] = {}
    for n in names:
        stems.setdefault(Path(n).stem, []).append(n)
    out = []
    for ev in events:
        found = stems.get(Path(ev.recording).stem, [])
        if ev.recording not in names and len(found) == 1:
            ev = dataclasses.replace(ev, recording=found[0])
        out.append(ev)
    return out


def load_session(
    directory: str | Path, *, parsed: Session | None = None, test: bool = True
) -> Session:
    """Load and validate a session directory.

    Parameters
    ----------
    directory : str or Path
        Folder holding ``session.toml`` and the files it names. Every file must be a
        relative path inside this folder (symlinks included); nothing outside it is
        read.
    parsed : Session, optional
        The same session already read from byte-identical copies of its files (as
        ``fingerfit session`` does before it writes the folder): its recordings (by file
        name), landmarks and events are used instead of parsing those files again; the
        folder's ``session.toml`` and the whole-session checks still run.
    test : bool
        Read the free-motion test recordings. False (``fingerfit fit``, which does not
        use them): their files are checked to be inside the folder and present, not
        read, and the session's ``test`` is empty (``files`` still lists them).

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
    session_file(directory, SESSION_FILE, meta_path, SESSION_FILE)
    meta = read_toml(meta_path)
    _check_keys(meta, TOP_KEYS, meta_path, SESSION_FILE)
    fmt = _require(meta, "format", str, meta_path)
    if fmt != FORMAT:
        raise FingerfitError(
            f"unsupported format '{shown(fmt)}' (expected '{FORMAT}')",
            path=meta_path,
            field="format",
        )
    subject = check_subject_id(_require(meta, "subject", str, meta_path), path=meta_path)
    hand = _require(meta, "hand", str, meta_path)
    if hand not in ("left", "right"):
        raise FingerfitError(
            f"must be 'left' or 'right', not '{shown(hand)}'", path=meta_path, field="hand"
        )
    units = _require(meta, "units", str, meta_path)
    if units not in UNITS_TO_MM:
        raise FingerfitError(
            f"must be one of {', '.join(UNITS_TO_MM)}, not '{shown(units)}'",
            path=meta_path,
            field="units",
        )
    rate_value = _require(meta, "rate_hz", (int, float), meta_path)
    if not (0 < rate_value <= MAX_RATE_HZ):  # NaN fails too; huge ints never reach float()
        raise FingerfitError(
            f"must be positive and at most {MAX_RATE_HZ:g} Hz", path=meta_path, field="rate_hz"
        )
    rate = float(rate_value)
    fingers = _require(meta, "fingers", list, meta_path)
    if (
        not fingers
        or not all(isinstance(f, str) for f in fingers)
        or any(f not in DIGIT_NAMES for f in fingers)
        or len(set(fingers)) != len(fingers)
    ):
        raise FingerfitError(
            f"must be a non-empty list of distinct names from {', '.join(DIGIT_NAMES)}",
            path=meta_path,
            field="fingers",
        )
    recs = _require(meta, "recordings", dict, meta_path)
    _check_keys(recs, RECORDING_KEYS, meta_path, "[recordings]", "recordings.")

    def file(name: object, key: str) -> Path:
        return session_file(directory, name, meta_path, f"recordings.{key}")

    # Check every named file first (containment, existence), then read.
    ref_name = _require(recs, "reference", str, meta_path, "recordings.")
    grasp_names = _file_list(
        _require(recs, "grasp", (str, list), meta_path, "recordings."),
        meta_path,
        "recordings.grasp",
    )
    if not grasp_names:
        raise FingerfitError(
            "needs at least one grasp recording", path=meta_path, field="recordings.grasp"
        )
    target_names = _file_list(recs.get("targets", []), meta_path, "recordings.targets")
    test_names = _file_list(recs.get("test", []), meta_path, "recordings.test")
    map_file = None
    if "markers" in meta:
        map_file = session_file(directory, meta["markers"], meta_path, "markers")
    ref_file = file(ref_name, "reference")
    grasp_files = [file(n, "grasp") for n in grasp_names]
    target_files = [file(n, "targets") for n in target_names]
    test_files = [file(n, "test") for n in test_names]
    for key, files in (
        ("reference", [ref_file]),
        ("grasp", grasp_files),
        ("targets", target_files),
        ("test", test_files),
    ):
        for f in files:
            check_recording_kind(f, map_file is not None, meta_path, f"recordings.{key}")
    events_file = None
    if "events" in recs:
        events_file = file(_require(recs, "events", str, meta_path, "recordings."), "events")
    landmarks_file: Path | None = None
    if map_file is None or os.path.lexists(directory / LANDMARKS_FILE):  # optional with markers
        landmarks_file = session_file(directory, LANDMARKS_FILE, meta_path, LANDMARKS_FILE)

    known = {r.name: r for r in parsed.recordings()} if parsed is not None else {}

    def load(f: Path) -> Recording:
        if f.name in known:
            return known[f.name]
        if map_file is not None:
            return read_marker_recording(f)  # in the units the file states
        return read_pose_csv(f, units=units, rate_hz=rate)

    reference = load(ref_file)
    grasp = [load(f) for f in grasp_files]
    targets = [load(f) for f in target_files]
    test = [load(f) for f in test_files] if test else []
    if parsed is not None:
        landmarks, events, marker_map = parsed.landmarks, parsed.events, parsed.marker_map
    else:
        landmarks = read_landmarks(landmarks_file, units) if landmarks_file is not None else {}
        events = read_events(events_file) if events_file is not None else []
        marker_map = read_marker_map(map_file) if map_file is not None else {}
    recordings = [reference, *grasp, *targets, *test]
    events = match_event_recordings(events, [r.name for r in recordings])
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
        files=(
            meta_path,
            ref_file,
            *grasp_files,
            *target_files,
            *test_files,
            *([landmarks_file] if landmarks_file is not None else []),
            *([events_file] if events_file is not None else []),
            *([map_file] if map_file is not None else []),
        ),
        marker_map=marker_map,
    )
    _check_complete(session, map_file)
    return session


def _check_complete(session: Session, map_file: Path | None = None) -> None:
    """Every listed finger has its sensors in the reference and grasp recordings and its
    landmarks; in a marker session (``map_file``), the map's segments take the place of
    the sensors (:func:`~fingerfit.io.markers.session.check_marker_session`) and no
    landmark is required."""
    assert session.path is not None
    if map_file is not None:
        check_marker_session(session, map_file)
    for finger in session.fingers if map_file is None else ():
        needed = digit_sensors(finger)
        for rec in [session.reference, *session.grasp]:
            for s in needed:
                if s not in rec.poses or not rec.poses[s].valid.any():
                    raise FingerfitError(
                        f"no samples for sensor '{s}' (finger '{finger}' is listed in {SESSION_FILE})",
                        path=session.path / rec.name,
                    )
        for lm in DIGITS[finger].landmarks:
            if f"{finger}.{lm}" not in session.landmarks:
                raise FingerfitError(
                    f"missing landmark '{finger}.{lm}' (finger '{finger}' is listed in {SESSION_FILE})",
                    path=session.path / LANDMARKS_FILE,
                )
    names = [r.name for r in session.recordings()]
    for i, ev in enumerate(session.events):
        if ev.recording not in names:
            raise FingerfitError(
                f"event names unknown recording '{shown(ev.recording)}' (the session's "
                f"recordings: {', '.join(names)}; a name with another extension is taken "
                "when its stem is one recording's)",
                path=session.path / "events.csv",
                line=i + 2,
                field="recording",
            )
        if ev.is_pinch:
            if ev.target not in session.fingers or ev.finger not in session.fingers:
                raise FingerfitError(
                    f"pinch event of '{ev.finger}' and '{ev.target}' names a digit not listed "
                    f"in {SESSION_FILE}",
                    path=session.path / "events.csv",
                )
        elif f"target.{ev.target}" not in session.landmarks:
            raise FingerfitError(
                f"event names target '{ev.target}' with no landmark 'target.{ev.target}'",
                path=session.path / "events.csv",
            )


def _toml_list(names: list[str]) -> str:
    return "[" + ", ".join(json.dumps(n) for n in names) + "]"


def write_session_toml(session: Session, directory: str | Path) -> Path:
    """Write ``session.toml`` naming the session's recordings (files are not written).

    ``events = "events.csv"`` is listed when the session has events, ``markers =
    "markers.toml"`` when it has a marker map.
    """
    lines = [
        f'format = "{FORMAT}"',
        f"subject = {json.dumps(session.subject)}",
        f'hand = "{session.hand}"',
        f'units = "{session.units}"',
        f"rate_hz = {float(session.rate_hz)!r}",
        f"fingers = {_toml_list(session.fingers)}",
        *([f'markers = "{MAP_FILE}"'] if session.marker_map else []),
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
        Arrays in mm; files are written in ``session.units``. A marker session's
        recordings are written as TRC (``<stem>.trc``), with its map (``markers.toml``)
        and, when it has landmarks, ``landmarks.csv``.
    directory : str or Path
        Created if needed; existing files of the same names are replaced.

    Returns
    -------
    Path
        The directory.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    if session.marker_map:
        session = trc_named(session)
        for rec in session.recordings():
            write_markers(directory / rec.name, rec, units=session.units)
        write_marker_map(directory / MAP_FILE, session.marker_map)
    else:
        for rec in session.recordings():
            write_pose_csv(directory / rec.name, rec, units=session.units)
    if session.landmarks or not session.marker_map:
        write_landmarks(directory / LANDMARKS_FILE, session.landmarks, session.units)
    if session.events:
        write_events(directory / EVENTS_FILE, session.events)
    write_session_toml(session, directory)
    return directory


def write_landmarks(path: str | Path, landmarks: dict[str, FloatArray], units: str = "mm") -> Path:
    """Write ``name,x,y,z`` landmarks, atomically.

    Parameters
    ----------
    path : str or Path
    landmarks : dict[str, ndarray]
        Name -> position ``(3,)`` in mm, tracker coordinates.
    units : str
        Units of the written coordinates.
    """
    scale = UNITS_TO_MM[units]
    lm = pd.DataFrame(
        [(k, *(v / scale)) for k, v in landmarks.items()], columns=["name", "x", "y", "z"]
    )
    with atomic_write(path, newline="") as fh:
        lm.to_csv(fh, index=False, lineterminator="\n")
    return Path(path)


def write_events(path: str | Path, events: list[TargetEvent]) -> Path:
    """Write ``recording,finger,target,start,end`` touch events (s), atomically."""
    ev = pd.DataFrame([e.__dict__ for e in events], columns=list(EVENTS_HEADER))
    with atomic_write(path, newline="") as fh:
        ev.to_csv(fh, index=False, lineterminator="\n")
    return Path(path)
