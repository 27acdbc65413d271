"""A package's public names imported on first use (PEP 562).

``fingerfit.io`` and ``fingerfit.estimate`` export readers and estimators whose modules
import large parts of SciPy (signal, stats); a command that needs one submodule (``angles``
reads a pose file and checks it) should not pay for the others. The names stay importable
as before: ``from fingerfit.io import read_c3d`` imports :mod:`fingerfit.io.c3d` then.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_exports(
    package: str, exports: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package`` whose names ``exports`` maps to the
    submodule (relative, e.g. ``".c3d"``) that defines each."""

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module, package), name)
        globals_of_package = importlib.import_module(package).__dict__
        globals_of_package[name] = value  # the next lookup is a plain attribute
        return value

    def __dir__() -> list[str]:
        return sorted({*importlib.import_module(package).__dict__, *exports})

    return __getattr__, __dir__
