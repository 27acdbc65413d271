"""Child processes that fingerfit starts beside a command's own loop (the live view, the
capture's evidence): started with ``multiprocessing``'s ``spawn``, clean of the caller's
script and of Ctrl-C.

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
  ends the child.

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
    """SIGINT blocked in this thread for the duration (and so in a child started in it);
    a Ctrl-C meanwhile is delivered to this process when the block ends."""
    if not hasattr(signal, "pthread_sigmask"):  # not POSIX: nothing to block
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


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
    with _STARTING, _no_main_script(), _interrupt_blocked():
        proc.start()
    return proc


def child_ignores_interrupt() -> None:
    """In a child of :func:`start_child`: ignore SIGINT (the parent handles Ctrl-C and
    ends the child), then unblock it (a Ctrl-C pending since the start is dropped)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
