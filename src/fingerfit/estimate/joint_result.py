"""The result of one joint fit (:func:`.joint.fit_joint`): the joint in both segments'
frames and the figures of how well the motion determined it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..transforms import FloatArray


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


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
