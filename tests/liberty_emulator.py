"""A Polhemus Liberty on a pseudo-terminal, for the streaming tests.

It answers the commands fingerfit sends the way the device does -- ``O`` sets the output
list, ``U0``/``U1`` inches/centimetres, ``F0``/``F1`` ASCII/binary, ``C`` starts
continuous output, ``P`` stops it (or sends one frame when stopped) -- and, in continuous
mode, writes one frame of station records every 1/240 s taken from a recording. Faults
on request: garbage bytes before a frame, a byte dropped from one record, and an unplug
(the master side closes, so the port's next read fails).

Records are encoded by :func:`fingerfit.io.liberty.liberty_binary_bytes` (ASCII by
:func:`~fingerfit.io.liberty.format_liberty_ascii`), the writers the file readers are
tested against.
"""

from __future__ import annotations

import fcntl
import os
import pty
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from fingerfit.io.liberty import (
    LibertyRecords,
    format_liberty_ascii,
    liberty_binary_bytes,
    parse_items,
)
from fingerfit.session import UNITS_TO_MM, Recording


@dataclass
class Faults:
    """Faults to inject, by frame index (0-based, in the order frames are sent).

    Attributes
    ----------
    garbage : dict[int, bytes]
        Bytes written just before the frame.
    drop : dict[int, tuple[int, int]]
        Frame -> (station index within the frame, byte offset in its record) to drop.
    pause : dict[int, float]
        Frame -> seconds without a byte just before it (the port stays open).
    unplug_after : int, optional
        Close the port after sending this many frames (once every byte was read).
    replug_after : float, optional
        With ``unplug_after``: seconds later, a new port at the same path, the device
        reset (it must be set up again), streaming on from the next frame; the end of
        the recording then unplugs it for good.
    restart_count : bool
        After the replug, frame counts start again at ``first_frame`` (a power cycle)
        instead of going on.
    """

    garbage: dict[int, bytes] = field(default_factory=dict)
    drop: dict[int, tuple[int, int]] = field(default_factory=dict)
    pause: dict[int, float] = field(default_factory=dict)
    unplug_after: int | None = None
    replug_after: float | None = None
    restart_count: bool = False


class LibertyEmulator:
    """A Liberty on a pty streaming ``recording`` (mm, tracker frame) at ``rate_hz``.

    Parameters
    ----------
    recording : Recording
    stations : dict[int, str]
        Station number -> sensor of the recording.
    faults : Faults
    rate_hz : float
    first_frame : int
        Frame count of the first frame sent.
    """

    def __init__(
        self,
        recording: Recording,
        stations: dict[int, str],
        faults: Faults | None = None,
        rate_hz: float = 240.0,
        first_frame: int = 5000,
    ) -> None:
        self.recording = recording
        self.stations = stations
        self.faults = faults or Faults()
        self.rate_hz = rate_hz
        self.first_frame = first_frame
        self.commands: list[bytes] = []
        self.sent_frames = 0
        self.plugs = 0  # ports plugged in so far
        self._count_base = 0  # frame index whose count is first_frame
        self._dir = tempfile.mkdtemp(prefix="liberty-")
        self.port = os.path.join(self._dir, "ttyLiberty")
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._gone = threading.Event()  # the current port is unplugged
        self._threads: list[threading.Thread] = []
        self._plug()
        t = threading.Thread(target=self._stream, daemon=True)
        self._threads.append(t)
        t.start()

    def _plug(self) -> None:
        """A new pseudo-terminal at :attr:`port`, a device in its power-on state."""
        self.items = parse_items("2,4,1")  # device default list
        self.units = "in"
        self.binary = False
        self.continuous = False
        self.master, slave = pty.openpty()
        tty.setraw(slave)
        self._slave = slave  # kept open so the pty exists until the port is opened
        os.symlink(os.ttyname(slave), self.port + ".new")
        os.replace(self.port + ".new", self.port)
        self._gone.clear()
        self.plugs += 1
        t = threading.Thread(target=self._read_commands, args=(self.master,), daemon=True)
        self._threads.append(t)
        t.start()

    # -- records --------------------------------------------------------------------

    def records(self, i: int, items: tuple[str, ...] | None = None, units: str | None = None):
        """The frame ``i``'s station records as :class:`LibertyRecords` (device units)."""
        items = items or self.items
        scale = UNITS_TO_MM[units or self.units]
        st = sorted(self.stations)
        values: dict[str, np.ndarray] = {}
        poses = [self.recording.poses[self.stations[s]] for s in st]
        pos = np.stack([p.position[i] for p in poses]) / scale
        rot = Rotation.from_matrix(np.stack([p.rotation[i] for p in poses]))
        for item in items:
            if item == "position":
                values[item] = pos
            elif item == "quaternion":
                values[item] = rot.as_quat(scalar_first=True)  # w, x, y, z
            elif item == "euler":
                values[item] = rot.as_euler("ZYX", degrees=True)
            elif item == "timestamp":
                values[item] = np.full(len(st), round(1000 * i / self.rate_hz), float)
            elif item == "frame":
                count = self.first_frame + i - self._count_base
                values[item] = np.full(len(st), count, float)
        k = len(st)
        return LibertyRecords(
            tuple(items),
            np.array(st),
            values,
            np.array([""] * k),
            np.arange(1, k + 1),
            binary=self.binary,
        )

    def frame_bytes(self, i: int) -> list[bytes]:
        """Frame ``i`` as it goes on the wire, one bytes object per station record."""
        recs = self.records(i)
        if not self.binary:
            return [ln.encode() + b"\r\n" for ln in format_liberty_ascii(recs).split("\r\n")[:-1]]
        raw = bytearray(liberty_binary_bytes(recs))
        size = len(raw) // recs.n_records
        for k in range(recs.n_records):
            raw[k * size + 3] = ord("C")  # command byte of continuous output
        return [bytes(raw[k * size : (k + 1) * size]) for k in range(recs.n_records)]

    # -- threads --------------------------------------------------------------------

    def _write(self, data: bytes) -> bool:
        try:
            os.write(self.master, data)
            return True
        except OSError:
            return False

    def _read_commands(self, master: int) -> None:
        buf = b""
        while not self._stop.is_set() and not self._gone.is_set():
            try:
                ready, _, _ = select.select([master], [], [], 0.05)
                if not ready:
                    continue
                chunk = os.read(master, 256)
            except (OSError, ValueError):
                return
            if not chunk:
                return
            buf += chunk
            while buf:
                if buf[:1] in (b"P", b"C"):  # single-character commands
                    cmd, buf = buf[:1], buf[1:]
                    if buf[:1] == b"\r":
                        buf = buf[1:]
                elif b"\r" in buf:
                    cmd, _, buf = buf.partition(b"\r")
                else:
                    break
                self._command(cmd)

    def _command(self, cmd: bytes) -> None:
        with self._lock:
            self.commands.append(cmd)
            text = cmd.decode("ascii", "replace")
            if text == "C":
                self.continuous = True
            elif text == "P":
                if self.continuous:
                    self.continuous = False
                elif self.sent_frames < self.recording.n_frames:
                    self._write(b"".join(self.frame_bytes(self.sent_frames)))
            elif text.startswith("O"):
                station, _, items = text[1:].partition(",")
                if station == "*":
                    self.items = parse_items(items)
            elif text in ("U0", "U1"):
                self.units = "in" if text == "U0" else "cm"
            elif text in ("F0", "F1"):
                self.binary = text == "F1"

    def _stream(self) -> None:
        period = 1.0 / self.rate_hz
        due = None
        while not self._stop.is_set():
            with self._lock:
                running = self.continuous
            if not running:
                due = None
                time.sleep(0.002)
                continue
            due = time.monotonic() if due is None else due + period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            i = self.sent_frames
            f = self.faults
            replug = f.replug_after is not None and self.plugs == 1
            end = self.recording.n_frames
            if f.unplug_after is not None and (replug or f.replug_after is None):
                end = f.unplug_after
            if i >= end:  # the recording is over: the cable is pulled once all is read
                self._wait_drained()
                if not replug:
                    self.unplug()
                    return
                self._pull()
                if self._stop.wait(f.replug_after):
                    return
                with self._lock:
                    if f.restart_count:
                        self._count_base = i
                    self._plug()
                continue
            if i in f.pause:  # silent for a while, then frame i and on at the rate
                if self._stop.wait(f.pause[i]):
                    return
                due = time.monotonic()
            with self._lock:
                parts = self.frame_bytes(i)
            if i in f.drop:
                k, off = f.drop[i]
                parts[k] = parts[k][:off] + parts[k][off + 1 :]
            data = f.garbage.get(i, b"") + b"".join(parts)
            if not self._write(data):
                return
            self.sent_frames = i + 1

    def _wait_drained(self, timeout: float = 60.0) -> None:
        """Wait until the port has read every byte sent (closing the master would drop
        them, which makes the number of frames delivered depend on timing).

        Bytes written to the master reach the port's input queue through the kernel's
        flip buffer, moved by a worker thread later: right after a write ``FIONREAD`` may
        be 0 with the bytes still on their way (two thirds of the trials with two busy
        processes running). A zero-timeout poll of the port first moves them (the line
        discipline's poll flushes the pending buffer) without reading any. ``timeout``
        only guards against a hang.
        """
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end and not self._stop.is_set():
            select.select([self._slave], [], [], 0)  # the flip buffer into the queue
            waiting = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
            if struct.unpack("i", waiting)[0] == 0:
                return
            time.sleep(0.005)

    def _pull(self) -> None:
        """The cable pulled: the port's path disappears, the master side closes (the
        port's next read fails)."""
        self._gone.set()
        try:
            os.unlink(self.port)
        except OSError:
            pass
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def unplug(self) -> None:
        """Pull the cable for good: the port's next read fails, and no replug."""
        self._stop.set()
        self._pull()

    def close(self) -> None:
        """Stop the threads and release the pty."""
        if not self._stop.is_set():
            self.unplug()
        for t in self._threads:
            t.join(timeout=2)
        shutil.rmtree(self._dir, ignore_errors=True)
