"""Fingertip errors of the model variants (paper Figs. 9-12).

* **Reference fingertip**: the distal sensor pose carrying the stylus-measured
  tip vector ``tip_local = R_d0^T (tip - t_d0)`` fixed in that sensor's frame.
* **Maximal flexion** (Fig. 10): in each grasp cycle, the frame where the sum
  of the joint angles peaks; error = distance of each model's fingertip to the
  reference fingertip there.
* **Targets** (Figs. 11-12): during each touch event, the mean fingertip of
  the reference and of each model; error = distance to the stylus-measured
  target.

Lengths mm, tracker coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..kinematics import Kinematics, compute_kinematics
from ..model import VARIANTS, HandModel
from ..session import Recording, Session, true_runs
from ..transforms import FloatArray, apply_pose

SOURCES = ("reference", *VARIANTS)


def reference_tip(model: HandModel, finger: str, recording: Recording) -> FloatArray:
    """Fingertip from the distal sensor and the stylus tip vector, ``(n_frames, 3)`` mm."""
    distal = model.fingers[finger].joints["dip"].child
    p0, r0 = model.reference_poses[distal]
    local = r0.T @ (model.fingers[finger].tip - p0)
    pose = recording.pose(distal)
    return apply_pose(pose.rotation, pose.position, local)


@dataclass(frozen=True)
class GraspEvaluation:
    """Fingertip trajectories and errors of one grasp recording for one finger.

    Attributes
    ----------
    time : ndarray, shape (n,)
    tips : dict[str, ndarray]
        ``reference``, ``user_axis``, ``orthogonal`` -> ``(n, 3)`` mm.
    max_flexion_frames : ndarray, shape (n_cycles,)
    errors : DataFrame
        One row per cycle: ``cycle``, ``user_axis``, ``orthogonal`` (mm).
    kinematics : Kinematics
    """

    time: FloatArray
    tips: dict[str, FloatArray]
    max_flexion_frames: np.ndarray
    errors: pd.DataFrame
    kinematics: Kinematics


def max_flexion_frames(total_flexion: FloatArray, rate_hz: float) -> np.ndarray:
    """Frame of peak summed flexion in each excursion above half its range, ``(n_cycles,)``."""
    f = np.nan_to_num(total_flexion, nan=-np.inf)
    lo, hi = np.nanpercentile(total_flexion, [5, 95])
    runs = true_runs(f > lo + 0.5 * (hi - lo))
    runs = runs[(runs[:, 1] - runs[:, 0]) > 0.1 * rate_hz]  # ignore sub-0.1 s blips
    return np.array([a + int(np.argmax(f[a:b])) for a, b in runs], dtype=int)


def evaluate_grasp(
    model: HandModel, finger: str, recording: Recording, rate_hz: float
) -> GraspEvaluation:
    """Fig. 9 trajectories and Fig. 10 errors at maximal flexion for one grasp recording."""
    kin = compute_kinematics(model, recording, fingers=[finger])
    tips = {"reference": reference_tip(model, finger, recording)}
    tips |= {v: kin.motions[v][finger].tip for v in VARIANTS}
    angles = kin.motions["user_axis"][finger].angles
    total = angles["mp"] + angles["pip"] + angles["dip"]  # flexion only, not ab/adduction
    frames = max_flexion_frames(total, rate_hz)
    errors = pd.DataFrame({"cycle": np.arange(1, frames.size + 1)})
    for v in VARIANTS:
        errors[v] = np.linalg.norm(tips[v][frames] - tips["reference"][frames], axis=1)
    return GraspEvaluation(recording.time, tips, frames, errors, kin)


def evaluate_targets(model: HandModel, session: Session) -> pd.DataFrame:
    """Target-reaching errors (Figs. 11-12).

    Returns
    -------
    DataFrame
        One row per touch event and source: ``finger``, ``target``, ``source``
        (``reference``/``user_axis``/``orthogonal``), ``error_mm``, and the
        offset ``dx, dy, dz`` of the mean fingertip from the target (mm).
    """
    rows = []
    cache: dict[tuple[str, str], dict[str, FloatArray]] = {}
    for ev in session.events:
        if ev.finger not in model.fingers:
            continue
        rec = session.recording(ev.recording)
        key = (ev.recording, ev.finger)
        if key not in cache:
            kin = compute_kinematics(model, rec, fingers=[ev.finger])
            cache[key] = {"reference": reference_tip(model, ev.finger, rec)} | {
                v: kin.motions[v][ev.finger].tip for v in VARIANTS
            }
        k = (rec.time >= ev.start) & (rec.time <= ev.end)
        target = session.landmark(f"target.{ev.target}")
        for src, tip in cache[key].items():
            mean = np.nanmean(tip[k], axis=0)
            d = mean - target
            rows.append((ev.finger, ev.target, src, float(np.linalg.norm(d)), *d))
    return pd.DataFrame(rows, columns=["finger", "target", "source", "error_mm", "dx", "dy", "dz"])
