"""Liberty/Patriot output lists and the raw station records both stream readers return.

:func:`parse_items` reads an output list (device codes of the ``O`` command or names);
:class:`LibertyRecords` holds the records of a stream in file order, in device units;
:func:`_check_records` refuses a bad station number or count.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import FingerfitError

#: Number of values of each data item.
ITEM_SIZE = {"position": 3, "euler": 3, "quaternion": 4, "timestamp": 1, "frame": 1}
#: Device item codes (``O`` command) and accepted names -> item; None = no data.
ITEM_ALIASES: dict[str, str | None] = {
    "0": None,
    "1": None,
    "2": "position",
    "3": "position",
    "4": "euler",
    "5": "euler",
    "7": "quaternion",
    "8": "timestamp",
    "9": "frame",
    "space": None,
    "crlf": None,
    "pos": "position",
    "position": "position",
    "euler": "euler",
    "quat": "quaternion",
    "quaternion": "quaternion",
    "time": "timestamp",
    "timestamp": "timestamp",
    "frame": "frame",
    "framecount": "frame",
}
#: The device's default output list ``O*,2,4,1``.
DEFAULT_ITEMS = ("position", "euler")
MAX_STATION = 16
_INT_ITEMS = ("timestamp", "frame")


def parse_items(spec: str | Sequence[str] | None) -> tuple[str, ...]:
    """The data items of an output list.

    Parameters
    ----------
    spec : str or sequence of str or None
        Device codes or names, comma-separated (``"2,4,1"``, ``"pos,quat,time"``);
        ``None`` gives the device default (position, Euler angles).

    Returns
    -------
    tuple of str
        Item names in stream order, from ``position``, ``euler``, ``quaternion``,
        ``timestamp``, ``frame`` (space and CR/LF dropped).

    Raises
    ------
    FingerfitError
        ``field 'items'``: unknown or repeated item, or no position or orientation.
    """
    if spec is None:
        return DEFAULT_ITEMS
    parts = spec.split(",") if isinstance(spec, str) else list(spec)
    out: list[str] = []
    for raw in parts:
        key = str(raw).strip().lower()
        if key == "6":
            raise FingerfitError(
                "item 6 (direction cosines) is not supported; use 7 (quaternion) or 4 (Euler)",
                field="items",
            )
        if key not in ITEM_ALIASES:
            raise FingerfitError(
                f"unknown output item '{raw}' (use codes 0-5, 7-9 or names "
                "pos, euler, quat, time, frame)",
                field="items",
            )
        item = ITEM_ALIASES[key]
        if item is None:
            continue
        if item in out:
            raise FingerfitError(f"item '{item}' listed twice", field="items")
        out.append(item)
    if "position" not in out or not ({"euler", "quaternion"} & set(out)):
        raise FingerfitError(
            "the output list needs a position (2) and an orientation (4 or 7) item",
            field="items",
        )
    return tuple(out)


@dataclass
class LibertyRecords:
    """Raw station records of a Liberty/Patriot stream, in file order.

    Attributes
    ----------
    items : tuple of str
        Data items in stream order (see :func:`parse_items`).
    station : ndarray of int (int16 from the readers), shape (n_records,)
        Station numbers 1-16.
    values : dict[str, ndarray]
        Per item, in device units: ``position`` ``(n, 3)`` (file units),
        ``euler`` ``(n, 3)`` degrees (azimuth, elevation, roll), ``quaternion``
        ``(n, 4)`` scalar first ``(w, x, y, z)``, ``timestamp`` ``(n,)`` ms and
        ``frame`` ``(n,)`` counts (integer valued floats). float64, except position,
        Euler angles and quaternion from a binary stream: float32 as sent (exact; use
        them as float64, e.g. ``np.asarray(v, dtype=float)``, before any arithmetic).
    indicator : ndarray of str, shape (n_records,)
        Indicator character after the station number (ASCII) or the error byte
        (binary) as a character; ``""`` when none.
    where : ndarray of int, shape (n_records,)
        1-based file line (ASCII) or record number (binary) of each record.
    binary : bool
        Whether ``where`` counts binary records.
    record_size : int
        Bytes per binary record (0 for ASCII).
    """

    items: tuple[str, ...]
    station: np.ndarray
    values: dict[str, np.ndarray]
    indicator: np.ndarray
    where: np.ndarray
    binary: bool = False
    record_size: int = 0
    family: str = field(default="LY")

    @property
    def n_records(self) -> int:
        return int(self.station.shape[0])

    def matrix(self) -> np.ndarray:
        """All item values side by side, ``(n_records, n_values)`` float."""
        cols = [self.values[i].reshape(self.n_records, -1) for i in self.items]
        return np.concatenate(cols, axis=1).astype(float)

    def error(
        self, message: str, i: int | None, path: str | Path, field: str | None = None
    ) -> FingerfitError:
        """A one-line error about record ``i`` (file line or binary record)."""
        if i is None:
            return FingerfitError(message, path=path, field=field)
        if self.binary:
            k = int(self.where[i])
            where = f"record {k} (byte {(k - 1) * self.record_size}): "
            if field is not None:
                where += f"field '{field}': "
            return FingerfitError(where + message, path=path)
        return FingerfitError(message, path=path, line=int(self.where[i]), field=field)

    def check_increasing(
        self, values: np.ndarray, index: np.ndarray, path: str | Path, what: str, strict: bool
    ) -> None:
        """Raise at the first record (of ``index``) where ``values`` decrease (or repeat)."""
        d = np.diff(values)
        bad = np.flatnonzero(d <= 0 if strict else d < 0)
        if bad.size:
            j = int(bad[0]) + 1
            verb = "goes backwards" if d[j - 1] < 0 else "does not increase"
            raise self.error(
                f"{what} {verb} ({values[j]:.15g} after {values[j - 1]:.15g})",
                int(index[j]),
                path,
                field=what,
            )


def _field_name(items: Sequence[str], column: int) -> str:
    k = 0
    for item in items:
        if column < k + ITEM_SIZE[item]:
            return item if ITEM_SIZE[item] == 1 else f"{item}[{column - k}]"
        k += ITEM_SIZE[item]
    return "?"


def _check_records(recs: LibertyRecords, path: str | Path) -> None:
    bad = np.flatnonzero((recs.station < 1) | (recs.station > MAX_STATION))
    if bad.size:
        i = int(bad[0])
        raise recs.error(
            f"unknown station {recs.station[i]} (stations are 1-{MAX_STATION})", i, path
        )
    for item in _INT_ITEMS:
        if item in recs.values:
            v = recs.values[item]
            bad = np.flatnonzero((v != np.floor(v)) | (v < 0))
            if bad.size:
                i = int(bad[0])
                raise recs.error(f"{item} must be a whole number >= 0, not {v[i]:g}", i, path)
