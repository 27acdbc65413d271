"""Sources of live frames: a recording replayed, a Polhemus Liberty, an LSL stream.

Every source yields :class:`Block` s: the frames that arrived together, as a
:class:`~fingerfit.session.Recording` (positions mm, rotations sensor -> tracker, the
same object the file readers return) with each frame's arrival time. Source specs:

* ``replay:FILE[@SPEED]`` -- a pose CSV as ``fingerfit angles`` reads it, played at its
  own rate (or ``SPEED`` times faster); each frame "arrives" at its due time;
* ``liberty:PORT[@BAUD]`` -- a Liberty on a serial port (:mod:`.liberty_serial`);
* ``lsl:NAME`` -- an LSL stream of type ``MoCap`` whose channels are labelled
  ``<sensor>.x|y|z`` (position, unit in the channel metadata) and
  ``<sensor>.qw|qx|qy|qz`` (quaternion, scalar first).

The live sources survive an outage: a serial port that fails is reopened, an LSL stream
that goes away is looked for again, for up to ``reconnect`` s (``--reconnect``), with one
warning per outage; meanwhile they yield None, and the stream's watchdog marks the
silence.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from ..session import UNITS_TO_MM, PoseSeries, Recording
from ..transforms import FloatArray, matrix_from_quat_wxyz
from . import require
from .liberty_serial import SETUP_COMMANDS, START, STOP, parse_records

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
    """``"1=hand,2=index.proximal,..."`` -> station -> sensor; every model sensor once.

    Raises
    ------
    FingerfitError
        ``field '--stations'``: a malformed pair, a station outside 1-16, a sensor
        the model does not use, a repeat, or a model sensor without a station.
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
    missing = [s for s in sensors if s not in out.values()]
    if missing:
        raise FingerfitError(f"no station for sensor '{missing[0]}'", field="--stations")
    return out


class LibertySource:
    """A Polhemus Liberty on a serial port, in continuous binary output.

    When the port fails (a pulled cable: the read raises ``OSError`` /
    ``SerialException``) the source warns once (:attr:`warn`), closes it and tries to
    open it again -- 0.05, 0.1, 0.2 ... s apart, at most 1 s -- and to set the device up
    again, for up to ``reconnect`` s; meanwhile it yields None every :data:`POLL_S` s (the
    stream's watchdog marks the silence). Once back, frames flow as before; the outage is
    counted in :attr:`stats` (``outages``, ``reconnects``).

    Parameters
    ----------
    port : str
        Serial device (``/dev/ttyUSB0``, ``/dev/serial/by-id/...``, ``COM3``).
    baud : int
    stations : dict[int, str]
        Station number -> sensor name (every sensor the model uses).
    rate_hz : float
        Device frame rate, for the frame time ``frame count / rate``.
    reconnect : float
        Seconds to keep trying to reopen a lost port (0: the stream ends at once).

    Attributes
    ----------
    warn : callable
        Called with the one-line warning of an outage (default: printed on stderr;
        :func:`fingerfit.live.stream.run` sets its own).
    """

    live = True

    def __init__(
        self,
        port: str,
        baud: int,
        stations: dict[int, str],
        rate_hz: float = LIBERTY_RATE_HZ,
        reconnect: float = DEFAULT_RECONNECT_S,
    ) -> None:
        self._pyserial = require("serial")
        self.name = f"liberty:{port}"
        self.port = port
        self.baud = baud
        self.stations = stations
        self.rate_hz = rate_hz
        self.reconnect = check_reconnect(reconnect)
        self.stats = SourceStats()
        self.warn: Callable[[str], None] = _stderr_warning
        self._station_list = np.array(sorted(stations), dtype=np.int64)
        self._col = {s: k for k, s in enumerate(sorted(stations))}
        try:
            self.serial = self._open()
        except (self._pyserial.SerialException, OSError, ValueError) as exc:
            raise FingerfitError(f"cannot open the serial port: {exc}", path=port) from None

    def _open(self):
        """Open the port and put the device into continuous binary output (the set-up of
        ``docs/streaming.md``, every time: a device that was power-cycled forgot it).

        Raises
        ------
        SerialException, OSError, ValueError
            The port does not open.
        FingerfitError
            A command could not be written (the port is closed again).
        """
        port = self._pyserial.Serial(self.port, self.baud, timeout=POLL_S)
        self.serial = port
        try:
            self._write(STOP)
            time.sleep(0.1)
            port.reset_input_buffer()
            for command in SETUP_COMMANDS:
                self._write(command)
            self._write(START)
        except BaseException:
            port.close()
            raise
        return port

    def _write(self, data: bytes) -> None:
        try:
            self.serial.write(data)
            self.serial.flush()
        except Exception as exc:  # pyserial raises SerialException / OSError
            raise FingerfitError(
                f"device disconnected (write failed: {exc})", path=self.port
            ) from None

    def _reopen(self, reason: str) -> Iterator[None]:
        """The port failed: close it, warn once, and reopen it within ``reconnect`` s
        (yielding None while waiting).

        Raises
        ------
        FingerfitError
            Not back in time (or ``reconnect`` is 0): ``device disconnected (...)``.
        """
        with contextlib.suppress(Exception):
            self.serial.close()
        what = f"device disconnected ({reason})" if reason else "device disconnected"
        if self.reconnect <= 0:
            raise FingerfitError(what, path=self.port)
        self.stats.outages += 1
        self.warn(f"{self.port}: {what}; reopening the port (up to {self.reconnect:g} s)")

        def attempt() -> bool:
            try:
                self._open()
            except (self._pyserial.SerialException, OSError, ValueError, FingerfitError):
                return False
            return True

        back = yield from _retry(attempt, time.monotonic() + self.reconnect)
        if not back:
            raise FingerfitError(f"{what}; not back within {self.reconnect:g} s", path=self.port)
        self.stats.reconnects += 1

    def blocks(self) -> Iterator[Block | None]:
        """Frames as their last station record arrives (None after a poll without data).

        A frame is complete when every mapped station has reported; a frame whose
        records are not all there is handed over (with NaN for the missing sensors)
        when the next frame starts. Frame-count gaps are counted as lost frames. After a
        reconnect, a frame count that went on counts the frames of the outage as lost; one
        that started again (the device was power-cycled) continues the time column from
        the last frame plus the outage's duration; a frame half received when the port
        failed is dropped.

        Raises
        ------
        FingerfitError
            The port fails and does not come back within ``reconnect`` s, or no byte
            arrives for :data:`NO_DATA_SECONDS` while the port is open.
        """
        buf = bytearray()
        k = len(self.stations)
        last_frame: int | None = None
        emitted: int | None = None
        first_frame: int | None = None
        t_offset = 0.0  # s added to the frame time (a counter restarted after an outage)
        t_last = 0.0  # time of the last frame handed over (s)
        lost_at: float | None = None  # when the port failed, until the first frame after
        # Pending records of the newest frame: columns = sorted stations.
        pend_pos = np.full((k, 3), np.nan)
        pend_quat = np.full((k, 4), np.nan)
        pend_frame: int | None = None
        quiet_since = time.monotonic()
        while True:
            try:
                chunk = self.serial.read(max(1, self.serial.in_waiting))
            except Exception as exc:  # SerialException / OSError on unplug
                if lost_at is None:
                    lost_at = time.monotonic()
                yield from self._reopen(str(exc))
                buf.clear()
                last_frame = pend_frame = None
                pend_pos, pend_quat = np.full((k, 3), np.nan), np.full((k, 4), np.nan)
                quiet_since = time.monotonic()
                continue
            now = time.monotonic()
            if not chunk:
                if now - quiet_since > NO_DATA_SECONDS:
                    raise FingerfitError(
                        f"no data for {NO_DATA_SECONDS:g} s (device off, unplugged or at "
                        "another baud rate?)",
                        path=self.port,
                    )
                yield None  # nothing this poll: the loop can check its duration
                continue
            quiet_since = now
            buf += chunk
            got = parse_records(buf, self._station_list, last_frame)
            del buf[: got.consumed]
            self.stats.skipped_bytes += got.skipped
            self.stats.rejected += got.rejected
            if got.station.size == 0:
                continue
            last_frame = int(got.frame[-1])
            frames: list[tuple[int, np.ndarray, np.ndarray]] = []
            for st, fc, p, q in zip(
                got.station.tolist(), got.frame.tolist(), got.position, got.quaternion, strict=True
            ):
                if pend_frame is not None and fc != pend_frame:
                    frames.append((pend_frame, pend_pos, pend_quat))
                    pend_pos, pend_quat = np.full((k, 3), np.nan), np.full((k, 4), np.nan)
                pend_frame = fc
                c = self._col[st]
                pend_pos[c], pend_quat[c] = p, q
            if pend_frame is not None and np.isfinite(pend_pos).all():
                frames.append((pend_frame, pend_pos, pend_quat))
                pend_pos, pend_quat = np.full((k, 3), np.nan), np.full((k, 4), np.nan)
                pend_frame = None
            if not frames:
                continue
            fcs = np.array([f[0] for f in frames], dtype=np.int64)
            if lost_at is not None and emitted is not None and fcs[0] <= emitted:
                # The counter started again: the time goes on from the last frame.
                t_offset = t_last + (now - lost_at)
                first_frame, emitted = int(fcs[0]), None
            lost_at = None
            lost = 0
            if emitted is not None:
                gaps = np.diff(np.concatenate([[emitted], fcs])) - 1
                lost = int(gaps[gaps > 0].sum())
            if first_frame is None:
                first_frame = int(fcs[0])
            emitted = int(fcs[-1])
            self.stats.lost_frames += lost
            pos = np.stack([f[1] for f in frames]) * _CM_TO_MM  # (n, k, 3) mm
            quat = np.stack([f[2] for f in frames])  # (n, k, 4) w, x, y, z
            n = len(frames)
            rot = np.full((n, k, 3, 3), np.nan)
            ok = np.isfinite(quat).all(axis=2)
            rot[ok] = matrix_from_quat_wxyz(quat[ok])
            poses = {
                self.stations[s]: PoseSeries(pos[:, c], rot[:, c]) for s, c in self._col.items()
            }
            time_s = (fcs - first_frame) / self.rate_hz + t_offset
            t_last = float(time_s[-1])
            yield Block(_recording(self.name, time_s, poses), np.full(n, now), lost)

    def close(self) -> None:
        """Stop continuous output (``P``) and close the port; a dead port is ignored."""
        try:
            self.serial.write(STOP)
            self.serial.flush()
        except Exception:
            pass
        try:
            self.serial.close()
        except Exception:
            pass


# -------------------------------------------------------------------------------- LSL

_QUAT = ("qw", "qx", "qy", "qz")
_UNIT_MM = {
    "mm": 1.0,
    "millimeters": 1.0,
    "millimetres": 1.0,
    "cm": 10.0,
    "centimeters": 10.0,
    "centimetres": 10.0,
    "m": 1000.0,
    "meters": 1000.0,
    "metres": 1000.0,
    "in": UNITS_TO_MM["in"],
    "inches": UNITS_TO_MM["in"],
}


def mocap_layout(
    labels: list[str], units: list[str], sensors: list[str], name: str
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """Channel indices of each sensor's position and quaternion in an LSL MoCap stream.

    Parameters
    ----------
    labels, units : list of str
        Channel labels (``<sensor>.x|y|z``, ``<sensor>.qw|qx|qy|qz``) and units.
    sensors : list of str
        Sensors the model needs.
    name : str
        Stream name, for messages.

    Returns
    -------
    positions, quaternions : dict[str, ndarray]
        sensor -> channel indices ``(3,)`` x, y, z and ``(4,)`` w, x, y, z.
    scale : ndarray, shape (n_channels,)
        Factor to millimetres per channel (1 for quaternion channels).

    Raises
    ------
    FingerfitError
        A sensor without all seven channels, or a position unit not understood.
    """
    if not any(labels):
        raise FingerfitError(
            f"{len(labels)} channel(s) without labels: need <sensor>.x|y|z and "
            "<sensor>.qw|qx|qy|qz for each sensor",
            path=f"lsl:{name}",
        )
    where = {lab: i for i, lab in enumerate(labels)}
    scale = np.ones(len(labels))
    pos, quat = {}, {}
    for s in sensors:
        pi = [where.get(f"{s}.{c}") for c in "xyz"]
        qi = [where.get(f"{s}.{c}") for c in _QUAT]
        if None in pi or None in qi:
            raise FingerfitError(
                f"no channels {s}.x|y|z and {s}.qw|qx|qy|qz (labels: "
                f"{shown(', '.join(labels), 80)})",
                path=f"lsl:{name}",
            )
        for i in pi:
            u = units[i].strip().lower()
            if u not in _UNIT_MM:
                raise FingerfitError(
                    f"channel {labels[i]}: unit '{shown(units[i])}' is not a length unit "
                    f"({', '.join(_UNIT_MM)})",
                    path=f"lsl:{name}",
                )
            scale[i] = _UNIT_MM[u]
        pos[s], quat[s] = np.array(pi), np.array(qi)
    return pos, quat, scale


#: Seconds a reconnecting LSL source waits for a stream it found to answer.
LSL_CONNECT_S = 0.5
#: LSL channel formats a pose stream may have (positions and unit quaternions).
LSL_FORMATS = ("float32", "double64")


class LslSource:
    """An LSL stream of sensor poses (type ``MoCap``).

    The stream is checked when it is found (type ``MoCap``, channel format float32 or
    double64, the seven channels of every sensor): a stream that fails ends the stream
    before anything is written, with one line. When the stream disappears (its outlet is
    destroyed: liblsl's ``LostError``) the source warns once (:attr:`warn`) and looks for
    a stream of that name again, 0.05, 0.1, 0.2 ... s apart (at most 1 s), for up to
    ``reconnect`` s, yielding None meanwhile (the stream's watchdog marks the silence);
    the one it finds is checked as the first was.

    Parameters
    ----------
    name : str
        Stream name to resolve.
    sensors : list of str
        Sensors the model needs; each must have ``<sensor>.x|y|z`` and
        ``<sensor>.qw|qx|qy|qz`` channels.
    timeout : float
        Seconds to wait for the stream to appear.
    reconnect : float
        Seconds to keep looking for a lost stream (0: the stream ends at once).

    Attributes
    ----------
    warn : callable
        Called with the one-line warning of an outage (default: printed on stderr).
    """

    live = True

    def __init__(
        self,
        name: str,
        sensors: list[str],
        timeout: float = 5.0,
        reconnect: float = DEFAULT_RECONNECT_S,
    ) -> None:
        self._pylsl = pylsl = require("pylsl")
        self.name = f"lsl:{name}"
        self.stream = name
        self.sensors = sensors
        self.timeout = timeout
        self.reconnect = check_reconnect(reconnect)
        self.stats = SourceStats()
        self.warn: Callable[[str], None] = _stderr_warning
        found = pylsl.resolve_byprop("name", name, minimum=1, timeout=timeout)
        if not found:
            raise FingerfitError(
                f"no LSL stream named '{shown(name)}' within {timeout:g} s", path=self.name
            )
        try:
            self._connect(found[0], timeout)
        except FingerfitError:
            raise
        except Exception as exc:  # pylsl's TimeoutError, LostError
            raise FingerfitError(
                f"the stream was found but did not answer ({exc})", path=self.name
            ) from None
        self._clock = pylsl.local_clock
        self._offset = pylsl.local_clock() - time.monotonic()

    def _connect(self, info, timeout: float) -> None:
        """Open an inlet on ``info`` and check its type, format and channels.

        Parameters
        ----------
        info : pylsl.StreamInfo
            As resolved.
        timeout : float
            Seconds to wait for the stream's full description and for it to open.

        Raises
        ------
        FingerfitError
            Not ``MoCap``, a channel format other than float32 / double64, or a sensor
            without its seven channels (the inlet is closed again).
        Exception
            pylsl's ``TimeoutError`` / ``LostError``: the stream did not answer (the
            inlet is closed again).
        """
        pylsl = self._pylsl
        if info.type() != "MoCap":
            raise FingerfitError(
                f"stream type is '{shown(info.type())}', not MoCap", path=self.name
            )
        fmt = _format_name(info.channel_format())
        if fmt not in LSL_FORMATS:
            raise FingerfitError(
                f"channel format is {fmt}, not {' or '.join(LSL_FORMATS)} (positions and "
                "unit quaternions)",
                path=self.name,
            )
        # recover=False: a destroyed outlet raises LostError at once instead of liblsl
        # waiting for it silently; the source then looks for the stream itself.
        inlet = pylsl.StreamInlet(info, max_buflen=10, processing_flags=0, recover=False)
        try:
            full = inlet.info(timeout=timeout)
            ch = full.desc().child("channels").child("channel")
            labels, units = [], []
            for _ in range(full.channel_count()):
                labels.append(ch.child_value("label"))
                units.append(ch.child_value("unit"))
                ch = ch.next_sibling()
            pos, quat, scale = mocap_layout(labels, units, self.sensors, self.stream)
            inlet.open_stream(timeout=timeout)
        except BaseException:
            with contextlib.suppress(Exception):
                inlet.close_stream()
            raise
        self.inlet, self.pos, self.quat, self.scale = inlet, pos, quat, scale

    def _refind(self) -> Iterator[None]:
        """The stream was lost: warn once and find it again within ``reconnect`` s
        (yielding None while waiting).

        Raises
        ------
        FingerfitError
            Not back in time (or ``reconnect`` is 0); the stream that came back does not
            check (:meth:`_connect`).
        """
        with contextlib.suppress(Exception):
            self.inlet.close_stream()
        if self.reconnect <= 0:
            raise FingerfitError("stream lost (its outlet was closed)", path=self.name)
        self.stats.outages += 1
        self.warn(
            f"{self.name}: stream lost (its outlet was closed); looking for it again "
            f"(up to {self.reconnect:g} s)"
        )

        def attempt() -> bool:
            found = self._pylsl.resolve_byprop("name", self.stream, minimum=1, timeout=POLL_S)
            if not found:
                return False
            try:  # a stream that fails the checks ends the stream (FingerfitError)
                self._connect(found[0], LSL_CONNECT_S)
            except FingerfitError:
                raise
            except Exception:  # found, but gone again (the old outlet, closing): retry
                return False
            return True

        back = yield from _retry(attempt, time.monotonic() + self.reconnect)
        if not back:
            raise FingerfitError(
                f"stream lost (its outlet was closed); not back within {self.reconnect:g} s",
                path=self.name,
            )
        self.stats.reconnects += 1

    def blocks(self) -> Iterator[Block | None]:
        """Samples as they are pulled (None after a poll without data); time = the
        sender's LSL timestamp, arrival = the moment the pull returned.

        Raises
        ------
        FingerfitError
            No sample for :data:`NO_DATA_SECONDS` (the sender stopped sending), or the
            stream lost and not back within ``reconnect`` s.
        """
        quiet_since = time.monotonic()
        t_first = None
        lost = _lsl_lost_error(self._pylsl)
        while True:
            try:
                data, stamps = self.inlet.pull_chunk(timeout=POLL_S, max_samples=MAX_BLOCK)
            except lost:
                yield from self._refind()
                quiet_since = time.monotonic()
                continue
            now = time.monotonic()
            if not stamps:
                if now - quiet_since > NO_DATA_SECONDS:
                    raise FingerfitError(f"no samples for {NO_DATA_SECONDS:g} s", path=self.name)
                yield None  # nothing this poll: the loop can check its duration
                continue
            quiet_since = now
            x = np.asarray(data, dtype=float) * self.scale
            ts = np.asarray(stamps, dtype=float)
            if t_first is None:
                t_first = ts[0]
            n = x.shape[0]
            poses = {}
            for s, pi in self.pos.items():
                q = x[:, self.quat[s]]
                rot = np.full((n, 3, 3), np.nan)
                norm = np.linalg.norm(q, axis=1)
                ok = np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) < 1e-3)
                rot[ok] = matrix_from_quat_wxyz(q[ok])
                p = x[:, pi].copy()
                p[~ok] = np.nan
                poses[s] = PoseSeries(p, rot)
            yield Block(_recording(self.name, ts - t_first, poses), np.full(n, now))

    def close(self) -> None:
        """Close the inlet."""
        with contextlib.suppress(Exception):
            self.inlet.close_stream()


def _lsl_lost_error(pylsl) -> type[BaseException]:
    """pylsl's ``LostError`` (``pylsl.util`` in pylsl 1.16+, the top level before)."""
    found = getattr(pylsl, "LostError", None)
    if found is None:
        from pylsl.util import LostError as found
    return found


def _format_name(code: int) -> str:
    """liblsl's channel format code -> its name (``float32``, ``string``, ...)."""
    names = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8"}
    return names.get(code, "int64" if code == 7 else f"format {code}")
