"""What a marker session adds to the session format (``fingerfit.session/1``): its
recordings are marker files, its map is checked against them, and it is saved as TRC.

A session is a marker session when ``session.toml`` names a marker map (``markers =
"markers.toml"``). Then every recording is a marker file (``.trc``, ``.tsv``, ``.c3d``,
read in the units it states), the map's segments take the place of the sensors in the
completeness check, and ``landmarks.csv`` is optional. See ``docs/formats.md``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ...errors import FingerfitError, shown
from ...session import Recording, Session
from . import MARKER_SUFFIXES, is_marker_file
from .markermap import check_marker_map

#: Largest relative difference between a marker recording's frame rate and the session's
#: ``rate_hz`` (a time column written to 5 decimals puts 120 Hz at 120.05 Hz).
RATE_TOLERANCE = 0.01


def check_recording_kind(f: Path, markers: bool, meta_path: Path, field: str) -> None:
    """Refuse a pose file in a marker session, or a marker file in a 6-DOF one.

    Raises
    ------
    FingerfitError
        Naming ``meta_path`` and ``field``.
    """
    if markers == is_marker_file(f):
        return
    if markers:
        why = (
            f"is not a marker recording ({', '.join(MARKER_SUFFIXES)}): a session with a "
            "marker map holds marker recordings only"
        )
    else:
        why = 'is a marker recording: name the marker map too (markers = "markers.toml"; --markers)'
    raise FingerfitError(f"'{shown(f.name)}' {why}", path=meta_path, field=field)


def frame_rate(recording: Recording) -> float:
    """A recording's frame rate (Hz): one over its median time step (NaN for one frame)."""
    steps = np.diff(recording.time)
    return float(1.0 / np.median(steps)) if steps.size else float("nan")


def check_marker_session(
    session: Session, map_path: Path, files: Mapping[str, Path] | None = None
) -> None:
    """A marker session's completeness: the map against the digits and the recordings,
    and every recording at the session's rate.

    Parameters
    ----------
    session : Session
        With ``marker_map``.
    map_path : Path
        The map's file, for messages.
    files : mapping of str to Path, optional
        The file of each recording by its name, for messages (default: in
        ``session.path``).

    Raises
    ------
    FingerfitError
        One line: see :func:`~fingerfit.io.markers.markermap.check_marker_map`; a
        recording whose frame rate is not ``rate_hz`` (naming the recording).
    """
    if files is None:
        folder = session.path if session.path is not None else Path()
        files = {r.name: folder / r.name for r in session.recordings()}
    for rec in session.recordings():
        rate = frame_rate(rec)
        if np.isfinite(rate) and abs(rate / session.rate_hz - 1.0) > RATE_TOLERANCE:
            raise FingerfitError(
                f"frame rate {rate:.6g} Hz, not the session's rate_hz {session.rate_hz:g}",
                path=files.get(rec.name, rec.name),
            )
    check_marker_map(
        session.marker_map,
        session.fingers,
        session.recordings(),
        map_path,
        sampled=[session.reference, *session.grasp],
        files=files,
    )


def trc_named(session: Session) -> Session:
    """The session with every recording named ``<stem>.trc`` (how it is saved).

    Raises
    ------
    FingerfitError
        When two recordings would get the same name.
    """
    seen: dict[str, str] = {}

    def renamed(rec: Recording) -> Recording:
        name = Path(rec.name).with_suffix(".trc").name
        if name in seen:
            raise FingerfitError(
                f"recordings '{seen[name]}' and '{rec.name}' would both be saved as {name}"
            )
        seen[name] = rec.name
        return dataclasses.replace(rec, name=name)

    out = dataclasses.replace(
        session,
        reference=renamed(session.reference),
        grasp=[renamed(r) for r in session.grasp],
        targets=[renamed(r) for r in session.targets],
        test=[renamed(r) for r in session.test],
    )
    new = {old: name for name, old in seen.items()}
    out.events = [
        dataclasses.replace(ev, recording=new.get(ev.recording, ev.recording))
        for ev in session.events
    ]
    return out
