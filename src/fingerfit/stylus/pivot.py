"""Pivot calibration of a stylus: where its tip sits in its sensor's frame.

The stylus is turned about its tip resting in a divot. Every frame ``i`` then satisfies
``R_i r + t_i = P``: ``r`` the tip in the sensor frame, ``P`` the divot in the tracker
frame, ``R_i`` (sensor -> tracker) and ``t_i`` (mm) the sensor's pose. Stacking
``[R_i  -I] [r; P] = -t_i`` over the frames gives a linear least-squares problem in six
unknowns, solved here with Huber weights (a few iteratively reweighted solves: a slipped
tip or a distorted sample weighs less) -- ``docs/lab.md``, *Stylus*.

Whether the rotations determine the tip is decided from the solution's own uncertainty:
the covariance ``s^2 (A^T W A)^-1``, ``s^2`` the residual variance inflated for the
residuals' correlation from frame to frame (a tracker's errors are not independent at
240 Hz: the effective number of frames is ``n (1 - rho) / (1 + rho)``, ``rho`` their
lag-one autocorrelation) -- or, when larger, the delete-one-block jackknife over
:data:`JACKKNIFE_BLOCKS` stretches of the recording, which also sees part of an error that
follows the stylus's orientation (a field distortion: it does not average out, and a
recording's residuals cannot show all of it, ``docs/lab.md``). A recording that barely
turns leaves ``r`` free along the stylus and is refused: its 95 % half-width along the
worst direction is over :data:`MAX_TIP_CI_MM`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray

#: The largest 95 % half-width (mm) of the tip offset along its worst direction that a
#: calibration may have (``../shared``'s method notes: "refuse when r's uncertainty is
#: over ~0.5 mm").
MAX_TIP_CI_MM = 0.5
#: Huber's tuning constant, in units of the residuals' robust scale (95 % efficiency).
HUBER_K = 1.345
#: Consecutive stretches of the recording the jackknife leaves out in turn.
JACKKNIFE_BLOCKS = 10
#: Frames at most used for the rotation span (evenly spaced; the span is pairwise).
SPAN_FRAMES = 400


@dataclass(frozen=True)
class PivotFit:
    """A stylus pivot calibration.

    Attributes
    ----------
    tip_offset_mm : ndarray, shape (3,)
        The tip in the stylus sensor's frame, mm.
    pivot_mm : ndarray, shape (3,)
        The divot in the tracker frame, mm.
    rms_mm : float
        RMS distance of the frames' tips ``R_i r + t_i`` from the pivot, mm.
    rotation_span_deg : float
        The largest angle between the stylus orientations of two frames (of at most
        :data:`SPAN_FRAMES` evenly spaced), degrees.
    n_frames : int
        Frames with a complete pose (the fit's).
    tip_ci_mm : float
        95 % half-width of ``tip_offset_mm`` along its worst-determined direction, mm.
    tip_ci_direction : ndarray, shape (3,)
        That direction, sensor frame (unit).
    downweighted : int
        Frames the Huber weights took at less than half weight.
    """

    tip_offset_mm: FloatArray
    pivot_mm: FloatArray
    rms_mm: float
    rotation_span_deg: float
    n_frames: int
    tip_ci_mm: float
    tip_ci_direction: FloatArray
    downweighted: int


def _sums(
    rot: FloatArray, pos: FloatArray, w: FloatArray
) -> tuple[float, FloatArray, FloatArray, FloatArray]:
    """The weighted sums the normal equations are made of: ``sum w``, ``sum w R``
    ``(3, 3)``, ``sum w R^T t`` ``(3,)``, ``sum w t`` ``(3,)``."""
    return (
        float(w.sum()),
        np.einsum("n,nij->ij", w, rot),
        np.einsum("n,nji,nj->i", w, rot, pos),
        np.einsum("n,ni->i", w, pos),
    )


def _solve(rot: FloatArray, pos: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted normal equations of ``[R_i -I][r; P] = -t_i``: the solution ``(6,)`` and
    ``(A^T W A)^-1`` ``(6, 6)``."""
    return _solve_sums(*_sums(rot, pos, w))


def _solve_sums(
    sw: float, sr: FloatArray, srt: FloatArray, st: FloatArray
) -> tuple[FloatArray, FloatArray]:
    n = np.zeros((6, 6))
    n[:3, :3] = sw * np.eye(3)  # sum w R^T R
    n[3:, 3:] = sw * np.eye(3)
    n[3:, :3] = -sr  # sum w (-I)^T R
    n[:3, 3:] = -sr.T
    rhs = np.concatenate([-srt, st])
    try:
        inv = np.linalg.inv(n)
    except np.linalg.LinAlgError:
        inv = np.full((6, 6), np.inf)
        return np.full(6, np.nan), inv
    return inv @ rhs, inv


def rotation_span_deg(rot: FloatArray) -> float:
    """The largest angle (deg) between two of the orientations ``rot (n, 3, 3)``, over at
    most :data:`SPAN_FRAMES` evenly spaced frames."""
    if rot.shape[0] < 2:
        return 0.0
    idx = np.unique(np.linspace(0, rot.shape[0] - 1, min(SPAN_FRAMES, rot.shape[0])).astype(int))
    r = rot[idx]
    # trace(R_i^T R_j) = sum of elementwise products.
    tr = np.einsum("ikl,jkl->ij", r, r)
    return float(np.degrees(np.arccos(np.clip((tr.min() - 1.0) / 2.0, -1.0, 1.0))))


def _jackknife_cov(rot: FloatArray, pos: FloatArray, w: FloatArray, blocks: int) -> FloatArray:
    """Delete-one-block jackknife covariance ``(3, 3)`` of the tip offset over ``blocks``
    consecutive stretches (the whole-recording sums less each block's)."""
    edges = np.linspace(0, rot.shape[0], blocks + 1).astype(int)
    whole = _sums(rot, pos, w)
    tips = []
    for a, b in itertools.pairwise(edges):
        part = _sums(rot[a:b], pos[a:b], w[a:b])
        sol, _ = _solve_sums(*(x - y for x, y in zip(whole, part, strict=True)))
        tips.append(sol[:3])
    t = np.array(tips)
    c = t - t.mean(axis=0)
    return (blocks - 1) / blocks * (c.T @ c)


def _lag_one(e: FloatArray) -> float:
    """Lag-one autocorrelation of residual vectors ``(n, 3)`` in time (0 for < 3)."""
    if e.shape[0] < 3:
        return 0.0
    c = e - e.mean(axis=0)
    den = float((c * c).sum())
    return 0.0 if den == 0 else float((c[1:] * c[:-1]).sum() / den)


def fit_pivot(
    position: FloatArray,
    rotation: FloatArray,
    *,
    max_tip_ci_mm: float = MAX_TIP_CI_MM,
    iterations: int = 10,
) -> PivotFit:
    """Pivot calibration from a stylus turned about its tip in a divot.

    Parameters
    ----------
    position : ndarray, shape (n_frames, 3)
        Stylus sensor origin, tracker frame, mm; NaN where missing.
    rotation : ndarray, shape (n_frames, 3, 3)
        Stylus sensor -> tracker rotation; NaN where missing.
    max_tip_ci_mm : float
        Refuse when the tip offset's 95 % half-width along its worst direction is over
        this (mm).
    iterations : int
        Huber reweighting iterations at most.

    Returns
    -------
    PivotFit

    Raises
    ------
    FingerfitError
        Fewer than 10 complete frames, or rotations that do not determine the tip (the
        message gives the half-width, the span and what to do).
    """
    ok = np.isfinite(position).all(axis=1) & np.isfinite(rotation).reshape(-1, 9).all(axis=1)
    pos, rot = position[ok], rotation[ok]
    n = pos.shape[0]
    if n < 10:
        raise FingerfitError(f"{n} frame(s) with a complete stylus pose: a pivot needs more")
    w = np.ones(n)
    sol = np.zeros(6)
    for _ in range(iterations):
        new, inv = _solve(rot, pos, w)
        if not np.isfinite(new).all():
            break
        e = np.einsum("nij,j->ni", rot, new[:3]) + pos - new[3:]
        d = np.linalg.norm(e, axis=1)
        # The Huber scale of the residual norms: 1.85 times their median (for 3-D Gaussian
        # noise of SD s per axis the median norm is about 1.54 s, so this is about 2.9 s).
        scale = 1.4826 * np.median(d) / 0.8 + 1e-12
        w_new = np.minimum(1.0, HUBER_K * scale / np.maximum(d, 1e-12))
        done = np.allclose(new, sol, atol=1e-6)
        sol, w = new, w_new
        if done:
            break
    span = rotation_span_deg(rot)
    new, inv = _solve(rot, pos, w)
    if np.isfinite(new).all():
        sol = new
    e = np.einsum("nij,j->ni", rot, sol[:3]) + pos - sol[3:]
    rms = float(np.sqrt((e * e).sum(axis=1).mean()))
    dof = max(3 * n - 6, 1)
    s2 = float((w[:, None] * e * e).sum() / dof)
    rho = min(max(_lag_one(e), 0.0), 0.999)
    cov = s2 * (1 + rho) / (1 - rho) * inv[:3, :3]
    if n >= 10 * JACKKNIFE_BLOCKS and np.isfinite(cov).all():
        jack = _jackknife_cov(rot, pos, w, JACKKNIFE_BLOCKS)
        if np.isfinite(jack).all() and np.linalg.eigvalsh(jack)[-1] > np.linalg.eigvalsh(cov)[-1]:
            cov = jack
    if np.isfinite(cov).all():
        vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
        ci = float(1.96 * np.sqrt(max(vals[-1], 0.0)))
        direction = vecs[:, -1]
    else:
        ci, direction = float("inf"), np.full(3, np.nan)
    if not (ci <= max_tip_ci_mm):
        raise FingerfitError(
            f"the rotations do not determine the tip: +/-{ci:.2g} mm (95 %) along its "
            f"worst direction (over {max_tip_ci_mm:g} mm), the stylus turned through "
            f"{span:.1f} deg: pivot it through a cone of 20-40 deg about its tip, with some "
            "roll"
        )
    return PivotFit(
        tip_offset_mm=sol[:3].copy(),
        pivot_mm=sol[3:].copy(),
        rms_mm=rms,
        rotation_span_deg=span,
        n_frames=n,
        tip_ci_mm=ci,
        tip_ci_direction=direction,
        downweighted=int((w < 0.5).sum()),
    )
