"""Plausibility problems: the :class:`Problem` records every check returns, the error and
warning they become (:func:`enforce`), and the unit mistake that explains a length.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ...errors import FingerfitError
from ...session import UNITS_TO_MM
from .bounds import SCALE_TOLERANCE, UNIT_NAMES, Bound


class PlausibilityError(FingerfitError):
    """The data are physically implausible (wrong units, wrong quaternion convention)."""


class PlausibilityWarning(UserWarning):
    """A plausibility problem that ``force`` let through (stored in the model's warnings)."""


@dataclass(frozen=True)
class Problem:
    """One implausible quantity.

    Attributes
    ----------
    message : str
        One line: the quantity, its value, the plausible range and the likely cause.
    path : Path, optional
        The file at fault.
    field : str, optional
        The field at fault (e.g. ``units``).
    """

    message: str
    path: Path | None = None
    field: str | None = None

    def error(self) -> PlausibilityError:
        """The problem as a one-line :class:`PlausibilityError`."""
        return PlausibilityError(self.message, path=self.path, field=self.field)

    def text(self) -> str:
        """The one line, with the file and field (as the error would print it)."""
        return str(self.error())


def enforce(problems: Sequence[Problem], force: bool) -> list[str]:
    """Refuse on the first problem, or (``force``) warn about each and return their lines.

    Raises
    ------
    PlausibilityError
        The first problem, unless ``force``.
    """
    if problems and not force:
        raise problems[0].error()
    lines = [p.text() + " (continued with --force)" for p in problems]
    for line in lines:
        warnings.warn(line, PlausibilityWarning, stacklevel=2)
    return lines


def fmt_mm(value: float) -> str:
    """A length for messages: 3 significant digits, thousands grouped by a space."""
    if not math.isfinite(value):
        return str(value)
    if abs(value) >= 1000:
        return f"{value:,.0f}".replace(",", " ")
    return f"{value:.3g}"


def _ratio_units(ratio: float) -> list[tuple[str, str]]:
    """Unit pairs ``(a, b)`` with ``UNITS_TO_MM[a] / UNITS_TO_MM[b]`` close to ``ratio``."""
    out = []
    for a, ma in UNITS_TO_MM.items():
        for b, mb in UNITS_TO_MM.items():
            if a != b and abs(math.log(ratio * mb / ma)) < math.log1p(SCALE_TOLERANCE):
                out.append((a, b))
    return out


def explaining_units(value: float, bound: Bound, declared: str) -> list[str]:
    """The units (keys of ``UNITS_TO_MM``) that bring a length ``value`` (mm, read as
    ``declared``) into ``bound``, nearest the middle of the range first (in log; the upper
    end of a range from 0)."""
    fits: list[tuple[float, str]] = []
    # The range's middle in log; a bound with no lower end: its upper end (least change).
    mid = math.sqrt(bound.lo * bound.hi) if bound.lo > 0 else bound.hi
    for actual, mm in UNITS_TO_MM.items():
        if actual == declared or not value > 0:
            continue
        v = value * mm / UNITS_TO_MM[declared]
        if bound.contains(v):
            fits.append((abs(math.log(v / mid)), actual))
    return [u for _, u in sorted(fits)]


def unit_cause(value: float, bound: Bound, declared: str, *, every: bool = False) -> str:
    """The likely cause of a length ``value`` (mm) outside ``bound`` when the data declare
    ``declared`` units: the actual units that bring it nearest the middle of the range
    (:func:`explaining_units`; ``every``: all of them, nearest the middle first -- for wide
    bounds that cannot tell them apart)."""
    fits = explaining_units(value, bound, declared)
    if not fits:
        return "no unit mistake explains it; check the sensor names and the data"
    names = [UNIT_NAMES[u] for u in fits]
    look = " or ".join(names if every else names[:1])
    return f"coordinates look like {look} declared as {UNIT_NAMES[declared]}"
