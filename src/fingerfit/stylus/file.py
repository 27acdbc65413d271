"""``stylus.json`` (format ``fingerfit.stylus/1``): a stylus's tip in its sensor's frame.

Written by ``fingerfit stylus`` from a pivot recording (or a maker's tip offset), read by
``fingerfit capture --protocol landmarks --stylus stylus.json`` (``docs/formats.md``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray

STYLUS_FORMAT = "fingerfit.stylus/1"


@dataclass(frozen=True)
class StylusCalibration:
    """A stylus's tip offset and where it came from.

    Attributes
    ----------
    sensor : str
        The stylus sensor's name in the recordings (``stylus``).
    tip_offset_mm : ndarray, shape (3,)
        The tip in the stylus sensor's frame, mm.
    pivot_mm : ndarray, shape (3,) or None
        The divot in the tracker frame (mm); None for a maker's offset.
    rms_mm : float
        The pivot fit's RMS residual (mm); NaN for a maker's offset.
    rotation_span_deg : float
        The pivot recording's rotation span (deg); NaN for a maker's offset.
    n_frames : int
        The pivot fit's frames (0 for a maker's offset).
    tip_ci_mm : float
        95 % half-width of the tip offset along its worst direction (mm); NaN for a
        maker's offset.
    """

    sensor: str
    tip_offset_mm: FloatArray
    pivot_mm: FloatArray | None = None
    rms_mm: float = math.nan
    rotation_span_deg: float = math.nan
    n_frames: int = 0
    tip_ci_mm: float = math.nan

    def to_json(self) -> dict:
        """The file's content (``null`` for what a maker's offset lacks)."""

        def num(x: float) -> float | None:
            return None if not math.isfinite(x) else round(float(x), 6)

        return {
            "format": STYLUS_FORMAT,
            "sensor": self.sensor,
            "tip_offset_mm": [round(float(v), 6) for v in self.tip_offset_mm],
            "pivot_mm": None
            if self.pivot_mm is None
            else [round(float(v), 6) for v in self.pivot_mm],
            "rms_mm": num(self.rms_mm),
            "rotation_span_deg": num(self.rotation_span_deg),
            "n_frames": int(self.n_frames),
            "tip_ci_mm": num(self.tip_ci_mm),
        }


def _vector(doc: dict, key: str, path: Path) -> FloatArray:
    v = doc.get(key)
    if (
        not isinstance(v, list)
        or len(v) != 3
        or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        or not all(math.isfinite(x) for x in v)
    ):
        raise FingerfitError("must be a list of three finite numbers (mm)", path=path, field=key)
    return np.asarray(v, dtype=float)


def read_stylus(path: str | Path) -> StylusCalibration:
    """Read ``stylus.json``.

    Raises
    ------
    FingerfitError
        Naming the file and the field: not JSON, another format, a missing or malformed
        field, a tip offset of an implausible length (under 10 mm or over 500 mm: a
        stylus's tip in another unit).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FingerfitError("no such file", path=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FingerfitError(f"not JSON ({exc})", path=path) from None
    if not isinstance(doc, dict) or doc.get("format") != STYLUS_FORMAT:
        raise FingerfitError(f"not a {STYLUS_FORMAT} file", path=path, field="format")
    sensor = doc.get("sensor")
    if not isinstance(sensor, str) or not sensor:
        raise FingerfitError("must be the stylus sensor's name", path=path, field="sensor")
    tip = _vector(doc, "tip_offset_mm", path)
    check_tip_offset(tip, path=path, field="tip_offset_mm")
    pivot = None if doc.get("pivot_mm") is None else _vector(doc, "pivot_mm", path)

    def num(key: str) -> float:
        v = doc.get(key)
        if v is None:
            return math.nan
        if not isinstance(v, int | float) or isinstance(v, bool):
            raise FingerfitError("must be a number or null", path=path, field=key)
        return float(v)

    n = doc.get("n_frames", 0)
    if not isinstance(n, int) or isinstance(n, bool) or n < 0:
        raise FingerfitError("must be a whole number", path=path, field="n_frames")
    return StylusCalibration(
        sensor, tip, pivot, num("rms_mm"), num("rotation_span_deg"), n, num("tip_ci_mm")
    )


def check_tip_offset(tip: FloatArray, *, path: str | Path | None = None, field: str) -> None:
    """Refuse a tip offset whose length (mm) is not a stylus's: under 10 or over 500 mm
    (a value in cm or m, or a sensor at the tip)."""
    length = float(np.linalg.norm(tip))
    if not (10.0 <= length <= 500.0):
        raise FingerfitError(
            f"a tip {length:.4g} mm from the sensor is not a stylus's (10-500 mm): give it in mm",
            path=path,
            field=field,
        )


def write_stylus(path: str | Path, calibration: StylusCalibration) -> Path:
    """Write ``stylus.json`` atomically (never half a file)."""
    from ..io.atomic import atomic_write

    path = Path(path)
    with atomic_write(path) as fh:
        json.dump(calibration.to_json(), fh, indent=2)
        fh.write("\n")
    return path
