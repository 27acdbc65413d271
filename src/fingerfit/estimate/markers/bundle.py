"""Bundle adjustment of one digit from its skin markers: Levenberg-Marquardt over the
lines, the markers' places, every frame's angles and hand frame (the unknowns and the
cost of :mod:`.chain`), on the block structure of :mod:`.normal`, each trial point's
frames moved by a step of their own (:func:`.frames.frames_step`), its steps mixed
(:mod:`.mixing`); and the covariance of the lines at the solution.
"""

from __future__ import annotations

import contextlib
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ...transforms import FloatArray, unit
from .chain import HandFrames, Lines, Point, Structure, total_cost
from .frames import frames_step
from .mixing import Mixer, information_weights
from .normal import (
    LAM_START,
    Normal,
    damping,
    normal_equations,
    promised,
    reduced,
    schur_step,
    symmetric_pinv,
)
from .observe import DigitMarkers


@dataclass
class BundleResult:
    """A converged bundle adjustment of one digit.

    Attributes
    ----------
    lines : Lines
    u : ndarray, shape (M, 3)
        Marker places at the reference posture (mm).
    q : ndarray, shape (L, n)
        Angles of every frame (rad).
    hand : HandFrames
        Each frame's correction of the hand's frame.
    slide : ndarray, shape (M, 3) or None
        Each marker's slide (mm/rad), when estimated.
    cost : float
        Sum of squared residuals (mm^2).
    rms_mm : float
        RMS residual per coordinate (mm).
    iterations : int
    converged : bool
        False when it stopped at ``max_iter`` with the cost still falling by more than
        ``tol`` of it per step.
    normal : Normal
        At the solution.
    free : ndarray of bool, shape (4 L + 3 M,)
    """

    lines: Lines
    u: FloatArray
    q: FloatArray
    hand: HandFrames
    slide: FloatArray | None
    cost: float
    rms_mm: float
    iterations: int
    converged: bool
    normal: Normal
    free: np.ndarray

    @property
    def point(self) -> Point:
        """The unknowns at the solution."""
        return Point(self.lines, self.u, self.q, self.hand, self.slide)


#: :func:`adjust`'s ``near`` in the fits: converged within ``sqrt(1e-3)``, about 0.03,
#: standard deviations of the minimum.
NEAR = 1e-3


def adjust(
    data: DigitMarkers,
    structure: Structure,
    lines: Lines,
    u: FloatArray,
    q: FloatArray,
    *,
    hand: HandFrames | None = None,
    slide: FloatArray | None = None,
    free: np.ndarray | None = None,
    max_iter: int = 100,
    tol: float = 1e-12,
    near: float | None = None,
    mix: bool = True,
    threads: int = 1,
) -> BundleResult:
    """Levenberg-Marquardt over the lines, the markers' places, every frame's angles and
    every frame's hand frame.

    Each trial point is the damped step of the whole problem (the frames eliminated by
    the Schur complement), then each frame's own damped Gauss-Newton step at the new
    model (:func:`.frames.frames_step`, the same damping), kept in the frames whose
    cost it lowers: the frames' part of the whole step is the linear model's, and
    where the model's step bends the frames' minima (two axes sharing the flexion), the
    frames' own step follows them, so the trial is judged nearer the cost the model
    would have with its frames solved.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
    lines : Lines
        Start (tracker coordinates at the reference posture, mm).
    u : ndarray, shape (M, 3)
        Start of the markers' places (mm).
    q : ndarray, shape (L, n)
        Start of the angles (rad).
    hand : HandFrames, optional
        Start of the hand frames' correction (default none: the rigid fit's).
    slide : ndarray, shape (M, 3), optional
        Start of the markers' slides (mm/rad): estimated too (:func:`places`).
    free : ndarray of bool, shape (4 L + 3 M,) or with ``slide`` (4 L + 6 M,), optional
        Global unknowns that move (default all).
    max_iter : int
    tol : float
        Converged when an accepted step lowers the cost by less than ``tol`` of it.
    near : float, optional
        Converged too when an accepted step lowers the cost by less than ``near``
        ``sigma^2`` (the residual variance per coordinate) and the Gauss-Newton step
        from the new point would too: the point is then within ``sqrt(near)``
        standard deviations of the minimum in the metric of the fit's covariance
        (the decrease ``b^T (J^T J)^-1 b`` of that step is ``sigma^2`` times its
        squared length in it).
    mix : bool
        Propose each step mixed with the last ones (:mod:`.mixing`), kept when it lowers
        the cost below the plain step's.
    threads : int
        Threads that work through the frames' blocks side by side (:func:`.chain.
        over_blocks`; the result is the same for any number).

    Returns
    -------
    BundleResult
    """
    L, M = structure.levels, len(data.labels)
    G = 4 * L + 3 * M * (1 if slide is None else 2)
    free = np.ones(G, dtype=bool) if free is None else free
    lines_free = bool(free[: 4 * L].any())
    hand = HandFrames.identity(data.frames) if hand is None else hand
    at = Point(lines.copy(), u.copy(), q.copy(), hand, slide)
    with ThreadPoolExecutor(threads) if threads > 1 else contextlib.nullcontext() as pool:
        nq, _ = normal_equations(data, structure, at, free, pool)
        diagonal = np.zeros(G)
        diagonal[free] = np.diag(nq.gg)
        sizes = [(2, 3)] * 2 * L + [(1, 1)] * (G - 4 * L)
        mixer = Mixer(information_weights(diagonal, sizes)) if mix else None
        lam = LAM_START
        it, done = 0, False
        for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
            done = False
            for _ in range(12):
                dq, dg = schur_step(nq, lam, pool)
                step = np.zeros(G)
                step[free] = dg
                trial = Point(
                    at.lines.moved(step[: 4 * L]) if lines_free else at.lines,
                    at.u + step[4 * L : 4 * L + 3 * M].reshape(M, 3),
                    at.q + dq[:, :L].T,
                    at.hand.moved(dq[:, L : L + 3], dq[:, L + 3 :]),
                    None if at.slide is None else at.slide + step[4 * L + 3 * M :].reshape(M, 3),
                )
                # The frames' part of the step is the linear model's; each frame's own
                # Gauss-Newton step at the new model follows the cost's curvature.
                trial = frames_step(data, structure, trial, lam, pool)
                cost = total_cost(data, structure, trial, pool)
                if cost <= nq.cost:
                    ratio = (nq.cost - cost) / max(promised(nq, dq, dg), 1e-300)
                    if mixer is not None:
                        here, there = _pack(at), _pack(trial)
                        mixed = mixer.propose(here, (there[0] - here[0], there[1] - here[1]))
                        if mixed is not None:
                            candidate = _unpack(*mixed, L, M, at.slide is not None)
                            c = total_cost(data, structure, candidate, pool)
                            if c < cost:
                                trial, cost = candidate, c
                    gain = nq.cost - cost
                    at = trial
                    nq, _ = normal_equations(data, structure, at, free, pool)
                    lam = float(damping(lam, True, ratio))
                    done = gain <= tol * max(cost, 1e-300) or (
                        near is not None and _near_minimum(nq, gain, near, pool)
                    )
                    break
                lam = float(damping(lam, False, 0.0))
                if mixer is not None:
                    mixer.forget()
            else:
                done = True  # no step lowers the cost
            if done:
                break
    rms = float(np.sqrt(nq.cost / max(nq.count, 1)))
    return BundleResult(at.lines, at.u, at.q, at.hand, at.slide, nq.cost, rms, it, done, nq, free)


def _near_minimum(nq: Normal, gain: float, near: float, pool: Executor | None) -> bool:
    """Whether the last step's ``gain`` (mm^2) and the Gauss-Newton step from ``nq``'s
    point would each lower the cost by less than ``near`` residual variances."""
    limit = near * nq.sigma2
    if gain > limit:
        return False
    dq, dg = schur_step(nq, 0.0, pool)
    return float(np.vdot(nq.bq, dq) + nq.bg @ dg) <= limit


def _pack(point: Point) -> tuple[FloatArray, FloatArray]:
    """A point's coordinates for :class:`.mixing.Mixer`: the global ones ``(6 L + 3 M,)``
    (each line's direction and point, the places, with slides the slides; mm, mm/rad)
    and each frame's ``(n, L + 6)`` (angles, the hand correction's rotation vector, rad,
    and offset, mm)."""
    lines, hand = point.lines, point.hand
    parts = [np.concatenate([lines.axis, lines.centre], axis=1).ravel(), point.u.ravel()]
    if point.slide is not None:
        parts.append(point.slide.ravel())
    rotvec = Rotation.from_matrix(hand.rotation).as_rotvec()
    return np.concatenate(parts), np.concatenate([point.q.T, rotvec, hand.offset], axis=1)


def _unpack(g: FloatArray, f: FloatArray, L: int, M: int, sliding: bool) -> Point:
    """The point of :func:`_pack`'s coordinates (each direction scaled to unit length)."""
    lines = g[: 6 * L].reshape(L, 6)
    places = g[6 * L :].reshape(-1, M, 3)
    hand = HandFrames(Rotation.from_rotvec(f[:, L : L + 3]).as_matrix(), f[:, L + 3 :].copy())
    return Point(
        Lines(unit(lines[:, :3]), lines[:, 3:].copy()),
        places[0].copy(),
        f[:, :L].T.copy(),
        hand,
        places[1].copy() if sliding else None,
    )


def line_covariance(result: BundleResult) -> FloatArray:
    """The covariance ``(L, 4, 4)`` of each line's unknowns (two direction, rad, and two
    point, mm, in the plane perpendicular to the axis: :meth:`Lines.moved`).

    ``sigma^2 S^-1``, with ``S`` the Schur complement of the frames' unknowns in the
    undamped normal matrix and ``sigma^2`` the residual variance per coordinate. ``S`` is
    inverted by :func:`.normal.symmetric_pinv`: a direction with no information
    gives its unknowns an infinite variance; unknowns held fixed are NaN.
    """
    s, _ = reduced(result.normal)
    inv, touched = symmetric_pinv(s)
    inv[touched, :] = inv[:, touched] = np.inf
    full = np.full((result.free.size, result.free.size), np.nan)
    idx = np.flatnonzero(result.free)
    full[np.ix_(idx, idx)] = result.normal.sigma2 * inv
    L = result.lines.axis.shape[0]
    return np.stack([full[4 * k : 4 * k + 4, 4 * k : 4 * k + 4] for k in range(L)])
