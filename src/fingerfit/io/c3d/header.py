"""The raw header and parameter section of a C3D file, checked before ezc3d reads it:
frame counts, data size and parameter records (a file that would crash or mislead the
library is refused in one line)."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

from ...errors import FingerfitError


@dataclass(frozen=True)
class C3DHeader:
    """What the raw 512-byte C3D header says, read before (and independently of) ezc3d.

    Attributes
    ----------
    n_points : int
        3D points per frame (header word 2).
    analog_per_frame : int
        Analog samples per 3D frame, all channels (word 3).
    first_frame, last_frame : int
        1-based frame numbers (words 4 and 5; 16-bit, so 65535 may mean "more").
    data_start : int
        Byte offset of the data section (``512 * (word 9 - 1)``).
    float_data : bool
        Whether samples are 4-byte floats (negative scale factor) or 2-byte integers.
    """

    n_points: int
    analog_per_frame: int
    first_frame: int
    last_frame: int
    data_start: int
    float_data: bool

    @property
    def n_frames(self) -> int:
        """Frames the header announces (``last - first + 1``, at least 0)."""
        return max(0, self.last_frame - self.first_frame + 1)

    @property
    def frame_bytes(self) -> int:
        """Bytes of one frame of data: 4 words per point plus the analog samples."""
        return (4 * self.n_points + self.analog_per_frame) * (4 if self.float_data else 2)


#: C3D processor types (byte 4 of the parameter section): Intel, DEC, MIPS.
_PROCESSORS = {84: "<", 85: "<", 86: ">"}
#: Byte of the header's scale factor (words 7-8) holding its sign bit, per processor.
_SCALE_SIGN_BYTE = {84: 15, 85: 13, 86: 12}


def read_c3d_header(path: Path) -> C3DHeader:
    """Read and check the raw header of a C3D file.

    Parameters
    ----------
    path : Path

    Returns
    -------
    C3DHeader

    Raises
    ------
    FingerfitError
        A file shorter than its header, a wrong key byte (not C3D), an unknown
        processor type, or a file too short for the frames its header announces
        (``truncated: header says 700 frames (needs 459200 bytes of data), file holds 149``).
    """
    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            head = fh.read(512)
            block = head[0] if head else 0
            fh.seek(max(block - 1, 0) * 512)
            param = fh.read(4)
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    if len(head) < 512:
        raise FingerfitError(
            f"not a readable C3D file ({size} bytes, shorter than the 512-byte header)", path=path
        )
    if head[1] != 0x50:
        raise FingerfitError(
            f"not a readable C3D file (byte 2 of the header is 0x{head[1]:02x}, not 0x50)",
            path=path,
        )
    proc = param[3] if len(param) == 4 and block >= 2 else None
    if proc not in _PROCESSORS:
        raise FingerfitError(
            f"not a readable C3D file (parameter section at block {block}: processor type "
            f"{proc}, expected 84 Intel, 85 DEC or 86 MIPS)",
            path=path,
        )
    endian = _PROCESSORS[proc]
    words = struct.unpack(endian + "12H", head[:24])
    header = C3DHeader(
        n_points=words[1],
        analog_per_frame=words[2],
        first_frame=words[3],
        last_frame=words[4],
        data_start=512 * max(words[8] - 1, 0),
        float_data=bool(head[_SCALE_SIGN_BYTE[proc]] & 0x80),
    )
    _check_size(header, size, path)
    if header.data_start < block * 512:
        raise FingerfitError(
            f"not a readable C3D file (data start block {words[8]} is inside the parameter "
            f"section at block {block})",
            path=path,
        )
    try:
        with path.open("rb") as fh:
            fh.seek((block - 1) * 512)
            section = fh.read(header.data_start - (block - 1) * 512)
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    params = _parameter_section(section, endian, path)
    for key in _COUNT_PARAMETERS:
        value = params.get(key)
        if value is not None and value < 0:
            raise FingerfitError(
                f"not a readable C3D file ({':'.join(key)} is {value}, must not be negative)",
                path=path,
            )
    used = params.get(("POINT", "USED"))
    if used is not None and used != header.n_points:
        raise FingerfitError(
            f"not a readable C3D file (POINT:USED is {used}, the header says "
            f"{header.n_points} points)",
            path=path,
        )
    return header


#: Scalar int16 parameters that count something: never negative (ezc3d trusts them).
_COUNT_PARAMETERS = (
    ("POINT", "USED"),
    ("ANALOG", "USED"),
    ("ROTATION", "USED"),
    ("ROTATION", "RATIO"),
)
#: Parameter data types of the C3D format: char, byte, int16, float32 -> bytes per value.
_PARAM_TYPES = {-1: 1, 1: 1, 2: 2, 4: 4}


def _parameter_section(section: bytes, endian: str, path: Path) -> dict[tuple[str, str], int]:
    """Walk the parameter records of a C3D file, checking every length and pointer.

    ezc3d trusts these fields; a corrupted one can make it read out of bounds or try a
    huge allocation, so the structure is checked here first.

    Parameters
    ----------
    section : bytes
        From the start of the parameter section to the start of the data.
    endian : str
        ``<`` or ``>``.
    path : Path
        For messages.

    Returns
    -------
    dict
        ``(GROUP, NAME) -> value`` of the scalar int16 parameters (e.g. ``POINT:USED``).

    Raises
    ------
    FingerfitError
        Naming the byte offset of the first malformed record.
    """
    groups: dict[int, str] = {}
    pending: list[tuple[int, str, int]] = []
    end = len(section)
    pos = 4

    def bad(what: str) -> FingerfitError:
        return FingerfitError(
            f"not a readable C3D file (parameter record at byte {pos} of the parameter "
            f"section: {what})",
            path=path,
        )

    while pos + 2 <= end:
        n_name = abs(struct.unpack("b", section[pos : pos + 1])[0])
        if n_name == 0:
            break
        gid = struct.unpack("b", section[pos + 1 : pos + 2])[0]
        q = pos + 2 + n_name
        if gid == 0 or q + 2 > end:
            raise bad("group id 0 or name past the end")
        name = section[pos + 2 : q]
        if not all(32 < c < 127 for c in name):
            raise bad("name is not ASCII text")
        step = struct.unpack(endian + "H", section[q : q + 2])[0]
        r = q + 2
        if gid > 0:  # a parameter: type, dimensions, data
            if r + 2 > end:
                raise bad("type past the end")
            kind = struct.unpack("b", section[r : r + 1])[0]
            if kind not in _PARAM_TYPES:
                raise bad(f"unknown data type {kind}")
            n_dims = section[r + 1]
            if r + 2 + n_dims > end:
                raise bad("dimensions past the end")
            dims = list(section[r + 2 : r + 2 + n_dims])
            n_bytes = _PARAM_TYPES[kind] * math.prod(dims)  # Python ints: no overflow
            r = r + 2 + n_dims + n_bytes
            if r + 1 > end:
                raise bad("data past the end of the section")
            if kind == 2 and not dims:
                v = struct.unpack(endian + "h", section[r - 2 : r])[0]
                pending.append((gid, name.decode("ascii").upper(), v))
        else:
            groups[-gid] = name.decode("ascii").upper()
            if r + 1 > end:
                raise bad("description past the end")
        r = r + 1 + section[r]  # description
        if r > end:
            raise bad("description past the end")
        if step == 0:
            break
        if q + step < r or q + step > end:
            raise bad(f"pointer to the next record ({step}) outside the record or section")
        pos = q + step
    return {(groups.get(g, "?"), n): v for g, n, v in pending}


def _check_size(header: C3DHeader, size: int, path: Path, read: int | None = None) -> None:
    """Raise if the file (``size`` bytes) or the frames read fall short of the header."""
    if header.last_frame == 0xFFFF:  # 16-bit limit: the header cannot state the count
        return
    need = header.n_frames * header.frame_bytes
    holds = max(0, size - header.data_start) // header.frame_bytes if header.frame_bytes else 0
    if header.frame_bytes and header.data_start + need > size:
        raise FingerfitError(
            f"truncated: header says {header.n_frames} frames (needs {need} bytes of data), "
            f"file holds {min(holds, header.n_frames)}",
            path=path,
        )
    if read is not None and read < header.n_frames:
        raise FingerfitError(
            f"truncated: header says {header.n_frames} frames (needs {need} bytes of data), "
            f"file holds {read}",
            path=path,
        )
