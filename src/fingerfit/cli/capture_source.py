"""Where ``fingerfit capture`` reads from: the ``--source`` of every protocol and step."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import FingerfitError, shown

if TYPE_CHECKING:
    from ..session import Recording


def source_files(spec: str) -> tuple[Path, ...]:
    """The files a source reads (a replayed recording), never to be written onto."""
    from ..live import sources as src

    if src.split_spec(spec)[0] == "replay":
        return (src.parse_replay(spec)[0],)
    return ()


def open_source(
    spec: str,
    *,
    units: str,
    rate_hz: float,
    sensors: list[str],
    stations: str | None,
    check: Callable[[Recording, Path], None] | None = None,
):
    """The source of ``--source`` for ``sensors``; a replayed recording is read (in the
    session's ``units``) and given to ``check`` first (which raises when it lacks what
    the protocol needs)."""
    from ..io import read_pose_csv
    from ..live import sources as src

    kind = src.split_spec(spec)[0]
    if kind == "replay":
        path, speed = src.parse_replay(spec)
        rec = read_pose_csv(path, units=units, rate_hz=rate_hz)
        if check is not None:
            check(rec, path)
        return src.ReplaySource(rec, speed)
    if kind == "liberty":
        port, baud = src.parse_liberty(spec)
        mapping = (
            src.parse_stations(stations, sensors) if stations else src.default_stations(sensors)
        )
        return src.LibertySource(port, baud, mapping, rate_hz)
    if kind == "lsl":
        return src.LslSource(src.split_spec(spec)[1], sensors)
    raise FingerfitError(
        f"unknown source '{shown(spec)}': replay:FILE, liberty:PORT or lsl:NAME", field="--source"
    )
