"""The ``tip`` method: per frame, robot joints minimising scaled fingertip error + pinch + smoothness.

For frame ``t`` with targets ``T_i`` (robot palm frame) and the previous solution
``q_prev`` (warm start; the first frame starts from the prior posture), a projected Gauss-Newton / damped least-squares iteration
minimises

    sum_i w_i |p_i(q) - T_i|^2                                 (fingertips, mm)
  + sum_p w_p(t) |(p_a(q) - p_b(q)) - v_p|^2                   (pinch: pad-to-pad vectors)
  + s^2 |q - q_prev|^2                                         (smoothness, mm/rad)
  + r^2 |q - q_prior|^2                                        (posture prior, mm/rad)
  + W^2 |c.(q + dq) - edge|^2 for couplings a step would take out of their band

over the free joints (the digits' chains; the wrist and absent digits are held), with
``dq = -(A^T A + mu I)^-1 A^T r`` over the joints not pinned at a limit the step pushes
against, then :meth:`fingerfit.retarget.limits.Limits.project` onto limits and couplings.
The prior is the ``joint`` method's posture (the person's angles through the map): a
weak pull that picks, among robot postures reaching the same tips, the one most like the
person's, and keeps the solver out of the local minima of fingers folded at a limit.
Everything inside an iteration is NumPy over joints and frames of the robot; the only
Python loops are over video frames (sequential by the warm start) and iterations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..transforms import FloatArray
from .limits import Limits
from .palm import Frame
from .robots import Robot

#: Residual units: positions are solved in millimetres (robot metres x 1000).
MM = 1000.0


@dataclass(frozen=True)
class TipOptions:
    """Weights and stopping rule of the ``tip`` solver.

    Attributes
    ----------
    smooth : float
        ``s`` (mm per rad): a joint change of 1 rad between frames costs as much as ``s`` mm
        of fingertip error. Large enough that a finger does not flip between two postures
        of nearly equal cost (jerk), small against the fingertip rows of a moving finger:
        at 240 Hz a joint moving 3 rad/s lags by ~0.1 mm (``docs/retargeting.md``).
    damping : float
        ``mu`` (mm^2/rad^2), Levenberg damping.
    pinch : float
        Largest pinch weight (relative to a fingertip's 1).
    prior : float
        ``r`` (mm per rad) of the posture prior (used when a prior is given).
    coupling : float
        ``W`` (mm/rad) of the stiff rows of active couplings (the projection makes them exact).
    iterations : int
        Most Gauss-Newton iterations per frame.
    restart_mm : float
        When a fingertip is still this far (mm) from its target, solve the frame again
        from the prior posture and keep the cheaper solution (only while that error grows
        by more than 0.5 mm a frame, or every 10th frame: an unreachable target costs a second
        solve only on every 10th frame).
    polish_smooth, polish_iterations : float, int
        After the solve, up to ``polish_iterations`` more with smoothness ``polish_smooth``
        (mm/rad) from the solution: the strong smoothness chose the posture, the polish
        removes its lag. Off by default (``polish_smooth = smooth``): on the benchmark it
        halved nothing but the lag and raised jerk 3-4x (docs/retargeting.md).
    max_step : float
        Largest joint change of one iteration (rad); a longer step is shortened.
    tol : float
        Stop when the largest joint step is below this (rad).
    """

    smooth: float = 20.0
    damping: float = 1e-3
    pinch: float = 10.0
    prior: float = 5.0
    coupling: float = 100.0
    iterations: int = 6
    restart_mm: float = 10.0
    polish_smooth: float = 20.0
    polish_iterations: int = 3
    max_step: float = 0.2
    tol: float = 1e-4


@dataclass(frozen=True)
class TipProblem:
    """What the solver needs about the robot.

    Attributes
    ----------
    robot : Robot
    palm : Frame
        Robot palm frame (robot world, m); fixed because its joints are held.
    frames : list of str
        Robot frames whose positions enter the cost (tips, then pads).
    free : ndarray of int
        Indices of the joints solved for (the others keep ``hold``).
    hold : ndarray, shape (nq,)
        Start and held configuration (rad).
    limits : Limits
    """

    robot: Robot
    palm: Frame
    frames: list[str]
    free: np.ndarray
    hold: FloatArray
    limits: Limits
    _ids: list = field(default_factory=list, repr=False)

    def kinematics(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Frame positions ``(k, 3)`` mm and Jacobians ``(k, 3, n_free)`` mm/rad, palm frame."""
        if not self._ids:
            self._ids.extend(self.robot.frame_ids(self.frames))
        pos, jac = self.robot.jacobians(q, self._ids)
        r = self.palm.rotation
        p = (pos - self.palm.origin) @ r * MM
        j = np.einsum("ji,kjm->kim", r, jac[:, :, self.free]) * MM
        return p, j


@dataclass(frozen=True)
class TipResult:
    """Joint trajectory and solver statistics.

    Attributes
    ----------
    q : ndarray, shape (n, nq)
        rad, every robot joint.
    seconds : ndarray, shape (n,)
        Wall time of each frame's solve.
    iterations : ndarray, shape (n,)
    """

    q: FloatArray
    seconds: FloatArray
    iterations: np.ndarray


def solve_tip(
    problem: TipProblem,
    targets: FloatArray,
    weights: FloatArray | None = None,
    pinch_pairs: list[tuple[int, int]] | None = None,
    pinch_targets: FloatArray | None = None,
    pinch_weights: FloatArray | None = None,
    options: TipOptions | None = None,
    prior: FloatArray | None = None,
) -> TipResult:
    """Solve every frame, warm-started from the previous one.

    Parameters
    ----------
    problem : TipProblem
    targets : ndarray, shape (n, k, 3)
        Target of each of the first ``k`` frames of ``problem.frames`` (robot palm frame,
        mm); NaN rows (a missing sensor) are left out of that frame's cost.
    weights : ndarray, shape (n, k), optional
        Per-frame fingertip weights (default 1).
    pinch_pairs : list of (int, int), optional
        Indices into ``problem.frames`` of each pinch pair's two points (``p``).
    pinch_targets : ndarray, shape (n, p, 3)
        Target of ``point_a - point_b`` (mm, palm frame).
    pinch_weights : ndarray, shape (n, p)
        0 (no pinch) .. 1, scaled by ``options.pinch``.
    options : TipOptions, optional
    prior : ndarray, shape (n, nq), optional
        Posture prior per frame (rad), e.g. the ``joint`` method's output.

    Returns
    -------
    TipResult
        A frame whose targets are all missing keeps the previous configuration.
    """
    o = options or TipOptions()
    n, k = targets.shape[:2]
    weights = np.ones((n, k)) if weights is None else weights
    pairs = np.array(pinch_pairs or [], dtype=int).reshape(-1, 2)
    n_free = problem.free.size
    lim = problem.limits
    # Soft coupling rows over free joints (coupled joints are expected to be free).
    pos = {j: i for i, j in enumerate(problem.free)}
    c_rows = [
        (pos[a], pos[b], ca, cb, lo, hi)
        for a, b, ca, cb, lo, hi in zip(lim.a, lim.b, lim.ca, lim.cb, lim.lo, lim.hi, strict=True)
        if a in pos and b in pos
    ]
    c_mat = np.zeros((len(c_rows), n_free))
    for r, (ia, ib, ca, cb, _, _) in enumerate(c_rows):
        nrm = np.hypot(ca, cb)
        c_mat[r, ia], c_mat[r, ib] = ca / nrm, cb / nrm
    c_lo = np.array([lo / np.hypot(ca, cb) for _, _, ca, cb, lo, _ in c_rows])
    c_hi = np.array([hi / np.hypot(ca, cb) for _, _, ca, cb, _, hi in c_rows])
    lo_f, hi_f = lim.lower[problem.free], lim.upper[problem.free]
    eye = np.eye(n_free)

    out = np.empty((n, problem.hold.size))
    secs = np.empty(n)
    iters = np.zeros(n, dtype=int)

    def gauss_newton(q, q_prev, t, tgt, w, pw, pv, smooth=o.smooth, iterations=o.iterations):
        cost = np.inf
        it = 0
        for it in range(iterations):  # noqa: B007
            p, jac = problem.kinematics(q)
            res = [((p[:k] - tgt) * w[:, None]).ravel()]
            rows = [(jac[:k] * w[:, None, None]).reshape(-1, n_free)]
            if pairs.size:
                d = p[pairs[:, 0]] - p[pairs[:, 1]] - pv
                res.append((d * pw[:, None]).ravel())
                rows.append(
                    ((jac[pairs[:, 0]] - jac[pairs[:, 1]]) * pw[:, None, None]).reshape(-1, n_free)
                )
            qf = q[problem.free]
            res.append(smooth * (qf - q_prev[problem.free]))
            rows.append(smooth * eye)
            if prior is not None:
                res.append(o.prior * (qf - prior[t, problem.free]))
                rows.append(o.prior * eye)
            a = np.vstack(rows)
            r = np.concatenate(res)
            cost = float(r @ r)
            h = a.T @ a + o.damping * eye
            g = a.T @ r
            # Active sets, grown until the step respects them: joints at a limit the step
            # pushes against are pinned; a coupling whose band edge the step would cross
            # (or already outside) becomes a stiff row c.(q + dq) = edge, so steps slide
            # along the band instead of being bent by the projection afterwards.
            pinned = np.zeros(n_free, dtype=bool)
            act = np.zeros(len(c_rows), dtype=bool)
            edge = np.zeros(len(c_rows))
            s_now = c_mat @ qf if c_rows else edge
            for _ in range(4):
                hh, gg = h, g
                if act.any():
                    ca = o.coupling * c_mat[act]
                    hh = h + ca.T @ ca
                    gg = g + ca.T @ (o.coupling * (s_now[act] - edge[act]))
                keep = ~pinned
                dq = np.zeros(n_free)
                dq[keep] = -np.linalg.solve(hh[np.ix_(keep, keep)], gg[keep])
                more = ((qf <= lo_f) & (dq < 0)) | ((qf >= hi_f) & (dq > 0))
                grown = bool((more & ~pinned).any())
                pinned |= more
                if c_rows:
                    s_new = s_now + c_mat @ dq
                    cross = ((s_new > c_hi + 1e-12) | (s_new < c_lo - 1e-12)) & ~act
                    edge = np.where(cross, np.where(s_new > c_hi, c_hi, c_lo), edge)
                    grown |= bool(cross.any())
                    act |= cross
                if not grown:
                    break
            big = np.max(np.abs(dq))
            if big > o.max_step:  # trust region: Gauss-Newton overshoots far from the optimum
                dq *= o.max_step / big
            q = q.copy()
            q[problem.free] = qf + dq
            q = lim.project(q)
            if np.max(np.abs(q[problem.free] - qf)) < o.tol:
                break
        return q, cost, it + 1, float(np.max(np.abs(p[:k] - tgt) * w[:, None]))

    pw = pv = None
    last = np.inf
    q = lim.project(problem.hold.copy() if prior is None else prior[0].copy())
    for t in range(n):
        start = time.perf_counter()
        q_prev = q.copy()
        tgt = targets[t]
        ok = np.isfinite(tgt).all(axis=1)
        w = np.where(ok, weights[t], 0.0)
        tgt = np.where(ok[:, None], tgt, 0.0)
        if pairs.size:
            pw = o.pinch * np.nan_to_num(pinch_weights[t])
            pv = np.nan_to_num(pinch_targets[t])
        if ok.any():
            q, cost, iters[t], worst = gauss_newton(q, q_prev, t, tgt, w, pw, pv)
            if prior is not None and worst > o.restart_mm and (worst > last + 0.5 or t % 10 == 0):
                # A finger caught folded at a limit: try again from the prior posture.
                q2, cost2, it2, _ = gauss_newton(
                    lim.project(prior[t].copy()), q_prev, t, tgt, w, pw, pv
                )
                iters[t] += it2
                if cost2 < cost:
                    q = q2
            if o.polish_smooth < o.smooth:
                # Polish in the basin chosen: the strong smoothness picked the posture (no
                # flips), a weak one removes its lag behind a moving target.
                q, _, it3, worst = gauss_newton(
                    q, q_prev, t, tgt, w, pw, pv, o.polish_smooth, o.polish_iterations
                )
                iters[t] += it3
            last = worst
        out[t] = q
        secs[t] = time.perf_counter() - start
    return TipResult(out, secs, iters)
