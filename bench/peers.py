"""Adapters that run peer implementations on fingerfit's joint data (benchmark only).

Each adapter takes the same movement frames the fingerfit estimators use (the
grasp-cycle movement periods of one joint, parent and child sensor poses in
tracker coordinates) and returns the peer's axis and/or centre in the parent
sensor frame. The peers are imported from their installed packages; nothing of
theirs is copied.
"""

from __future__ import annotations

import logging

import numpy as np

from fingerfit.session import Recording
from fingerfit.transforms import FloatArray, transform_from_pr

try:  # biobuddy is an optional peer (extra "peers")
    from biobuddy.model_modifiers.joint_center_tool import Sara, Score
    from biobuddy.utils.linear_algebra import RotoTransMatrixTimeSeries

    logging.getLogger("biobuddy").setLevel(logging.WARNING)
    HAVE_BIOBUDDY = True
except ImportError:  # pragma: no cover - depends on the environment
    HAVE_BIOBUDDY = False


def _series(position: FloatArray, rotation: FloatArray) -> RotoTransMatrixTimeSeries:
    """biobuddy time series from poses ``(n, 3)`` mm and ``(n, 3, 3)``: 4 x 4 x n."""
    rt = np.moveaxis(transform_from_pr(position, rotation), 0, -1)
    return RotoTransMatrixTimeSeries.from_rt_matrix(np.ascontiguousarray(rt))


def joint_frames(
    recordings: list[Recording], parent: str, child: str, frames: np.ndarray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Parent and child poses (tracker frame) of the selected frames of concatenated recordings."""
    pp = np.concatenate([r.pose(parent).position for r in recordings])[frames]
    pr = np.concatenate([r.pose(parent).rotation for r in recordings])[frames]
    cp = np.concatenate([r.pose(child).position for r in recordings])[frames]
    cr = np.concatenate([r.pose(child).rotation for r in recordings])[frames]
    return pp, pr, cp, cr


def biobuddy_sara(
    parent_position: FloatArray,
    parent_rotation: FloatArray,
    child_position: FloatArray,
    child_rotation: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """biobuddy ``Sara.perform_algorithm`` (with its outlier removal).

    Returns
    -------
    axis, point : ndarray, shape (3,)
        Unit axis and its centre of rotation (the peer's pseudo-inverse point),
        both in the parent sensor frame (mm).
    """
    out = Sara.perform_algorithm(
        _series(parent_position, parent_rotation),
        _series(child_position, child_rotation),
        None,
        recursive_outlier_removal=True,
    )
    axis, point = np.asarray(out[1], float)[:3], np.asarray(out[4], float)[:3]
    return axis / np.linalg.norm(axis), point


def biobuddy_score(
    parent_position: FloatArray,
    parent_rotation: FloatArray,
    child_position: FloatArray,
    child_rotation: FloatArray,
) -> FloatArray:
    """biobuddy ``Score.perform_algorithm`` (with its outlier removal): centre ``(3,)`` mm,
    parent sensor frame."""
    out = Score.perform_algorithm(
        _series(parent_position, parent_rotation),
        _series(child_position, child_rotation),
        recursive_outlier_removal=True,
    )
    return np.asarray(out[1], float)[:3]


# --------------------------------------------------------------------------- real data table


def real_accuracy_table(data_dir: str = "../shared/data/polhemus-liberty", seed: int = 0) -> list:
    """Hinge axis of sensor 2 about sensor 1 on the real Liberty logs: fingerfit vs biobuddy.

    The axis is not known independently (hand-turned sensor), so each estimator's axis on
    the clean data is its own reference; the table gives (1) the angle between estimators on
    the clean data, (2) each estimator's axis change when Gaussian noise (0.5 mm per
    coordinate, 0.5 deg per axis, per sensor and frame) is added, (3) the axis change
    between the two halves of the recording and (4) the run time. Frames between the
    hemisphere flips of ``rotate-90deg-x.csv`` are left out.
    """
    import time
    from pathlib import Path

    from scipy.spatial.transform import Rotation

    from fingerfit.estimate import hinge_axis
    from fingerfit.io.hygiene import find_jumps
    from fingerfit.io.widecsv import read_wide_csv
    from fingerfit.transforms import angle_between_axes, transform_from_pr

    rows = []
    rng = np.random.default_rng(seed)
    for name in ("rotate-90deg-x.csv", "rotate-90deg-y.csv", "rotate-90deg-z.csv"):
        rec = read_wide_csv(
            Path(data_dir) / name, units="cm", rate_hz=120.0,
            sensors={1: "hand", 2: "index.proximal"},
        )  # fmt: skip
        p, c = rec.poses["hand"], rec.poses["index.proximal"]
        ok = p.valid & c.valid
        flips = [j.frame for j in find_jumps(rec) if j.hemisphere]
        if flips:
            ok[flips[0] - 1 : flips[-1] + 1] = False
        pp, pr, cp, cr = p.position[ok], p.rotation[ok], c.position[ok], c.rotation[ok]
        n = pp.shape[0]

        def noisy(pos, rot):
            turn = Rotation.from_rotvec(rng.normal(0, np.radians(0.5), (len(pos), 3))).as_matrix()
            return pos + rng.normal(0, 0.5, pos.shape), turn @ rot

        variants = {"clean": (pp, pr, cp, cr), "noisy": (*noisy(pp, pr), *noisy(cp, cr))}
        axes: dict = {}
        for tag, (a, b, cc, d) in variants.items():
            for est in ("fingerfit sara", "fingerfit robust", "biobuddy SARA"):
                t0 = time.perf_counter()
                if est.startswith("fingerfit"):
                    f = hinge_axis(
                        transform_from_pr(a, b), transform_from_pr(cc, d),
                        method=est.split()[1], check_convention=False,
                    )  # fmt: skip
                    axis = f.axis_parent
                    h = n // 2
                    halves = [
                        hinge_axis(transform_from_pr(a[s], b[s]), transform_from_pr(cc[s], d[s]),
                                   method=est.split()[1], check_convention=False).axis_parent
                        for s in (slice(0, h), slice(h, n))
                    ]  # fmt: skip
                else:
                    axis = biobuddy_sara(a, b, cc, d)[0]
                    h = n // 2
                    halves = [biobuddy_sara(a[s], b[s], cc[s], d[s])[0] for s in (slice(0, h), slice(h, n))]  # fmt: skip
                dt = time.perf_counter() - t0
                axes[(tag, est)] = (axis, halves, dt)
        for est in ("fingerfit sara", "fingerfit robust", "biobuddy SARA"):
            clean, halves, dt = axes[("clean", est)]
            noisy_axis = axes[("noisy", est)][0]
            rows.append(
                {
                    "file": name,
                    "estimator": est,
                    "vs fingerfit sara, clean (deg)": float(np.degrees(angle_between_axes(clean, axes[("clean", "fingerfit sara")][0]))),
                    "change with noise (deg)": float(np.degrees(angle_between_axes(clean, noisy_axis))),
                    "halves (deg)": float(np.degrees(angle_between_axes(*halves))),
                    "time incl. halves (ms)": 1000 * dt,
                }
            )  # fmt: skip
    return rows


if __name__ == "__main__":  # pragma: no cover - benchmark entry point
    import pandas as pd

    print(pd.DataFrame(real_accuracy_table()).to_string(index=False, float_format="%.2f"))
