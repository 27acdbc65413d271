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

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..kinematics import Kinematics, compute_kinematics
from ..model import VARIANTS, HandModel
from ..session import Recording, Session, true_runs
from ..transforms import FloatArray, apply_pose

SOURCES = ("reference", *VARIANTS)


def _distal_sensor(model: HandModel, digit: str) -> str:
    """The sensor on a digit's distal segment (child of its last flexion joint)."""
    return list(model.fingers[digit].joints.values())[-1].child


def sensor_carried(
    model: HandModel, digit: str, recording: Recording, point: FloatArray
) -> FloatArray:
    """A point ``(3,)`` (mm, tracker frame at the reference posture) carried by the digit's
    distal sensor through a recording, ``(n_frames, 3)`` mm (tracker frame)."""
    distal = _distal_sensor(model, digit)
    p0, r0 = model.reference_poses[distal]
    pose = recording.pose(distal)
    return apply_pose(pose.rotation, pose.position, r0.T @ (np.asarray(point) - p0))


def reference_tip(model: HandModel, finger: str, recording: Recording) -> FloatArray:
    """Tip from the distal sensor and the stylus tip vector, ``(n_frames, 3)`` mm.

    Any digit: the distal sensor is the child of the digit's last flexion joint
    (``dip`` of a finger, ``ip`` of the thumb).
    """
    distal = _distal_sensor(model, finger)
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
    # Flexion only, not ab/adduction: mp + pip + dip (the thumb: cmc + mcp + ip).
    first, *rest = model.fingers[finger].joints
    total = angles[first]
    for j in rest:
        total = total + angles[j]
    frames = max_flexion_frames(total, rate_hz)
    errors = pd.DataFrame({"cycle": np.arange(1, frames.size + 1)})
    for v in VARIANTS:
        errors[v] = np.linalg.norm(tips[v][frames] - tips["reference"][frames], axis=1)
    return GraspEvaluation(recording.time, tips, frames, errors, kin)


def skipped_events(model: HandModel, session: Session) -> list[dict]:
    """The touch events (targets and pinches) that cannot be evaluated, with the reason.

    An event cannot be evaluated when the model lacks its digit (or, for a pinch, the
    digit touched). Every other event is evaluated: a target touch by
    :func:`evaluate_targets`, a pinch by :func:`fingerfit.evaluate.pinch.evaluate_pinches`.

    Returns
    -------
    list of dict
        ``recording``, ``finger``, ``target``, ``start``, ``end`` (s), ``kind``
        (``"target"`` for a target touch, ``"pinch"``; :func:`count_skipped` counts them)
        and ``reason``.
    """
    out = []
    for ev in session.events:
        missing = [d for d in (ev.finger, ev.target if ev.is_pinch else None) if d]
        missing = [d for d in missing if d not in model.fingers]
        if missing:
            kind = "pinch" if ev.is_pinch else "target touch"
            out.append(
                {
                    "recording": ev.recording,
                    "finger": ev.finger,
                    "target": ev.target,
                    "start": float(ev.start),
                    "end": float(ev.end),
                    "kind": "pinch" if ev.is_pinch else "target",
                    "reason": f"{kind} {ev.finger} -> {ev.target} in {ev.recording} at "
                    f"{ev.start:g}-{ev.end:g} s not evaluated: the model has no digit "
                    f"'{missing[0]}'",
                }
            )
    return out


def count_skipped(skipped: Iterable[dict]) -> dict[str, int]:
    """How many events of each kind were not evaluated.

    Parameters
    ----------
    skipped : iterable of dict
        Events as :func:`skipped_events` lists them (of one session or several).

    Returns
    -------
    dict of str to int
        ``target_touches`` and ``pinches``: the number of each.
    """
    kinds = [e["kind"] for e in skipped]
    return {"target_touches": kinds.count("target"), "pinches": kinds.count("pinch")}


def evaluate_targets(model: HandModel, session: Session) -> pd.DataFrame:
    """Target-reaching errors (Figs. 11-12).

    Pinch events (``target`` a digit) are not target touches: see
    :func:`fingerfit.evaluate.pinch.evaluate_pinches`. Touches by a digit the model
    lacks are not evaluated: :func:`skipped_events` lists them with the reason,
    :func:`count_skipped` counts them, and the study reports the count
    (``summary.json → events_not_evaluated``, the report, ``fingerfit study``).

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
        if ev.is_pinch or ev.finger not in model.fingers:
            continue  # a pinch: evaluate_pinches; a missing digit: skipped_events
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
