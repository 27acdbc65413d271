"""Polhemus Liberty / Patriot output: ASCII and binary streams -> :class:`Recording`.

* :mod:`.records` -- the output list (device codes of the ``O`` command: ``2``/``3``
  position x, y, z; ``4``/``5`` Euler angles azimuth, elevation, roll in degrees,
  ``R = Rz(az) Ry(el) Rx(roll)``; ``7`` quaternion **w, x, y, z**; ``8`` timestamp (ms);
  ``9`` frame count; ``0`` space and ``1`` CR/LF ignored; device default ``2,4,1``,
  inches) and the raw station records both formats parse into;
* :mod:`.ascii` -- the ASCII stream (one CR/LF line per station), parsed and written;
* :mod:`.binary` -- the ``LY``/``PA`` binary records, parsed and written (the live serial
  driver decodes the wire with the same record layout);
* :mod:`.frames` -- records grouped into frames on the time grid, as a
  :class:`Recording` (positions mm, tracker coordinates; rotations sensor -> tracker,
  ``docs/conventions.md``), and the two file readers.

Every name is importable from here.
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
