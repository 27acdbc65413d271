"""Inverse kinematics of stacked chains: the angles that best explain the sensors present.

For chain ``d`` in frame ``t`` with sensors ``s`` present (poses relative to the hand sensor,
carried back to its reference pose: :class:`Observed`), the cost is

``sum_s w_p(s) |p_s - p̂_s(q)|^2 + w_r(s) (3 - tr(R_s R̂_s(q)^T))
 + sum_k (excess_k(q) / b_k)^2 + temporal prior``

with ``w_p = 1/sigma_p^2`` and ``w_r = 1/sigma_r^2`` from each sensor's spread about the
model in the calibration recordings; ``3 - tr(R R̂^T) = 2 (1 - cos theta) ≈ theta^2`` is the
chordal distance of the two orientations (monotone up to 180 deg, so a far start still
descends); ``excess_k`` how far angle ``k`` lies outside the calibration's range, ``b_k``
a fraction of that range; the temporal prior ``((q_t - q_{t-1}) / (v_k dt))^2`` with
``v_k`` the angle's fastest calibration speed (``docs/tracking.md``).

The Gauss-Newton normal equations come without forming the Jacobian of the orientations:
for a chordal residual ``J^T J`` is ``w_r a_k·a_l`` (the axes where the chain puts them)
and ``J^T r`` is ``w_r a_k·vee(E - E^T)/2`` with ``E = R R̂^T``. Position columns are
``a_k × (p̂ - c_k)`` (plus the migration term). Everything runs over frames and chains at
once, frames last; a normal matrix is kept as its upper triangle, ``P = L (L + 1) / 2``
rows (:mod:`.packed`). :func:`solve_frames` runs Levenberg-Marquardt on every frame on its
own (optionally with a prior toward a given angle: the live filter);
:func:`.smoother.smooth` adds the temporal prior between consecutive frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import FloatArray
from .chains import ChainPose, Chains, matmul_rows, matvec_rows
from .packed import (
    cholesky_packed,
    diagonal,
    gram_rows,
    packed_matvec,
    solve_cholesky,
    solve_packed,
)

#: Added to the diagonal of every frame's normal matrix (1/rad^2): makes an undetermined
#: angle stay where it is (data terms are 1e3-1e6 per rad^2).
RIDGE = 1e-6
#: Frames evaluated together (a block's Jacobian stays in cache-sized arrays).
BLOCK = 2048
#: Largest step of one angle in one iteration (rad).
MAX_STEP = 0.5


@dataclass(frozen=True)
class Weights:
    """The weights of the cost, per chain (``D``) and level (``L``) or segment (``S``).

    Attributes
    ----------
    position : ndarray, shape (D, S)
        ``1 / sigma_p^2`` (1/mm^2) of each segment's sensor.
    orientation : ndarray, shape (D, S)
        ``1 / sigma_r^2`` (1/rad^2).
    low, high : ndarray, shape (D, L)
        The calibration's range of each angle (rad); padding levels 0.
    bound : ndarray, shape (D, L)
        ``b``: the angle outside its range by ``b`` costs as one standard deviation (rad);
        ``inf``: no bound.
    speed : ndarray, shape (D, L)
        ``v`` (rad/s) of the temporal prior; ``inf``: no temporal prior.
    """

    position: FloatArray
    orientation: FloatArray
    low: FloatArray
    high: FloatArray
    bound: FloatArray
    speed: FloatArray


@dataclass(frozen=True)
class Observed:
    """Sensor poses relative to the hand sensor, carried back to its reference pose
    (frames last).

    Attributes
    ----------
    position : ndarray, shape (D, S, 3, m)
        mm, tracker coordinates at the reference posture; 0 where not present.
    rotation : ndarray, shape (D, S, 3, 3, m)
        The segment's rotation from the reference posture, ``R R_0^T`` (``R`` the
        sensor's measured rotation, ``R_0`` its reference); identity where not present.
    present : ndarray of bool, shape (D, S, m)
    """

    position: FloatArray
    rotation: FloatArray
    present: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.present.shape[-1])

    def take(self, index: np.ndarray | slice) -> Observed:
        """The frames ``index``."""
        return Observed(
            self.position[..., index], self.rotation[..., index], self.present[..., index]
        )


def observe(
    chains: Chains,
    hand_position: FloatArray,
    hand_rotation: FloatArray,
    positions: dict[str, FloatArray],
    rotations: dict[str, FloatArray],
) -> Observed:
    """Every chain's sensors relative to the hand sensor, at its reference pose.

    Parameters
    ----------
    chains : Chains
    hand_position : ndarray, shape (m, 3)
        Hand sensor origin (mm, tracker coordinates); NaN where missing.
    hand_rotation : ndarray, shape (m, 3, 3)
    positions, rotations : dict
        Sensor name -> ``(m, 3)`` mm and ``(m, 3, 3)`` (sensor -> tracker), NaN where
        missing; a sensor absent from the dicts is missing in every frame.

    Returns
    -------
    Observed
        ``p = R_h0 R_h^T (p_s - p_h) + p_h0``, ``R = R_h0 R_h^T R_s R_s0^T``; present where
        the hand and the sensor are both complete in the frame.
    """
    m = hand_position.shape[0]
    n_chain = chains.size
    # R_h0 R_h^T of every frame, frames last: (3, 3, m).
    back = np.ascontiguousarray(
        (chains.hand_rotation @ np.swapaxes(hand_rotation, -1, -2)).transpose(1, 2, 0)
    )
    hand_p = np.ascontiguousarray(hand_position.T)  # (3, m)
    pos = np.zeros((n_chain, 3, 3, m))
    rot = np.zeros((n_chain, 3, 3, 3, m))
    present = np.zeros((n_chain, 3, m), dtype=bool)
    done: dict[str, tuple[FloatArray, FloatArray, np.ndarray]] = {}
    for d, row in enumerate(chains.sensors):
        for s, name in enumerate(row):
            if name not in positions:
                rot[d, s] = np.eye(3)[..., None]
                continue
            if name not in done:
                p = matvec_rows(back, positions[name].T - hand_p)
                p += chains.hand_position[:, None]
                r = matmul_rows(back, np.ascontiguousarray(rotations[name].transpose(1, 2, 0)))
                ok = np.isfinite(p).all(axis=0) & np.isfinite(r).all(axis=(0, 1))
                done[name] = (p, r, ok)
            p, r, ok = done[name]
            r = matmul_rows(r, chains.sensor_rotation[d, s].T[..., None])
            pos[d, s] = np.where(ok, p, 0.0)
            rot[d, s] = np.where(ok, r, np.eye(3)[..., None])
            present[d, s] = ok
    return Observed(pos, rot, present)


@dataclass(frozen=True)
class Terms:
    """The sensors' part of the normal equations at ``q`` (frames last).

    Attributes
    ----------
    hessian : ndarray, shape (D, P, m)
        Upper triangle of ``J^T W J`` (:func:`pairs` order).
    gradient : ndarray, shape (D, L, m)
        ``J^T W r`` (``r`` measured minus predicted): the step's right-hand side.
    cost : ndarray, shape (D, m)
        Weighted sum of squares of the sensors.
    rms_mm : ndarray, shape (D, m)
        RMS over the present sensors of the position residual's length (mm); NaN with none.
    """

    hessian: FloatArray
    gradient: FloatArray
    cost: FloatArray
    rms_mm: FloatArray


def data_terms(
    chains: Chains, weights: Weights, obs: Observed, q: FloatArray, pose: ChainPose | None = None
) -> Terms:
    """The sensors' part of the normal equations at ``q (D, L, m)`` (see the module notes),
    evaluated in blocks of :data:`BLOCK` frames; ``pose``: the chains already posed at
    ``q`` (one block)."""
    m = q.shape[-1]
    if m > BLOCK:
        L = chains.L
        out = Terms(
            np.empty((q.shape[0], L * (L + 1) // 2, m)),
            np.empty(q.shape),
            np.empty((q.shape[0], m)),
            np.empty((q.shape[0], m)),
        )
        for s in range(0, m, BLOCK):
            part = data_terms(chains, weights, obs.take(slice(s, s + BLOCK)), q[..., s : s + BLOCK])
            for f in Terms.__dataclass_fields__:
                getattr(out, f)[..., s : s + BLOCK] = getattr(part, f)
        return out
    if pose is None:
        pose = chains.pose(q)
    n_chain, L, m = q.shape
    present = obs.present
    wp = present * weights.position[..., None]  # (D, S, m)
    wr = present * weights.orientation[..., None]
    e = obs.position - pose.sensor_position  # (D, S, 3, m); 0 - p̂ where absent: weight 0
    # The orientation's residual: the vector of the skew part of E = R A^T (R the measured
    # segment rotation, A the predicted one), vee(E - E^T) / 2 = sum_k a_k x r_k / 2 over
    # the columns a_k of A and r_k of R: no product of the two matrices is needed.
    A, R = pose.segment_rotation, obs.rotation  # (D, S, 3, 3, m)
    skew_part = np.empty(e.shape)
    if m == 1:  # one frame (live): E itself, one small matmul
        E = R[..., 0] @ np.swapaxes(A[..., 0], -1, -2)  # (D, S, 3, 3)
        np.subtract(E[..., 2, 1], E[..., 1, 2], out=skew_part[:, :, 0, 0])
        np.subtract(E[..., 0, 2], E[..., 2, 0], out=skew_part[:, :, 1, 0])
        np.subtract(E[..., 1, 0], E[..., 0, 1], out=skew_part[:, :, 2, 0])
    else:
        skew_part[:] = 0.0
        for k in range(3):
            a, r = A[:, :, :, k], R[:, :, :, k]
            skew_part[:, :, 0] += a[:, :, 1] * r[:, :, 2] - a[:, :, 2] * r[:, :, 1]
            skew_part[:, :, 1] += a[:, :, 2] * r[:, :, 0] - a[:, :, 0] * r[:, :, 2]
            skew_part[:, :, 2] += a[:, :, 0] * r[:, :, 1] - a[:, :, 1] * r[:, :, 0]
    skew_part *= 0.5  # (D, S, 3, m)
    # The weighted Jacobian's rows, (D, L, 2 S, 3, m): per segment s three position rows,
    # a_k x (p̂_s - c_k) (+ migration), and three orientation rows, a_k (for a chordal
    # residual J^T J = a_k·a_l); zero where axis k does not move segment s.
    a = pose.axes[:, :, None]  # (D, L, 1, 3, m)
    d = pose.sensor_position[:, None] - pose.centres[:, :, None]  # (D, L, S, 3, m)
    S = d.shape[2]
    j = np.empty((n_chain, L, 2 * S, 3, m))
    jp = j[:, :, :S]
    np.multiply(a[:, :, :, 1], d[:, :, :, 2], out=jp[:, :, :, 0])
    jp[:, :, :, 0] -= a[:, :, :, 2] * d[:, :, :, 1]
    np.multiply(a[:, :, :, 2], d[:, :, :, 0], out=jp[:, :, :, 1])
    jp[:, :, :, 1] -= a[:, :, :, 0] * d[:, :, :, 2]
    np.multiply(a[:, :, :, 0], d[:, :, :, 1], out=jp[:, :, :, 2])
    jp[:, :, :, 2] -= a[:, :, :, 1] * d[:, :, :, 0]
    if pose.migration is not None:
        jp += pose.migration[:, :, None]
    j[:, :, S:] = a
    root = np.sqrt(np.concatenate([wp, wr], axis=1))  # (D, 2 S, m)
    j *= np.concatenate([chains.moves, chains.moves], axis=2)[..., None, None]
    j *= root[:, None, :, None, :]
    r = np.concatenate([e, skew_part], axis=1)  # (D, 2 S, 3, m): measured minus predicted
    r *= root[:, :, None]
    j = j.reshape(n_chain, L, 6 * S, m)
    r = r.reshape(n_chain, 6 * S, m)
    hessian = gram_rows(j)
    gradient = np.einsum("dlkm,dkm->dlm", j, r)  # (D, L, m)
    sq = (e * e).sum(axis=2) * present  # (D, S, m)
    # 3 - tr(R A^T) = |R - A|^2 / 2, without the cancellation of 3 - tr near the optimum.
    chord = obs.rotation - pose.segment_rotation
    chord *= chord
    cost = (wp * sq).sum(axis=1) + 0.5 * (wr * chord.sum(axis=(2, 3))).sum(axis=1)
    count = present.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(sq.sum(axis=1) / count)
    return Terms(hessian, gradient, cost, rms)


def bound_terms(weights: Weights, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The soft bounds at ``q (D, L, m)``: diagonal of the normal matrix ``(D, L, m)``,
    right-hand side ``(D, L, m)`` and cost ``(D, m)``."""
    low, high = weights.low[..., None], weights.high[..., None]
    excess = q - np.clip(q, low, high)
    inv = (1.0 / weights.bound**2)[..., None]
    return (excess != 0.0) * inv, -excess * inv, (excess * excess * inv).sum(axis=1)


def wrap(q: FloatArray) -> FloatArray:
    """Angles ``q`` (rad) in ``[-pi, pi)``: the same rotations, no turn counted twice."""
    return (q + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class Solution:
    """Angles found for a block of frames (frames last).

    Attributes
    ----------
    q : ndarray, shape (D, L, m)
        rad (padding levels 0).
    rms_mm : ndarray, shape (D, m)
        RMS position residual of the present sensors (mm).
    hessian : ndarray, shape (D, P, m)
        The sensors' normal matrix at ``q`` (upper triangle), for :func:`uncertainty`.
    iterations : int
    cost : ndarray, shape (D, m), optional
        Each frame's cost at ``q`` (:func:`solve_frames`: sensors, bounds and prior).
    """

    q: FloatArray
    rms_mm: FloatArray
    hessian: FloatArray
    iterations: int
    cost: FloatArray | None = None


def gauss_newton_step(
    chains: Chains,
    weights: Weights,
    obs: Observed,
    q: FloatArray,
    prior: tuple[FloatArray, FloatArray] | None = None,
    pose: ChainPose | None = None,
) -> tuple[FloatArray, FloatArray, float]:
    """One Gauss-Newton step of every frame (the live filter's: no step control; a frame
    starts within one frame's motion of its solution).

    Parameters
    ----------
    chains, weights, obs
        As :func:`solve_frames`.
    q : ndarray, shape (D, L, m)
        Where the step starts (rad).
    prior : (ndarray, ndarray), optional
        ``(centre (D, L, m) rad, information (D, P, m) 1/rad^2)``: adds
        ``(q - centre)^T Lambda (q - centre)``, ``Lambda`` given as its upper triangle
        (:func:`pairs` order): the filter's prior from the frame before.
    pose : ChainPose, optional
        The chains posed at ``q`` (kept from the frame before).

    Returns
    -------
    q : ndarray, shape (D, L, m)
        After the step (rad).
    hessian : ndarray, shape (D, P, m)
        The normal matrix of the step (sensors, bounds, prior; upper triangle): the
        information of the solution, for the next frame's prior.
    moved : float
        The largest change of an angle (rad).
    """
    pad = (~chains.active)[..., None]
    diag = diagonal(chains.L)
    t = data_terms(chains, weights, obs, q, pose)
    bd, bg, _ = bound_terms(weights, q)
    h = t.hessian
    h[:, diag] += bd + RIDGE + pad
    g = t.gradient + bg
    if prior is not None:
        centre, info = prior
        h += info
        g += packed_matvec(info, centre - q)
    g *= ~pad
    step = np.clip(solve_packed(h, g), -MAX_STEP, MAX_STEP)
    return wrap(q + step), h, float(np.abs(step).max(initial=0.0))


#: A frame has converged when its step would lower its cost by less than this (the cost is
#: a chi-square: a sensor's standard deviation is 1): the step is below a thousandth of
#: what the frame's sensors determine.
DECREMENT = 1e-6


def solve_frames(
    chains: Chains,
    weights: Weights,
    obs: Observed,
    q0: FloatArray,
    prior: tuple[FloatArray, FloatArray] | None = None,
    *,
    max_iter: int = 30,
    decrement: float = DECREMENT,
) -> Solution:
    """Levenberg-Marquardt on every frame at once, each frame on its own.

    Frames that have converged (every chain's step lowers its cost by less than
    ``decrement``) leave the batch; the others go on.

    Parameters
    ----------
    chains : Chains
    weights : Weights
    obs : Observed
        ``m`` frames.
    q0 : ndarray, shape (D, L, m)
        Start (rad).
    prior : (ndarray, ndarray), optional
        ``(centre (D, L, m) rad, weight (D, L, m) 1/rad^2)``: adds ``weight (q - centre)^2``
        (the live filter's prior toward the previous frame).
    max_iter : int
    decrement : float
        Convergence, in the cost's units (chi-square).

    Returns
    -------
    Solution
        ``iterations``: of the slowest frame.
    """
    pad = (~chains.active)[..., None]
    diag = diagonal(chains.L)

    def evaluate(x: FloatArray, cols: np.ndarray | slice) -> tuple:
        sub = obs if isinstance(cols, slice) else obs.take(cols)
        t = data_terms(chains, weights, sub, x)
        bd, bg, bc = bound_terms(weights, x)
        h = t.hessian.copy()
        h[:, diag] += bd + RIDGE + pad
        g = t.gradient + bg
        c = t.cost + bc
        if prior is not None:
            centre, w = prior[0][..., cols], prior[1][..., cols]
            h[:, diag] += w
            g += w * (centre - x)
            c += (w * (x - centre) ** 2).sum(axis=1)
        g *= ~pad
        return h, g, c, t

    q = np.where(pad, 0.0, q0)
    h, g, cost, t = evaluate(q, slice(None))
    data_h, rms = t.hessian, t.rms_mm
    lam = np.full(cost.shape, 1e-3)[:, None, :]
    cols = np.arange(q.shape[-1])
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        a = h[..., cols].copy()
        a[:, diag] *= 1.0 + lam[..., cols]
        gc = g[..., cols]
        step = np.clip(solve_packed(a, gc), -MAX_STEP, MAX_STEP)
        # Converged: the undamped (Gauss-Newton) step would lower the cost by < decrement.
        newton = (solve_packed(h[..., cols], gc) * gc).sum(axis=1)
        done = (newton < decrement).all(axis=0)  # (k,)
        trial = wrap(q[..., cols] + step)
        h2, g2, cost2, t2 = evaluate(trial, cols)
        ok = cost2 <= cost[..., cols] * (1.0 + 1e-12) + 1e-12  # not refused for rounding
        ok1 = ok[:, None]
        q[..., cols] = np.where(ok1, trial, q[..., cols])
        h[..., cols] = np.where(ok1, h2, h[..., cols])
        g[..., cols] = np.where(ok1, g2, gc)
        data_h[..., cols] = np.where(ok1, t2.hessian, data_h[..., cols])
        rms[..., cols] = np.where(ok, t2.rms_mm, rms[..., cols])
        cost[..., cols] = np.where(ok, cost2, cost[..., cols])
        lam[..., cols] = np.where(ok1, lam[..., cols] / 3.0, lam[..., cols] * 4.0)
        cols = cols[~done]
        if cols.size == 0:
            break
    return Solution(q, rms, data_h, it, cost)


def uncertainty(chains: Chains, hessian: FloatArray) -> FloatArray:
    """Standard deviation of every angle from the sensors of its frame alone.

    Parameters
    ----------
    chains : Chains
    hessian : ndarray, shape (D, P, m)
        The sensors' normal matrix at the solution (:attr:`Solution.hessian`).

    Returns
    -------
    ndarray, shape (D, L, m)
        ``sqrt(diag((J^T W J)^-1))`` (rad): what the frame's sensors determine, without the
        bounds and the temporal prior; ``inf`` where they do not determine the angle (more
        than 1 rad), NaN on padding levels.
    """
    L = chains.L
    pad = (~chains.active)[..., None]
    h = hessian.copy()
    h[:, diagonal(L)] += RIDGE + pad
    u = cholesky_packed(h)
    var = np.empty((*h.shape[:1], L, h.shape[-1]))
    for k in range(L):
        e = np.zeros(var.shape)
        e[:, k] = 1.0
        var[:, k] = solve_cholesky(u, e)[:, k]
    sd = np.sqrt(np.maximum(var, 0.0))
    sd[sd > 1.0] = np.inf
    return np.where(pad, np.nan, sd)
