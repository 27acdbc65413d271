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
against, shortened to a trust radius, then
:meth:`fingerfit.retarget.limits.Limits.project` onto limits and couplings. A step that
raises the cost is taken back and retried four times shorter: with targets out of the
robot's reach the residuals are large, the linearisation poor, and plain Gauss-Newton
alternated between two postures (on the Allegro it held a pinch 6 mm open).
The prior is the ``joint`` method's posture (the person's angles through the map): a
weak pull that picks, among robot postures reaching the same tips, the one most like the
person's, and keeps the solver out of the local minima of fingers folded at a limit. A
pinch that stays open while its weight is high (digits at limits on the far sides of it)
is closed alone and the frame solved again from there (``TipOptions.pinch_restart_mm``).
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
    pinch_restart_mm : float
        When a pinch pair at more than half its weight is still this far (mm) from its
        pad-to-pad target, the solution is caught in a posture from which no step closes
        it (joints pinned at their limits; on an Allegro it held a pinch 21 mm open): the
        pinch alone is closed from there, the frame solved again from that posture, and
        the cheaper solution kept (with the same "grows, or every 10th frame" rule).
    polish_smooth, polish_iterations : float, int
        After the solve, up to ``polish_iterations`` more with smoothness ``polish_smooth``
        (mm/rad) from the solution: the strong smoothness chose the posture, the polish
        removes its lag. Off by default (``polish_smooth = smooth``): on the benchmark it
        halved nothing but the lag and raised jerk 3-4x (docs/retargeting.md).
    max_step : float
        Largest joint change of one iteration (rad); a longer step is shortened.
    tol : float
        Stop when the largest joint step is below this (rad).
    ftol : float
        Or when an iteration lowered the cost by less than this fraction of it (with a
        target out of reach Gauss-Newton converges slowly, by steps of a few mrad that move
        nothing that matters).
    """

    smooth: float = 20.0
    damping: float = 1e-3
    pinch: float = 10.0
    prior: float = 5.0
    coupling: float = 100.0
    iterations: int = 6
    restart_mm: float = 10.0
    pinch_restart_mm: float = 1.5
    polish_smooth: float = 20.0
    polish_iterations: int = 3
    max_step: float = 0.2
    tol: float = 1e-4
    ftol: float = 1e-5


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


class TipSolver:
    """The ``tip`` solver with its warm start: each :meth:`solve` continues from the last frame.

    Offline, one call solves a whole recording (:func:`solve_tip`); live, one call per block
    of frames as they arrive gives the same joints as one call over all of them.

    Parameters
    ----------
    problem : TipProblem
    pinch_pairs : list of (int, int), optional
        Indices into ``problem.frames`` of each pinch pair's two points (``p`` pairs).
    options : TipOptions, optional
    """

    def __init__(
        self,
        problem: TipProblem,
        pinch_pairs: list[tuple[int, int]] | None = None,
        options: TipOptions | None = None,
    ) -> None:
        self.problem = problem
        self.options = options or TipOptions()
        self.pairs = np.array(pinch_pairs or [], dtype=int).reshape(-1, 2)
        free = problem.free
        self.n_free = n_free = free.size
        lim = problem.limits
        # Stiff coupling rows over free joints (coupled joints are expected to be free),
        # normalised so a row's value is a distance (rad) from the band's edges.
        pos = {j: i for i, j in enumerate(free)}
        rows = [
            (pos[a], pos[b], ca, cb, lo, hi)
            for a, b, ca, cb, lo, hi in zip(
                lim.a, lim.b, lim.ca, lim.cb, lim.lo, lim.hi, strict=True
            )
            if a in pos and b in pos
        ]
        self.c_mat = np.zeros((len(rows), n_free))
        for r, (ia, ib, ca, cb, _, _) in enumerate(rows):
            self.c_mat[r, ia], self.c_mat[r, ib] = ca / np.hypot(ca, cb), cb / np.hypot(ca, cb)
        self.c_lo = np.array([lo / np.hypot(ca, cb) for _, _, ca, cb, lo, _ in rows])
        self.c_hi = np.array([hi / np.hypot(ca, cb) for _, _, ca, cb, _, hi in rows])
        self.lo_f, self.hi_f = lim.lower[free], lim.upper[free]
        self.eye = np.eye(n_free)
        #: Configuration of the last frame solved (rad, ``(nq,)``); ``None`` before the first.
        self.q: FloatArray | None = None
        self._last = np.inf
        self._last_pinch = np.inf
        self._frame = 0

    def solve(
        self,
        targets: FloatArray,
        weights: FloatArray | None = None,
        pinch_targets: FloatArray | None = None,
        pinch_weights: FloatArray | None = None,
        prior: FloatArray | None = None,
    ) -> TipResult:
        """Solve the next frames, warm-started from the previous one.

        Parameters
        ----------
        targets : ndarray, shape (n, k, 3)
            Target of each of the first ``k`` frames of ``problem.frames`` (robot palm
            frame, mm); NaN rows (a missing sensor) are left out of that frame's cost.
        weights : ndarray, shape (n, k), optional
            Per-frame fingertip weights (default 1).
        pinch_targets : ndarray, shape (n, p, 3)
            Target of ``point_a - point_b`` (mm, palm frame), with pinch pairs.
        pinch_weights : ndarray, shape (n, p)
            0 (no pinch) .. 1, scaled by ``options.pinch``.
        prior : ndarray, shape (n, nq), optional
            Posture prior per frame (rad), e.g. the ``joint`` method's output.

        Returns
        -------
        TipResult
            A frame whose targets are all missing keeps the previous configuration.
        """
        o, lim = self.options, self.problem.limits
        n, k = targets.shape[:2]
        weights = np.ones((n, k)) if weights is None else weights
        out = np.empty((n, self.problem.hold.size))
        secs = np.empty(n)
        iters = np.zeros(n, dtype=int)
        pw = pv = None
        if self.q is None:
            self.q = lim.project(self.problem.hold.copy() if prior is None else prior[0].copy())
        q = self.q
        for t in range(n):
            start = time.perf_counter()
            q_prev = q
            tgt = targets[t]
            ok = np.isfinite(tgt).all(axis=1)
            w = np.where(ok, weights[t], 0.0)
            tgt = np.where(ok[:, None], tgt, 0.0)
            if self.pairs.size:
                pw = o.pinch * np.nan_to_num(pinch_weights[t])
                pv = np.nan_to_num(pinch_targets[t])
            qp = None if prior is None else prior[t]
            if ok.any():
                q, cost, iters[t], worst = self._gauss_newton(q, q_prev, qp, tgt, w, pw, pv)
                again = worst > self._last + 0.5 or (self._frame + t) % 10 == 0
                if qp is not None and worst > o.restart_mm and again:
                    # A finger caught folded at a limit: try again from the prior posture.
                    q2, cost2, it2, worst2 = self._gauss_newton(
                        lim.project(qp.copy()), q_prev, qp, tgt, w, pw, pv
                    )
                    iters[t] += it2
                    if cost2 < cost:
                        q, cost, worst = q2, cost2, worst2
                if self.pairs.size:
                    q, cost, worst, it4 = self._close_pinch(
                        q, cost, worst, q_prev, qp, tgt, w, pw, pv, self._frame + t
                    )
                    iters[t] += it4
                if o.polish_smooth < o.smooth:
                    # Polish in the basin chosen: the strong smoothness picked the posture
                    # (no flips), a weak one removes its lag behind a moving target.
                    q, _, it3, worst = self._gauss_newton(
                        q, q_prev, qp, tgt, w, pw, pv, o.polish_smooth, o.polish_iterations
                    )
                    iters[t] += it3
                self._last = worst
            out[t] = q
            secs[t] = time.perf_counter() - start
        self.q = q
        self._frame += n
        return TipResult(out, secs, iters)

    def _close_pinch(
        self,
        q: FloatArray,
        cost: float,
        worst: float,
        q_prev: FloatArray,
        prior: FloatArray | None,
        tgt: FloatArray,
        w: FloatArray,
        pw: FloatArray,
        pv: FloatArray,
        frame: int,
    ) -> tuple[FloatArray, float, float, int]:
        """The frame's solution, or a cheaper one when a pinch stayed open
        (``pinch_restart_mm``): ``(q, cost, worst, iterations spent)``.

        From a posture caught with a pinch open (the digits pinned at limits on the far
        side of it), a Gauss-Newton step that also keeps the fingertips near their targets
        cannot close it. Closing the pinch alone (fingertip weights 0, a weak pull to this
        frame's posture) leaves that basin; the whole cost from there decides.
        """
        o, pairs = self.options, self.pairs
        engaged = pw >= 0.5 * o.pinch
        if not engaged.any():
            self._last_pinch = 0.0
            return q, cost, worst, 0
        p, _ = self.problem.kinematics(q)
        off = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]] - pv, axis=1)
        off = float(np.max(off[engaged]))
        again = off > self._last_pinch + 0.5 or frame % 10 == 0
        self._last_pinch = off
        if off <= o.pinch_restart_mm or not again:
            return q, cost, worst, 0
        q1, _, it1, _ = self._gauss_newton(
            q, q, prior, tgt, np.zeros_like(w), pw, pv, 1.0, 2 * o.iterations
        )
        q2, cost2, it2, worst2 = self._gauss_newton(q1, q_prev, prior, tgt, w, pw, pv)
        if cost2 < cost:
            return q2, cost2, worst2, it1 + it2
        return q, cost, worst, it1 + it2

    def _gauss_newton(
        self,
        q: FloatArray,
        q_prev: FloatArray,
        prior: FloatArray | None,
        tgt: FloatArray,
        w: FloatArray,
        pw: FloatArray | None,
        pv: FloatArray | None,
        smooth: float | None = None,
        iterations: int | None = None,
    ) -> tuple[FloatArray, float, int, float]:
        """One frame: ``(q, cost, iterations, worst weighted fingertip error mm)``.

        A step that raises the cost is taken back and retried four times shorter (a trust
        region): far from the optimum, with fingertip targets out of the robot's reach, the
        Gauss-Newton step overshoots and would alternate between two postures.
        """
        o, prob, lim = self.options, self.problem, self.problem.limits
        free, pairs, n_free, k = prob.free, self.pairs, self.n_free, len(tgt)
        smooth = o.smooth if smooth is None else smooth
        iterations = o.iterations if iterations is None else iterations
        diag = smooth**2 + (o.prior**2 if prior is not None else 0.0) + o.damping
        radius = taken = o.max_step
        best: tuple | None = None
        it, worst = 0, np.inf
        for it in range(iterations):  # noqa: B007
            qf = q[free]
            p, jac = prob.kinematics(q)
            e = (p[:k] - tgt) * w[:, None]
            a = (jac[:k] * w[:, None, None]).reshape(-1, n_free)
            h = a.T @ a
            g = a.T @ e.ravel()
            cost = float(np.sum(e * e))
            if pairs.size:
                d = (p[pairs[:, 0]] - p[pairs[:, 1]] - pv) * pw[:, None]
                ad = ((jac[pairs[:, 0]] - jac[pairs[:, 1]]) * pw[:, None, None]).reshape(-1, n_free)
                h += ad.T @ ad
                g += ad.T @ d.ravel()
                cost += float(np.sum(d * d))
            dprev = qf - q_prev[free]
            g += smooth**2 * dprev
            cost += smooth**2 * float(dprev @ dprev)
            if prior is not None:
                dprior = qf - prior[free]
                g += o.prior**2 * dprior
                cost += o.prior**2 * float(dprior @ dprior)
            if best is not None and cost > best[0]:
                # The last step made things worse: back to where it started, shorter.
                cost, q, qf, h, g, worst = best
                radius = 0.25 * taken
            else:
                worst = float(np.max(np.abs(p[:k] - tgt) * w[:, None]))
                converged = best is not None and best[0] - cost < o.ftol * (1.0 + cost)
                best = (cost, q, qf, h, g, worst)
                if converged:  # the last step bought next to nothing: keep it, stop
                    break
            h = h + diag * self.eye
            dq = self._step(qf, h, g)
            big = float(np.max(np.abs(dq)))
            if big > radius:
                dq *= radius / big
            taken = min(big, radius)
            q = q.copy()
            q[free] = qf + dq
            q = lim.project(q)
            if np.max(np.abs(q[free] - qf)) < o.tol:
                break
        return q, best[0] if best is not None else np.inf, it + 1, worst

    def _step(self, qf: FloatArray, h: FloatArray, g: FloatArray) -> FloatArray:
        """Gauss-Newton step over the free joints with active sets of limits and couplings.

        Joints at a limit the step pushes against are pinned; a coupling whose band edge
        the step would cross (or is outside of) becomes a stiff row ``c.(q + dq) = edge``,
        so steps slide along the band instead of being bent by the projection afterwards.
        Both sets grow until the step respects them (at most four rounds).
        """
        o, c_mat, n_free = self.options, self.c_mat, self.n_free
        n_c = c_mat.shape[0]
        pinned = np.zeros(n_free, dtype=bool)
        act = np.zeros(n_c, dtype=bool)
        edge = np.zeros(n_c)
        s_now = c_mat @ qf if n_c else edge
        dq = np.zeros(n_free)
        for _ in range(4):
            hh, gg = h, g
            if act.any():
                ca = o.coupling * c_mat[act]
                hh = h + ca.T @ ca
                gg = g + ca.T @ (o.coupling * (s_now[act] - edge[act]))
            if pinned.any():
                keep = ~pinned
                dq = np.zeros(n_free)
                dq[keep] = -np.linalg.solve(hh[np.ix_(keep, keep)], gg[keep])
            else:
                dq = -np.linalg.solve(hh, gg)
            more = ((qf <= self.lo_f) & (dq < 0)) | ((qf >= self.hi_f) & (dq > 0))
            grown = bool((more & ~pinned).any())
            pinned |= more
            if n_c:
                s_new = s_now + c_mat @ dq
                cross = ((s_new > self.c_hi + 1e-12) | (s_new < self.c_lo - 1e-12)) & ~act
                edge = np.where(cross, np.where(s_new > self.c_hi, self.c_hi, self.c_lo), edge)
                grown |= bool(cross.any())
                act |= cross
            if not grown:
                break
        return dq


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
    """Solve a whole recording: :meth:`TipSolver.solve` of a fresh :class:`TipSolver`.

    Parameters are those of :class:`TipSolver` and :meth:`TipSolver.solve`.
    """
    solver = TipSolver(problem, pinch_pairs, options)
    return solver.solve(targets, weights, pinch_targets, pinch_weights, prior)
