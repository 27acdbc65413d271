"""One entry to the tracker-file readers: the reader of each input format, which options
apply to it, and the units its positions were read in.

``fingerfit convert`` and ``fingerfit joint`` read the same files (``--from``); both call
:func:`check_format_options` and :func:`read_tracker_file`, so a new format or option is
added here once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import FingerfitError, shown
from ..session import UNITS_TO_MM, Recording

#: ``--from`` values and the units each reads positions in when ``--units`` is not given
#: (``None``: the file states them: a wide Parquet file, a C3D file's ``POINT:UNITS``).
DEFAULT_UNITS: dict[str, str | None] = {
    "pose-csv": "mm",
    "liberty": "in",
    "liberty-binary": "in",
    "wide-csv": None,
    "c3d": None,
}
#: Option -> the ``--from`` formats it applies to.
FORMAT_OPTIONS: dict[str, tuple[str, ...]] = {
    "--items": ("liberty", "liberty-binary"),
    "--columns": ("wide-csv",),
    "--clusters": ("c3d",),
    "--static": ("c3d",),
    "--residuals": ("c3d",),
    "--rate": ("pose-csv", "liberty", "liberty-binary", "wide-csv"),
}


@dataclass
class TrackerFile:
    """What :func:`read_tracker_file` read.

    Attributes
    ----------
    recording : Recording
        Positions mm (tracker frame), rotations sensor -> tracker.
    declared_units : str
        The units the file's positions were read in (``--units``, the format's default or
        the file's own statement).
    fits : dict
        C3D marker clusters: segment -> its per-frame rigid fit (empty for other formats).
    """

    recording: Recording
    declared_units: str
    fits: dict = field(default_factory=dict)


def infer_format(source: Path) -> str:
    """The ``--from`` format of a file given without it, from its name and content.

    A ``.parquet`` file by the table its metadata names (``fingerfit.pose/1``:
    ``pose-csv``, ``fingerfit.wide/1``: ``wide-csv``), a ``.c3d`` file ``c3d``, a text
    file whose first line is the pose CSV's header ``pose-csv``. A Liberty file or a
    wide CSV does not say what it is: those need ``--from``.

    Parameters
    ----------
    source : Path

    Returns
    -------
    str
        A key of :data:`DEFAULT_UNITS`.

    Raises
    ------
    FingerfitError
        The format cannot be told (``field '--from'``), or a Parquet file holds a table
        that is not a recording.
    """
    from .parquet import FORMAT_KEY, POSE, WIDE, is_parquet, parquet_schema
    from .posecsv import PARQUET_MAGIC, header_line, is_pose_header, read_magic

    if is_parquet(source):
        table = parquet_schema(source)[1].get(FORMAT_KEY)
        if table in (POSE, WIDE):
            return "pose-csv" if table == POSE else "wide-csv"
        what = f"a '{shown(table)}' table" if table else f"no '{FORMAT_KEY}' metadata"
        raise FingerfitError(
            f"holds {what}, not a recording ({POSE} or {WIDE})", path=source, field="--from"
        )
    if source.suffix.lower() == ".c3d":
        return "c3d"
    try:
        pose = is_pose_header(header_line(source))
    except FingerfitError as exc:  # a binary file: a Liberty binary capture, or not a recording
        if read_magic(source) == PARQUET_MAGIC:
            raise exc from None  # a Parquet file under another name: that error says so
        pose = False
    if pose:
        return "pose-csv"
    raise FingerfitError(
        "neither a pose CSV nor a .parquet or .c3d file: give --from liberty, "
        "liberty-binary, wide-csv or c3d",
        path=source,
        field="--from",
    )


def check_format_options(fmt: str, units: str | None, **given: Any) -> None:
    """Refuse ``--units`` outside the known units and an option its format does not take.

    Parameters
    ----------
    fmt : str
        A ``--from`` value (:data:`DEFAULT_UNITS`).
    units : str, optional
        ``--units``.
    **given
        Option name without dashes (``items``, ``columns``, ``clusters``, ``static``,
        ``residuals``, ``rate``) -> its value (``None``: not given).

    Raises
    ------
    FingerfitError
        ``field '--units'`` or ``field '--<option>': does not apply to --from <fmt>``.
    """
    if units is not None and units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
    for name, value in given.items():
        opt = f"--{name}"
        if value is not None and fmt not in FORMAT_OPTIONS[opt]:
            raise FingerfitError(f"does not apply to --from {fmt}", field=opt)


def read_tracker_file(
    source: Path,
    fmt: str,
    *,
    units: str | None = None,
    rate: float | None = None,
    items: str | None = None,
    columns: str | None = None,
    clusters: str | None = None,
    sensors: dict | None = None,
    static: Path | None = None,
    keep_repeats: bool = False,
) -> TrackerFile:
    """Read a tracker file in ``--from`` format ``fmt`` without the recording checks.

    Parameters
    ----------
    source : Path
    fmt : {"pose-csv", "liberty", "liberty-binary", "wide-csv", "c3d"}
    units : str, optional
        The file's position units (default: :data:`DEFAULT_UNITS`).
    rate, items, columns, clusters, static, keep_repeats
        The readers' options of the same names (``--rate`` Hz; ``--items``; ``--columns``
        wide layout; ``--clusters`` C3D marker clusters; ``--static`` C3D static trial).
    sensors : dict, optional
        Station / segment -> session sensor name (``--map``).

    Returns
    -------
    TrackerFile
    """
    if fmt == "pose-csv":
        from .parquet import UNITS_KEY, is_parquet, parquet_schema
        from .posecsv import read_pose_csv

        if units is None:  # a Parquet file states its units; a CSV's default is mm
            units = parquet_schema(source)[1].get(UNITS_KEY, "mm") if is_parquet(source) else "mm"
        return TrackerFile(read_pose_csv(source, units=units, rate_hz=rate), units)
    if fmt in ("liberty", "liberty-binary"):
        from .liberty import read_liberty_ascii, read_liberty_binary

        reader = read_liberty_ascii if fmt == "liberty" else read_liberty_binary
        rec = reader(
            source,
            items=items,
            units=units or "in",
            rate_hz=rate,
            sensors=sensors,
            keep_repeats=keep_repeats,
            check=False,
        )
        return TrackerFile(rec, units or "in")
    if fmt == "wide-csv":
        from .parquet import is_parquet
        from .widecsv import read_wide_csv, wide_parquet_units

        rec = read_wide_csv(
            source, units=units, layout=columns, rate_hz=rate, sensors=sensors, check=False
        )
        declared = units or (wide_parquet_units(source, None) if is_parquet(source) else None)
        assert declared is not None  # a wide CSV without units is refused by the reader
        return TrackerFile(rec, declared)
    from .c3d import c3d_point_units, parse_clusters, read_c3d_segments

    seg = read_c3d_segments(
        source,
        units=units,
        clusters=None if clusters is None else parse_clusters(clusters),
        segments=sensors,
        static=static,
        check=False,
    )
    return TrackerFile(seg.recording, units or c3d_point_units(source), seg.fits)
