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


# --------------------------------------------------------------------------- real data tables

NOISE_MM, NOISE_DEG = 0.5, 0.5


def real_datasets(data_dir: str = "../shared/data/polhemus-liberty") -> list[dict]:
    """Real two-segment recordings: parent and child poses (tracker frame, mm).

    The three hand-turned Liberty logs of ``../shared/data`` (if present; frames between
    the hemisphere flips of ``rotate-90deg-x.csv`` left out; no known axis) and the
    mechanical hinge of ``tests/data/ancillao-hinge`` (GPL-3.0 excerpt), whose pin axis
    was measured by markers on the pin (``truth``: unit axis and a point of it, parent
    frame, mm).
    """
    from pathlib import Path

    from tests.realdata import load_measured_hinge

    from fingerfit.io.hygiene import find_jumps
    from fingerfit.io.widecsv import read_wide_csv

    out = []
    for name in ("rotate-90deg-x.csv", "rotate-90deg-y.csv", "rotate-90deg-z.csv"):
        path = Path(data_dir) / name
        if not path.is_file():
            continue
        rec = read_wide_csv(path, units="cm", rate_hz=120.0)
        p, c = rec.poses["1"], rec.poses["2"]
        ok = p.valid & c.valid
        flips = [j.frame for j in find_jumps(rec) if j.hemisphere]
        if flips:
            ok[flips[0] - 1 : flips[-1] + 1] = False
        poses = (p.position[ok], p.rotation[ok], c.position[ok], c.rotation[ok])
        out.append({"name": f"Liberty {name[-5]}", "poses": poses, "truth": None})
    h = load_measured_hinge()
    p, c = h.recording.poses["1"], h.recording.poses["2"]
    out.append({
        "name": "mechanical hinge",
        "poses": (p.position, p.rotation, c.position, c.rotation),
        "truth": (h.axis_parent, h.point_parent),
    })  # fmt: skip
    return out


def _noisy(poses: tuple, rng: np.random.Generator) -> tuple:
    """The poses with Gaussian noise: NOISE_MM per coordinate, NOISE_DEG per axis."""
    from scipy.spatial.transform import Rotation

    out = []
    for pos, rot in (poses[:2], poses[2:]):
        turn = Rotation.from_rotvec(rng.normal(0, np.radians(NOISE_DEG), (len(pos), 3)))
        out += [pos + rng.normal(0, NOISE_MM, pos.shape), turn.as_matrix() @ rot]
    return tuple(out)


def _fingerfit(poses: tuple, method: str):
    from fingerfit.estimate import hinge_axis

    a, b, c, d = poses
    return hinge_axis(
        transform_from_pr(a, b), transform_from_pr(c, d), method=method, check_convention=False
    )


def _axis(est: str, poses: tuple) -> tuple[FloatArray, FloatArray]:
    """(unit axis, a point of it) in the parent frame (mm) by one estimator."""
    if est == "biobuddy SARA":
        return biobuddy_sara(*poses)
    f = _fingerfit(poses, est.split()[1])
    return f.axis_parent, f.centre_parent


def real_accuracy_table(seed: int = 0) -> tuple[list, list]:
    """Hinge axis and centre of the child about the parent on real recordings:
    fingerfit vs biobuddy's SARA (axis) and SCoRE (centre).

    Axis table, per recording and estimator: the angle to fingerfit ``sara`` on the clean
    data, to the measured pin axis (mechanical hinge only), the axis change when noise
    (``NOISE_MM`` per coordinate, ``NOISE_DEG`` per axis, per segment and frame) is added,
    the angle between the axes of the two halves of the recording (``refused`` when the
    estimator refuses a half), and the time of the three fits (whole, halves).

    Centre table: on a hinge the SCoRE centre may be any point of the axis, so it is
    compared by its distance to a line: fingerfit ``sara``'s fitted axis (clean and noisy
    data, each against the same data's fitted axis) and the measured pin axis; fingerfit's
    own point of the axis against the pin axis for comparison.
    """
    import time

    from fingerfit.errors import FingerfitError
    from fingerfit.transforms import angle_between_axes, distance_point_to_line

    def deg(a, b) -> float:
        return float(np.degrees(angle_between_axes(a, b)))

    rng = np.random.default_rng(seed)
    axis_rows, centre_rows = [], []
    datasets = real_datasets()
    for est in ("fingerfit sara", "fingerfit robust", "biobuddy SARA"):  # warm-up (imports)
        _axis(est, datasets[-1]["poses"])
    biobuddy_score(*datasets[-1]["poses"])
    for ds in datasets:
        clean = ds["poses"]
        variants = {"clean": clean, "noisy": _noisy(clean, rng)}
        n = clean[0].shape[0]
        halves = [tuple(x[s] for x in clean) for s in (slice(0, n // 2), slice(n // 2, n))]
        fits = {}
        for est in ("fingerfit sara", "fingerfit robust", "biobuddy SARA"):
            t0 = time.perf_counter()
            res = {tag: _axis(est, v) for tag, v in variants.items()}
            try:
                hv = [_axis(est, h)[0] for h in halves]
                halves_deg: float | str = deg(*hv)
            except FingerfitError:
                halves_deg = "refused"
            dt = time.perf_counter() - t0
            fits[est] = res
            truth = ds["truth"]
            axis_rows.append({
                "recording": ds["name"],
                "estimator": est,
                "vs fingerfit sara (deg)": deg(res["clean"][0], fits["fingerfit sara"]["clean"][0]),
                "vs measured axis (deg)": deg(res["clean"][0], truth[0]) if truth else None,
                "change with noise (deg)": deg(res["clean"][0], res["noisy"][0]),
                "halves (deg)": halves_deg,
                "time incl. halves (ms)": 1000 * dt,
            })  # fmt: skip
        score, dt = {}, 0.0
        for tag, v in variants.items():
            t0 = time.perf_counter()
            score[tag] = biobuddy_score(*v)
            dt += time.perf_counter() - t0
        ff = fits["fingerfit sara"]
        truth = ds["truth"]
        centre_rows.append({
            "recording": ds["name"],
            "SCoRE to fingerfit axis, clean (mm)": distance_point_to_line(score["clean"], ff["clean"][1], ff["clean"][0]),
            "SCoRE to fingerfit axis, noisy (mm)": distance_point_to_line(score["noisy"], ff["noisy"][1], ff["noisy"][0]),
            "SCoRE to measured axis (mm)": distance_point_to_line(score["clean"], truth[1], truth[0]) if truth else None,
            "fingerfit to measured axis (mm)": distance_point_to_line(ff["clean"][1], truth[1], truth[0]) if truth else None,
            "SCoRE time, clean + noisy (ms)": 1000 * dt,
        })  # fmt: skip
    return axis_rows, centre_rows


if __name__ == "__main__":  # pragma: no cover - benchmark entry point
    import sys
    from pathlib import Path

    import pandas as pd

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    axis_rows, centre_rows = real_accuracy_table()

    def cell(v: object) -> str:
        return "-" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)

    for rows in (axis_rows, centre_rows):
        print(
            pd.DataFrame([{k: cell(v) for k, v in r.items()} for r in rows]).to_string(index=False)
        )
        print()
