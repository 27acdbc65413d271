"""Plausibility of the quaternion convention: the pivot residual of each joint under each
reading of the stored rotations (:data:`CONVENTIONS`) and with one axis negated
(:data:`MIRRORS`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...session import PoseSeries, Recording, Session, joint_sensors
from ...transforms import FloatArray, matrix_from_quat_wxyz, quat_wxyz_from_matrix, relative_pose
from ..centre import centre_of_rotation
from .bounds import CONVENTION_RATIO, PIVOT_FLOOR_MM, PIVOT_MIN_MM, PIVOT_NOISE_FACTOR
from .problems import Problem

#: Alternative readings of the stored rotations: what the data would be if the file's
#: quaternions had been written in another convention (``(w, x, y, z)`` arrays).
CONVENTIONS: dict[str, str] = {
    "as read": "w,x,y,z (as declared)",
    "conjugated": "conjugated (transposed rotations)",
    "xyzw": "written in x,y,z,w order",
    "xyzw conjugated": "written in x,y,z,w order and conjugated",
}


def _alternatives(rotation: FloatArray) -> dict[str, FloatArray]:
    """Rotations ``(n, 3, 3)`` under each reading of :data:`CONVENTIONS`.

    A file written ``x,y,z,w`` but read as ``w,x,y,z`` gives ``q_read = (x, y, z, w)``;
    the true quaternion is ``(q_read[3], q_read[0], q_read[1], q_read[2])``.
    """
    swapped = matrix_from_quat_wxyz(np.roll(quat_wxyz_from_matrix(rotation), 1, axis=1))
    return {
        "as read": rotation,
        "conjugated": np.swapaxes(rotation, 1, 2),
        "xyzw": swapped,
        "xyzw conjugated": np.swapaxes(swapped, 1, 2),
    }


@dataclass(frozen=True)
class PivotCheck:
    """Pivot residuals of one joint under each reading of the quaternions.

    Attributes
    ----------
    finger, joint : str
    residual_mm : dict[str, float]
        RMS pivot residual (mm) per key of :data:`CONVENTIONS`.
    noise_mm : float
        Static RMS scatter (mm, 3-D) of the child origin in the parent frame over the
        reference recording (NaN without one).
    frames : int
        Frames used.
    """

    finger: str
    joint: str
    residual_mm: dict[str, float]
    noise_mm: float
    frames: int

    @property
    def threshold_mm(self) -> float:
        """Largest plausible as-read residual (mm): ``max(floor, factor x noise)``."""
        noise = self.noise_mm if math.isfinite(self.noise_mm) else 0.0
        return max(PIVOT_FLOOR_MM, PIVOT_NOISE_FACTOR * noise)


#: Mirrored readings of the positions (a left-handed tracker frame): the position axis
#: negated, by key of :func:`pivot_residuals`' result.
MIRRORS: dict[str, int] = {"x negated": 0, "y negated": 1, "z negated": 2}


def pivot_residuals(
    parent: PoseSeries, child: PoseSeries, max_frames: int = 400, *, mirrored: bool = False
) -> tuple[dict[str, float], int]:
    """RMS pivot residual (mm) of two sensors under each quaternion reading.

    Parameters
    ----------
    parent, child : PoseSeries
        The same frames of both sensors (mm, tracker coordinates).
    max_frames : int
        Evenly subsample longer recordings to this many frames (cost).
    mirrored : bool
        Also evaluate the as-read rotations with one position axis negated (keys of
        :data:`MIRRORS`): positions in a left-handed frame agree with right-handed
        rotations again once the mirrored axis is negated.

    Returns
    -------
    residual_mm : dict[str, float]
        Per key of :data:`CONVENTIONS` (and of :data:`MIRRORS` with ``mirrored``).
    frames : int
        Frames used (both sensors valid).
    """
    ok = np.flatnonzero(_valid(parent) & _valid(child))
    if ok.size > max_frames:
        ok = ok[np.linspace(0, ok.size - 1, max_frames).astype(int)]
    if ok.size < 10:
        return {}, int(ok.size)
    pr, cr = parent.rotation[ok], child.rotation[ok]
    pp, cp = parent.position[ok], child.position[ok]
    pa, ca = _alternatives(pr), _alternatives(cr)
    readings = [(k, pa[k], ca[k], np.ones(3)) for k in CONVENTIONS]
    if mirrored:
        readings += [
            (k, pr, cr, np.where(np.arange(3) == i, -1.0, 1.0)) for k, i in MIRRORS.items()
        ]
    out = {}
    for k, rp, rc, flip in readings:
        r, t = relative_pose(rp, pp * flip, rc, cp * flip)
        out[k] = centre_of_rotation(r, t).rms_mm
    return out, int(ok.size)


def _valid(series: PoseSeries) -> np.ndarray:
    """Frames ``(n,)`` with a sample (readers blank a whole pose when any field is missing)."""
    return np.isfinite(series.position[:, 0]) & np.isfinite(series.rotation[:, 0, 0])


def _concat(recordings: Sequence[Recording], sensor: str, step: int = 1) -> PoseSeries | None:
    if not all(sensor in r.poses for r in recordings):
        return None
    return PoseSeries(
        np.concatenate([r.poses[sensor].position[::step] for r in recordings]),
        np.concatenate([r.poses[sensor].rotation[::step] for r in recordings]),
    )


def convention_checks(session: Session, fingers: Sequence[str]) -> list[PivotCheck]:
    """:class:`PivotCheck` of every joint of ``fingers`` over the grasp recordings."""
    checks = []
    for f in fingers:
        for j, (p, c) in joint_sensors(f).items():
            step = max(1, sum(r.n_frames for r in session.grasp) // 2400)
            ps, cs = _concat(session.grasp, p, step), _concat(session.grasp, c, step)
            if ps is None or cs is None:
                continue
            res, n = pivot_residuals(ps, cs)
            if not res:
                continue
            noise = math.nan
            ref = session.reference.poses
            if p in ref and c in ref:
                ok = ref[p].valid & ref[c].valid
                if ok.sum() > 2:
                    _, t = relative_pose(
                        ref[p].rotation[ok], ref[p].position[ok],
                        ref[c].rotation[ok], ref[c].position[ok],
                    )  # fmt: skip
                    noise = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))
            checks.append(PivotCheck(f, j, res, noise, n))
    return checks


def _pooled_rms(checks: Sequence[PivotCheck], reading: str) -> float:
    """RMS over joints of the pivot residual under one reading of the quaternions (mm)."""
    return float(np.sqrt(np.mean([c.residual_mm[reading] ** 2 for c in checks])))


def convention_problems(checks: Sequence[PivotCheck], path: Path | None = None) -> list[Problem]:
    """Refusals from :func:`convention_checks`.

    First the pooled comparison: when another reading of the quaternions gives a pooled
    RMS residual below ``CONVENTION_RATIO`` x the as-read one, the joint with the largest
    as-read residual is named with that reading. Then every joint whose as-read residual
    exceeds its :attr:`PivotCheck.threshold_mm`.
    """
    if not checks:
        return []

    def pooled(k: str) -> float:
        return _pooled_rms(checks, k)

    read = pooled("as read")
    alt = min((k for k in CONVENTIONS if k != "as read"), key=pooled)
    worst = max(checks, key=lambda c: c.residual_mm["as read"])
    head = (
        f"{worst.finger} {worst.joint}: the sensors do not agree on a joint centre (pivot "
        f"residual {worst.residual_mm['as read']:.1f} mm, expected < {worst.threshold_mm:.3g} mm)"
    )
    if read > PIVOT_MIN_MM and pooled(alt) < CONVENTION_RATIO * read:
        return [
            Problem(
                f"{head}: quaternions look {CONVENTIONS[alt]}, not w,x,y,z (pivot residual "
                f"{worst.residual_mm[alt]:.1f} mm read that way; all joints {read:.1f} -> "
                f"{pooled(alt):.1f} mm RMS)",
                path=path,
            )
        ]
    problems = []
    for c in checks:
        r = c.residual_mm["as read"]
        if r > c.threshold_mm:
            problems.append(
                Problem(
                    f"{c.finger} {c.joint}: the sensors do not agree on a joint centre (pivot "
                    f"residual {r:.1f} mm, expected < {c.threshold_mm:.3g} mm): quaternions may "
                    "be in x,y,z,w order or conjugated, a sensor may have slipped, or the "
                    "sensor names may be swapped",
                    path=path,
                )
            )
    return problems
