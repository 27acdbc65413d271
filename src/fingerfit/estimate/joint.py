"""One joint between any two tracked segments: the public estimation API.

Given the poses of a parent and a child segment over time (any tracker, any length
unit), find the joint between them:

* :func:`joint_centre` -- a ball joint: the centre of rotation (O'Brien et al. 2000,
  :mod:`.centre`);
* :func:`hinge_axis` -- a hinge: SARA axis and SCoRE centre (:mod:`.pooled`), with the
  outlier rules (:mod:`.robust`) or the per-cycle line of Tang et al. 2018 (:mod:`.axis`);
* :func:`two_axis` -- two non-intersecting axes, flexion then ab/adduction (:mod:`.twoaxis`);
* :func:`fit_joint` -- any of these, or ``kind="auto"`` to choose.

Every estimator here is the one the finger pipeline uses (:mod:`.fit`); this module
normalises the input, checks that the motion can determine the joint, and reports the
result in both segments' frames with quality figures. Frames: the *parent frame* and the
*child frame* are the coordinate frames of the given parent and child poses (for
:math:`4 \\times 4` transforms ``T``, ``T @ [p_local, 1]`` is the point in the tracker
frame). Results are in the caller's length unit (``units``); residuals are given in that
unit and in mm. Cycles of movement are optional: continuous motion and one swing work;
only ``method="tang2018"`` needs repeated cycles (and says so). ``docs/joint.md`` has the
details, the refusals and what a wrong quaternion convention does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..kinematics import twist_angle, two_axis_angles
from ..session import UNITS_TO_MM, PoseSeries
from ..transforms import (
    FloatArray,
    angle_between_axes,
    axis_angle_matrix,
    matrix_from_quat_wxyz,
    relative_pose,
    rotation_angle,
    rotation_vector,
)
from .axis import AxisFit, line_through_centres
from .centre import CentreFit, centre_of_rotation
from .cycles import extract_cycles
from .plausibility import (
    CONVENTION_RATIO,
    CONVENTIONS,
    MIRRORS,
    PIVOT_MIN_MM,
    joint_reach_problems,
    pivot_residuals,
)
from .pooled import PooledHinge, pooled_hinge, sara_axis
from .robust import RobustHinge, robust_hinge
from .twoaxis import MIN_RANGE_DEG, TwoAxisFit, fit_two_axis

KINDS = ("hinge", "two_axis", "ball", "auto")
HINGE_METHODS = ("sara", "robust", "tang2018")

#: The child must turn at least this much relative to the parent (deg, the 99th
#: percentile angle between its orientations) for any joint to be found.
MIN_ROM_DEG = 10.0
#: Below :data:`MIN_ROM_DEG`, a child origin moving more than this (mm, 99th percentile
#: distance from its median position in the parent frame) is called pure translation.
TRANSLATION_MM = 5.0
#: A hinge needs the rotation about its axis to be this many times the rotation off it
#: (``s5/s6`` of the SARA system; the finger pipeline's ``min_conditioning``).
MIN_HINGE_CONDITIONING = 3.0
#: A ball joint needs rotation about more than one axis: ``s5/s6`` above this means the
#: motion turns about one axis and the centre along it is not determined.
MAX_BALL_CONDITIONING = 10.0
#: ``kind="auto"`` takes a two-axis joint over a hinge only when its second axis spans at
#: least this (deg, 5th-95th percentile); ``kind="two_axis"`` accepts from 1.5 deg.
AUTO_MIN_SECOND_DEG = 5.0
#: The segments share no fixed centre of rotation when the RMS pivot residual (mm) of the
#: as-read poses exceeds this. Measured: a real mechanical hinge 1.2 mm clean and 2-3 mm on
#: one fast swing (issue 16); hand-held Liberty rotations 4.1-8.6 mm (``docs/joint.md``);
#: a swapped quaternion order on the real hinge ~70 mm.
MAX_PIVOT_MM = 20.0
#: Block bootstrap of the axis direction: resamples and blocks (contiguous in time).
BOOTSTRAP_RESAMPLES = 200
BOOTSTRAP_BLOCKS = 20
MIN_FRAMES = 10


@dataclass(frozen=True)
class JointQuality:
    """How well the motion determines the joint.

    Attributes
    ----------
    frames : int
        Frames used (both poses finite).
    dropped_frames : int
        Frames dropped because a value of either pose was NaN or infinite.
    rom_deg : float
        Range of motion: 99th percentile angle between the child's orientations
        relative to the parent (deg).
    pivot_residual : float
        RMS over frames of ``|u_p - R(k) u_c - t(k)|`` for the fitted joint (caller's
        units): how far the segments are from sharing the fitted centre/axis.
    pivot_residual_mm : float
        The same in mm.
    axis_conditioning : float
        ``s5/s6`` of the SARA system: RMS rotation about the best single axis over the
        RMS rotation off it (large for a hinge, ~1 for a ball joint).
    centre_condition : float
        ``s1/s6`` of the O'Brien centre system (ball joints; small is well determined;
        ``inf`` for an exact hinge).
    axis_spread_deg : float
        95th percentile angle between the axis and its block-bootstrap replicates (deg;
        time blocks, ``BOOTSTRAP_RESAMPLES`` resamples, seeded). Two-axis joints: the
        flexion axis' cluster-robust SD over time blocks times 1.96. NaN for a ball joint.
    centre_spread : float
        Ball joints: 95th percentile distance of the block-bootstrap centres from the
        centre (caller's units); NaN otherwise.
    cycles : int
        Movement cycles found (0 without ``rate_hz`` or for continuous motion).
    convention_residual_mm : dict of str to float
        Pivot residual (mm) under each reading of the rotations
        (:data:`fingerfit.estimate.plausibility.CONVENTIONS`).
    notes : tuple of str
    """

    frames: int
    dropped_frames: int
    rom_deg: float
    pivot_residual: float
    pivot_residual_mm: float
    axis_conditioning: float
    centre_condition: float
    axis_spread_deg: float
    centre_spread: float
    cycles: int
    convention_residual_mm: dict[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class JointFit:
    """A fitted joint between a parent and a child segment.

    Attributes
    ----------
    kind : str
        ``"hinge"``, ``"two_axis"`` or ``"ball"``.
    method : str
        Estimator used (``"obrien"`` for a ball, ``"sara"``, ``"robust"`` or
        ``"tang2018"`` for a hinge, ``"twoaxis"``).
    units : str
        Length unit of every position here (the caller's).
    centre_parent, centre_child : ndarray, shape (3,)
        The joint centre in the parent and the child frame. Hinge and two-axis: the
        point of the (flexion) axis nearest the segments' origins (a hinge's centre
        along its axis is not determined by the motion).
    axis_parent, axis_child : ndarray, shape (3,) or None
        Unit hinge/flexion axis in the parent and the child frame (``axis_parent =
        R(k) axis_child`` at the reference frame). The sign makes the largest-magnitude
        component of ``axis_parent`` positive. None for a ball.
    second_axis_parent : ndarray, shape (3,) or None
        Two-axis joints: the unit ab/adduction axis, fixed in the parent frame.
    second_point_parent : ndarray, shape (3,) or None
        Its point nearest the flexion axis (parent frame).
    angles_deg : ndarray, shape (n, k)
        Per used frame, from the reference frame (deg): hinge ``k = 1`` (twist about the
        axis); two-axis ``k = 2`` (flexion, ab/adduction); ball ``k = 3`` (rotation
        vector of ``R(k) R_ref^T`` in the parent frame).
    frames : ndarray of int, shape (n,)
        Indices into the input of the frames used.
    reference_frame : int
        Input index of the reference frame (angles zero): the frame nearest the mean
        orientation.
    quality : JointQuality
    """

    kind: str
    method: str
    units: str
    centre_parent: FloatArray
    centre_child: FloatArray
    axis_parent: FloatArray | None
    axis_child: FloatArray | None
    second_axis_parent: FloatArray | None
    second_point_parent: FloatArray | None
    angles_deg: FloatArray
    frames: np.ndarray
    reference_frame: int
    quality: JointQuality

    def summary(self) -> dict:
        """JSON-ready dict of the result (lists of floats; ``angles_deg`` left out)."""

        def vec(v: FloatArray | None) -> list[float] | None:
            return None if v is None else [float(x) for x in v]

        q = self.quality
        return {
            "kind": self.kind,
            "method": self.method,
            "units": self.units,
            "centre_parent": vec(self.centre_parent),
            "centre_child": vec(self.centre_child),
            "axis_parent": vec(self.axis_parent),
            "axis_child": vec(self.axis_child),
            "second_axis_parent": vec(self.second_axis_parent),
            "second_point_parent": vec(self.second_point_parent),
            "reference_frame": self.reference_frame,
            "angle_range_deg": [[float(np.min(c)), float(np.max(c))] for c in self.angles_deg.T],
            "quality": {
                "frames": q.frames,
                "dropped_frames": q.dropped_frames,
                "rom_deg": q.rom_deg,
                "pivot_residual": q.pivot_residual,
                "pivot_residual_mm": q.pivot_residual_mm,
                "axis_conditioning": _finite(q.axis_conditioning),
                "centre_condition": _finite(q.centre_condition),
                "axis_spread_deg": _finite(q.axis_spread_deg),
                "centre_spread": _finite(q.centre_spread),
                "cycles": q.cycles,
                "convention_residual_mm": q.convention_residual_mm,
                "notes": list(q.notes),
            },
        }


def _conditioning(singular_values: FloatArray) -> float:
    """``s5 / s6`` of a hinge fit's two smallest singular values (inf for an exact hinge)."""
    s5, s6 = singular_values
    return float(s5 / s6) if s6 > 0 else math.inf


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


# --------------------------------------------------------------------------- input


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


# --------------------------------------------------------------------------- checks


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


# --------------------------------------------------------------------------- bootstrap


def _block_sums(values: FloatArray, n_blocks: int) -> FloatArray:
    """Sums of ``values (n, ...)`` over ``n_blocks`` contiguous blocks: ``(n_blocks, ...)``."""
    edges = np.linspace(0, values.shape[0], n_blocks + 1).astype(int)
    return np.add.reduceat(values, edges[:-1], axis=0)


def _resample_counts(n_blocks: int, seed: int) -> FloatArray:
    """``(BOOTSTRAP_RESAMPLES, n_blocks)`` counts of each block in each resample."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, n_blocks, size=(BOOTSTRAP_RESAMPLES, n_blocks))
    counts = np.zeros((BOOTSTRAP_RESAMPLES, n_blocks))
    np.add.at(counts, (np.arange(BOOTSTRAP_RESAMPLES)[:, None], pick), 1.0)
    return counts


def axis_bootstrap_deg(
    rotation: FloatArray, axis: FloatArray, weights: FloatArray | None = None, seed: int = 0
) -> float:
    """95th percentile angle (deg) between the SARA axis and its block-bootstrap replicates.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations in time order.
    axis : ndarray, shape (3,)
        The fitted axis (parent frame).
    weights : ndarray, shape (n,), optional
        Frame weights of the fit.
    seed : int
        Seed of the resampling (results are reproducible).

    Returns
    -------
    float
        Each replicate resamples ``BOOTSTRAP_BLOCKS`` contiguous time blocks with
        replacement; the SARA axis of a replicate is the leading left singular vector of
        its summed rotation matrix (:func:`.pooled.sara_axis`), all replicates in one
        batched SVD.
    """
    n_blocks = min(BOOTSTRAP_BLOCKS, rotation.shape[0] // 2)
    w = np.ones(rotation.shape[0]) if weights is None else weights
    sums = _block_sums(w[:, None, None] * rotation, n_blocks)
    s = np.einsum("bk,kij->bij", _resample_counts(n_blocks, seed), sums)
    u, _, _ = np.linalg.svd(s)
    return float(np.degrees(np.percentile(angle_between_axes(u[:, :, 0], axis), 95)))


def _centre_bootstrap_mm(
    rotation: FloatArray, translation: FloatArray, centre: FloatArray
) -> float:
    """95th percentile distance (mm) of block-bootstrap O'Brien centres from ``centre``."""
    n = rotation.shape[0]
    n_blocks = min(BOOTSTRAP_BLOCKS, n // 2)
    # Normal equations of [I  -R] [u_p; u_c] = t per frame: A^T A (6 x 6) and A^T t (6,).
    ata = np.empty((n, 6, 6))
    ata[:, :3, :3] = np.eye(3)
    ata[:, :3, 3:] = -rotation
    ata[:, 3:, :3] = -np.swapaxes(rotation, 1, 2)
    ata[:, 3:, 3:] = np.eye(3)
    atb = np.concatenate([translation, -np.einsum("nji,nj->ni", rotation, translation)], axis=1)
    counts = _resample_counts(n_blocks, 1)
    m = np.einsum("bk,kij->bij", counts, _block_sums(ata, n_blocks))
    rhs = np.einsum("bk,ki->bi", counts, _block_sums(atb, n_blocks))
    sol = np.linalg.solve(m + 1e-9 * np.eye(6), rhs[..., None])[..., 0]
    return float(np.percentile(np.linalg.norm(sol[:, :3] - centre, axis=1), 95))


# --------------------------------------------------------------------------- estimators


@dataclass(frozen=True)
class HingeEstimate:
    """One hinge estimator's result on relative poses (parent frame, mm).

    :func:`estimate_hinge` is the one place the hinge estimators are invoked and
    configured, for :func:`fit_joint` and the finger pipeline (:mod:`.fit`) alike.

    Attributes
    ----------
    method : str
        ``"sara"``, ``"robust"`` or ``"tang2018"``.
    axis : ndarray, shape (3,)
        Unit axis in the parent frame (sign as the estimator gives it).
    point : ndarray, shape (3,)
        A point of the axis in the parent frame (mm): the SCoRE centre, or the point of
        the line through the per-cycle centres.
    frames : ndarray of int
        Frames (indices into the given arrays) the axis was fitted to; ``tang2018``: all
        given frames (the conditioning is computed over them).
    weights : ndarray, shape (len(frames),) or None
        Frame weights of the fit (``robust``; mean 1).
    groups : ndarray of int, shape (len(frames),) or None
        Cycle index of each frame (``robust``).
    singular_values : ndarray, shape (2,)
        ``(s5, s6)`` of the SARA system over ``frames`` (with ``weights``).
    hinge : PooledHinge or None
        The SARA/SCoRE fit (``sara``, ``robust``): axis and centre in both frames and the
        per-frame residuals.
    robust : RobustHinge or None
        The outlier rules' result (``robust``).
    centres : list of CentreFit
        Per-cycle O'Brien centres (``tang2018``).
    line : AxisFit or None
        The line through the per-cycle centres (``tang2018``).
    """

    method: str
    axis: FloatArray
    point: FloatArray
    frames: np.ndarray
    weights: FloatArray | None
    groups: np.ndarray | None
    singular_values: FloatArray
    hinge: PooledHinge | None = None
    robust: RobustHinge | None = None
    centres: list[CentreFit] = field(default_factory=list)
    line: AxisFit | None = None

    @property
    def conditioning(self) -> float:
        """``s5 / s6`` (inf for an exact hinge)."""
        return _conditioning(self.singular_values)

    @property
    def noise_mm(self) -> float:
        """Per-coordinate noise of the SCoRE residual (mm, ``sqrt(mean |r|^2 / 3)``,
        at least 1e-6); ``sara`` and ``robust`` only."""
        if self.hinge is None:
            raise ValueError(f"method '{self.method}' has no SCoRE residual")
        return max(float(np.sqrt(np.mean(self.hinge.centre_residual**2) / 3.0)), 1e-6)


def estimate_hinge(
    rotation: FloatArray,
    translation: FloatArray,
    method: str,
    periods: list[np.ndarray] | None = None,
) -> HingeEstimate:
    """Fit a hinge to relative poses by one of :data:`HINGE_METHODS`.

    Parameters
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations, time order, no NaN.
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    method : {"sara", "robust", "tang2018"}
        ``sara``: SARA axis and SCoRE centre (:func:`.pooled.pooled_hinge`) over the
        frames of ``periods``, or every frame without them; ``robust``: the same after the
        outlier rules (:func:`.robust.robust_hinge`) with ``periods`` as the cycles, or one
        period of every frame without them; ``tang2018``: O'Brien centre per period and
        the line through them (:func:`.axis.line_through_centres`; two or more periods).
    periods : list of ndarray, optional
        Frame indices of each movement cycle.

    Returns
    -------
    HingeEstimate
    """
    n = rotation.shape[0]
    if method == "tang2018":
        if periods is None or len(periods) < 2:
            found = 0 if periods is None else len(periods)
            raise FingerfitError(
                f"method 'tang2018' needs at least 2 movement cycles (found {found})",
                field="method",
            )
        centres = [centre_of_rotation(rotation[p], translation[p]) for p in periods]
        line = line_through_centres(centres)
        return HingeEstimate(
            method, line.direction, line.point, np.arange(n), None, None,
            sara_axis(rotation)[2], centres=centres, line=line,
        )  # fmt: skip
    if method == "robust":
        rh = robust_hinge(rotation, translation, periods or [np.arange(n)])
        h = rh.fit
        return HingeEstimate(
            method, h.axis_parent, h.centre_parent, rh.frames, rh.weights, rh.labels,
            h.singular_values, hinge=h, robust=rh,
        )  # fmt: skip
    if method == "sara":
        used = np.concatenate(periods) if periods else np.arange(n)
        h = pooled_hinge(rotation[used], translation[used])
        return HingeEstimate(
            method, h.axis_parent, h.centre_parent, used, None, None, h.singular_values, hinge=h
        )
    raise FingerfitError(
        f"unknown hinge method '{method}' (have: {', '.join(HINGE_METHODS)})", field="method"
    )


def estimate_two_axis(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    hinge: HingeEstimate,
    finger_direction: FloatArray | None = None,
) -> TwoAxisFit:
    """Two-axis joint (flexion, then ab/adduction) started from a hinge fit.

    Parameters
    ----------
    rotation, translation : ndarray, shapes (n, 3, 3) and (n, 3)
        The relative poses ``hinge`` was fitted to (parent frame, mm).
    reference_rotation : ndarray, shape (3, 3)
        Relative rotation at zero flexion and ab/adduction.
    hinge : HingeEstimate
        A ``sara`` or ``robust`` fit: its frames, weights, axis (initial flexion axis) and
        SCoRE noise are used; its cycles group the frames for the stability test, else
        :data:`BOOTSTRAP_BLOCKS` contiguous time blocks do.
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched finger (parent frame), for the initial
        ab/adduction axis.

    Returns
    -------
    TwoAxisFit
        :func:`.twoaxis.fit_two_axis`'s result; ``accepted`` says whether the data
        support the second axis.
    """
    k = hinge.frames
    groups = hinge.groups
    if groups is None:
        groups = np.arange(k.size) * BOOTSTRAP_BLOCKS // k.size
    return fit_two_axis(
        rotation[k], translation[k], reference_rotation, hinge.axis, hinge.weights,
        hinge.noise_mm, finger_direction, groups,
    )  # fmt: skip


def _orient(axis: FloatArray) -> float:
    """Sign that makes the largest-magnitude component of ``axis`` positive."""
    return 1.0 if axis[int(np.argmax(np.abs(axis)))] >= 0 else -1.0


def _hinge(w: _Work, method: str, conv: dict[str, float]) -> JointFit:
    if method not in HINGE_METHODS:
        raise FingerfitError(
            f"unknown hinge method '{method}' (have: {', '.join(HINGE_METHODS)})", field="method"
        )
    m, ref, periods = w.m, w.ref, w.periods
    notes: list[str] = []
    if method == "tang2018":
        if len(periods) < 2:
            raise FingerfitError(
                f"method 'tang2018' needs at least 2 movement cycles (found {len(periods)}"
                f"{'' if m.rate_hz else '; give rate_hz to look for them'}); use method='sara'",
                field="method",
            )
        est = estimate_hinge(m.rotation, m.translation, method, periods)
        a_p = est.axis
        a_c = m.rotation[ref].T @ a_p
        # The point of the line in the child frame, through the reference pose.
        u_p = est.point
        u_c = m.rotation[ref].T @ (u_p - m.translation[ref])
        resid = np.linalg.norm(u_p - m.rotation @ u_c - m.translation, axis=1)
    else:
        # robust: the cycles when found (the cycle rule needs them), else one period of
        # every frame; sara: every frame.
        cycles = periods if method == "robust" and len(periods) >= 3 else None
        if method == "robust" and cycles is None:
            notes.append("robust: no repeated cycles; frame rule only")
        est = (
            w.sara
            if method == "sara"
            else estimate_hinge(m.rotation, m.translation, method, cycles)
        )
        h = est.hinge
        assert h is not None
        if est.robust is not None:
            # The kept frames must pass the range-of-motion rule themselves. On one swing
            # that starts or ends at rest, the rest frames set the frame rule's robust SD
            # and the moving frames, which fit a hand-held hinge worse, are taken for
            # outliers (measured: the second half of the real rotate-90deg-x.csv log kept
            # 0.3 of 29.8 deg and its axis moved 18 deg).
            kept = range_of_motion_deg(m.rotation[est.frames])
            if kept < MIN_ROM_DEG:
                raise FingerfitError(
                    f"method 'robust' kept {est.frames.size} of {m.frames.size} frames spanning "
                    f"only {kept:.1f} deg of the {w.rom:.1f} deg motion (need >= "
                    f"{MIN_ROM_DEG:g} deg): its frame rule took the moving frames for outliers "
                    "of the frames at rest, so the axis is not determined; use method='sara', "
                    "or record repeated cycles and give rate_hz",
                    field="method",
                )
            if est.robust.rejected_frames:
                notes.append(f"{est.robust.rejected_frames} outlier frame(s) rejected")
            if est.robust.rejected_cycles:
                rej = ", ".join(str(i + 1) for i in est.robust.rejected_cycles)
                notes.append(f"cycles {rej} rejected")
        a_p, a_c, u_p, u_c = h.axis_parent, h.axis_child, h.centre_parent, h.centre_child
        resid = h.centre_residual
    used, weights = est.frames, est.weights
    cond = est.conditioning
    if cond < MIN_HINGE_CONDITIONING:
        raise FingerfitError(
            f"not a hinge: rotation about the best axis is only {cond:.1f} times the rotation "
            f"off it (need >= {MIN_HINGE_CONDITIONING:g}); try kind='two_axis' or 'ball'",
            field="kind",
        )
    s = _orient(a_p)
    a_p, a_c = s * a_p, s * a_c
    q = m.rotation[used] @ m.rotation[ref].T
    angles = np.degrees(twist_angle(q, a_p))[:, None]
    spread = axis_bootstrap_deg(m.rotation[used], a_p, weights)
    rms = float(np.sqrt(np.mean(resid**2)))
    return _result(
        m, "hinge", method, u_p, u_c, a_p, a_c, None, None, angles, used, ref, w.rom, rms,
        cond, math.nan, spread, math.nan, len(periods), conv, notes,
    )  # fmt: skip


def _ball(w: _Work, conv: dict[str, float]) -> JointFit:
    m, ref = w.m, w.ref
    cond = w.sara.conditioning
    if cond > MAX_BALL_CONDITIONING:
        raise FingerfitError(
            f"the motion turns about one axis only (rotation about it {cond:.0f} times the "
            f"rotation off it, ball joints need < {MAX_BALL_CONDITIONING:g}): the centre along "
            "that axis is not determined; use kind='hinge'",
            field="kind",
        )
    c = centre_of_rotation(m.rotation, m.translation)
    s = c.singular_values
    used = np.arange(m.rotation.shape[0])
    angles = np.degrees(rotation_vector(m.rotation @ m.rotation[ref].T))
    spread = _centre_bootstrap_mm(m.rotation, m.translation, c.parent_point)
    return _result(
        m, "ball", "obrien", c.parent_point, c.child_point, None, None, None, None, angles,
        used, ref, w.rom, c.rms_mm, cond, float(s[0] / s[-1]) if s[-1] > 0 else math.inf,
        math.nan, spread, len(w.periods), conv, [],
    )  # fmt: skip


def _two_axis(w: _Work, conv: dict[str, float], *, strict: bool = True) -> JointFit | None:
    m, ref, h = w.m, w.ref, w.sara
    cond = h.conditioning
    n = m.rotation.shape[0]
    tf = estimate_two_axis(m.rotation, m.translation, m.rotation[ref], h)
    if not tf.accepted:
        if not strict:
            return None
        raise FingerfitError(
            f"only one axis is excited: a second axis spans {tf.abduction_range_deg:.1f} deg "
            f"(need >= {MIN_RANGE_DEG:g}) and leaves {np.degrees(tf.rms_two_axis_rad):.2f} deg "
            f"RMS of the hinge's {np.degrees(tf.rms_hinge_rad):.2f} deg (need half or less), "
            f"and the ab/adduction at zero flexion varies between blocks of frames by >= "
            f"{tf.rest_spread_low_deg:.2f} deg SD (95 %; need more than the two-axis RMS); "
            "use kind='hinge'",
            field="kind",
        )
    a, b = tf.flexion_axis, tf.abduction_axis
    sa, sb = _orient(a), _orient(b)
    a, b = sa * a, sb * b
    q = m.rotation @ m.rotation[ref].T
    beta, theta = two_axis_angles(q, a, b)
    # Flexion axis and point are fixed in the child: carry them there by the reference pose.
    r0, t0 = m.rotation[ref], m.translation[ref]
    a_c = r0.T @ a
    u_c = r0.T @ (tf.flexion_point - t0)
    rot_b = axis_angle_matrix(b, beta)
    c_b = tf.abduction_point
    model = rot_b @ (tf.flexion_point - c_b) + c_b
    resid = np.linalg.norm(m.rotation @ u_c + m.translation - model, axis=1)
    angles = np.degrees(np.column_stack([theta, beta]))
    return _result(
        m, "two_axis", "twoaxis", tf.flexion_point, u_c, a, a_c, b, c_b, angles,
        np.arange(n), ref, w.rom, float(np.sqrt(np.mean(resid**2))), cond, math.nan,
        1.96 * tf.flexion_sd_deg, math.nan, len(w.periods), conv,
        tf.stability_notes("joint", f"{BOOTSTRAP_BLOCKS} contiguous blocks of frames"),
    )  # fmt: skip


def _result(
    m: _Motion, kind: str, method: str, u_p: FloatArray, u_c: FloatArray,
    a_p: FloatArray | None, a_c: FloatArray | None, b: FloatArray | None,
    c_b: FloatArray | None, angles: FloatArray, used: np.ndarray, ref: int, rom: float,
    rms_mm: float, cond: float, centre_cond: float, spread: float, centre_spread_mm: float,
    cycles: int, conv: dict[str, float], notes: list[str],
) -> JointFit:  # fmt: skip
    s = m.scale
    quality = JointQuality(
        frames=int(m.frames.size),
        dropped_frames=m.dropped,
        rom_deg=rom,
        pivot_residual=rms_mm / s,
        pivot_residual_mm=rms_mm,
        axis_conditioning=cond,
        centre_condition=centre_cond,
        axis_spread_deg=spread,
        centre_spread=centre_spread_mm / s,
        cycles=cycles,
        convention_residual_mm=dict(conv),
        notes=tuple(notes),
    )
    return JointFit(
        kind=kind,
        method=method,
        units=m.units,
        centre_parent=np.asarray(u_p) / s,
        centre_child=np.asarray(u_c) / s,
        axis_parent=a_p,
        axis_child=a_c,
        second_axis_parent=b,
        second_point_parent=None if c_b is None else np.asarray(c_b) / s,
        angles_deg=angles,
        frames=m.frames[used],
        reference_frame=int(m.frames[ref]),
        quality=quality,
    )


# --------------------------------------------------------------------------- public API


def fit_joint(
    parent: object,
    child: object,
    kind: str = "auto",
    *,
    units: str = "mm",
    method: str = "sara",
    rate_hz: float | None = None,
    check_convention: bool = True,
) -> JointFit:
    """Find the joint between two tracked segments.

    Parameters
    ----------
    parent, child : ndarray, shape (n, 4, 4), or tuple (positions, quaternions)
        The segments' poses in one tracker frame over the same ``n`` frames, in time
        order: homogeneous transforms (segment -> tracker; last row ``0 0 0 1``), or
        positions ``(n, 3)`` and unit quaternions ``(n, 4)`` scalar first (w, x, y, z;
        note scipy's order is x, y, z, w). Frames with a NaN or infinite value in either
        are dropped and counted.
    kind : {"hinge", "two_axis", "ball", "auto"}
        Joint model. ``auto``: ``two_axis`` when a second axis is supported and spans
        :data:`AUTO_MIN_SECOND_DEG` or more, else
        ``hinge`` when the rotation is about one axis (``s5/s6 >=``
        :data:`MIN_HINGE_CONDITIONING`), else ``ball``.
    units : {"mm", "cm", "m", "in"}
        Length unit of the positions; every result is in the same unit. Checked: the
        joint centre must lie 10 mm to 2 m from the farther segment origin
        (:data:`.plausibility.JOINT_REACH_MM`).
    method : {"sara", "robust", "tang2018"}
        Hinge estimator: SARA axis and SCoRE centre over all frames, the same after the
        outlier rules (cycles used when found), or the line through per-cycle centres
        (needs ``rate_hz`` and at least two movement cycles).
    rate_hz : float, optional
        Sampling rate (Hz); needed only to find movement cycles.
    check_convention : bool
        Refuse a recording whose rotations fit the joint much better in another
        quaternion convention (``docs/joint.md``).

    Returns
    -------
    JointFit

    Raises
    ------
    FingerfitError
        One line naming the cause: malformed input, fewer than ten valid frames, too
        small a range of motion, pure translation, a wrong quaternion order or handedness,
        implausible units (a :class:`.plausibility.PlausibilityError`, field ``units``),
        no common centre of rotation, a motion the requested kind cannot describe (not a
        hinge; one axis only for ``two_axis`` or ``ball``), ``tang2018`` without cycles,
        ``robust`` keeping frames that span less than :data:`MIN_ROM_DEG`.
    """
    if kind not in KINDS:
        raise FingerfitError(f"unknown kind '{kind}' (have: {', '.join(KINDS)})", field="kind")
    # Each step below is computed once and shared (_Work): the reference frame, the range
    # of motion, the cycles and the SARA/SCoRE fit over every frame.
    w = _Work(_motion(parent, child, units, rate_hz))
    _check_motion(w)
    conv = _check_convention(w) if check_convention else {}
    _check_units(w)
    _check_common_centre(conv)
    if kind == "hinge":
        return _hinge(w, method, conv)
    if kind == "ball":
        return _ball(w, conv)
    if kind == "two_axis":
        return _two_axis(w, conv)
    cond = w.sara.conditioning
    fit = _two_axis(w, conv, strict=False) if cond <= 1e6 else None
    if fit is not None:
        lo, hi = np.percentile(fit.angles_deg[:, 1], [5, 95])
        if hi - lo >= AUTO_MIN_SECOND_DEG or cond < MIN_HINGE_CONDITIONING:
            return fit
    if cond >= MIN_HINGE_CONDITIONING:
        return _hinge(w, method, conv)
    return _ball(w, conv)


def joint_centre(parent: object, child: object, **kwargs) -> JointFit:
    """Centre of rotation of a ball joint (O'Brien et al. 2000): :func:`fit_joint` with
    ``kind="ball"``; same parameters and result."""
    return fit_joint(parent, child, "ball", **kwargs)


def hinge_axis(parent: object, child: object, method: str = "sara", **kwargs) -> JointFit:
    """Hinge axis and a point of it: :func:`fit_joint` with ``kind="hinge"``.

    ``method`` is ``"sara"`` (SARA axis, SCoRE centre; Ehrig et al. 2006, 2007), ``"robust"``
    (the same after the outlier rules of :mod:`.robust`) or ``"tang2018"`` (line through
    per-cycle centres; needs ``rate_hz`` and two or more cycles). Other parameters and the
    result as :func:`fit_joint`.
    """
    return fit_joint(parent, child, "hinge", method=method, **kwargs)


def two_axis(parent: object, child: object, **kwargs) -> JointFit:
    """Two-axis joint (flexion, then ab/adduction about an axis fixed in the parent):
    :func:`fit_joint` with ``kind="two_axis"``; same parameters and result."""
    return fit_joint(parent, child, "two_axis", **kwargs)


__all__ = [
    "HINGE_METHODS",
    "KINDS",
    "HingeEstimate",
    "JointFit",
    "JointQuality",
    "axis_bootstrap_deg",
    "estimate_hinge",
    "estimate_two_axis",
    "fit_joint",
    "hinge_axis",
    "joint_centre",
    "range_of_motion_deg",
    "two_axis",
]
