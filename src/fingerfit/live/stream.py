"""The streaming loop: source -> kinematics -> outputs, in two lanes (the per-block work in
:mod:`.streamer`).

Frames go through :func:`fingerfit.kinematics.compute_kinematics` -- the function
``fingerfit angles`` uses, so the streamed numbers are the same -- in two lanes:

* the **robot lane** (LSL, DDS: what a robot or a teleoperation consumer acts on) is
  latest-wins: of the frames that arrived together only the newest is computed and sent,
  the others are counted as skipped, and a frame older than ``max_age`` is never sent
  (counted as stale);
* the **data lane** (``--record``, ``--ros2-bag``) writes every frame, on its own thread
  and in vectorised blocks, so a recording is complete whatever the robot lane skipped.

A frame with a missing sensor is solved by the model (:mod:`fingerfit.track`: the robot
lane one frame at a time with :class:`~fingerfit.track.live.LiveTracker`, the data lane
block by block as ``fingerfit angles`` does); the ``<digit>.source`` channels say what
each digit's values come from. Per output column, a value the model cannot solve (the
hand sensor or every sensor of a digit missing) holds the column's last value; the
``valid`` channel says whether every sensor the model uses was present in the frame. The
angles CSV (``--record``) gets the frames as ``fingerfit angles`` writes them (empty fields
where nothing could be computed), not the held values.

With a :class:`fingerfit.retarget.Retargeter` (``--retarget ROBOT``), the sent frames'
kinematics then go through :meth:`~fingerfit.retarget.Retargeter.step`, which keeps the
solver's warm start from frame to frame; the ROS 2 outputs carry the robot's joints and
LSL gets a third outlet ``PREFIX-robot``. The bag's robot joints come from a second
retargeter that steps through every frame (the offline ``fingerfit retarget`` joints).

A watchdog marks a source that falls silent (``valid`` 0 on the live outputs and the
robot's ``hold`` or ``release`` policy, :meth:`.streamer.Streamer.silence`).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np

from ..errors import FingerfitError
from .datalane import DATA_PERIOD, DataLane
from .streamer import DEFAULT_MAX_AGE_MS, SILENCE_POLICIES, Streamer, check_max_age, positive_ms
from .values import (
    Channels,
    FrameValues,
    Summary,
    Values,
    block_values,
    channels_of,
    concat_blocks,
    empty_recording,
    frames_valid,
    hold,
    model_sensors,
    robot_joint_units,
    sensor_presence,
    source_codes,
)

#: Seconds between status-line updates.
STATUS_PERIOD = 0.5
#: Default ``--silence-ms`` (ms): the watchdog fires after this long without a frame.
DEFAULT_SILENCE_MS = 50.0
#: Python's thread switch interval (s) while a data lane runs beside the robot lane.
SWITCH_INTERVAL = 0.0005


class StatusLine:
    """One self-overwriting line on stderr: rate, latency, the lanes' counts."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self._t = time.monotonic()
        self._frames = 0

    def update(self, s: Summary, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._t < STATUS_PERIOD and not force:
            return
        rate = (s.received - self._frames) / max(now - self._t, 1e-9)
        lat = 1e3 * np.concatenate(s.window) if s.window else np.zeros(1)
        comp = 1e3 * np.array(s.compute_window) if s.compute_window else np.zeros(1)
        s.window.clear()
        s.compute_window.clear()
        sys.stderr.write(
            f"\r{rate:6.1f} frames/s  latency {np.median(lat):5.2f} ms (max {lat.max():5.2f})"
            f"  compute {np.median(comp):5.2f} ms/frame  lost {s.lost}"
            f"  model {s.invalid - s.held}  held {s.held}"
            f"  sent {s.sent}  skipped {s.skipped}  stale {s.stale}  recorded {s.recorded}"
            "\x1b[K"
        )
        sys.stderr.flush()
        self._t, self._frames = now, s.received

    def clear(self) -> None:
        if self.enabled:
            sys.stderr.write("\r\x1b[K")
            sys.stderr.flush()


def check_silence(ms: float) -> float:
    """``--silence-ms`` in ms -> s; a clear error unless a positive number."""
    return positive_ms(ms, "--silence-ms")


@contextlib.contextmanager
def _ctrl_c_sets(flag: threading.Event) -> Iterator[None]:
    """Ctrl-C (SIGINT) sets ``flag`` instead of raising KeyboardInterrupt anywhere: the
    loop stops between blocks, so both lanes have handled every frame received (only in
    the main thread; elsewhere Python delivers no signal)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.SIG_IGN:  # Ctrl-C ignored by whoever started us: keep it so
        yield
        return
    signal.signal(signal.SIGINT, lambda *_: flag.set())
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def run(
    source,
    streamer: Streamer,
    *,
    wait: float | None = None,
    status: bool = True,
    duration: float | None = None,
    silence: float | None = DEFAULT_SILENCE_MS / 1e3,
    warn: Callable[[str], None] | None = None,
    realtime: bool = False,
    note: Callable[[str], None] | None = None,
    threads_before: set[int] | None = None,
) -> Summary:
    """Stream until the source ends, ``duration`` passes, or Ctrl-C.

    Parameters
    ----------
    source
        A :mod:`.sources` source (``blocks()`` yielding blocks, or None after a poll
        without data; ``close()``; ``live``).
    streamer : Streamer
    wait : float, optional
        Replay only: seconds to wait for a consumer on every network output before
        the first frame (error when none comes).
    status : bool
        Show the status line (only on a terminal).
    duration : float, optional
        Seconds to stream, from the first frame's arrival.
    silence : float, optional
        The watchdog: seconds without a frame (after the first) before
        :meth:`.streamer.Streamer.silence` and one ``warn`` line; again after frames come back
        and stop again. None: no watchdog.
    warn : callable, optional
        Called with the watchdog's one-line warning, and with a live source's outage
        warning (``source.warn`` is set to it; default: printed on stderr).
    realtime : bool
        Ask for a real-time class for the loop's thread (the robot lane) once streaming
        starts (after ``wait``): SCHED_FIFO, memory locked, CPU affinity
        (:class:`~fingerfit.live.realtime.Realtime`; restored at the end). What was
        granted goes to ``note`` in one line; nothing refused stops the stream.
    note : callable, optional
        Called with the ``--realtime`` line (default: ``realtime: ...`` on stderr).
    threads_before : set of int, optional
        With ``realtime``: the process's thread ids before the live outputs were made
        (:func:`~fingerfit.live.realtime.task_ids`); the native threads started since
        (liblsl's, Cyclone DDS's: they send the robot lane's frames) get the real-time
        class too.

    Returns
    -------
    Summary
        ``interrupted`` when Ctrl-C ended it. Outputs are closed (files kept, the data
        lane's backlog written first) in every case; an error from the source (a device
        unplugged) is raised after that.
    """
    line = StatusLine(status)
    stop = threading.Event()
    say = warn or (lambda text: print(f"warning: {text}", file=sys.stderr, flush=True))
    if hasattr(source, "warn"):  # a live source's outage warning, past the status line

        def source_warns(text: str) -> None:
            line.clear()
            say(text)

        source.warn = source_warns
    # Installed until the outputs are closed: a Ctrl-C while the data lane writes its
    # backlog lets it finish (the files complete).
    tell = note or (lambda text: print(f"realtime: {text}", file=sys.stderr, flush=True))
    with _ctrl_c_sets(stop):
        _run(
            source,
            streamer,
            line,
            stop,
            wait,
            duration,
            silence,
            say,
            tell if realtime else None,
            threads_before,
        )
    return streamer.summary


def _run(
    source,
    streamer: Streamer,
    line: StatusLine,
    stop: threading.Event,
    wait: float | None,
    duration: float | None,
    silence: float | None,
    say: Callable[[str], None],
    realtime: Callable[[str], None] | None = None,
    threads_before: set[int] | None = None,
) -> None:
    """:func:`run`'s loop, with Ctrl-C setting ``stop``; ``realtime``: ask for a real-time
    class (for the outputs' threads started since ``threads_before`` too) and tell it
    what was granted."""
    s = streamer.summary
    ok = True
    t0 = last = None
    silent = False
    rt = contextlib.ExitStack()  # the real-time class, until the outputs are closed
    # The data lane's thread gives the GIL back every SWITCH_INTERVAL (Python's default
    # is 5 ms, which the robot lane would wait on).
    interval = sys.getswitchinterval()
    if streamer.data is not None:
        sys.setswitchinterval(min(interval, SWITCH_INTERVAL))
    try:
        if wait is not None:
            t_end = time.monotonic() + wait
            while not streamer.has_consumers():
                if stop.is_set():
                    raise KeyboardInterrupt
                if time.monotonic() > t_end:
                    raise FingerfitError(
                        f"no consumer within {wait:g} s for every output", field="--wait"
                    )
                time.sleep(0.01)
        if realtime is not None:
            from .realtime import Realtime, threads_started

            others = [streamer.data.thread] if streamer.data is not None else []
            lane = "robot lane" if streamer.live else "stream loop"
            # the outputs' own threads, started by now (liblsl starts some when a
            # consumer connects)
            native = threads_started(threads_before) if threads_before is not None else []
            realtime(rt.enter_context(Realtime(others=others, lane=lane, threads=native)).line())
        for block in source.blocks():
            if block is not None and block.recording.n_frames:
                if t0 is None:
                    t0 = float(block.arrival[0])
                streamer.process(block)
                last, silent = float(block.arrival[-1]), False
            elif silence is not None and last is not None and not silent:
                now = time.monotonic()
                if now - last > silence:
                    silent = True
                    streamer.silence(now)
                    line.clear()
                    say(
                        f"no frame for {1e3 * silence:g} ms: valid = 0 on the live outputs, "
                        f"robot: {streamer.on_silence}"
                    )
            line.update(s)
            if stop.is_set():
                s.interrupted = True
                break
            if duration is not None and t0 is not None and time.monotonic() - t0 >= duration:
                break
        if t0 is not None:
            s.seconds = time.monotonic() - t0
    except KeyboardInterrupt:
        s.interrupted = True
    except FingerfitError:
        ok = s.received > 0  # a device lost mid-stream: keep what was streamed
        if ok and not silent:  # the robot's last command: valid 0, its policy
            with contextlib.suppress(Exception):
                streamer.invalidate(time.monotonic())
        raise
    except BaseException:
        ok = False
        raise
    finally:
        stats = getattr(source, "stats", None)
        s.outages = getattr(stats, "outages", 0)
        s.reconnects = getattr(stats, "reconnects", 0)
        line.update(s, force=True)  # the final figures, at least once
        line.clear()
        source.close()
        try:
            streamer.close(ok)
        finally:
            sys.setswitchinterval(interval)
            rt.close()


#: Names of this module and those it gathers from :mod:`.streamer`, :mod:`.values` and
#: :mod:`.datalane`
#: (importable from here as before they moved).
__all__ = [
    "DATA_PERIOD",
    "DEFAULT_MAX_AGE_MS",
    "DEFAULT_SILENCE_MS",
    "SILENCE_POLICIES",
    "STATUS_PERIOD",
    "SWITCH_INTERVAL",
    "Channels",
    "DataLane",
    "FrameValues",
    "StatusLine",
    "Streamer",
    "Summary",
    "Values",
    "block_values",
    "channels_of",
    "check_max_age",
    "check_silence",
    "concat_blocks",
    "empty_recording",
    "frames_valid",
    "hold",
    "model_sensors",
    "robot_joint_units",
    "run",
    "sensor_presence",
    "source_codes",
]
