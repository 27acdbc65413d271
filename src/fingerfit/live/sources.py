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
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
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
    frames lost (frame-count gaps)."""

    skipped_bytes: int = 0
    rejected: int = 0
    lost_frames: int = 0
    notes: list[str] = field(default_factory=list)


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

    Parameters
    ----------
    port : str
        Serial device (``/dev/ttyUSB0``, ``COM3``).
    baud : int
    stations : dict[int, str]
        Station number -> sensor name (every sensor the model uses).
    rate_hz : float
        Device frame rate, for the frame time ``frame count / rate``.
    """

    live = True

    def __init__(
        self, port: str, baud: int, stations: dict[int, str], rate_hz: float = LIBERTY_RATE_HZ
    ) -> None:
        serial = require("serial")
        self.name = f"liberty:{port}"
        self.port = port
        self.stations = stations
        self.rate_hz = rate_hz
        self.stats = SourceStats()
        self._station_list = np.array(sorted(stations), dtype=np.int64)
        self._col = {s: k for k, s in enumerate(sorted(stations))}
        try:
            self.serial = serial.Serial(port, baud, timeout=POLL_S)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise FingerfitError(f"cannot open the serial port: {exc}", path=port) from None
        try:
            self._write(STOP)
            time.sleep(0.1)
            self.serial.reset_input_buffer()
            for command in SETUP_COMMANDS:
                self._write(command)
            self._write(START)
        except FingerfitError:
            self.serial.close()
            raise

    def _write(self, data: bytes) -> None:
        try:
            self.serial.write(data)
            self.serial.flush()
        except Exception as exc:  # pyserial raises SerialException / OSError
            raise FingerfitError(
                f"device disconnected (write failed: {exc})", path=self.port
            ) from None

    def blocks(self) -> Iterator[Block | None]:
        """Frames as their last station record arrives (None after a poll without data).

        A frame is complete when every mapped station has reported; a frame whose
        records are not all there is handed over (with NaN for the missing sensors)
        when the next frame starts. Frame-count gaps are counted as lost frames.

        Raises
        ------
        FingerfitError
            The port fails (unplugged) or no byte arrives for :data:`NO_DATA_SECONDS`.
        """
        buf = bytearray()
        k = len(self.stations)
        last_frame: int | None = None
        emitted: int | None = None
        first_frame: int | None = None
        # Pending records of the newest frame: columns = sorted stations.
        pend_pos = np.full((k, 3), np.nan)
        pend_quat = np.full((k, 4), np.nan)
        pend_frame: int | None = None
        quiet_since = time.monotonic()
        while True:
            try:
                chunk = self.serial.read(max(1, self.serial.in_waiting))
            except Exception as exc:  # SerialException / OSError on unplug
                raise FingerfitError(
                    f"device disconnected ({exc})" if str(exc) else "device disconnected",
                    path=self.port,
                ) from None
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
            time_s = (fcs - first_frame) / self.rate_hz
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


class LslSource:
    """An LSL stream of sensor poses (type ``MoCap``).

    Parameters
    ----------
    name : str
        Stream name to resolve.
    sensors : list of str
        Sensors the model needs; each must have ``<sensor>.x|y|z`` and
        ``<sensor>.qw|qx|qy|qz`` channels.
    timeout : float
        Seconds to wait for the stream to appear.
    """

    live = True

    def __init__(self, name: str, sensors: list[str], timeout: float = 5.0) -> None:
        pylsl = require("pylsl")
        self.name = f"lsl:{name}"
        self.stats = SourceStats()
        found = pylsl.resolve_byprop("name", name, minimum=1, timeout=timeout)
        if not found:
            raise FingerfitError(
                f"no LSL stream named '{shown(name)}' within {timeout:g} s", path=self.name
            )
        info = found[0]
        if info.type() != "MoCap":
            raise FingerfitError(
                f"stream type is '{shown(info.type())}', not MoCap", path=self.name
            )
        self.inlet = pylsl.StreamInlet(info, max_buflen=10, processing_flags=0)
        full = self.inlet.info(timeout=timeout)
        ch = full.desc().child("channels").child("channel")
        labels, units = [], []
        for _ in range(full.channel_count()):
            labels.append(ch.child_value("label"))
            units.append(ch.child_value("unit"))
            ch = ch.next_sibling()
        self.pos, self.quat, self.scale = mocap_layout(labels, units, sensors, name)
        self.inlet.open_stream(timeout=timeout)
        self._clock = pylsl.local_clock
        self._offset = pylsl.local_clock() - time.monotonic()

    def blocks(self) -> Iterator[Block | None]:
        """Samples as they are pulled (None after a poll without data); time = the sender's LSL timestamp, arrival =
        the moment the pull returned.

        Raises
        ------
        FingerfitError
            No sample for :data:`NO_DATA_SECONDS` (the sender stopped).
        """
        quiet_since = time.monotonic()
        t_first = None
        while True:
            data, stamps = self.inlet.pull_chunk(timeout=POLL_S, max_samples=MAX_BLOCK)
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
        try:
            self.inlet.close_stream()
        except Exception:
            pass
