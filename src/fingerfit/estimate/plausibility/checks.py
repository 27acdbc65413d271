"""The entry points of the plausibility checks: a session before fitting
(:func:`check_session`) and a recording against a model (:func:`check_recording`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...session import Recording, Session
from ...transforms import FloatArray, relative_pose
from .bounds import CONVENTION_RATIO, RECORDING_RESIDUAL_MM, UNIT_NAMES
from .convention import (
    CONVENTIONS,
    _alternatives,
    _pooled_rms,
    _valid,
    convention_checks,
    convention_problems,
)
from .problems import Problem, _ratio_units
from .units import check_landmarks, check_recording_units

if TYPE_CHECKING:
    from ...model import HandModel
    from ...track import Tracked


def check_session(
    session: Session,
    fingers: Sequence[str],
    reference: dict[str, tuple[FloatArray, FloatArray]],
) -> list[Problem]:
    """Every plausibility check of a session before fitting, most basic first.

    Units of every recording (neighbouring sensors), then landmarks against the sensors
    and the bounds, then the quaternion convention (pivot residuals over the grasp
    recordings). Later groups are skipped once one finds a problem: a unit mistake
    upsets everything after it, and the first cause is the one worth naming.

    Parameters
    ----------
    session : Session
    fingers : sequence of str
        The fingers to fit.
    reference : dict
        Sensor -> mean reference pose ``(position (3,) mm, rotation (3, 3))``.
    """
    base = session.path
    groups: list[Callable[[], list[Problem]]] = [
        lambda: [
            p
            for r in session.recordings()
            for p in check_recording_units(
                r, session.units, fingers, None if base is None else base / r.name
            )
        ],
        lambda: check_landmarks(session, fingers, reference),
        lambda: convention_problems(
            convention_checks(session, fingers),
            None if base is None or not session.grasp else base / session.grasp[0].name,
        ),
    ]
    for group in groups:
        problems = group()
        if problems:
            return problems
    return []


@dataclass(frozen=True)
class RecordingCheck:
    """One joint of a recording compared with a model (``fingerfit angles``).

    Attributes
    ----------
    finger, joint : str
    scale : float
        Factor on the recording's positions that best fits the model's centre
        (1 = same units).
    residual_mm : dict[str, float]
        RMS of ``R c_c + t - c_p`` (mm) with the model's centre, per reading of the
        quaternions (:data:`CONVENTIONS`).
    model_distance_mm : float
        Distance of the child sensor origin from the joint centre in the model.
    """

    finger: str
    joint: str
    scale: float
    residual_mm: dict[str, float]
    model_distance_mm: float


def recording_checks(model: HandModel, recording: Recording) -> list[RecordingCheck]:
    """Compare each joint's sensors in ``recording`` with the model's joint centre.

    For a joint with centre ``c_p`` (parent frame) and ``c_c`` (child frame), every frame
    must satisfy ``R c_c + t = c_p`` with the relative pose ``(R, t)``. The scale
    ``s = sum t . (c_p - R c_c) / sum |t|^2`` fits it with the positions scaled.
    """
    out = []
    for f, fm in model.fingers.items():
        for j, jm in fm.joints.items():
            if jm.parent not in recording.poses or jm.child not in recording.poses:
                continue
            if jm.parent not in model.reference_poses or jm.child not in model.reference_poses:
                continue
            p, c = recording.poses[jm.parent], recording.poses[jm.child]
            ok = np.flatnonzero(_valid(p) & _valid(c))
            if ok.size > 600:
                ok = ok[np.linspace(0, ok.size - 1, 600).astype(int)]
            if ok.size < 2:
                continue
            pp, pr = model.reference_poses[jm.parent]
            cp_, cr = model.reference_poses[jm.child]
            c_p, c_c = pr.T @ (jm.center - pp), cr.T @ (jm.center - cp_)
            pa, ca = _alternatives(p.rotation[ok]), _alternatives(c.rotation[ok])
            res, scale = {}, math.nan
            for k in CONVENTIONS:
                r, t = relative_pose(pa[k], p.position[ok], ca[k], c.position[ok])
                target = c_p - r @ c_c
                if k == "as read":
                    den = float(np.sum(t * t))
                    scale = float(np.sum(t * target) / den) if den > 0 else math.nan
                res[k] = float(np.sqrt(np.mean(np.sum((t - target) ** 2, axis=1))))
            out.append(RecordingCheck(f, j, scale, res, float(np.linalg.norm(c_c))))
    return out


def check_tracking(tracked: Tracked, path: Path | None = None) -> list[Problem]:
    """Problems of the frames a model solved (``fingerfit angles`` with missing sensors).

    A layout without two sensors on one joint (the hand and each distal sensor) leaves the
    pivot check of :func:`check_recording` nothing to compare; the residual of the model's
    solution takes its place: sensors in the wrong units, with quaternions in another
    order, or of another subject do not fit the model at any angles.

    Parameters
    ----------
    tracked : fingerfit.track.Tracked
    path : Path, optional
        The recording, for the message.

    Returns
    -------
    list of Problem
        One for the digit whose median residual (mm, RMS over the frame's sensors) over the
        frames it was solved in exceeds :data:`RECORDING_RESIDUAL_MM` the most.
    """
    worst = None
    for d, t in tracked.digits.items():
        rms = t.rms_mm[t.model]
        rms = rms[np.isfinite(rms)]
        if rms.size and (median := float(np.median(rms))) > RECORDING_RESIDUAL_MM:
            if worst is None or median > worst[1]:
                worst = (d, median)
    if worst is None:
        return []
    return [
        Problem(
            f"{worst[0]}: the sensors do not fit the model where it solved the frames "
            f"(median residual {worst[1]:.1f} mm, expected < {RECORDING_RESIDUAL_MM:g} mm): "
            "wrong --units or quaternion order, or another subject's recording?",
            path=path,
        )
    ]


def check_recording(
    model: HandModel, recording: Recording, units: str, path: Path | None = None
) -> list[Problem]:
    """Problems of a recording against a model (units, quaternion convention, identity).

    Parameters
    ----------
    model : HandModel
    recording : Recording
        Positions mm, read in ``units``.
    units : str
        The units the recording was read in (for the cause).
    path : Path, optional
        The recording file, for messages.
    """
    checks = recording_checks(model, recording)
    bad = [c for c in checks if c.residual_mm["as read"] > RECORDING_RESIDUAL_MM]
    if not bad:
        return []
    worst = max(bad, key=lambda c: c.residual_mm["as read"])
    scale = float(np.median([c.scale for c in checks]))
    head = (
        f"{worst.finger} {worst.joint}: the child sensor does not keep its distance from the "
        f"model's joint centre (pivot residual {worst.residual_mm['as read']:.1f} mm, expected "
        f"< {RECORDING_RESIDUAL_MM:g} mm; scale that fits {scale:.3g})"
    )
    pairs = [(a, b) for a, b in _ratio_units(scale) if b == units] if scale > 0 else []
    if pairs and abs(math.log(scale)) > math.log(2.0):
        cause = (
            f"the recording looks like {UNIT_NAMES[pairs[0][0]]} read as {UNIT_NAMES[units]} "
            "(--units)"
        )
    else:
        alt = min((k for k in CONVENTIONS if k != "as read"), key=lambda k: _pooled_rms(checks, k))
        if _pooled_rms(checks, alt) < CONVENTION_RATIO * _pooled_rms(checks, "as read"):
            cause = (
                f"quaternions look {CONVENTIONS[alt]}, not w,x,y,z (residual "
                f"{worst.residual_mm[alt]:.1f} mm read that way)"
            )
        else:
            cause = "is it this subject's recording with the sensors mounted as for the model?"
    return [Problem(f"{head}: {cause}", path=path)]
