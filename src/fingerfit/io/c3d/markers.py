"""C3D marker trajectories (via the optional ``ezc3d``) and marker clusters by name.

Positions in mm, lab (tracker) coordinates; a marker with a negative residual is missing
(NaN)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import FingerfitError
from ...session import UNITS_TO_MM
from ..hygiene import (
    MAX_RATE_HZ,
    implausible_message,
    implausible_rows,
)
from .header import (
    _check_size,
    read_c3d_header,
)

_CLUSTER_RE = re.compile(r"^(.*?[^\d])(\d+)$")


def _ezc3d():
    from ...extras import require

    return require("ezc3d", "c3d", "reading C3D files")


@dataclass
class C3DMarkers:
    """Marker trajectories of a C3D file.

    Attributes
    ----------
    labels : list of str
    points : ndarray, shape (n_frames, n_markers, 3)
        Positions in mm, lab coordinates; NaN where a marker is not visible.
    time : ndarray, shape (n_frames,)
        Seconds, ``(first_frame + k) / rate_hz``.
    rate_hz : float
    """

    labels: list[str]
    points: np.ndarray
    time: np.ndarray
    rate_hz: float

    def marker(self, label: str) -> np.ndarray:
        """Trajectory ``(n_frames, 3)`` mm of one marker."""
        try:
            return self.points[:, self.labels.index(label)]
        except ValueError:
            raise FingerfitError(f"no marker '{label}' in the C3D file") from None

    def cluster(self, labels: list[str]) -> np.ndarray:
        """Trajectories ``(n_frames, m, 3)`` mm of several markers."""
        return np.stack([self.marker(lb) for lb in labels], axis=1)


def _param(c, group: str, name: str, default=None):
    try:
        return c["parameters"][group][name]["value"]
    except KeyError:
        return default


def c3d_point_units(path: Path) -> str:
    """The file's ``POINT:UNITS`` (e.g. ``mm``; empty when the file states none)."""
    value = _param(_ezc3d().c3d(str(path)), "POINT", "UNITS", [""])
    return str(value[0] if len(value) else "").strip()


def _open(path: Path):
    ezc3d = _ezc3d()
    if not path.is_file():
        raise FingerfitError("file not found", path=path)
    header = read_c3d_header(path)
    try:
        c = ezc3d.c3d(str(path))
    except Exception as exc:  # ezc3d raises plain RuntimeError/IOError on bad files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FingerfitError(f"not a readable C3D file ({msg[:120]})", path=path) from None
    # ezc3d rewrites its header and POINT:FRAMES to what it managed to read: compare
    # the frames it holds with what the raw header announced.
    pts = c["data"]["points"]
    n_read = int(np.shape(pts)[2]) if np.ndim(pts) == 3 else 0
    if header.n_points or header.analog_per_frame:
        _check_size(header, path.stat().st_size, path, read=n_read)
    return c


def _scale(c, path: Path, units: str | None) -> float:
    if units is not None:
        if units not in UNITS_TO_MM:
            raise FingerfitError(
                f"unknown units '{units}' (use {', '.join(UNITS_TO_MM)})", path=path, field="units"
            )
        return UNITS_TO_MM[units]
    u = _param(c, "POINT", "UNITS", [""])
    u = (u[0] if len(u) else "").strip()
    if u not in UNITS_TO_MM:
        raise FingerfitError(f"unknown units '{u}' (give --units)", path=path, field="POINT:UNITS")
    return UNITS_TO_MM[u]


def read_c3d_markers(path: str | Path, *, units: str | None = None) -> C3DMarkers:
    """Read the marker trajectories of a C3D file.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Overrides ``POINT:UNITS``.

    Returns
    -------
    C3DMarkers
        Positions mm; markers with a negative residual or NaN are missing (NaN).
    """
    path = Path(path)
    c = _open(path)
    return _markers(c, path, units)


def _markers(c, path: Path, units: str | None) -> C3DMarkers:
    scale = _scale(c, path, units)
    labels = [str(s).strip() for s in _param(c, "POINT", "LABELS", [])]
    k = 2
    while (more := _param(c, "POINT", f"LABELS{k}")) is not None:
        labels += [str(s).strip() for s in more]
        k += 1
    pts = np.asarray(c["data"]["points"], dtype=float)
    n_markers, n_frames = pts.shape[1], pts.shape[2]
    labels = labels[:n_markers]
    if len(labels) < n_markers:
        labels += [f"marker{i + 1}" for i in range(len(labels), n_markers)]
    xyz = np.transpose(pts[:3], (2, 1, 0)) * scale
    resid = c["data"].get("meta_points", {}).get("residuals")
    if resid is not None and np.size(resid):
        bad = np.transpose(np.asarray(resid)[0], (1, 0)) < 0
        xyz[bad] = np.nan
    big = implausible_rows(xyz.reshape(n_frames, -1))
    if big.size:
        k = int(big[0])
        m, j = np.unravel_index(int(np.nanargmax(np.abs(xyz[k]))), xyz.shape[1:])
        raise FingerfitError(
            f"frame {k + 1}: " + implausible_message(float(xyz[k, m, j])),
            path=path,
            field=f"POINT:{labels[m]}",
        )
    rate = float(_param(c, "POINT", "RATE", [0.0])[0])
    if not 0 < rate <= MAX_RATE_HZ:
        raise FingerfitError(
            f"POINT:RATE must be positive and at most {MAX_RATE_HZ:g} Hz, not {rate:g}",
            path=path,
            field="POINT:RATE",
        )
    first = int(c["header"]["points"]["first_frame"])
    time = (first + np.arange(n_frames)) / rate
    return C3DMarkers(labels, xyz, time, rate)


def find_clusters(labels: list[str], min_markers: int = 3) -> dict[str, list[str]]:
    """Group markers named ``<segment><number>`` into clusters.

    Parameters
    ----------
    labels : list of str
    min_markers : int
        Fewest members for a group to count as a cluster.

    Returns
    -------
    dict[str, list[str]]
        Segment -> marker labels ordered by number (marker 1 first).
    """
    groups: dict[str, list[tuple[int, str]]] = {}
    for lb in labels:
        m = _CLUSTER_RE.match(lb)
        if m:
            groups.setdefault(m.group(1), []).append((int(m.group(2)), lb))
    return {
        seg: [lb for _, lb in sorted(members)]
        for seg, members in groups.items()
        if len(members) >= min_markers
    }


def parse_clusters(spec: str) -> dict[str, list[str]]:
    """Parse ``Segment=m1,m2,m3;Other=a,b,c`` into segment -> marker labels.

    Parameters
    ----------
    spec : str

    Returns
    -------
    dict[str, list[str]]
        Marker 1 first (it and markers 2-3 define the technical frame).

    Raises
    ------
    FingerfitError
        ``field 'clusters'``: a part is not ``name=label,label,label`` (3 or more).
    """
    out: dict[str, list[str]] = {}
    for part in spec.split(";"):
        if not part.strip():
            continue
        seg, sep, rest = part.partition("=")
        labels = [s.strip() for s in rest.split(",") if s.strip()]
        if not sep or not seg.strip() or len(labels) < 3:
            raise FingerfitError(
                f"'{part}' is not Segment=marker,marker,marker (3 or more markers)",
                field="clusters",
            )
        out[seg.strip()] = labels
    return out
