"""The input of a joint fit and the refusals before any joint is fitted.

:func:`_motion` normalises the poses (transforms or positions + quaternions, any unit) into
relative poses in mm; :class:`_Work` computes once what the steps share (reference frame,
range of motion, cycles, the SARA/SCoRE fit over every frame); the ``_check_*`` functions
refuse too little motion, a wrong quaternion convention or handedness, implausible units
and segments without a common centre of rotation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..session import UNITS_TO_MM, PoseSeries
from ..transforms import (
    FloatArray,
    matrix_from_quat_wxyz,
    relative_pose,
    rotation_angle,
)
from .cycles import extract_cycles
from .joint_estimators import HingeEstimate, estimate_hinge
from .plausibility import (
    CONVENTION_RATIO,
    CONVENTIONS,
    MIRRORS,
    PIVOT_MIN_MM,
    joint_reach_problems,
    pivot_residuals,
)

#: The child must turn at least this much relative to the parent (deg, the 99th
#: percentile angle between its orientations) for any joint to be found.
MIN_ROM_DEG = 10.0
#: Below :data:`MIN_ROM_DEG`, a child origin moving more than this (mm, 99th percentile
#: distance from its median position in the parent frame) is called pure translation.
TRANSLATION_MM = 5.0
#: The segments share no fixed centre of rotation when the RMS pivot residual (mm) of the
#: as-read poses exceeds this. Measured: a real mechanical hinge 1.2 mm clean and 2-3 mm on
#: one fast swing (issue 16); hand-held Liberty rotations 4.1-8.6 mm (``docs/joint.md``);
#: a swapped quaternion order on the real hinge ~70 mm.
MAX_PIVOT_MM = 20.0
MIN_FRAMES = 10


@dataclass(frozen=True)
class _Motion:
    """Normalised input: absolute and relative poses of the valid frames (mm)."""

    parent: PoseSeries
    child: PoseSeries
    rotation: FloatArray  # (n, 3, 3) child in parent
    translation: FloatArray  # (n, 3) mm, child origin in parent
    frames: np.ndarray
    dropped: int
    scale: float  # mm per caller unit
    units: str
    rate_hz: float | None


def _poses(value: object, name: str) -> tuple[FloatArray, FloatArray]:
    """``(positions (n, 3), rotations (n, 3, 3))`` from transforms or positions + quaternions."""
    if isinstance(value, tuple | list) and len(value) == 2:
        pos = np.asarray(value[0], dtype=float)
        quat = np.asarray(value[1], dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 3 or quat.shape != (pos.shape[0], 4):
            raise FingerfitError(
                f"positions must be (n, 3) and quaternions (n, 4) w,x,y,z; got {pos.shape} "
                f"and {quat.shape}",
                field=name,
            )
        norm = np.linalg.norm(quat, axis=1)
        ok = np.isfinite(norm)
        if ok.any() and (np.abs(norm[ok] - 1.0) > 0.1).any():
            lo, hi = float(norm[ok].min()), float(norm[ok].max())
            raise FingerfitError(
                f"quaternion norms range {lo:.3g}-{hi:.3g}: not unit quaternions (are the "
                "columns right?)",
                field=name,
            )
        return pos, matrix_from_quat_wxyz(quat)
    t = np.asarray(value, dtype=float)
    if t.ndim != 3 or t.shape[1:] != (4, 4):
        raise FingerfitError(
            f"give (n, 4, 4) transforms or (positions (n, 3), quaternions (n, 4)); got an "
            f"array of shape {t.shape}",
            field=name,
        )
    ok = np.isfinite(t).all(axis=(1, 2))
    if ok.any():
        bottom = t[ok, 3, :]
        if np.abs(bottom - [0.0, 0.0, 0.0, 1.0]).max() > 1e-6:
            raise FingerfitError(
                "the last row of the transforms is not (0, 0, 0, 1): transposed matrices?",
                field=name,
            )
        r = t[ok, :3, :3]
        err = np.abs(np.swapaxes(r, 1, 2) @ r - np.eye(3)).max()
        if err > 1e-3:
            raise FingerfitError(
                f"the 3 x 3 blocks are not rotations (R^T R differs from I by {err:.3g}): "
                "scaled or sheared transforms?",
                field=name,
            )
        det = np.linalg.det(r)
        if (det < 0).any():
            raise FingerfitError(
                f"{int((det < 0).sum())} transform(s) have determinant -1: a left-handed "
                "(mirrored) frame, not a rotation; check the handedness of the axes",
                field=name,
            )
    return t[:, :3, 3], t[:, :3, :3]


def _motion(parent: object, child: object, units: str, rate_hz: float | None) -> _Motion:
    if units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="units")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise FingerfitError(f"must be a positive number of Hz, not {rate_hz}", field="rate_hz")
    pp, pr = _poses(parent, "parent")
    cp, cr = _poses(child, "child")
    if pp.shape[0] != cp.shape[0]:
        raise FingerfitError(
            f"parent has {pp.shape[0]} frames and child {cp.shape[0]}: give the same frames",
            field="child",
        )
    ok = (
        np.isfinite(pp).all(axis=1)
        & np.isfinite(pr).all(axis=(1, 2))
        & np.isfinite(cp).all(axis=1)
        & np.isfinite(cr).all(axis=(1, 2))
    )
    frames = np.flatnonzero(ok)
    if frames.size < MIN_FRAMES:
        raise FingerfitError(
            f"only {frames.size} frame(s) with both poses finite (need {MIN_FRAMES})",
            field="child",
        )
    scale = UNITS_TO_MM[units]
    ps = PoseSeries(pp[frames] * scale, pr[frames])
    cs = PoseSeries(cp[frames] * scale, cr[frames])
    r, t = relative_pose(ps.rotation, ps.position, cs.rotation, cs.position)
    return _Motion(ps, cs, r, t, frames, int(pp.shape[0] - frames.size), scale, units, rate_hz)


def _reference(rotation: FloatArray) -> int:
    """Index of the frame nearest the chordal mean orientation."""
    mean = Rotation.from_matrix(rotation).mean().as_matrix()
    return int(np.argmin(rotation_angle(rotation @ mean.T)))


def _extreme(rotation: FloatArray, ref: int | None = None) -> int:
    """Index of a frame at one end of the motion: at the 99th percentile angle from the
    mean (from frame ``ref``, :func:`_reference` unless given)."""
    r0 = rotation[_reference(rotation) if ref is None else ref]
    d = rotation_angle(rotation @ r0.T)
    return int(np.argmin(np.abs(d - np.percentile(d, 99))))


def _rom(rotation: FloatArray, far: int) -> float:
    """99th percentile angle (deg) from frame ``far`` to all the others."""
    d = rotation_angle(rotation @ rotation[far].T)
    return float(np.degrees(np.percentile(d, 99)))


def range_of_motion_deg(rotation: FloatArray) -> float:
    """Approximate range of motion (deg) of relative rotations ``(n, 3, 3)``.

    The 99th percentile angle from the orientation furthest from the mean (by the same
    percentile) to all the others: the diameter of the set of orientations, robust to a
    few glitches.
    """
    return _rom(rotation, _extreme(rotation))


class _Work:
    """What one :func:`fit_joint` call computes at most once and its steps share."""

    def __init__(self, m: _Motion) -> None:
        self.m = m

    @cached_property
    def ref(self) -> int:
        """Reference frame (angles zero): nearest the mean orientation."""
        return _reference(self.m.rotation)

    @cached_property
    def extreme(self) -> int:
        """A frame at one end of the motion (:func:`_extreme`)."""
        return _extreme(self.m.rotation, self.ref)

    @cached_property
    def rom(self) -> float:
        """Range of motion (deg, :func:`range_of_motion_deg`)."""
        return _rom(self.m.rotation, self.extreme)

    @cached_property
    def periods(self) -> list[np.ndarray]:
        """Movement cycles (:func:`.cycles.extract_cycles`), angles measured from one end
        of the motion; none without ``rate_hz``."""
        m = self.m
        if m.rate_hz is None:
            return []
        return extract_cycles(m.rotation, m.rotation[self.extreme], m.rate_hz).periods

    @cached_property
    def sara(self) -> HingeEstimate:
        """SARA axis and SCoRE centre over every frame (:func:`estimate_hinge`)."""
        return estimate_hinge(self.m.rotation, self.m.translation, "sara")


def _check_motion(w: _Work) -> float:
    """Refuse too small a range of motion or pure translation; return the ROM (deg)."""
    m, rom = w.m, w.rom
    if rom >= MIN_ROM_DEG:
        return rom
    move = np.percentile(
        np.linalg.norm(m.translation - np.median(m.translation, axis=0), axis=1), 99
    )
    if move > TRANSLATION_MM:
        raise FingerfitError(
            f"pure translation: the child moves {move / m.scale:.3g} {m.units} relative to the "
            f"parent but turns only {rom:.1f} deg (need >= {MIN_ROM_DEG:g} deg); a joint is "
            "found from rotation",
            field="child",
        )
    raise FingerfitError(
        f"range of motion too small: the child turns only {rom:.1f} deg relative to the parent "
        f"(need >= {MIN_ROM_DEG:g} deg)",
        field="child",
    )


def _check_convention(w: _Work) -> dict[str, float]:
    """Pivot residuals under each reading of the rotations; refuse a wrong one.

    Refuses when another reading (:data:`CONVENTIONS`) or the positions with one axis
    negated (:data:`.plausibility.MIRRORS`) give a pivot residual below
    ``CONVENTION_RATIO`` x the as-read one (as read above ``PIVOT_MIN_MM``). Returns the
    residuals of :data:`CONVENTIONS` (mm).
    """
    m = w.m
    every, _ = pivot_residuals(m.parent, m.child, mirrored=True)
    if not every:
        return {}
    res = {k: every[k] for k in CONVENTIONS}
    read = res["as read"]
    alt = min((k for k in CONVENTIONS if k != "as read"), key=res.__getitem__)
    if read > PIVOT_MIN_MM and res[alt] < CONVENTION_RATIO * read:
        raise FingerfitError(
            f"the rotations look {CONVENTIONS[alt]}, not as given: pivot residual "
            f"{res[alt]:.1f} mm read that way, {read:.1f} mm as read (quaternions must be "
            "w,x,y,z, rotations right-handed, sensor to tracker)",
            field="child",
        )
    flip = min(MIRRORS, key=every.__getitem__)
    if read > PIVOT_MIN_MM and every[flip] < CONVENTION_RATIO * read:
        raise FingerfitError(
            f"the positions look mirrored ({flip}: a left-handed frame) relative to "
            f"the rotations: pivot residual {every[flip]:.1f} mm with {flip}, "
            f"{read:.1f} mm as given; positions and rotations must share one right-handed "
            "tracker frame",
            field="child",
        )
    return res


def _check_units(w: _Work) -> None:
    """Refuse positions whose declared units put the joint implausibly near or far from
    the segment origins (:func:`.plausibility.joint_reach_problems`; the SARA/SCoRE centre
    over every frame, in both segments' frames)."""
    h = w.sara.hinge
    assert h is not None
    reach = max(float(np.linalg.norm(h.centre_parent)), float(np.linalg.norm(h.centre_child)))
    problems = joint_reach_problems(reach, w.m.units)
    if problems:
        raise problems[0].error()


def _check_common_centre(conv: dict[str, float]) -> None:
    """Refuse an as-read pivot residual above :data:`MAX_PIVOT_MM`."""
    read = conv.get("as read", 0.0)
    if read > MAX_PIVOT_MM:
        raise FingerfitError(
            f"the segments do not share a fixed centre of rotation: pivot residual {read:.1f} "
            f"mm (expected < {MAX_PIVOT_MM:g} mm); wrong quaternion order or units, a marker "
            "or sensor that slipped, position jumps, or no joint between these segments",
            field="child",
        )
