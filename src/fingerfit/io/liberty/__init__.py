"""Polhemus Liberty / Patriot output: ASCII and binary streams -> :class:`Recording`.

**ASCII** (as captured from the device or saved by its host software): one CR/LF
line per station, whitespace-separated: the station number (one or two digits,
optionally followed by one indicator character, e.g. ``01`` or ``01D``), then the
items of the output list in order. Numbers glued together by a sign (fixed-width
fields overflowing, ``12.345-6.789``) are split.

**Binary**: records of an 8-byte header -- ``'LY'`` (Liberty) or ``'PA'`` (Patriot),
station byte, command byte, error byte, reserved byte, little-endian ``uint16`` body
size -- then the items as little-endian ``float32`` (timestamp and frame count as
``uint32``). The space and CR/LF items carry no data in binary records.

Output-list items (device codes of the ``O`` command): ``2``/``3`` position x, y, z;
``4``/``5`` Euler angles azimuth, elevation, roll in degrees, ``R = Rz(az) Ry(el)
Rx(roll)``; ``7`` quaternion **w, x, y, z**; ``8`` timestamp (ms); ``9`` frame count;
``0`` space and ``1`` CR/LF (ignored). The device default list is ``2,4,1`` and the
default units inches.

Frames: by the frame-count item when present; otherwise by station cycle (a record
whose station number is not above the previous one starts a new frame). Time: from
the timestamp item, else frame count / rate, else cycle index / rate. With a rate,
frames are placed on the ``1/rate`` grid and missing frames appear as NaN rows.
Returned positions are millimetres in tracker coordinates and rotation matrices map
sensor into tracker coordinates (``docs/conventions.md``).
"""

from .ascii import ASCII_DECIMALS, format_liberty_ascii, parse_liberty_ascii, write_liberty_ascii
from .ascii import _ascii_to_csv as _ascii_to_csv
from .ascii import _ascii_to_csv_quick as _ascii_to_csv_quick
from .ascii import _parse_ascii_fast as _parse_ascii_fast
from .binary import _binary_dtype as _binary_dtype
from .binary import liberty_binary_bytes, parse_liberty_binary, write_liberty_binary
from .frames import (
    MAX_EULER_DEG,
    QUAT_NORM_TOLERANCE,
    read_liberty_ascii,
    read_liberty_binary,
    records_to_recording,
)
from .records import (
    DEFAULT_ITEMS,
    ITEM_ALIASES,
    ITEM_SIZE,
    MAX_STATION,
    LibertyRecords,
    parse_items,
)

__all__ = [
    "ASCII_DECIMALS",
    "DEFAULT_ITEMS",
    "ITEM_ALIASES",
    "ITEM_SIZE",
    "MAX_EULER_DEG",
    "MAX_STATION",
    "QUAT_NORM_TOLERANCE",
    "LibertyRecords",
    "format_liberty_ascii",
    "liberty_binary_bytes",
    "parse_items",
    "parse_liberty_ascii",
    "parse_liberty_binary",
    "read_liberty_ascii",
    "read_liberty_binary",
    "records_to_recording",
    "write_liberty_ascii",
    "write_liberty_binary",
]
