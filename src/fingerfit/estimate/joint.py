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

Here: the public functions and the fit of each kind. Beside it: :mod:`.joint_checks` (the
input and the refusals), :mod:`.joint_estimators` (the hinge and two-axis estimators as
configured for this API and the finger pipeline), :mod:`.bootstrap` (the spread figures)
and :mod:`.joint_result` (:class:`JointFit`, :class:`JointQuality`); their public names
are importable from here too.
"""

from __future__ import annotations

import math

import numpy as np

from ..angles import twist_angle, two_axis_angles
from ..errors import FingerfitError
from ..transforms import (
    FloatArray,
    axis_angle_matrix,
    rotation_vector,
)
from .bootstrap import BOOTSTRAP_BLOCKS, _centre_bootstrap_mm, axis_bootstrap_deg
from .bootstrap import BOOTSTRAP_RESAMPLES as BOOTSTRAP_RESAMPLES
from .centre import centre_of_rotation
from .joint_checks import MAX_PIVOT_MM as MAX_PIVOT_MM
from .joint_checks import MIN_FRAMES as MIN_FRAMES
from .joint_checks import (
    MIN_ROM_DEG,
    _check_common_centre,
    _check_convention,
    _check_motion,
    _check_units,
    _Motion,
    _motion,
    _Work,
    range_of_motion_deg,
)
from .joint_checks import TRANSLATION_MM as TRANSLATION_MM
from .joint_estimators import HINGE_METHODS, HingeEstimate, estimate_hinge, estimate_two_axis
from .joint_result import JointFit, JointQuality
from .twoaxis import MIN_RANGE_DEG

KINDS = ("hinge", "two_axis", "ball", "auto")

#: A hinge needs the rotation about its axis to be this many times the rotation off it
#: (``s5/s6`` of the SARA system; the finger pipeline's ``min_conditioning``).
MIN_HINGE_CONDITIONING = 3.0
#: A ball joint needs rotation about more than one axis: ``s5/s6`` above this means the
#: motion turns about one axis and the centre along it is not determined.
MAX_BALL_CONDITIONING = 10.0
#: ``kind="auto"`` takes a two-axis joint over a hinge only when its second axis spans at
#: least this (deg, 5th-95th percentile); ``kind="two_axis"`` accepts from 1.5 deg.
AUTO_MIN_SECOND_DEG = 5.0


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
