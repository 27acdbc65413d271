"""The axis estimators of a joint between two tracked segments (``METHODS``,
``docs/methods.md``): what each takes (:class:`JointData`) and gives
(:class:`AxisEstimate`).

* ``tang2018`` -- the paper: a centre of rotation per cycle (:mod:`.centre`) and the line
  through them (:mod:`.axis`);
* ``pooled`` -- SARA axis and SCoRE centre over all movement frames (:mod:`.pooled`);
* ``robust`` -- ``pooled`` after the outlier-frame and -cycle rules, with per-cycle
  weights (:mod:`.robust`);
* ``twoaxis`` -- ``robust``, and a second (ab/adduction) axis at a joint that may have
  one where held-out cycles choose it, in the order they choose (:mod:`.choice`,
  :mod:`.twoaxis`);
* ``rolling`` -- ``twoaxis`` plus rolling-contact migration of every centre
  (:mod:`.migration`).

:mod:`.fit` runs them over a session's digits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..angles import twist_angle, two_axis_angles
from ..digits import ABDUCTION_FIRST, FLEXION_FIRST
from ..errors import FingerfitError
from ..transforms import FloatArray, angle_between_axes
from .axis import AxisFit, mean_null_axis
from .centre import CentreFit, centre_of_rotation
from .choice import TWO_AXIS, ModelChoice, choose_joint_model
from .cycles import period_labels
from .joint_estimators import estimate_hinge, estimate_two_axis, estimate_two_axis_directions
from .migration import fit_axis_points
from .saddle import SaddleFit
from .twoaxis import TwoAxisFit

DEFAULT_METHOD = "twoaxis"


class FitError(FingerfitError):
    """The motion cannot determine a joint (named in the message)."""


@dataclass(frozen=True)
class JointData:
    """Everything an axis estimator may use for one joint (parent sensor frame, mm, rad).

    Attributes
    ----------
    rotation : ndarray, shape (n, 3, 3)
        Child-in-parent rotations over all grasp recordings (concatenated).
    translation : ndarray, shape (n, 3)
        Child origin in the parent frame (mm).
    periods : list of ndarray
        Frame indices (into the arrays above) of each cycle's movement period.
    rom : ndarray, shape (n_cycles,)
        Range of motion per cycle (rad).
    reference_rotation : ndarray, shape (3, 3)
    reference_offset : ndarray, shape (3,)
        Relative pose at the reference posture.
    joint : str
        The joint's name (``mp``, ``pip``, ``dip``; ``cmc``, ``mcp``, ``ip``).
    finger_direction : ndarray, shape (3,), optional
        Unit direction of the stretched digit in the parent frame (least-squares
        line through the dorsal landmarks, proximal to distal).
    second_axis : str, optional
        For a joint that may have a second (ab/adduction) axis, its order
        (``abduction_first`` or ``flexion_first``, :mod:`fingerfit.digits`); the
        ``twoaxis`` and ``rolling`` estimators then test for it.
    """

    rotation: FloatArray
    translation: FloatArray
    periods: list[np.ndarray]
    rom: FloatArray
    reference_rotation: FloatArray
    reference_offset: FloatArray
    joint: str = ""
    finger_direction: FloatArray | None = None
    second_axis: str | None = None

    def reversed(self) -> JointData:
        """The same joint seen from the child: parent-in-child poses (child frame, mm).

        A joint ``Q = Rot(a, theta) Rot(b, beta)`` with ``a`` proximal becomes
        ``Q' = Rot(b', -beta) Rot(a', -theta)`` with ``b' = R_ref^T b`` proximal, so an
        estimator of the ab/adduction-first form fits a flexion-first joint this way.
        """
        rot = np.swapaxes(self.rotation, 1, 2)
        ref = self.reference_rotation
        fd = None if self.finger_direction is None else ref.T @ self.finger_direction
        return replace(
            self,
            rotation=rot,
            translation=-np.einsum("nij,nj->ni", rot, self.translation),
            reference_rotation=ref.T,
            reference_offset=-ref.T @ self.reference_offset,
            finger_direction=fd,
        )


@dataclass(frozen=True)
class AxisEstimate:
    """An estimator's result (parent sensor frame, mm) plus diagnostics.

    Attributes
    ----------
    axis : AxisFit
        The flexion axis: ``point`` and ``direction``; ``distances`` of the
        per-cycle centres to it.
    centres : list of CentreFit
        Per-cycle O'Brien centres (of the cycles used).
    abduction : TwoAxisFit or SaddleFit, optional
        The second axis when a two-axis joint was fitted and accepted (parent frame).
    migration : ndarray, shape (3,), optional
        Centre migration (mm/rad, parent frame).
    pooled_conditioning : float, optional
        ``s5/s6`` of the pooled hinge system.
    rejected_frames : int
    rejected_cycles : list of int
    notes : list of str
        Facts worth keeping in the joint's quality notes.
    choice : ModelChoice, optional
        Hinge vs two axes by held-out prediction (joints that may have a second axis,
        ``twoaxis`` and ``rolling``).
    """

    axis: AxisFit
    centres: list[CentreFit]
    abduction: TwoAxisFit | SaddleFit | None = None
    migration: FloatArray | None = None
    pooled_conditioning: float | None = None
    rejected_frames: int = 0
    rejected_cycles: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    choice: ModelChoice | None = None


def tang2018(data: JointData) -> AxisEstimate:
    """The paper's estimator: untruncated O'Brien centre per cycle, line through them (eq. 1)."""
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "tang2018", data.periods)
    assert est.line is not None
    return AxisEstimate(est.line, est.centres)


def _cycle_centres(data: JointData, cycles: list[int]) -> list[CentreFit]:
    """Per-cycle O'Brien centres (quality figures: paper Fig. 8)."""
    return [
        centre_of_rotation(data.rotation[data.periods[i]], data.translation[data.periods[i]])
        for i in cycles
    ]


def _axis_fit(point: FloatArray, direction: FloatArray, centres: list[CentreFit]) -> AxisFit:
    """An :class:`AxisFit` for a line found by a pooled method, with per-cycle diagnostics."""
    c = np.array([f.parent_point for f in centres])
    distances = np.linalg.norm(np.cross(c - point, direction), axis=1)
    along = (c - c.mean(axis=0)) @ direction
    spread = float(np.sqrt(np.mean(along**2)))
    agreement = float(np.degrees(angle_between_axes(direction, mean_null_axis(centres))))
    return AxisFit(point, direction, distances, spread, False, agreement)


def _need_cycles(data: JointData) -> None:
    """Refuse (one line) a joint without movement cycles: the estimators pool their frames."""
    if not data.periods:
        raise FitError(
            f"{data.joint or 'joint'}: no movement cycles found, nothing to fit (for continuous "
            "motion or one swing use fingerfit.estimate.fit_joint or 'fingerfit joint')"
        )


def pooled(data: JointData) -> AxisEstimate:
    """SARA axis and axis-truncated SCoRE centre over all movement frames (:mod:`.pooled`)."""
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "sara", data.periods)
    centres = _cycle_centres(data, list(range(len(data.periods))))
    return AxisEstimate(
        _axis_fit(est.point, est.axis, centres),
        centres,
        pooled_conditioning=est.conditioning,
    )


def robust(data: JointData) -> AxisEstimate:
    """``pooled`` after the outlier-frame and -cycle rules, with cycle weights (:mod:`.robust`)."""
    return _robust_family(data, two_axis=False, migration=False)


def twoaxis(data: JointData) -> AxisEstimate:
    """``robust``, with a second axis at a finger's MP or the thumb's MCP where the data show
    one (:mod:`.twoaxis`)."""
    return _robust_family(data, two_axis=True, migration=False)


def rolling(data: JointData) -> AxisEstimate:
    """``twoaxis`` plus rolling-contact migration of every joint centre (:mod:`.migration`)."""
    return _robust_family(data, two_axis=True, migration=True)


def _robust_family(data: JointData, *, two_axis: bool, migration: bool) -> AxisEstimate:
    _need_cycles(data)
    est = estimate_hinge(data.rotation, data.translation, "robust", data.periods)
    rh = est.robust
    assert rh is not None
    k = est.frames
    centres = _cycle_centres(data, rh.kept_cycles)
    point, direction = est.point, est.axis
    notes = []
    rejected_cycles = rh.rejected_cycles
    listed = ", ".join(str(i + 1) for i in rejected_cycles)
    if rh.rejected_frames:
        notes.append(f"{rh.rejected_frames} outlier frame(s) rejected")
    abduction = None
    choice = None
    name = data.joint.upper() or "joint"
    if two_axis and data.second_axis is not None:
        tf, choice = second_axis_choice(data)
        if choice.chosen == TWO_AXIS:
            abduction = tf
            point, direction = tf.flexion_point, tf.flexion_axis
            if rejected_cycles:
                # The two-axis fit uses every cycle: those off one axis are not slips.
                notes.append(
                    f"cycles {listed} are off one axis and kept: the two axes explain them"
                )
                rejected_cycles = []
            notes.append(
                f"two-axis {name}: ab/adduction spans {tf.abduction_range_deg:.1f} deg; rotation "
                f"off the model {np.degrees(tf.rms_hinge_rad):.2f} -> "
                f"{np.degrees(tf.rms_two_axis_rad):.2f} deg RMS"
            )
            notes.extend(tf.stability_notes())
        notes.append(f"{name}: {choice.note}")
    if rejected_cycles:
        notes.insert(0, f"cycles {listed} rejected as inconsistent with the others (sensor slip?)")
    mig = None
    if migration and not (
        abduction is not None and choice is not None and choice.order == FLEXION_FIRST
    ):
        q = data.rotation[k] @ data.reference_rotation.T
        if abduction is not None:
            beta, theta = two_axis_angles(q, direction, abduction.abduction_axis)
            extra = {"abduction_axis": abduction.abduction_axis, "beta": beta}
        else:
            theta, extra = twist_angle(q, direction), {}
        pts = fit_axis_points(
            data.rotation[k],
            data.translation[k],
            data.reference_rotation,
            direction,
            theta,
            migration=True,
            weights=est.weights,
            noise_mm=est.noise_mm,
            groups=est.groups,
            **extra,
        )
        point, mig = pts.centre, pts.migration
        if abduction is not None:
            abduction = replace(abduction, flexion_point=point)
    return AxisEstimate(
        _axis_fit(point, direction, centres),
        centres,
        abduction=abduction,
        migration=mig,
        pooled_conditioning=est.conditioning,
        rejected_frames=rh.rejected_frames,
        rejected_cycles=rejected_cycles,
        notes=notes,
        choice=choice,
    )


def second_axis_choice(data: JointData) -> tuple[TwoAxisFit, ModelChoice]:
    """The two-axis candidate of a joint that may have a second axis, and the choice.

    A candidate of each order is fitted to every movement frame of every cycle with
    uniform weights (the hinge's outlier rules and cycle weights would discard or
    down-weight exactly the cycles that carry the second degree of freedom), started from
    the SARA hinge axis, and the hinge and both are compared by
    :func:`.choice.choose_joint_model`.

    ``estimate_two_axis`` fits ``Q = Rot(b, beta) Rot(a, theta)`` with the ab/adduction
    axis ``b`` proximal; the flexion-first joint is that form seen from the child
    (:meth:`JointData.reversed`): fitted there and brought back to the parent frame.
    Returns the fit of the order :attr:`ModelChoice.order` names, parent frame. The choice
    needs only each order's directions; the joint is completed (angles, axis points) for
    the chosen order alone.
    """
    starts, directions = {}, {}
    for order in (ABDUCTION_FIRST, FLEXION_FIRST):
        d = data.reversed() if order == FLEXION_FIRST else data
        start = estimate_hinge(d.rotation, d.translation, "sara", d.periods)
        starts[order] = (d, replace(start, groups=period_labels(d.periods)))
        directions[order] = estimate_two_axis_directions(
            d.rotation, d.reference_rotation, starts[order][1], d.finger_direction
        )
    frames = np.concatenate(data.periods)
    choice = choose_joint_model(
        data.rotation[frames],
        data.translation[frames],
        data.reference_rotation,
        data.reference_offset,
        period_labels(data.periods),
        directions,
        data.second_axis or ABDUCTION_FIRST,
    )
    d, start = starts[choice.order]
    tf = estimate_two_axis(
        d.rotation,
        d.translation,
        d.reference_rotation,
        start,
        d.finger_direction,
        directions[choice.order],
    )
    if choice.order == ABDUCTION_FIRST:
        return tf, choice
    ref, off = data.reference_rotation, data.reference_offset
    back = replace(
        tf,
        flexion_axis=ref @ tf.flexion_axis,
        abduction_axis=ref @ tf.abduction_axis,
        flexion_point=ref @ tf.flexion_point + off,
        abduction_point=ref @ tf.abduction_point + off,
    )
    return back, choice


METHODS: dict[str, Callable[[JointData], AxisEstimate]] = {
    "tang2018": tang2018,
    "pooled": pooled,
    "robust": robust,
    "twoaxis": twoaxis,
    "rolling": rolling,
}
# One sentence per method and angle method, for reports.
METHOD_SUMMARY = {
    "tang2018": "the paper's estimator: a centre of rotation per grasp cycle (O'Brien et al. "
    "2000, untruncated least squares) and the line through those centres (Tang et al. 2018, "
    "eq. 1)",
    "pooled": "the SARA hinge axis over all movement frames (Ehrig et al. 2007)",
    "robust": "the SARA hinge axis after rejecting outlier frames and cycles, cycles weighted "
    "by their residual",
    "twoaxis": "robust SARA hinge axes, with a second (ab/adduction) axis at a finger's MP "
    "and the thumb's MCP where it predicts held-out grasp cycles better than one axis (the "
    "two axes' order, ab/adduction or flexion proximal, chosen by the held-out cycles' "
    "orientations)",
    "rolling": "twoaxis, with rolling-contact migration of each joint centre",
}
ANGLE_SUMMARY = {
    "projection": "projection of the child sensor's position on the plane normal to each "
    "axis (paper Fig. 6)",
    "swing_twist": "the twist of the child sensor's relative orientation about each axis "
    "(swing-twist decomposition; a two-axis joint: its proximal axis, then its distal one -- "
    "a finger's MP ab/adduction then flexion, the thumb's CMC and MCP flexion then "
    "ab/adduction)",
}
# Angle method each estimator's models use unless FitOptions.angle_method says otherwise.
METHOD_ANGLES = {"tang2018": "projection"} | {m: "swing_twist" for m in METHODS if m != "tang2018"}
