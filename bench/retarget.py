"""Retargeting benchmark: tip vs joint method vs the orthogonal model as source, one run.

    python bench/retarget.py [--subjects 1] [--frames 3000] [--out bench/retarget.json]
                             [--dex-python "$FINGERFIT_DEX_PYTHON"]

Simulated subjects (four fingers, ``fingerfit.simulate``), model fitted by
``fit_session``, the grasp recording retargeted onto Shadow (MJCF, MuJoCo) and Allegro
(URDF, Pinocchio). Per robot and source: fingertip error in the robot palm frame against
the scaled targets of the fitted (user-axis) model (median / p95, mm), joint-limit and
coupling violations, jerk (RMS third difference of the joint trajectory, rad/s^3),
per-frame solve time (p50 / p99, ms), and how closely the robot's tips copy the person's
true fingertips (simulator truth, each in its finger's true anatomical frame) after the
best scale and offset per digit (RMS, mm, mean over digits: what a palm frame turned
against the hand's anatomy or a target out of reach costs). Then whole-hand subjects (thumb, pad points) on
``pinch.csv``: the robot pad points' distance during the person's pinch holds (the frames
of the ``events.csv`` pinch events of each thumb-finger pair the map names: the
simulator's truth of when the pads touch, not the model's pad distance).

``--dex-python`` adds dex-retargeting (``pip install dex-retargeting torch`` in a venv of
its own, docs/retargeting.md; that venv's python is ``FINGERFIT_DEX_PYTHON`` there) on the Allegro URDF, the robot file fingerfit loads (it
reads URDF only, not Shadow's MJCF): ``bench/dex_peer.py`` runs under that interpreter on
exactly the frames and the scaled fingertip targets fingerfit's ``tip`` method gets
(its ``PositionOptimizer`` on the tips; on the pinch recording also its
``DexPilotOptimizer`` on the map's pad points), and its joint angles are scored here with
fingerfit's robot kinematics and the same metrics.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from fingerfit.estimate import fit_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.retarget import (
    PINCH_FAR_MM,
    person_points,
    pinch_terms,
    resolve,
    retarget,
    robot_points,
    setup,
    targets,
)
from fingerfit.retarget.agreement import scale_offset_fit
from fingerfit.retarget.palm import Frame, in_palm
from fingerfit.retarget.pipeline import Setup
from fingerfit.retarget.solve import MM
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject

FINGERS = ("index", "middle", "ring", "little")
SOURCES = (
    ("tip", "user_axis"),
    ("joint", "user_axis"),
    ("tip", "orthogonal"),
    ("joint", "orthogonal"),
)


def jerk(q: np.ndarray, dt: float) -> float:
    """RMS over frames and joints of the third difference (rad/s^3)."""
    d3 = np.diff(q, n=3, axis=0) / dt**3
    return float(np.sqrt(np.mean(d3**2)))


DEX_PEER = Path(__file__).with_name("dex_peer.py")
#: dex-retargeting runs: (label, optimiser, output low-pass alpha, stopping tolerance).
#: As shipped: the filter of its Allegro configs (``configs/offline/allegro_hand_right.yml``:
#: 1 = off for position retargeting; ``configs/teleop/allegro_hand_right_dexpilot.yml``: 0.2
#: for DexPilot) and the optimisers' own tolerance (None). The other two runs show what
#: its stopping tolerance and its filter cost.
DEX_RUNS = (
    ("dex-position", "position", 1.0, None),
    ("dex-position-ftol1e-8", "position", 1.0, 1e-8),
    ("dex-dexpilot", "dexpilot", 0.2, None),
    ("dex-dexpilot-nofilter", "dexpilot", 1.0, None),
)
#: Largest disagreement (m) between dex-retargeting's and fingerfit's kinematics of the
#: same q: more means a joint-order or frame mix-up, and the comparison stops.
FK_TOLERANCE = 1e-6


def to_world(s: Setup, p_mm: np.ndarray) -> np.ndarray:
    """Robot palm frame (mm) -> robot world = URDF root frame (m); ``(..., 3)``."""
    return s.robot_palm.origin + (p_mm / MM) @ s.robot_palm.rotation.T


def rigid_offset(s: Setup, frame: str, parent: str) -> np.ndarray:
    """Offset ``(3,)`` (m, ``parent``'s axes) of ``frame`` rigidly carried by ``parent``.

    For a point fingerfit added to the robot (a map's pad offset) that the URDF does not
    name; checked at the neutral posture and at the joint-limit midpoints.
    """
    r = s.robot
    mid = np.where(np.isfinite(r.lower + r.upper), 0.5 * (r.lower + r.upper), 0.0)
    offs = []
    for q in (s.hold, mid):
        o, rot = r.pose(q, parent)
        offs.append(rot.T @ (r.positions(q[None], [frame])[0, 0] - o))
    if np.max(np.abs(offs[0] - offs[1])) > FK_TOLERANCE:
        raise SystemExit(f"robot frame '{frame}' does not move rigidly with '{parent}'")
    return offs[0]


def urdf_links(path: Path) -> set[str]:
    """Link names of a URDF file."""
    import xml.etree.ElementTree as ET

    return {e.get("name", "") for e in ET.parse(path).getroot().findall("link")}


def run_dex(
    dex_python: str,
    s: Setup,
    mode: str,
    alpha: float,
    frames: list[str],
    parents: list[str],
    points_mm: np.ndarray,
    pair_vectors_mm: np.ndarray | None = None,
    ftol: float | None = None,
) -> tuple[np.ndarray, np.ndarray, str]:
    """dex-retargeting's joint angles for one recording, in fingerfit's joint order.

    Parameters
    ----------
    frames : list of str
        ``k`` robot frames to place (``dexpilot``: thumb first); a frame that is not a
        URDF link (a pad point fingerfit added) is given to dex-retargeting as a fixed
        child link of ``parents[i]`` at the same offset.
    points_mm : ndarray, shape (n, k, 3)
        Where each frame should be (robot palm frame, mm).
    pair_vectors_mm : ndarray, shape (n, k, k, 3), optional
        ``dexpilot``: ``[:, i, j]`` = the commanded ``frame_i - frame_j`` (robot palm frame
        axes, mm), whose length switches DexPilot's pinch projection on and off.
    ftol : float, optional
        The optimiser's stopping tolerance; None: the package's own.

    Returns
    -------
    q : ndarray, shape (n, nq)
        rad, fingerfit's ``robot.joint_names`` order.
    seconds : ndarray, shape (n,)
        Per-frame solve time in dex-retargeting.
    version : str
    """
    if not np.isfinite(points_mm).all():
        raise SystemExit("dex-retargeting needs every target: a frame has a missing one")
    robot = s.robot
    links = urdf_links(robot.path)
    names, extra_names, extra_parents, extra_offsets = [], [], [], []
    for f, par in zip(frames, parents, strict=True):
        if f in links:
            names.append(f)
        else:
            names.append(f"dex_peer_{len(extra_names)}")
            extra_names.append(names[-1])
            extra_parents.append(par)
            extra_offsets.append(rigid_offset(s, f, par))
    free = [robot.joint_names[i] for i in s.free]
    held = [n for i, n in enumerate(robot.joint_names) if i not in set(s.free.tolist())]
    inputs = {
        "urdf": str(robot.path),
        "mode": mode,
        "links": np.array(names),
        "points": to_world(s, points_mm),
        "joints": np.array(free),
        "fixed_names": np.array(held, dtype=str),
        "fixed_values": np.array([s.hold[robot.joint_names.index(n)] for n in held]),
        "extra_names": np.array(extra_names, dtype=str),
        "extra_parents": np.array(extra_parents, dtype=str),
        "extra_offsets": np.array(extra_offsets, dtype=float).reshape(-1, 3),
        "low_pass_alpha": alpha,
    }
    if mode == "dexpilot":
        inputs["wrist"] = s.rmap.palm
        inputs["wrist_point"] = robot.pose(s.hold, s.rmap.palm)[0]
        if pair_vectors_mm is not None:
            inputs["pair_vectors"] = (pair_vectors_mm / MM) @ s.robot_palm.rotation.T
    if ftol is not None:
        inputs["ftol_abs"] = ftol
    with tempfile.TemporaryDirectory(prefix="bench-dex-") as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, **inputs)
        run = subprocess.run(
            [dex_python, str(DEX_PEER), str(src), str(dst)], capture_output=True, text=True
        )
        if run.returncode != 0:
            last = (run.stderr.strip().splitlines() or ["no output"])[-1]
            raise SystemExit(f"dex-retargeting ({dex_python}) failed: {last}")
        out = dict(np.load(dst, allow_pickle=False))
    dex_names = [str(x) for x in out["joint_names"]]
    if sorted(dex_names) != sorted(robot.joint_names):
        raise SystemExit(f"dex-retargeting's joints {dex_names} are not {robot.joint_names}")
    q = out["q"][:, [dex_names.index(n) for n in robot.joint_names]]
    # Same q, same frames: both kinematics must agree (joint order, root frame, offsets).
    gap = np.abs(robot.positions(q, frames) - out["links_reached"]).max()
    if gap > FK_TOLERANCE:
        raise SystemExit(f"dex-retargeting's kinematics disagree with fingerfit's by {gap} m")
    return q, out["seconds"], str(out["version"])


def limit_excess(s: Setup, q: np.ndarray) -> float:
    """Largest joint-limit excess (rad) of ``q (n, nq)``; 0 when within limits."""
    over = np.maximum(s.robot.lower - q, q - s.robot.upper)
    return float(max(np.max(over), 0.0))


def trajectory_metrics(s: Setup, q: np.ndarray, sec: np.ndarray, dt: float) -> dict:
    """Limits, jerk and per-frame solve time of one joint trajectory ``q (n, nq)``."""
    return {
        "violations": s.limits.violations(q),
        "limit_excess_max_rad": limit_excess(s, q),
        "jerk_rad_s3": jerk(q, dt),
        "solve_p50_ms": float(np.median(sec) * 1e3),
        "solve_p99_ms": float(np.percentile(sec, 99) * 1e3),
    }


def person_agreement(s: Setup, model, sub, rec: Recording, q: np.ndarray, cut: slice) -> float:
    """Mean over fingers of the robot tip's RMS distance (mm) from the person's true tip.

    The person's true fingertip (``sub.truth``, frames ``cut`` of ``rec``'s truth) in its
    finger's true anatomical frame, mirrored when the hands differ, against the robot
    tip (robot palm frame) after the best scale and offset per finger (the thumb, whose
    frame is not the palm's, is left out).
    """
    truth = sub.truth.frames[rec.name]
    tips = s.robot.positions(q, [s.rmap.digits[d].tip for d in s.digits])
    robot = (tips - s.robot_palm.origin) @ s.robot_palm.rotation * MM
    mirror = np.array([1.0, -1.0 if s.mirror else 1.0, 1.0])
    rms = []
    for i, d in enumerate(s.digits):
        if d not in sub.truth.fingers:
            continue
        anat = sub.truth.fingers[d]
        true = Frame(anat.centre[0], anat.frame)
        person = in_palm(model, true, rec, truth["tip"][d][cut][:, None])[:, 0]
        rms.append(scale_offset_fit(person * mirror, robot[:, i]).rms_mm)
    return float(np.mean(rms))


def _command() -> str:
    """This run's command line, the dex-retargeting python written as
    ``$FINGERFIT_DEX_PYTHON`` when it is that variable's value (no machine path)."""
    dex = os.environ.get("FINGERFIT_DEX_PYTHON")
    args = ["$FINGERFIT_DEX_PYTHON" if dex and a == dex else a for a in sys.argv]
    return " ".join(["python", *args])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--subjects", type=int, default=1)
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--out", type=Path, default=Path("bench/retarget.json"))
    ap.add_argument(
        "--dex-python",
        default=None,
        help="python of a venv with dex-retargeting and torch: compare it on the Allegro",
    )
    a = ap.parse_args()
    dex_version = None
    rows = []
    for seed in range(a.subjects):
        sub = simulate_subject(SimConfig(fingers=FINGERS), seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = fit_session(sub.session)
        rec = sub.session.grasp[0]
        n = min(a.frames, rec.n_frames)
        rec = Recording(
            rec.name,
            rec.time[:n],
            {k: PoseSeries(v.position[:n], v.rotation[:n]) for k, v in rec.poses.items()},
        )
        dt = float(np.median(np.diff(rec.time)))
        for robot_name in ("shadow", "allegro"):
            robot, rmap = resolve(robot_name, None, model.hand)
            s = setup(model, robot, rmap)
            tips = [rmap.digits[d].tip for d in s.digits]
            ref = None
            runs = []
            for method, variant in SOURCES:
                t0 = time.perf_counter()
                res = retarget(model, rec, robot, rmap, method, variant)
                wall = time.perf_counter() - t0
                if ref is None:
                    ref = res.targets  # user-axis targets: what the person did
                runs.append((method, variant, res.q, res.seconds, wall))
            if a.dex_python and robot_name == "allegro":
                for label, mode, alpha, ftol in DEX_RUNS:
                    if mode != "position":  # no thumb: nothing to pinch
                        continue
                    t0 = time.perf_counter()
                    q, sec, dex_version = run_dex(
                        a.dex_python, s, mode, alpha, tips, tips, ref, ftol=ftol
                    )
                    runs.append((label, "user_axis", q, sec, time.perf_counter() - t0))
            for method, variant, q, sec, wall in runs:
                err = np.linalg.norm(robot_points(s, q, tips) - ref, axis=2)
                r = {
                    "subject": seed,
                    "robot": robot_name,
                    "method": method,
                    "source": variant,
                    "frames": len(q),
                    "tip_err_median_mm": float(np.nanmedian(err)),
                    "tip_err_p95_mm": float(np.nanpercentile(err, 95)),
                    "tip_vs_person_rms_mm": person_agreement(s, model, sub, rec, q, slice(0, n)),
                    **trajectory_metrics(s, q, sec, dt),
                    "wall_s": wall,
                }
                rows.append(r)
                print(
                    f"| {robot_name} | {method} | {variant} | {r['tip_err_median_mm']:.2f} | "
                    f"{r['tip_err_p95_mm']:.1f} | {r['tip_vs_person_rms_mm']:.2f} | "
                    f"{r['violations']} | {r['jerk_rad_s3']:.0f} | "
                    f"{r['solve_p50_ms']:.3f} | {r['solve_p99_ms']:.2f} |",
                    flush=True,
                )
    # Whole hand (thumb + four fingers, pad points): the pinch recording.
    print(
        "| robot | method | source | pinch distance median mm | p95 mm | max mm | touch frames | "
        "tip error median mm | tip vs person RMS mm | violations | jerk rad/s^3 | solve p50 ms | p99 ms |"
    )
    pinch_rows = []
    for seed in range(a.subjects):
        sub = simulate_subject(SimConfig(fingers=("thumb", *FINGERS)), seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = fit_session(sub.session)
        rec = sub.session.recording("pinch.csv")
        dt = float(np.median(np.diff(rec.time)))
        for robot_name in ("shadow", "allegro"):
            robot, rmap = resolve(robot_name, None, model.hand)
            s = setup(model, robot, rmap)
            tips = [rmap.digits[d].tip for d in s.digits]
            kin = compute_kinematics(model, rec)
            pads = person_points(s, model, kin, rec, "user_axis", "pad")
            pairs, _, _, dist = pinch_terms(s, pads)
            touch = np.zeros(dist.shape, dtype=bool)  # the person's pads touch (frame, pair)
            for e in sub.session.events:
                if e.recording == rec.name and e.is_pinch:
                    for i, pair in enumerate(pairs):
                        if {e.finger, e.target} == set(pair):
                            touch[(rec.time >= e.start) & (rec.time <= e.end), i] = True
            pad_frames = [rmap.digits[d].pad for d in s.digits]
            pad_ref = targets(s, np.stack([pads[d] for d in s.digits], axis=1), s.digits)
            ref = None
            runs = []
            for method, variant in SOURCES:
                res = retarget(model, rec, robot, rmap, method, variant, kin=kin)
                ref = res.targets if ref is None else ref
                runs.append((method, variant, res.q, res.seconds))
            if a.dex_python and robot_name == "allegro":
                # DexPilot: the thumb first; its finger points are the map's pad points
                # (those the pinch is measured on). Wrist-to-finger: the pad targets scaled
                # per digit like the tips. Finger-to-finger: the person's pad-to-pad
                # vector, mirrored and scaled by the pair's mean scale (the pinch term's
                # vector before --contact-mm): per-digit scaling about different bases
                # puts touching pads' targets ~50 mm apart, which never pinches.
                order = ["thumb", *(d for d in s.digits if d != "thumb")]
                pp = np.stack([pads[d] for d in order], axis=1)
                pad_targets = targets(s, pp, order)
                mirror = np.array([1.0, -1.0 if s.mirror else 1.0, 1.0])
                k = np.array([s.scale[d] for d in order])
                pair_vec = (
                    0.5
                    * (k[:, None] + k[None, :])[None, :, :, None]
                    * (pp[:, :, None, :] - pp[:, None, :, :])
                    * mirror
                )
                # The tip method's vector where the pinch term does not shorten it (pads
                # PINCH_FAR_MM apart and more).
                _, vec0, _, _ = pinch_terms(s, pads, 0.0)
                for i, (x, y) in enumerate(pairs):
                    far = dist[:, i] >= PINCH_FAR_MM
                    ours = pair_vec[far, order.index(x), order.index(y)]
                    if not far.any() or not np.allclose(vec0[far, i], ours):
                        raise SystemExit(f"DexPilot's {x}-{y} vector is not the pinch term's")
                for label, mode, alpha, ftol in DEX_RUNS:
                    if mode == "position":
                        frames, parents, pts = tips, tips, ref
                    else:
                        frames = [rmap.digits[d].pad for d in order]
                        parents = [rmap.digits[d].tip for d in order]
                        pts = pad_targets
                    q, sec, dex_version = run_dex(
                        a.dex_python, s, mode, alpha, frames, parents, pts, pair_vec, ftol
                    )
                    runs.append((label, "user_axis", q, sec))
            for method, variant, q, sec in runs:
                pa = robot.positions(q, [rmap.digits[x].pad for x, _ in pairs])
                pb = robot.positions(q, [rmap.digits[y].pad for _, y in pairs])
                rd = np.linalg.norm(pa - pb, axis=2) * 1000.0
                err = np.linalg.norm(robot_points(s, q, tips) - ref, axis=2)
                pad_err = np.linalg.norm(robot_points(s, q, pad_frames) - pad_ref, axis=2)
                r = {
                    "subject": seed,
                    "robot": robot_name,
                    "method": method,
                    "source": variant,
                    "touch_frames": int(touch.sum()),
                    "tip_err_median_mm_by_digit": dict(
                        zip(s.digits, np.nanmedian(err, axis=0).tolist(), strict=True)
                    ),
                    "pad_err_median_mm": float(np.nanmedian(pad_err)),
                    "pinch_median_mm": float(np.median(rd[touch])),
                    "pinch_p95_mm": float(np.percentile(rd[touch], 95)),
                    "pinch_max_mm": float(np.max(rd[touch])),
                    "tip_err_median_mm": float(np.nanmedian(err)),
                    "tip_err_p95_mm": float(np.nanpercentile(err, 95)),
                    "tip_vs_person_rms_mm": person_agreement(s, model, sub, rec, q, slice(None)),
                    **trajectory_metrics(s, q, sec, dt),
                }
                pinch_rows.append(r)
                print(
                    f"| {robot_name} | {method} | {variant} | {r['pinch_median_mm']:.1f} | "
                    f"{r['pinch_p95_mm']:.1f} | {r['pinch_max_mm']:.1f} | {r['touch_frames']} | "
                    f"{r['tip_err_median_mm']:.2f} | {r['tip_vs_person_rms_mm']:.2f} | "
                    f"{r['violations']} | "
                    f"{r['jerk_rad_s3']:.0f} | {r['solve_p50_ms']:.3f} | "
                    f"{r['solve_p99_ms']:.2f} |",
                    flush=True,
                )
    a.out.write_text(
        json.dumps(
            {
                "command": _command(),
                "python": platform.python_version(),
                "dex_retargeting": dex_version,
                "rows": rows,
                "pinch_rows": pinch_rows,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
