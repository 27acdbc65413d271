"""The marker map: which segment carries which skin markers (``markers.toml``).

::

    [markers]
    hand = ["H1", "H2", "H3", "H4"]
    "index.proximal" = ["IP1", "IP2"]
    "index.middle" = ["IM1", "IM2"]
    "index.distal" = ["ID1"]

Segments are the sensor names of the session format (``hand``, ``<finger>.proximal``,
``.middle``, ``.distal``, ``thumb.metacarpal``, ``.proximal``, ``.distal``); markers are
the labels of the recordings. :func:`read_marker_map` checks the file alone,
:func:`check_marker_map` the map against a session's digits and recordings.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ...digits import DIGIT_NAMES, DIGITS, HAND_SENSOR
from ...errors import FingerfitError, shown
from ...session import Recording
from ..atomic import atomic_write
from ..textfile import read_toml
from .frames import check_marker_length, median_pair_distances, sample_frames

#: The map's file name in a session folder.
MAP_FILE = "markers.toml"
#: Fewest markers on the hand: three give its pose.
MIN_HAND_MARKERS = 3
#: Plausible span (mm) of a session's mapped markers: the largest median distance between
#: two of them. Measured: 183 mm on the real Qualisys glove recording (hand plate to the
#: middle fingertip); a hand plate and one proximal phalanx span 60 mm or more, a whole
#: hand at most about 250 mm. Centimetres read as millimetres fall below, millimetres
#: read as centimetres above.
HAND_SPAN_MM = (25.0, 400.0)
_TOP_KEYS = ("markers",)
#: Every segment a map may name.
SEGMENTS = (HAND_SENSOR, *(DIGITS[d].sensor(s) for d in DIGIT_NAMES for s in DIGITS[d].segments))


def segment_names() -> str:
    """The segment names a map may use, for messages."""
    return "hand, <finger>.proximal|middle|distal, thumb.metacarpal|proximal|distal"


def segment_digit(segment: str) -> str | None:
    """The digit a segment belongs to (None for ``hand``)."""
    return None if segment == HAND_SENSOR else segment.split(".", 1)[0]


def read_marker_map(path: str | Path) -> dict[str, tuple[str, ...]]:
    """Read a marker map (TOML, one ``[markers]`` table: segment -> labels).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict[str, tuple of str]
        Segment name -> its marker labels, in the file's order.

    Raises
    ------
    FingerfitError
        One line naming the file and the field (``markers.<segment>``): not TOML, an
        unknown key or segment, a segment with no markers, a label that is not a
        non-empty string, a marker listed twice or under two segments, no ``hand`` or
        fewer than :data:`MIN_HAND_MARKERS` on it.
    """
    path = Path(path)
    meta = read_toml(path)
    for key in meta:
        if key not in _TOP_KEYS:
            raise FingerfitError(
                f"unknown key '{shown(key)}' (the map is one [markers] table)",
                path=path,
                field=shown(key),
            )
    table = meta.get("markers")
    if not isinstance(table, dict):
        raise FingerfitError(
            "missing [markers] table (segment = [marker labels])", path=path, field="markers"
        )
    out: dict[str, tuple[str, ...]] = {}
    owner: dict[str, str] = {}
    for segment, labels in table.items():
        field = f"markers.{shown(segment)}"
        if segment not in SEGMENTS:
            close = difflib.get_close_matches(segment, SEGMENTS, n=1)
            hint = f", did you mean '{close[0]}'?" if close else f" (segments: {segment_names()})"
            raise FingerfitError(
                f"unknown segment '{shown(segment)}'{hint}", path=path, field=field
            )
        if isinstance(labels, str):
            labels = [labels]
        if not isinstance(labels, list) or not all(
            isinstance(x, str) and x.strip() for x in labels
        ):
            raise FingerfitError(
                "must be a list of marker labels (non-empty strings)", path=path, field=field
            )
        if not labels:
            raise FingerfitError(f"segment '{segment}' has no markers", path=path, field=field)
        for label in labels:
            if label in owner:
                where = (
                    "twice"
                    if owner[label] == segment
                    else f"under '{owner[label]}' and '{segment}'"
                )
                raise FingerfitError(
                    f"marker '{shown(label)}' is listed {where}", path=path, field=field
                )
            owner[label] = segment
        out[segment] = tuple(labels)
    hand = out.get(HAND_SENSOR, ())
    if len(hand) < MIN_HAND_MARKERS:
        raise FingerfitError(
            f"the hand needs {MIN_HAND_MARKERS} or more markers, found {len(hand)}",
            path=path,
            field=f"markers.{HAND_SENSOR}",
        )
    return out


def check_marker_map(
    marker_map: dict[str, tuple[str, ...]],
    fingers: Sequence[str],
    recordings: Sequence[Recording],
    path: Path,
    *,
    sampled: Sequence[Recording] = (),
    files: Mapping[str, Path] | None = None,
) -> None:
    """Check a marker map against a session's digits and recordings.

    Parameters
    ----------
    marker_map : dict[str, tuple of str]
        From :func:`read_marker_map`.
    fingers : sequence of str
        The session's digits.
    recordings : sequence of Recording
        Every recording: each must hold every mapped marker.
    path : Path
        The map's file, for messages.
    sampled : sequence of Recording
        The recordings in which every mapped marker must have been seen at least once
        (the reference and the grasp recordings).
    files : mapping of str to Path, optional
        The file of each recording (by its name), for messages.

    Raises
    ------
    FingerfitError
        One line: a segment of a digit not in ``fingers`` or a listed digit with no
        segment (naming the map and the field), a mapped marker a recording lacks (naming
        the map, the segment and the recording), a marker never seen in a reference or
        grasp recording or markers spanning an implausible size (naming the recording).
    """
    for segment in marker_map:
        digit = segment_digit(segment)
        if digit is not None and digit not in fingers:
            raise FingerfitError(
                f"segment '{segment}' belongs to digit '{digit}', which is not one of the "
                f"session's fingers ({', '.join(fingers)})",
                path=path,
                field=f"markers.{segment}",
            )
    for finger in fingers:
        if not any(segment_digit(s) == finger for s in marker_map):
            raise FingerfitError(
                f"finger '{finger}' is one of the session's fingers but has no markers "
                f"(give '{finger}.<segment>' = [labels])",
                path=path,
                field="markers",
            )
    files = files or {}

    def where(rec: Recording) -> Path:
        return files.get(rec.name, Path(rec.name))

    for rec in recordings:
        for segment, labels in marker_map.items():
            for label in labels:
                if label not in rec.markers:
                    close = difflib.get_close_matches(label, list(rec.markers), n=1)
                    hint = f", did you mean '{close[0]}'?" if close else ""
                    raise FingerfitError(
                        f"unknown marker '{shown(label)}': not in recording {where(rec)}{hint}",
                        path=path,
                        field=f"markers.{segment}",
                    )
    for rec in sampled:
        for segment, labels in marker_map.items():
            for label in labels:
                if not np.isfinite(rec.markers[label][:, 0]).any():
                    raise FingerfitError(
                        f"no samples for marker '{label}' (segment '{segment}' in {path.name})",
                        path=where(rec),
                    )
    for rec in recordings:
        check_hand_span(rec, marker_map, where(rec))


def check_hand_span(
    recording: Recording, marker_map: dict[str, tuple[str, ...]], path: str | Path
) -> None:
    """Refuse mapped markers spanning more or less than a hand (:data:`HAND_SPAN_MM`).

    Parameters
    ----------
    recording : Recording
        Holding every mapped marker (mm).
    marker_map : dict[str, tuple of str]
    path : str or Path
        The recording's file, for the message.

    Raises
    ------
    FingerfitError
        ``field 'units'``: the span found and the plausible range.
    """
    labels = [lb for labels in marker_map.values() for lb in labels]
    idx = sample_frames(recording.n_frames)
    pts = np.stack([recording.markers[lb][idx] for lb in labels], axis=1)
    with np.errstate(all="ignore"):
        d = median_pair_distances(pts)
    if not np.isfinite(d).any():
        return
    check_marker_length(
        float(np.nanmax(d)),
        HAND_SPAN_MM,
        "span of the mapped markers",
        "the farthest two, median over frames",
        path,
    )


def write_marker_map(path: str | Path, marker_map: dict[str, tuple[str, ...]]) -> Path:
    """Write a marker map as TOML (``[markers]``: segment -> labels), atomically.

    Returns
    -------
    Path
        :func:`read_marker_map` reads back the same map.
    """
    lines = ["[markers]"] + [
        f"{json.dumps(seg)} = [{', '.join(json.dumps(lb) for lb in labels)}]"
        for seg, labels in marker_map.items()
    ]
    with atomic_write(path) as fh:
        fh.write("\n".join(lines) + "\n")
    return Path(path)
