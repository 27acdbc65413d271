"""Memory the process has freed, handed back to the system between steps (the readers
after a parse, the study after joining its tables)."""

from __future__ import annotations

import sys
from collections.abc import Callable

_TRIM: Callable[[int], int] | None = None


def release_freed_memory() -> None:
    """Hand memory freed by a parse (or any pandas work) back to the system.

    The C library keeps freed blocks for reuse (Arrow's worker threads each keep their
    own), and so does Arrow's own allocator (mimalloc or jemalloc, which holds the
    buffers of pandas' string columns); they count in the process's peak once the next
    arrays are allocated on top. ``malloc_trim(0)`` of the GNU C library and Arrow's
    ``MemoryPool.release_unused`` return them (Arrow only when it is imported already);
    elsewhere the C library's part does nothing.
    """
    global _TRIM
    if _TRIM is None:
        try:
            import ctypes

            _TRIM = ctypes.CDLL(None).malloc_trim
        except (OSError, AttributeError, TypeError):  # TypeError: no CDLL(None) on Windows
            _TRIM = lambda pad: 0  # noqa: E731 -- not the GNU C library
    arrow = sys.modules.get("pyarrow")
    if arrow is not None:
        arrow.default_memory_pool().release_unused()
    _TRIM(0)
