"""What a Parquet table's numbers mean: the extension that selects Parquet, the format
names and metadata keys, :class:`TableMeta` (the ``fingerfit.*`` key-value metadata of a
file) and that of each kind of table, and pyarrow imported on demand. :mod:`.parquet`
writes the files, :mod:`.parquet_read` reads and checks them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

#: The file extension that selects Parquet (case-insensitive).
SUFFIX = ".parquet"

#: Metadata keys (every one a UTF-8 string value).
FORMAT_KEY = "fingerfit.format"
UNITS_KEY = "fingerfit.units"
TIME_UNITS_KEY = "fingerfit.time_units"
ANGLE_UNITS_KEY = "fingerfit.angle_units"
FRAME_KEY = "fingerfit.frame"
QUAT_KEY = "fingerfit.quaternion_order"
TABLE_KEY = "fingerfit.table"

#: Formats (values of ``fingerfit.format``).
POSE = "fingerfit.pose/1"
WIDE = "fingerfit.wide/1"
ANGLES = "fingerfit.angles/1"
JOINTS = "fingerfit.joints/1"
RESIDUALS = "fingerfit.residuals/1"
STUDY_TABLE = "fingerfit.study_table/1"

#: Quaternion order of every fingerfit file: scalar first.
QUAT_ORDER = "w,x,y,z"
#: The frame of positions and rotations in recordings and fingertip columns.
TRACKER_FRAME = "tracker"


def is_parquet(path: str | Path) -> bool:
    """Whether ``path`` names a Parquet file (its extension is ``.parquet``)."""
    return Path(path).suffix.lower() == SUFFIX


@dataclass(frozen=True)
class TableMeta:
    """What a table's numbers mean, stored in the Parquet file's key-value metadata.

    Attributes
    ----------
    format : str
        ``fingerfit.format``: :data:`POSE`, :data:`WIDE`, :data:`ANGLES`, ...
    units : str, optional
        ``fingerfit.units``: length units of the positions (``mm``, ``cm``, ``m``, ``in``).
    frame : str, optional
        ``fingerfit.frame``: the frame of positions and rotations (``tracker``).
    quaternion_order : str, optional
        ``fingerfit.quaternion_order``: ``w,x,y,z`` (scalar first).
    time_units : str, optional
        ``fingerfit.time_units``: ``s``.
    angle_units : str, optional
        ``fingerfit.angle_units``: ``deg`` or ``rad``.
    extra : dict of str to str
        Further ``fingerfit.*`` keys (e.g. ``fingerfit.table`` of a study table).
    """

    format: str
    units: str | None = None
    frame: str | None = None
    quaternion_order: str | None = None
    time_units: str | None = "s"
    angle_units: str | None = None
    extra: dict[str, str] = field(default_factory=dict)

    def items(self) -> dict[str, str]:
        """The metadata as written: key -> value, absent values left out."""
        pairs = {
            FORMAT_KEY: self.format,
            UNITS_KEY: self.units,
            TIME_UNITS_KEY: self.time_units,
            ANGLE_UNITS_KEY: self.angle_units,
            FRAME_KEY: self.frame,
            QUAT_KEY: self.quaternion_order,
            **self.extra,
        }
        return {k: v for k, v in pairs.items() if v is not None}


def pose_meta(units: str) -> TableMeta:
    """Metadata of a pose recording (long or wide): positions in ``units``, tracker frame,
    rotations sensor -> tracker as quaternions ``w,x,y,z``."""
    return TableMeta(POSE, units=units, frame=TRACKER_FRAME, quaternion_order=QUAT_ORDER)


def angles_meta(units: str) -> TableMeta:
    """Metadata of an angles table (``fingerfit angles``, ``stream --record``): angles in
    degrees, fingertip and pad points in ``units``, tracker frame."""
    return TableMeta(ANGLES, units=units, frame=TRACKER_FRAME, angle_units="deg")


def joints_meta() -> TableMeta:
    """Metadata of a joint trajectory (``retarget -o``, ``angles --urdf-names``): joint
    positions in radians."""
    return TableMeta(JOINTS, angle_units="rad")


def _pa():
    import pyarrow as pa
    import pyarrow.parquet as pq

    return pa, pq
