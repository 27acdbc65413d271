"""A Polhemus Liberty on a serial port as a live source (``liberty:PORT[@BAUD]``)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator

import numpy as np

from ...errors import FingerfitError
from ...session import PoseSeries
from ...transforms import matrix_from_quat_wxyz
from .. import require
from ..liberty_serial import SETUP_COMMANDS, START, STOP, parse_records
from .common import (
    _CM_TO_MM,
    DEFAULT_RECONNECT_S,
    LIBERTY_RATE_HZ,
    NO_DATA_SECONDS,
    POLL_S,
    Block,
    SourceStats,
    _recording,
    _retry,
    _stderr_warning,
    check_reconnect,
)


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
