"""The Polhemus Liberty serial protocol: set-up commands, binary records, resynchronisation.

The record layout (8-byte header ``'LY'``, station, command, error, reserved, uint16 body
size, then little-endian float32 items and uint32 counters) is the one
:mod:`fingerfit.io.liberty` reads from files; this module only adds what a live link
needs: the commands that put the device into continuous binary output, and a parser that
takes whatever bytes the port delivered, keeps the complete records, and resynchronises
after garbage or a lost byte. ``docs/streaming.md`` lists every command with the
manual's section.

Set-up, in order (:data:`SETUP_COMMANDS`): ``P`` (stop any continuous output; the reply,
if any, is discarded), ``O*,2,7,9`` (output list: position, quaternion w,x,y,z, frame
count, every station), ``U1`` (centimetres), ``F1`` (binary), then ``C`` (continuous
output). Closing sends ``P`` again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.hygiene import QUAT_NORM_TOLERANCE
from ..io.liberty import _binary_dtype

#: Output list (``O`` command) fingerfit asks for: position, quaternion, frame count.
ITEMS = ("position", "quaternion", "frame")
#: Centimetres per device unit after ``U1``; positions are converted to mm with it.
UNITS_CM = "cm"
#: Commands sent before continuous output starts (bytes exactly as written).
SETUP_COMMANDS = (b"O*,2,7,9\r", b"U1\r", b"F1\r")
#: Starts continuous output.
START = b"C"
#: Stops continuous output (a single-record request when not in continuous mode).
STOP = b"P"
#: Header magics accepted: Liberty, Patriot.
MAGICS = (b"LY", b"PA")
#: Command bytes of a data record: ``C`` (continuous) or ``P`` (single record).
DATA_COMMANDS = (ord("C"), ord("P"))
#: Largest frame count accepted (310 h at 240 Hz): a byte lost inside the counter shifts
#: the next record's ``'L'`` into its top byte, which this catches.
MAX_FRAME_COUNT = 2**28
#: Largest forward jump of the frame count between consecutive accepted records.
MAX_FRAME_JUMP = 2400
#: Largest position magnitude accepted (cm): the Liberty's range is a few metres.
MAX_POSITION_CM = 1000.0

RECORD = _binary_dtype(ITEMS)


@dataclass
class ParsedRecords:
    """Complete, checked records taken from the front of a byte buffer.

    Attributes
    ----------
    station : ndarray of int, shape (n,)
    frame : ndarray of int, shape (n,)
        Device frame counts.
    position : ndarray, shape (n, 3)
        Centimetres (device units after ``U1``), tracker frame.
    quaternion : ndarray, shape (n, 4)
        Scalar first ``(w, x, y, z)``, sensor -> tracker.
    consumed : int
        Bytes used from the buffer (the rest is an incomplete record).
    skipped : int
        Bytes discarded while resynchronising (garbage, the remains of a record that
        lost a byte).
    rejected : int
        Records discarded because a check failed (header, station, values).
    """

    station: np.ndarray
    frame: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    consumed: int
    skipped: int
    rejected: int


def _valid(recs: np.ndarray, stations: np.ndarray, last_frame: int | None) -> np.ndarray:
    """Boolean ``(n,)``: records that pass every check (vectorised)."""
    ok = np.isin(recs["magic"], MAGICS)
    ok &= np.isin(recs["command"], DATA_COMMANDS)
    ok &= recs["size"] == RECORD.itemsize - 8
    ok &= np.isin(recs["station"], stations)
    with np.errstate(invalid="ignore", over="ignore"):
        pos = recs["position"].astype(float)
        quat = recs["quaternion"].astype(float)
        ok &= np.isfinite(pos).all(axis=1) & (np.abs(pos) < MAX_POSITION_CM).all(axis=1)
        ok &= np.isfinite(quat).all(axis=1)
        ok &= np.abs(np.linalg.norm(np.nan_to_num(quat), axis=1) - 1.0) < QUAT_NORM_TOLERANCE
    fc = recs["frame"].astype(np.int64)
    ok &= fc < MAX_FRAME_COUNT
    if last_frame is not None:
        ok &= (fc >= last_frame) & (fc <= last_frame + MAX_FRAME_JUMP)
    return ok


def parse_records(
    buffer: bytes | bytearray, stations: np.ndarray, last_frame: int | None = None
) -> ParsedRecords:
    """Take the complete, valid records from the front of ``buffer``.

    Runs of consecutive records are decoded and checked in one NumPy pass; at the
    first record that fails a check (wrong magic, command byte, body size or station;
    a non-finite or out-of-range value; a quaternion whose norm is not 1; a frame
    count that goes back or jumps) one byte is dropped and the next header is
    searched for, so garbage and a record that lost a byte cost only themselves.

    Parameters
    ----------
    buffer : bytes or bytearray
        Bytes read from the port, oldest first.
    stations : ndarray of int
        Station numbers expected (others are rejected).
    last_frame : int, optional
        Frame count of the last accepted record (frame counts never go back).

    Returns
    -------
    ParsedRecords
        Records in arrival order; ``consumed`` bytes may be dropped from the buffer.
    """
    size = RECORD.itemsize
    view = bytes(buffer)
    pos, skipped, rejected = 0, 0, 0
    parts: list[np.ndarray] = []
    while True:
        starts = [i for i in (view.find(m, pos) for m in MAGICS) if i >= 0]
        if not starts:  # keep a last byte that may be the first of a magic
            keep = 1 if view[-1:] in (b"L", b"P") else 0
            end = max(pos, len(view) - keep)
            skipped += end - pos
            pos = end
            break
        start = min(starts)
        skipped += start - pos
        pos = start
        n = (len(view) - start) // size
        if n == 0:
            break
        recs = np.frombuffer(view, RECORD, count=n, offset=start)
        last = int(parts[-1]["frame"][-1]) if parts else last_frame
        ok = _valid(recs, stations, last)
        if last is None and ok.any():  # first record ever: later ones must not go back
            first = int(np.argmax(ok))
            ok[first:] &= _valid(recs[first:], stations, int(recs["frame"][first]))
        bad = np.flatnonzero(~ok)
        good = n if bad.size == 0 else int(bad[0])
        if good:
            parts.append(recs[:good])
            pos = start + good * size
        if good == n:
            break
        rejected += 1
        skipped += 1
        pos += 1
    recs = np.concatenate(parts) if parts else np.zeros(0, RECORD)
    return ParsedRecords(
        recs["station"].astype(np.int64),
        recs["frame"].astype(np.int64),
        recs["position"].astype(float),
        recs["quaternion"].astype(float),
        pos,
        skipped,
        rejected,
    )
