"""The layouts of a wide CSV: column templates per station (``{n}`` = station number),
the default layout of common Liberty logging scripts, ``--columns`` parsed, and a header
checked against a layout (its stations, sensor names and the columns it leaves unused).
:mod:`.widecsv` reads and writes the files."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ..errors import FingerfitError

_POS = ("x", "y", "z")
_QUAT = ("qw", "qx", "qy", "qz")
_EULER = ("az", "el", "roll")


@dataclass(frozen=True)
class WideLayout:
    """Column templates of a wide CSV (``{n}`` = station number).

    Attributes
    ----------
    time : str or None
        Name of the time column (seconds), or None when the file has none.
    columns : dict[str, str]
        ``x, y, z`` and either ``qw, qx, qy, qz`` or ``az, el, roll`` -> template.
    """

    time: str | None
    columns: dict[str, str]

    @property
    def orientation(self) -> tuple[str, ...]:
        return _QUAT if "qw" in self.columns else _EULER

    @property
    def keys(self) -> tuple[str, ...]:
        return _POS + self.orientation


DEFAULT_LAYOUT = WideLayout(
    "Time",
    {
        "qw": "w{n}",
        "qx": "x{n}",
        "qy": "y{n}",
        "qz": "z{n}",
        "x": "loc{n}_x",
        "y": "loc{n}_y",
        "z": "loc{n}_z",
    },
)


def parse_layout(spec: str | None) -> WideLayout:
    """Parse ``key=template;key=template;...`` into a :class:`WideLayout`.

    Parameters
    ----------
    spec : str or None
        ``time=<column>`` (optional; ``time=`` for none), ``x=,y=,z=`` and either
        ``qw=,qx=,qy=,qz=`` (scalar-first quaternion) or ``az=,el=,roll=`` (degrees).
        ``None`` gives :data:`DEFAULT_LAYOUT`.

    Returns
    -------
    WideLayout

    Raises
    ------
    FingerfitError
        ``field 'columns'``: unknown key, missing key, or both orientation kinds.
    """
    if spec is None:
        return DEFAULT_LAYOUT
    cols: dict[str, str] = {}
    time: str | None = None
    for part in spec.split(";"):
        if not part.strip():
            continue
        key, sep, value = part.partition("=")
        key = key.strip()
        if not sep:
            raise FingerfitError(f"'{part}' is not key=column", field="columns")
        if key == "time":
            time = value.strip() or None
        elif key in _POS + _QUAT + _EULER:
            if not value.strip():
                raise FingerfitError(f"empty column template for '{key}'", field="columns")
            cols[key] = value.strip()
        else:
            raise FingerfitError(
                f"unknown key '{key}' (use time, x, y, z, qw, qx, qy, qz, az, el, roll)",
                field="columns",
            )
    has_q = any(k in cols for k in _QUAT)
    has_e = any(k in cols for k in _EULER)
    if has_q and has_e:
        raise FingerfitError("give a quaternion or Euler angles, not both", field="columns")
    need = _POS + (_EULER if has_e else _QUAT)
    missing = [k for k in need if k not in cols]
    if missing:
        raise FingerfitError(f"missing key(s) {', '.join(missing)}", field="columns")
    return WideLayout(time, cols)


def _template_regex(template: str) -> re.Pattern:
    return re.compile("^" + re.escape(template).replace(r"\{n\}", r"(\d+)") + "$")


def _stations(header: list[str], layout: WideLayout, path: Path) -> list[int]:
    tx = layout.columns["x"]
    if "{n}" not in tx:
        return [1] if tx in header else []
    rx = _template_regex(tx)
    return sorted({int(m.group(1)) for h in header if (m := rx.match(h))})


def _column(template: str, station: int) -> str:
    return template.replace("{n}", str(station))


def _header_plan(
    header: list[str], lay: WideLayout, sensors: Mapping[int, str] | None, path: Path
) -> tuple[list[int], list[str], list[str]]:
    """Stations, sensor names and the unused-columns note, from the header."""
    stations = _stations(header, lay, path)
    if not stations:
        raise FingerfitError(
            f"no column matches '{lay.columns['x']}' (wrong --columns?)", path=path, line=1
        )
    if lay.time is not None and lay.time not in header:
        raise FingerfitError(
            f"no time column '{lay.time}' (wrong --columns?)", path=path, line=1, field=lay.time
        )
    used: list[str] = [] if lay.time is None else [lay.time]
    for s in stations:
        for key in lay.keys:
            c = _column(lay.columns[key], s)
            if c not in header:
                raise FingerfitError(
                    f"column '{c}' missing for station {s}", path=path, line=1, field=c
                )
            used.append(c)
    notes: list[str] = []
    ignored = [h for h in header if h not in used]
    if ignored:
        notes.append(f"columns not used: {', '.join(ignored)}")
    if sensors is not None:
        extra = [s for s in stations if s not in sensors]
        if extra:
            mapped = ", ".join(f"{k}={v}" for k, v in sensors.items())
            raise FingerfitError(
                f"unknown station {extra[0]} (not in the map {mapped})",
                path=path,
                line=1,
                field=_column(lay.columns["x"], extra[0]),
            )
        absent = [k for k in sensors if k not in stations]
        if absent:
            raise FingerfitError(
                f"mapped station {absent[0]} ('{sensors[absent[0]]}') has no columns",
                path=path,
                line=1,
            )
        names = [sensors[s] for s in stations]
    else:
        names = [str(s) for s in stations]
    return stations, names, notes
