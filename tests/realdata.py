"""Loaders of the real recordings kept under ``tests/data`` (with their licences)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fingerfit.session import Recording

HINGE_DIR = Path(__file__).resolve().parent / "data" / "ancillao-hinge"


@dataclass(frozen=True)
class MeasuredHinge:
    """A real hinge recording and its independently measured axis.

    Attributes
    ----------
    recording : Recording
        Stations ``"1"`` (proximal segment, the parent) and ``"2"`` (distal, the child);
        positions mm, rotations segment -> lab; 50 Hz.
    axis_parent : ndarray, shape (3,)
        Unit direction of the pin (marker ``ax1`` to ``ax2``) in the parent frame.
    point_parent : ndarray, shape (3,)
        Midpoint of the two pin markers in the parent frame (mm).
    marker_rms_mm : float
        RMS motion of the pin markers in the parent frame (mm): how rigid the truth is.
    """

    recording: Recording
    axis_parent: np.ndarray
    point_parent: np.ndarray
    marker_rms_mm: float


def load_measured_hinge(folder: Path = HINGE_DIR) -> MeasuredHinge:
    """Read ``hinge.csv`` and ``axis-markers.csv`` (``tests/data/ancillao-hinge/README.md``)."""
    from fingerfit.io.widecsv import read_wide_csv

    rec = read_wide_csv(folder / "hinge.csv", units="mm", rate_hz=50.0)
    m = np.loadtxt(folder / "axis-markers.csv", delimiter=",", skiprows=1)
    p = rec.poses["1"]
    if m.shape[0] != rec.n_frames:
        raise ValueError(f"{m.shape[0]} marker rows for {rec.n_frames} frames")
    local = [np.einsum("nji,nj->ni", p.rotation, m[:, k : k + 3] - p.position) for k in (1, 4)]
    axis = (local[1] - local[0]).mean(axis=0)
    mid = 0.5 * (local[0] + local[1])
    spread = np.concatenate([x - x.mean(axis=0) for x in local])
    return MeasuredHinge(
        rec,
        axis / np.linalg.norm(axis),
        mid.mean(axis=0),
        float(np.sqrt(np.mean(np.sum(spread**2, axis=1)))),
    )
