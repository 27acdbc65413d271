"""The hinge estimators as the joint API and the finger pipeline invoke them: one place
that configures SARA/SCoRE, the outlier rules and the per-cycle line (:func:`estimate_hinge`),
and the two-axis fit started from a hinge (:func:`estimate_two_axis`; its directions alone:
:func:`estimate_two_axis_directions`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray
from .axis import AxisFit, line_through_centres
from .bootstrap import BOOTSTRAP_BLOCKS
from .centre import CentreFit, centre_of_rotation
from .pooled import PooledHinge, pooled_hinge, sara_axis
from .robust import RobustHinge, robust_hinge
from .twoaxis import TwoAxisDirections, TwoAxisFit, fit_two_axis, two_axis_directions

HINGE_METHODS = ("sara", "robust", "tang2018")


def _conditioning(singular_values: FloatArray) -> float:
    """``s5 / s6`` of a hinge fit's two smallest singular values (inf for an exact hinge)."""
    s5, s6 = singular_values
    return float(s5 / s6) if s6 > 0 else math.inf


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


def _hinge_frames(hinge: HingeEstimate) -> tuple[np.ndarray, np.ndarray]:
    """The frames a hinge fit used ``(k,)`` and their groups ``(k,)``: its cycles, else
    :data:`BOOTSTRAP_BLOCKS` contiguous time blocks."""
    k = hinge.frames
    groups = hinge.groups
    if groups is None:
        groups = np.arange(k.size) * BOOTSTRAP_BLOCKS // k.size
    return k, groups


def estimate_two_axis_directions(
    rotation: FloatArray,
    reference_rotation: FloatArray,
    hinge: HingeEstimate,
    finger_direction: FloatArray | None = None,
) -> TwoAxisDirections:
    """The directions :func:`estimate_two_axis` would fit, alone (its arguments of the same
    names): :func:`.twoaxis.two_axis_directions` on the hinge's frames, weights and groups.

    Returns
    -------
    TwoAxisDirections
        Parent frame at the reference posture; pass it to :func:`estimate_two_axis` as
        ``directions`` to complete the joint without searching again.
    """
    k, groups = _hinge_frames(hinge)
    return two_axis_directions(
        rotation[k], reference_rotation, hinge.axis, hinge.weights, finger_direction, groups
    )


def estimate_two_axis(
    rotation: FloatArray,
    translation: FloatArray,
    reference_rotation: FloatArray,
    hinge: HingeEstimate,
    finger_direction: FloatArray | None = None,
    directions: TwoAxisDirections | None = None,
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
    directions : TwoAxisDirections, optional
        :func:`estimate_two_axis_directions` of the same arguments, when already found.

    Returns
    -------
    TwoAxisFit
        :func:`.twoaxis.fit_two_axis`'s result; ``accepted`` says whether the data
        support the second axis.
    """
    k, groups = _hinge_frames(hinge)
    return fit_two_axis(
        rotation[k], translation[k], reference_rotation, hinge.axis, hinge.weights,
        hinge.noise_mm, finger_direction, groups, directions,
    )  # fmt: skip
