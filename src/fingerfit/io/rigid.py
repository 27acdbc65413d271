"""Segment poses from marker clusters: a least-squares rigid fit over all frames at once.

A cluster is three or more markers on one rigid segment. Its *shape* is the markers'
coordinates in the segment's technical frame (origin at the markers' centroid, x from
marker 1 to marker 2, z normal to the plane of markers 1-3, ``y = z x x``). Each
frame's pose is the rotation and translation that best map the shape onto the
visible markers (weighted Kabsch solution, batched SVD; no per-frame loop), with the
RMS residual reported per frame. Lengths are millimetres; a pose maps segment
coordinates into lab (tracker) coordinates: ``p_lab = R @ p_segment + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Relative size of the second singular value below which markers count as collinear.
_COLLINEAR = 1e-6


@dataclass(frozen=True)
class ClusterFit:
    """Per-frame pose of a segment fitted to its marker cluster.

    Attributes
    ----------
    rotation : ndarray, shape (n_frames, 3, 3)
        Segment -> lab rotation; NaN where fewer than ``min_markers`` were visible.
    translation : ndarray, shape (n_frames, 3)
        Segment frame origin in lab coordinates (mm); NaN where not fitted.
    residual : ndarray, shape (n_frames,)
        RMS distance between the fitted and measured markers (mm); NaN where not fitted.
    n_markers : ndarray of int, shape (n_frames,)
        Markers used in each frame.
    """

    rotation: np.ndarray
    translation: np.ndarray
    residual: np.ndarray
    n_markers: np.ndarray


def technical_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Technical frame of a cluster from its first three markers.

    Parameters
    ----------
    points : ndarray, shape (..., m, 3)
        Marker positions (mm), ``m >= 3``.

    Returns
    -------
    rotation : ndarray, shape (..., 3, 3)
        Columns are the frame axes in the points' coordinates: x from marker 1 to
        marker 2, z normal to the plane of markers 1-3, ``y = z x x``.
    origin : ndarray, shape (..., 3)
        Centroid of all ``m`` markers.
    """
    p = np.asarray(points, dtype=float)
    x = p[..., 1, :] - p[..., 0, :]
    with np.errstate(invalid="ignore", divide="ignore"):  # coincident markers: NaN axes
        x = x / np.linalg.norm(x, axis=-1, keepdims=True)
        z = np.cross(x, p[..., 2, :] - p[..., 0, :])
        z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1), p.mean(axis=-2)


def fit_cluster(markers: np.ndarray, shape: np.ndarray, *, min_markers: int = 3) -> ClusterFit:
    """Least-squares rigid fit of a cluster shape to measured markers, every frame at once.

    Parameters
    ----------
    markers : ndarray, shape (n_frames, m, 3)
        Measured marker positions (mm, lab frame); NaN where a marker is not visible.
    shape : ndarray, shape (m, 3)
        The same markers in segment coordinates (mm), e.g. from :func:`cluster_shape`.
    min_markers : int
        Fewest visible markers to fit a frame (at least 3).

    Returns
    -------
    ClusterFit
        Frames with fewer visible markers, or visible markers on one line, are NaN.
    """
    x = np.asarray(markers, dtype=float)
    s = np.asarray(shape, dtype=float)
    if x.ndim != 3 or x.shape[2] != 3 or s.shape != (x.shape[1], 3):
        raise ValueError(f"need markers (n, m, 3) and shape (m, 3); got {x.shape} and {s.shape}")
    vis = np.isfinite(x).all(axis=2)
    w = vis.astype(float)
    count = w.sum(axis=1)
    xz = np.where(vis[..., None], x, 0.0)
    safe = np.maximum(count, 1.0)[:, None]
    xc = (w[..., None] * xz).sum(axis=1) / safe
    sc = (w @ s) / safe
    ds = s[None, :, :] - sc[:, None, :]
    dx = xz - xc[:, None, :]
    with np.errstate(over="ignore", invalid="ignore"):
        h = np.einsum("nm,nmi,nmj->nij", w, ds, dx)
    # Garbled coordinates (huge values overflowing the products, a shape with NaN) make
    # the cross-covariance non-finite: those frames are not fitted (NaN), never an error.
    finite = np.isfinite(h).all(axis=(1, 2)) & np.isfinite(ds).all(axis=(1, 2))
    h = np.where(finite[:, None, None], h, np.eye(3))
    u, sv, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.matmul(vt.transpose(0, 2, 1), u.transpose(0, 2, 1))))
    d[d == 0] = 1.0
    fix = np.ones((x.shape[0], 3))
    fix[:, 2] = d
    rot = np.matmul(vt.transpose(0, 2, 1) * fix[:, None, :], u.transpose(0, 2, 1))
    trans = xc - np.einsum("nij,nj->ni", rot, sc)
    ok = (count >= max(min_markers, 3)) & (sv[:, 1] > _COLLINEAR * np.maximum(sv[:, 0], 1e-300))
    ok &= finite
    fitted = np.einsum("nij,mj->nmi", rot, s) + trans[:, None, :]
    with np.errstate(over="ignore", invalid="ignore"):
        err = np.where(vis, np.sum((fitted - xz) ** 2, axis=2), 0.0)
    resid = np.sqrt(err.sum(axis=1) / safe[:, 0])
    rot[~ok] = np.nan
    trans[~ok] = np.nan
    resid[~ok] = np.nan
    return ClusterFit(rot, trans, resid, count.astype(np.int64))


def cluster_shape(markers: np.ndarray) -> np.ndarray:
    """Mean shape of a marker cluster in its technical frame.

    The markers of every frame where all are visible are expressed in that frame's
    technical frame and averaged; one Procrustes pass (fit, re-express, average)
    refines the mean, which is finally re-expressed in its own technical frame, so the
    segment frame is reproducible from any recording of the same cluster.

    Parameters
    ----------
    markers : ndarray, shape (n_frames, m, 3)
        Marker positions (mm, lab frame), ``m >= 3``; NaN where not visible.

    Returns
    -------
    ndarray, shape (m, 3)
        Marker coordinates in the segment's technical frame (mm).

    Raises
    ------
    ValueError
        If fewer than 3 markers, no frame shows every marker, or markers 1-3 are
        (nearly) collinear.
    """
    x = np.asarray(markers, dtype=float)
    if x.ndim != 3 or x.shape[1] < 3 or x.shape[2] != 3:
        raise ValueError(f"a cluster needs at least 3 markers, shape (n, m>=3, 3); got {x.shape}")
    full = np.isfinite(x).all(axis=(1, 2))
    if not full.any():
        raise ValueError("no frame shows every marker of the cluster")
    xf = x[full]
    e1 = np.linalg.norm(xf[:, 1] - xf[:, 0], axis=1)
    e2 = np.linalg.norm(np.cross(xf[:, 1] - xf[:, 0], xf[:, 2] - xf[:, 0]), axis=1)
    if np.median(e2) <= _COLLINEAR * np.median(e1) ** 2 or np.median(e1) == 0:
        raise ValueError("markers 1-3 of the cluster are collinear")
    rot, origin = technical_frame(xf)
    local = np.einsum("nji,nmj->nmi", rot, xf - origin[:, None, :])
    shape = local.mean(axis=0)
    fit = fit_cluster(xf, shape)
    local = np.einsum("nji,nmj->nmi", fit.rotation, xf - fit.translation[:, None, :])
    shape = local.mean(axis=0)
    rot, origin = technical_frame(shape)
    return (shape - origin) @ rot
