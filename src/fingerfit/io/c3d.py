"""C3D motion files (via the optional ``ezc3d`` package): 6-DOF channels and marker clusters.

Two sources of segment poses:

* **ROTATION channels** (C3D ``ROTATION`` group): one 4x4 homogeneous transform per
  channel and frame, segment -> lab; translations in ``POINT:UNITS``.
* **Marker clusters**: three or more markers on one segment. By default every group
  of markers named ``<segment><number>`` with at least three members is a cluster
  (``ArmR1, ArmR2, ArmR3`` -> ``ArmR``). Each frame's pose is the least-squares rigid
  fit of the cluster's shape (:mod:`fingerfit.io.rigid`), with the RMS residual per
  frame reported. The shape comes from the same file or from a static trial.

Positions are returned in mm (lab = tracker coordinates), rotations map segment into
lab coordinates (``docs/conventions.md``). Install with ``pip install fingerfit[c3d]``.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FingerfitError
from ..session import UNITS_TO_MM, PoseSeries, Recording
from .hygiene import (
    MAX_RATE_HZ,
    check_recording,
    implausible_message,
    implausible_rows,
    sensor_missing_notes,
)
from .rigid import ClusterFit, cluster_shape, fit_cluster

#: Residual RMS (mm) above which a frame of a cluster fit is counted as suspect.
MAX_RESIDUAL_MM = 5.0
#: Largest deviation of a ROTATION channel's 3x3 block from orthonormal.
ORTHONORMAL_TOLERANCE = 1e-3
_CLUSTER_RE = re.compile(r"^(.*?[^\d])(\d+)$")


def _ezc3d():
    from ..extras import require

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


@dataclass
class C3DSegments:
    """Segment poses read from a C3D file.

    Attributes
    ----------
    recording : Recording
        One pose series per segment (mm, segment -> lab rotations).
    fits : dict[str, ClusterFit]
        Per marker-cluster segment (by output name): per-frame residual RMS (mm) and
        markers used.
    shapes : dict[str, ndarray]
        Per cluster segment, marker coordinates ``(m, 3)`` mm in the segment frame.
    clusters : dict[str, list[str]]
        Per cluster segment, its marker labels.
    """

    recording: Recording
    fits: dict[str, ClusterFit] = field(default_factory=dict)
    shapes: dict[str, np.ndarray] = field(default_factory=dict)
    clusters: dict[str, list[str]] = field(default_factory=dict)


def _rotation_channels(c, path: Path, scale: float) -> tuple[dict[str, PoseSeries], float, int]:
    rot = np.asarray(c["data"].get("rotations", np.zeros((4, 4, 0, 0))), dtype=float)
    if rot.ndim != 4 or rot.shape[2] == 0:
        return {}, 0.0, 1
    labels = [str(s).strip() for s in _param(c, "ROTATION", "LABELS", [])]
    n_ch = rot.shape[2]
    labels = labels[:n_ch] + [f"rotation{i + 1}" for i in range(len(labels), n_ch)]
    ratio = int(np.asarray(_param(c, "ROTATION", "RATIO", [1])).ravel()[0] or 1)
    rate = float(np.asarray(_param(c, "ROTATION", "RATE", [0.0])).ravel()[0] or 0.0)
    m = np.transpose(rot, (2, 3, 0, 1))  # (channel, frame, 4, 4)
    out: dict[str, PoseSeries] = {}
    eye = np.eye(3)
    for ch, label in enumerate(labels):
        r = m[ch, :, :3, :3].copy()
        t = m[ch, :, :3, 3] * scale
        inf = np.flatnonzero(np.isinf(m[ch, :, :3, :]).any(axis=(1, 2)))
        if inf.size:
            raise FingerfitError(
                f"frame {int(inf[0]) + 1}: infinite value (garbled data)",
                path=path,
                field=f"ROTATION:{label}",
            )
        ok = np.isfinite(m[ch, :, :3, :]).all(axis=(1, 2))
        dev = np.abs(np.swapaxes(r[ok], 1, 2) @ r[ok] - eye).max(axis=(1, 2))
        det = np.linalg.det(r[ok])
        bad = (dev > ORTHONORMAL_TOLERANCE) | (det <= 0)
        if bad.any():
            k = int(np.flatnonzero(ok)[np.flatnonzero(bad)[0]])
            raise FingerfitError(
                f"frame {k + 1}: not a rotation matrix (deviation {dev[bad][0]:.3g}, "
                f"det {det[bad][0]:.3g})",
                path=path,
                field=f"ROTATION:{label}",
            )
        r[~ok] = np.nan
        t[~ok] = np.nan
        big = implausible_rows(t)
        if big.size:
            k = int(big[0])
            raise FingerfitError(
                f"frame {k + 1}: "
                + implausible_message(float(t[k, int(np.nanargmax(np.abs(t[k])))])),
                path=path,
                field=f"ROTATION:{label}",
            )
        out[label] = PoseSeries(t, r)
    return out, rate, ratio


def read_c3d_segments(
    path: str | Path,
    *,
    units: str | None = None,
    clusters: Mapping[str, list[str]] | None = None,
    segments: Mapping[str, str] | None = None,
    static: str | Path | None = None,
    shapes: Mapping[str, np.ndarray] | None = None,
    rotations: bool = True,
    max_residual_mm: float = MAX_RESIDUAL_MM,
    check: bool = True,
) -> C3DSegments:
    """Segment poses from a C3D file: ROTATION channels and marker clusters.

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Overrides ``POINT:UNITS`` (also used for ROTATION translations).
    clusters : mapping segment -> marker labels, optional
        Default: :func:`find_clusters` on the file's labels.
    segments : mapping str -> str, optional
        Cluster or channel name -> output sensor name; only these are returned and
        each must exist. Default: every cluster and channel, under its own name.
    static : str or Path, optional
        A static trial of the same markers defining each cluster's shape (default:
        the shape averaged over this file).
    shapes : mapping segment -> ndarray (m, 3), optional
        Cluster shapes (mm, segment frame) to use as given, e.g. from another trial,
        so segment frames are identical across trials. Takes precedence over ``static``.
    rotations : bool
        Whether to read ROTATION channels.
    max_residual_mm : float
        Frames with a larger residual RMS are counted in the notes (kept).
    check : bool
        Run :func:`~fingerfit.io.hygiene.check_recording`.

    Returns
    -------
    C3DSegments
        ``recording`` (time s, positions mm, rotations segment -> lab), per-frame
        fit residuals and the shapes used.
    """
    path = Path(path)
    c = _open(path)
    mk = _markers(c, path, units)
    scale = _scale(c, path, units)
    explicit = clusters is not None or segments is not None
    if clusters is None:
        clusters = find_clusters(mk.labels)
    for seg, labels in clusters.items():
        for lb in labels:
            if lb not in mk.labels:
                raise FingerfitError(
                    f"cluster '{seg}' names marker '{lb}', which is not in the file",
                    path=path,
                    field="clusters",
                )
    rot_poses: dict[str, PoseSeries] = {}
    rot_rate, ratio = 0.0, 1
    if rotations:
        rot_poses, rot_rate, ratio = _rotation_channels(c, path, scale)
    available = list(clusters) + list(rot_poses)
    if segments is None:
        wanted = {s: s for s in available}
    else:
        missing = [s for s in segments if s not in available]
        if missing:
            raise FingerfitError(
                f"no cluster or ROTATION channel '{missing[0]}' (has: "
                f"{', '.join(available) or 'none'})",
                path=path,
                field="map",
            )
        wanted = dict(segments)
    if len(set(wanted.values())) != len(wanted):
        raise FingerfitError("two segments map to the same sensor name", path=path, field="map")
    if not wanted:
        raise FingerfitError("no marker cluster or ROTATION channel found", path=path)
    use_markers = any(s in clusters for s in wanted)
    use_rot = any(s in rot_poses for s in wanted)
    if use_rot and ratio != 1 and use_markers:
        raise FingerfitError(
            f"ROTATION:RATIO is {ratio}: channels and markers have different rates; "
            "convert them separately",
            path=path,
            field="ROTATION:RATIO",
        )
    if use_markers or not use_rot:
        time = mk.time
    else:
        n_rot = next(iter(rot_poses.values())).n_frames
        rate = rot_rate or mk.rate_hz * ratio
        time = (int(c["header"]["points"]["first_frame"]) * ratio + np.arange(n_rot)) / rate

    static_mk = None
    if static is not None and shapes is None:
        static_mk = read_c3d_markers(static, units=units)
    notes: list[str] = []
    poses: dict[str, PoseSeries] = {}
    fits: dict[str, ClusterFit] = {}
    used_shapes: dict[str, np.ndarray] = {}
    used_clusters: dict[str, list[str]] = {}
    for seg, name in wanted.items():
        if seg in rot_poses:
            poses[name] = rot_poses[seg]
            notes.append(f"segment '{name}': ROTATION channel '{seg}'")
            continue
        labels = list(clusters[seg])
        xyz = mk.cluster(labels)
        try:
            if shapes is not None and seg in shapes:
                shape = np.asarray(shapes[seg], dtype=float)
                src = "given shape"
            elif static_mk is not None:
                shape = cluster_shape(static_mk.cluster(labels))
                src = f"shape from {Path(static).name}"
            else:
                shape = cluster_shape(xyz)
                src = "shape averaged over this file"
        except ValueError as exc:
            if explicit:
                raise FingerfitError(
                    f"cluster '{seg}': {exc}", path=path, field="clusters"
                ) from None
            notes.append(f"cluster '{seg}' ({', '.join(labels)}) skipped: {exc}")
            continue
        except FingerfitError as exc:
            raise FingerfitError(f"cluster '{seg}': {exc.reason}", path=static) from None
        fit = fit_cluster(xyz, shape)
        poses[name] = PoseSeries(fit.translation, fit.rotation)
        fits[name] = fit
        used_shapes[name] = shape
        used_clusters[name] = labels
        ok = np.isfinite(fit.residual)
        if ok.any():
            worst = int(np.nanargmax(fit.residual))
            big = int((fit.residual[ok] > max_residual_mm).sum())
            notes.append(
                f"segment '{name}': rigid fit of {len(labels)} markers ({src}), residual RMS "
                f"median {np.median(fit.residual[ok]):.2f} mm, max "
                f"{fit.residual[worst]:.2f} mm (frame {worst})"
                + (f"; {big} frames above {max_residual_mm:g} mm" if big else "")
            )
        else:
            notes.append(f"segment '{name}': no frame with 3 visible markers")
    rec = Recording(path.name, np.asarray(time, dtype=float), poses, notes)
    rec.notes.extend(sensor_missing_notes(rec))
    if check:
        check_recording(rec, path)
    return C3DSegments(rec, fits, used_shapes, used_clusters)


def read_c3d(path: str | Path, **kwargs) -> Recording:
    """Segment poses of a C3D file as a :class:`Recording`.

    Parameters
    ----------
    path : str or Path
    **kwargs
        As for :func:`read_c3d_segments`.

    Returns
    -------
    Recording
        Time s, positions mm (lab frame), rotations segment -> lab; the fit residuals
        are summarised in the notes (see :func:`read_c3d_segments` for per-frame values).
    """
    return read_c3d_segments(path, **kwargs).recording
