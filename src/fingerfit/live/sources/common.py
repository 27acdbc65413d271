"""What every live source shares: the block of frames it yields, its counts, the spec
parsing, the reconnect loop, and the replay of a recorded file."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import FingerfitError, shown
from ...session import PoseSeries, Recording
from ...transforms import FloatArray

#: Frames handed over at most per block (a fast replay catches up in blocks this big).
MAX_BLOCK = 2048
#: Seconds without a byte from a live device before the stream ends with an error.
NO_DATA_SECONDS = 2.0
#: Seconds a source waits for data before it yields None (the loop then checks its
#: duration, Ctrl-C and the silence watchdog).
POLL_S = 0.01
#: Default ``--reconnect`` (s): how long a live source may stay lost (serial port gone,
#: LSL stream gone) before the stream ends.
DEFAULT_RECONNECT_S = 10.0
#: Seconds between attempts to reopen a lost source: doubled after each failed attempt
#: from the first value, up to the second.
RECONNECT_BACKOFF_S = (0.05, 1.0)
#: Liberty frame rate (Hz): the device's default, one frame every 4.2 ms.
LIBERTY_RATE_HZ = 240.0
#: The Liberty sample rate after ``U1`` is in cm.
_CM_TO_MM = 10.0


@dataclass
class Block:
    """Frames that arrived together.

    Attributes
    ----------
    recording : Recording
        ``time (n,)`` s (recording or device time), poses per sensor (mm, tracker
        frame; NaN where a sensor's record is missing).
    arrival : ndarray, shape (n,)
        Arrival at fingerfit, ``time.monotonic()`` seconds (the LSL clock on Linux).
    lost : int
        Frames known to be lost just before this block (device frame-count gaps).
    """

    recording: Recording
    arrival: FloatArray
    lost: int = 0


@dataclass
class SourceStats:
    """Counts a source keeps: bytes skipped and records rejected while resynchronising,
    frames lost (frame-count gaps), outages (the device or stream lost) and reconnects
    (an outage over: the source is back)."""

    skipped_bytes: int = 0
    rejected: int = 0
    lost_frames: int = 0
    outages: int = 0
    reconnects: int = 0
    notes: list[str] = field(default_factory=list)


def _stderr_warning(text: str) -> None:
    print(f"warning: {text}", file=sys.stderr, flush=True)


def check_reconnect(seconds: float) -> float:
    """``--reconnect`` in s; a clear error unless a number >= 0."""
    if not (math.isfinite(seconds) and seconds >= 0):
        raise FingerfitError(
            f"must be a number of seconds >= 0, not {seconds:g}", field="--reconnect"
        )
    return seconds


def _retry(attempt: Callable[[], bool], deadline: float) -> Iterator[None]:
    """Call ``attempt`` until it returns True or ``deadline`` (``time.monotonic()`` s)
    passes, waiting 0.05, 0.1, 0.2 ... s between attempts (at most
    :data:`RECONNECT_BACKOFF_S` [1]); None is yielded every :data:`POLL_S` s meanwhile,
    so the loop keeps checking its watchdog, ``--duration`` and Ctrl-C.

    Parameters
    ----------
    attempt : callable
        One try (reopen the port, find the stream): True when it worked.
    deadline : float
        ``time.monotonic()`` s after which no attempt starts.

    Yields
    ------
    None
        While waiting for the next attempt.

    Returns
    -------
    bool
        The generator's value (``back = yield from _retry(...)``): whether an attempt
        worked.
    """
    delay, cap = RECONNECT_BACKOFF_S
    while True:
        if attempt():
            return True
        now = time.monotonic()
        if now >= deadline:
            return False
        wake = min(now + delay, deadline)
        delay = min(2 * delay, cap)
        while time.monotonic() < wake:
            time.sleep(min(POLL_S, max(0.0, wake - time.monotonic())))
            yield None


def split_spec(spec: str) -> tuple[str, str, str | None]:
    """``kind:TARGET[@PARAM]`` -> ``(kind, target, param)``.

    The ``@PARAM`` part is taken only if it follows the last ``@`` and the rest is not
    empty (file names may hold ``@``: ``replay:a@b.csv`` is the file ``a@b.csv``
    unless ``b.csv`` parses as the parameter, which the caller checks).

    Raises
    ------
    FingerfitError
        ``field '--source'``: no ``kind:`` or an unknown kind.
    """
    kind, sep, rest = spec.partition(":")
    if not sep or kind not in ("replay", "liberty", "lsl") or not rest:
        raise FingerfitError(
            f"'{shown(spec)}' is not a source: use replay:FILE[@SPEED], liberty:PORT[@BAUD] "
            "or lsl:NAME",
            field="--source",
        )
    target, at, param = rest.rpartition("@")
    if not at or not target:
        return kind, rest, None
    return kind, target, param


def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise FingerfitError(
            f"{what} in '{shown(spec)}' must be a positive number, not '{shown(text)}'",
            field="--source",
        )
    return value


def parse_replay(spec: str) -> tuple[Path, float]:
    """``replay:FILE[@SPEED]`` -> ``(path, speed)``; ``@SPEED`` is taken only when it
    is a number and ``FILE@SPEED`` is not itself an existing file."""
    _, target, param = split_spec(spec)
    if param is None or Path(f"{target}@{param}").exists():
        return Path(target if param is None else f"{target}@{param}"), 1.0
    return Path(target), _number(param, "the replay speed", spec)


def parse_liberty(spec: str) -> tuple[str, int]:
    """``liberty:PORT[@BAUD]`` -> ``(port, baud)`` (default 115200 baud)."""
    _, target, param = split_spec(spec)
    baud = 115200 if param is None else _number(param, "the baud rate", spec)
    if baud != int(baud):
        raise FingerfitError(f"the baud rate in '{shown(spec)}' must be whole", field="--source")
    return target, int(baud)


def _recording(name: str, time_s: FloatArray, poses: dict[str, PoseSeries]) -> Recording:
    return Recording(name, time_s, poses)


# ----------------------------------------------------------------------------- replay


class ReplaySource:
    """A recording played at its own rate, ``speed`` times faster.

    Parameters
    ----------
    recording : Recording
        As read by :func:`fingerfit.io.read_pose_csv` (mm, tracker frame).
    speed : float
        Playback speed (1 = real time).
    """

    live = False

    def __init__(self, recording: Recording, speed: float = 1.0) -> None:
        self.recording = recording
        self.speed = speed
        self.name = recording.name
        self.stats = SourceStats()

    def blocks(self) -> Iterator[Block | None]:
        """Frames as they fall due: each frame's arrival is its due time
        (``monotonic`` at the start + recording time / speed), so a late wake-up shows
        as latency; every frame due is in the block. Frames whose time is NaN are due
        with the previous frame. While no frame is due, None every :data:`POLL_S`."""
        rec = self.recording
        n = rec.n_frames
        if n == 0:
            return
        t = rec.time - rec.time[0]
        t = np.fmax.accumulate(np.where(np.isfinite(t), t, 0.0)) / self.speed
        t0 = time.monotonic()
        due = t0 + t
        i = 0
        while i < n:
            now = time.monotonic()
            if due[i] > now:
                if due[i] - now > POLL_S:
                    time.sleep(POLL_S)
                    yield None  # nothing due yet: the loop can check its watchdog
                else:
                    time.sleep(due[i] - now)
                continue
            j = min(n, i + MAX_BLOCK, int(np.searchsorted(due, now, side="right")))
            yield Block(rec.slice(slice(i, j)), due[i:j].copy())
            i = j

    def close(self) -> None:
        """Nothing to release."""


# ---------------------------------------------------------------------------- Liberty


def default_stations(sensors: list[str]) -> dict[int, str]:
    """Stations 1, 2, ... -> the model's sensors in order (hand first)."""
    return {i + 1: s for i, s in enumerate(sensors)}


def parse_stations(text: str, sensors: list[str]) -> dict[int, str]:
    """``"1=hand,2=index.proximal,..."`` -> station -> sensor: any of the model's sensors
    once (a sensor without a station is missing in every frame; whether the rest determine
    the joints is checked by the caller, :func:`fingerfit.track.check_layout`).

    Raises
    ------
    FingerfitError
        ``field '--stations'``: a malformed pair, a station outside 1-16, a sensor
        the model does not use, or a repeat.
    """
    out: dict[int, str] = {}
    for part in text.split(","):
        key, eq, name = part.strip().partition("=")
        if not eq or not key.strip().isdigit() or not 1 <= int(key) <= 16:
            raise FingerfitError(
                f"'{shown(part)}' is not STATION=SENSOR with a station 1-16", field="--stations"
            )
        name = name.strip()
        if name not in sensors:
            raise FingerfitError(
                f"sensor '{shown(name)}' is not one the model uses ({', '.join(sensors)})",
                field="--stations",
            )
        if int(key) in out or name in out.values():
            raise FingerfitError(f"'{shown(part)}' repeats a station or sensor", field="--stations")
        out[int(key)] = name
    return out
