"""Child processes that fingerfit starts beside a command's own loop (the live view, the
capture's evidence): started with ``multiprocessing``'s ``spawn``, clean of the caller's
script and of Ctrl-C; and :class:`Interrupts`, Ctrl-C held while a command's files are
written.

* **No ``if __name__ == "__main__":`` needed.** ``spawn`` runs the caller's main script
  again in the child, so that objects defined there can be unpickled; a script that
  makes a :class:`fingerfit.view.LiveView` at its top level would start its whole work
  again in the child (and fail there). fingerfit's children need nothing of the caller's
  script (their work and arguments are fingerfit's), so :func:`start_child` starts them
  while ``__main__`` is a module without a file: the child imports no script.
* **Ctrl-C is the parent's.** A terminal's Ctrl-C reaches every process of its group; a
  child still importing its modules would print a ``KeyboardInterrupt`` traceback. The
  child is started with SIGINT blocked (a signal mask survives ``fork`` and ``exec``),
  and :func:`child_ignores_interrupt`, its first call, ignores SIGINT and unblocks it:
  a Ctrl-C at any moment of its start is dropped, and the parent, which handles it,
  ends the child. In the parent a Ctrl-C while the child starts is raised once it has
  started, and the child is ended (:func:`end_child`): never left to start alone. The
  workers of :func:`worker_pool` (``--jobs``) start the same way.

It imports nothing else of the package.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
import sys
import threading
import types
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any

#: Serialises the moment ``__main__`` is swapped while a child starts.
_STARTING = threading.Lock()


def context() -> Any:
    """The ``spawn`` context of every child (its queues and pipes are made from it)."""
    return multiprocessing.get_context("spawn")


@contextlib.contextmanager
def _no_main_script() -> Iterator[None]:
    """``__main__`` without a file for the duration: ``spawn`` then runs no script in the
    child (``multiprocessing.spawn.get_preparation_data``)."""
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


@contextlib.contextmanager
def _interrupt_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread for the duration (and so in a child started in it:
    a signal mask survives ``fork`` and ``exec``)."""
    if not hasattr(signal, "pthread_sigmask"):  # not POSIX: nothing to block
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """A Ctrl-C during the block (which another thread may receive, and Python then
    handles in this one) is only noted; after the block it is raised again, to the
    handler that was there (``KeyboardInterrupt`` by default). Python handles signals in
    the main thread only: elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
    if noted:
        signal.raise_signal(signal.SIGINT)


def start_child(target: Callable[..., Any], args: tuple, name: str) -> Any:
    """Start ``target(*args)`` in a ``spawn`` child (a daemon) that runs no script of the
    caller's and is started with SIGINT blocked (module docstring).

    Parameters
    ----------
    target : callable
        A module-level function of fingerfit; its first call should be
        :func:`child_ignores_interrupt`.
    args : tuple
        Its arguments (pickled: fingerfit's types, queues and pipes of :func:`context`).
    name : str
        The process's name.

    Returns
    -------
    multiprocessing.Process
        Started.
    """
    proc = context().Process(target=target, args=args, name=name, daemon=True)
    with _STARTING, _no_main_script():
        try:
            with _interrupt_deferred(), _interrupt_blocked():
                proc.start()
        except BaseException:  # a Ctrl-C deferred during the start, raised as it ends
            end_child(proc)
            raise
    return proc


class _QuietPool(ProcessPoolExecutor):
    """A process pool whose workers start as :func:`start_child`'s children do: a
    submit, which may start a worker, runs with SIGINT blocked (a Ctrl-C meanwhile is
    raised after it), and each worker's initializer is :func:`child_ignores_interrupt`."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        with _interrupt_deferred(), _interrupt_blocked():
            return super().submit(fn, *args, **kwargs)


@contextlib.contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers`` whose workers leave Ctrl-C to this
    process (module docstring): none prints a traceback, and when the block ends by an
    exception (Ctrl-C's ``KeyboardInterrupt`` included) they are ended at once (SIGTERM)
    instead of finishing their tasks; else the pool is shut down, its tasks done."""
    pool = _QuietPool(workers, mp_context=context(), initializer=child_ignores_interrupt)
    try:
        yield pool
    except BaseException:
        # No public way to end a pool's workers before Python 3.14.
        for proc in list(pool._processes.values()):
            proc.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def end_child(proc: Any, timeout_s: float | None = 0.0) -> None:
    """Wait up to ``timeout_s`` (None: as long as it takes) for a child to end, then
    terminate it (SIGTERM: it ends without a word, also while still starting) and wait
    for it."""
    if proc.pid is None:  # never started
        return
    proc.join(timeout_s)
    if proc.exitcode is None:
        proc.terminate()
        proc.join()


def child_ignores_interrupt() -> None:
    """In a child of :func:`start_child`: ignore SIGINT (the parent handles Ctrl-C and
    ends the child), then unblock it (a Ctrl-C pending since the start is dropped)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


class Interrupts:
    """What Ctrl-C does during a command that must not leave half a result (``fingerfit
    capture``): a context, SIGINT's handler while it lasts.

    The first Ctrl-C raises ``KeyboardInterrupt`` (it stops the recording, or before it
    the start); from then on, and while :meth:`hold` holds them (the files being
    written), Ctrl-C is only noted, so nothing half-done is left by a second press.
    :meth:`release` lets the next Ctrl-C raise again (the final evidence may be cut
    short) and raises at once for one noted meanwhile. Outside the main thread (where
    Python runs signal handlers) it does nothing.
    """

    def __init__(self) -> None:
        self.held = False
        self.noted = False
        self._old: Any = None

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)

    def _handle(self, signum: int, frame: object) -> None:
        if self.held:
            self.noted = True
            return
        self.held = True  # a second Ctrl-C while the first is handled is only noted
        raise KeyboardInterrupt

    def hold(self) -> None:
        """Note Ctrl-C from now on instead of raising."""
        self.held = True

    def release(self) -> None:
        """Let Ctrl-C raise again; raise ``KeyboardInterrupt`` now for one noted."""
        self.held = False
        if self.noted:
            self.noted = False
            self.held = True
            raise KeyboardInterrupt
