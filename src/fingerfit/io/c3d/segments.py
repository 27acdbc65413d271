"""Segment poses from a C3D file: its ROTATION channels (6-DOF) or the rigid fit of
marker clusters, as a :class:`~fingerfit.session.Recording`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...errors import FingerfitError
from ...session import PoseSeries, Recording
from ..hygiene import (
    check_recording,
    implausible_message,
    implausible_rows,
    sensor_missing_notes,
)
from ..rigid import ClusterFit, cluster_shape, fit_cluster
from .markers import (
    _markers,
    _open,
    _param,
    _scale,
    find_clusters,
    read_c3d_markers,
)

#: Residual RMS (mm) above which a frame of a cluster fit is counted as suspect.
MAX_RESIDUAL_MM = 5.0
#: Largest deviation of a ROTATION channel's 3x3 block from orthonormal.
ORTHONORMAL_TOLERANCE = 1e-3


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
