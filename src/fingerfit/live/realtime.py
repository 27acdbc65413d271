"""``--realtime``: ask the OS for a real-time class for the robot lane, where permitted.

Three requests, each independent and none fatal:

* **SCHED_FIFO** at :data:`REALTIME_PRIORITY` for the thread that runs the robot lane
  (:func:`os.sched_setscheduler` on the calling thread; Linux applies it per thread, so
  the data lane's thread, started before, keeps the normal class; threads started later
  by the robot lane's thread inherit it), and for the native threads the live outputs
  started (``threads``: liblsl's and Cyclone DDS's own threads, which send what the
  robot lane hands them; :func:`threads_started` finds them), so that a frame does not
  wait behind other processes between the robot lane and the network either;
* **memory locked** (``mlockall(MCL_CURRENT | MCL_FUTURE)`` through ctypes): no page of
  the process is swapped out or faulted in from disk mid-frame;
* **CPU affinity** (:func:`os.sched_setaffinity`): the robot lane's thread on the last
  CPU the process may use, the data lane's thread on the others (when there are
  others).

What was granted is summed up in one line (:meth:`Realtime.line`); what was not is named
with its reason (``EPERM``: the user may not; ``ENOMEM``: ``RLIMIT_MEMLOCK`` too small)
and the stream runs on as it would without ``--realtime``. Leaving the context restores
the thread's class, the affinities and unlocks the memory (an in-process caller, such as a
test, gets its process back as it was).
"""

from __future__ import annotations

import ctypes
import errno
import os
import threading
from types import TracebackType

#: SCHED_FIFO priority asked for (1-99; ros2_control's real-time threads use 50 too).
REALTIME_PRIORITY = 50
#: ``mlockall`` flags (Linux ``<sys/mman.h>``): pages mapped now, and pages mapped later.
MCL_CURRENT, MCL_FUTURE = 1, 2


def _reason(exc: OSError) -> str:
    """``EPERM``, ``ENOMEM`` ... (or the message when there is no errno)."""
    return errno.errorcode.get(exc.errno or 0, str(exc) or type(exc).__name__)


def task_ids() -> set[int]:
    """The kernel ids of this process's threads (Linux ``/proc/self/task``; empty where
    there is no such list)."""
    try:
        return {int(t) for t in os.listdir("/proc/self/task")}
    except (OSError, ValueError):
        return set()


def threads_started(before: set[int]) -> list[int]:
    """The native threads started since ``before`` (:func:`task_ids`) that are not Python
    threads (``threading``): those a library started, e.g. liblsl's and Cyclone DDS's
    for the live outputs. Sorted kernel thread ids."""
    python = {t.native_id for t in threading.enumerate()}
    return sorted(task_ids() - before - python)


def _libc():
    """The C library through ctypes, or None (no ``mlockall`` on this system)."""
    try:
        lib = ctypes.CDLL(None, use_errno=True)
        lib.mlockall  # noqa: B018 (raises AttributeError when absent)
        lib.munlockall  # noqa: B018
    except (OSError, AttributeError, TypeError):
        return None
    return lib


def mlockall() -> str | None:
    """Lock the process's memory (current and future pages).

    Returns
    -------
    str or None
        None when locked, else why not (``EPERM``, ``ENOMEM``, ``not available``).
    """
    lib = _libc()
    if lib is None:
        return "not available"
    if lib.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        code = ctypes.get_errno()
        return errno.errorcode.get(code, f"errno {code}")
    return None


def munlockall() -> None:
    """Unlock the process's memory (after :func:`mlockall`)."""
    lib = _libc()
    if lib is not None:
        lib.munlockall()


class Realtime:
    """Context manager: the real-time requests on entry, everything restored on exit.

    Parameters
    ----------
    priority : int
        SCHED_FIFO priority (1-99).
    others : list of threading.Thread
        Threads of the stream to keep off the robot lane's CPU (the data lane's), already
        started.
    lane : str
        What the calling thread runs, for the line (``robot lane``).
    threads : sequence of int
        Kernel ids of native threads to raise to the same class (the live outputs'
        threads, :func:`threads_started`); their affinity is left as it is. One that
        ended meanwhile is skipped.

    Attributes
    ----------
    fifo : str or None
        None when SCHED_FIFO was granted, else why not.
    locked : str or None
        None when the memory is locked, else why not.
    cpu : int or None
        The robot lane's CPU, None when its affinity was not set.
    other_cpus : list of int
        The CPUs of ``others`` (empty when they were left alone).
    raised : list of int
        The ``threads`` given SCHED_FIFO.
    """

    def __init__(
        self,
        priority: int = REALTIME_PRIORITY,
        others: list[threading.Thread] | None = None,
        lane: str = "robot lane",
        threads: list[int] | tuple[int, ...] = (),
    ) -> None:
        self.priority = priority
        self.others = [t for t in (others or []) if t.native_id is not None]
        self.lane = lane
        self.threads = list(threads)
        self.raised: list[int] = []
        self._thread_sched: dict[int, tuple[int, int]] = {}
        self.fifo: str | None = "not requested"
        self.locked: str | None = "not requested"
        self.cpu: int | None = None
        self.cpu_note = ""
        self.other_cpus: list[int] = []
        self._sched: tuple[int, int] | None = None
        self._affinity: dict[int, set[int]] = {}

    def __enter__(self) -> Realtime:
        # The lock first: it faults every page in, which is no work for a FIFO thread.
        self.locked = mlockall()
        self._pin()
        self._fifo()
        return self

    def _fifo(self) -> None:
        if not hasattr(os, "sched_setscheduler"):
            self.fifo = "not available on this system"
            return
        try:
            before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        except OSError as exc:
            self.fifo = _reason(exc)
            return
        self._sched, self.fifo = before, None
        for tid in self.threads:
            try:
                was = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(self.priority))
            except OSError:  # the thread ended meanwhile: nothing to raise
                continue
            self._thread_sched[tid] = was
            self.raised.append(tid)

    def _pin(self) -> None:
        if not hasattr(os, "sched_setaffinity"):
            self.cpu_note = "CPU affinity not available on this system"
            return
        try:
            allowed = sorted(os.sched_getaffinity(0))
            self._affinity[0] = set(allowed)
            os.sched_setaffinity(0, {allowed[-1]})
        except OSError as exc:
            self._affinity.pop(0, None)
            self.cpu_note = f"CPU affinity not permitted ({_reason(exc)})"
            return
        self.cpu = allowed[-1]
        if len(allowed) < 2:
            self.cpu_note = "the only CPU allowed"
            return
        rest = set(allowed[:-1])
        for t in self.others:
            try:
                self._affinity[t.native_id] = os.sched_getaffinity(t.native_id)
                os.sched_setaffinity(t.native_id, rest)
            except OSError:  # the thread ended, or not permitted: left alone
                self._affinity.pop(t.native_id, None)
            else:
                self.other_cpus = sorted(rest)

    def line(self) -> str:
        """What was granted, in one line (without the ``realtime:`` prefix), e.g.
        ``SCHED_FIFO 50 granted, memory locked, robot lane on CPU 1 (data lane on CPU
        0)`` or ``SCHED_FIFO not permitted (EPERM), memory lock not permitted (EPERM),
        robot lane on CPU 1; running at normal priority``."""
        parts = []
        if self.fifo is None:
            n = len(self.raised)
            also = f" (and to the outputs' {n} thread{'s' * (n != 1)})" if n else ""
            parts.append(f"SCHED_FIFO {self.priority} granted{also}")
        elif self.fifo.startswith("not "):
            parts.append(f"SCHED_FIFO {self.fifo}")
        else:
            parts.append(f"SCHED_FIFO not permitted ({self.fifo})")
        if self.locked is None:
            parts.append("memory locked")
        elif self.locked.startswith("not "):
            parts.append(f"memory lock {self.locked}")
        else:
            parts.append(f"memory lock not permitted ({self.locked})")
        if self.cpu is not None:
            where = f"{self.lane} on CPU {self.cpu}"
            if self.other_cpus:
                cpus = ",".join(str(c) for c in self.other_cpus)
                where += f" (data lane on CPU {cpus})"
            elif self.cpu_note:
                where += f" ({self.cpu_note})"
            parts.append(where)
        elif self.cpu_note:
            parts.append(self.cpu_note)
        text = ", ".join(parts)
        if self.fifo is not None:
            text += "; running at normal priority"
        return text

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Restore the thread's scheduling class, the affinities; unlock the memory."""
        if self._sched is not None:
            policy, prio = self._sched
            try:
                os.sched_setscheduler(0, policy, os.sched_param(prio))
            except OSError:
                pass
        for tid, (policy, prio) in self._thread_sched.items():
            try:
                os.sched_setscheduler(tid, policy, os.sched_param(prio))
            except OSError:  # ended since
                pass
        for tid, cpus in self._affinity.items():
            try:
                os.sched_setaffinity(tid, cpus)
            except OSError:
                pass
        if self.locked is None:
            munlockall()
