"""Joint limits and two-joint couplings: projection onto them and violation counts.

A coupling ``lo <= c_a q_a + c_b q_b <= hi`` (``a`` = the map's first joint, the driven
one; ``b`` the driver) is a slab in the ``(q_a, q_b)`` plane; with the box limits it is a
convex polygon. :meth:`Limits.project` moves configurations close to their projection on
the box and slabs (alternating projections) and then makes them exactly feasible: ``q_b``
is clipped to the range for which some ``q_a`` is feasible, then ``q_a`` to its feasible
interval. So every output satisfies every limit and coupling (to rounding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray
from .maps import RobotMap
from .robots import Robot

#: Tolerance of :meth:`Limits.violations` (rad): rounding, not a violation.
TOLERANCE = 1e-9


@dataclass(frozen=True)
class Limits:
    """Box limits ``(nq,)`` and couplings (arrays over couplings, ``(c,)``)."""

    lower: FloatArray
    upper: FloatArray
    a: np.ndarray
    b: np.ndarray
    ca: FloatArray
    cb: FloatArray
    lo: FloatArray
    hi: FloatArray
    b_lo: FloatArray
    b_hi: FloatArray

    def _slab(self, q: FloatArray) -> FloatArray:
        s = self.ca * q[:, self.a] + self.cb * q[:, self.b]
        over = np.where(s > self.hi, s - self.hi, np.where(s < self.lo, s - self.lo, 0.0))
        k = over / (self.ca**2 + self.cb**2)
        q[:, self.a] -= k * self.ca
        q[:, self.b] -= k * self.cb
        return q

    def project(self, q: FloatArray, sweeps: int = 4) -> FloatArray:
        """Feasible configurations near ``q``.

        Parameters
        ----------
        q : ndarray, shape (n, nq) or (nq,)
            rad (m for slide joints).

        Returns
        -------
        ndarray, same shape
            Within every limit and coupling.
        """
        single = q.ndim == 1
        if self.contains(q):  # the solver's usual case: nothing to do
            return np.array(q, dtype=float)
        q = np.clip(np.atleast_2d(np.array(q, dtype=float)), self.lower, self.upper)
        if self.a.size:
            for _ in range(sweeps):
                q = np.clip(self._slab(q), self.lower, self.upper)
            qb = np.clip(q[:, self.b], self.b_lo, self.b_hi)
            v1 = (self.lo - self.cb * qb) / self.ca
            v2 = (self.hi - self.cb * qb) / self.ca
            a_lo = np.maximum(np.minimum(v1, v2), self.lower[self.a])
            a_hi = np.minimum(np.maximum(v1, v2), self.upper[self.a])
            q[:, self.b] = qb
            q[:, self.a] = np.clip(q[:, self.a], a_lo, a_hi)
        return q[0] if single else q

    def contains(self, q: FloatArray) -> bool:
        """Whether configurations ``(nq,)`` or ``(n, nq)`` are all within every limit and
        coupling (exactly; NaN is not)."""
        if not (np.all(q >= self.lower) and np.all(q <= self.upper)):
            return False
        if self.a.size:
            s = self.ca * q[..., self.a] + self.cb * q[..., self.b]
            return bool(np.all(s >= self.lo) and np.all(s <= self.hi))
        return True

    def violations(self, q: FloatArray, tol: float = TOLERANCE) -> int:
        """Number of (frame, limit or coupling) pairs violated by more than ``tol``.

        Parameters
        ----------
        q : ndarray, shape (n, nq)
        """
        q = np.atleast_2d(q)
        n = int(np.sum(q < self.lower - tol) + np.sum(q > self.upper + tol))
        if self.a.size:
            s = self.ca * q[:, self.a] + self.cb * q[:, self.b]
            n += int(np.sum(s < self.lo - tol) + np.sum(s > self.hi + tol))
        return n + int(np.sum(~np.isfinite(q)))


def limits_of(robot: Robot, rmap: RobotMap) -> Limits:
    """The robot's joint limits and the map's couplings as :class:`Limits`.

    Raises
    ------
    FingerfitError
        A coupling no configuration within the limits can satisfy (naming the map field).
    """
    idx = {n: i for i, n in enumerate(robot.joint_names)}
    a = np.array([idx[c.joints[0]] for c in rmap.couplings], dtype=int)
    b = np.array([idx[c.joints[1]] for c in rmap.couplings], dtype=int)
    ca = np.array([c.coef[0] for c in rmap.couplings], dtype=float)
    cb = np.array([c.coef[1] for c in rmap.couplings], dtype=float)
    lo = np.array([c.lo for c in rmap.couplings], dtype=float)
    hi = np.array([c.hi for c in rmap.couplings], dtype=float)
    lower, upper = robot.lower.astype(float), robot.upper.astype(float)
    with np.errstate(invalid="ignore"):
        e1, e2 = ca * lower[a], ca * upper[a]
        m1, m2 = np.minimum(e1, e2), np.maximum(e1, e2)
        r1, r2 = (lo - m2) / cb, (hi - m1) / cb
    b_lo = np.maximum(np.minimum(r1, r2), lower[b])
    b_hi = np.minimum(np.maximum(r1, r2), upper[b])
    bad = np.flatnonzero(~(b_lo <= b_hi))
    if bad.size:
        raise FingerfitError(
            "no configuration within the joint limits satisfies this coupling",
            path=rmap.path,
            field=f"coupling[{bad[0]}]",
        )
    return Limits(lower, upper, a, b, ca, cb, lo, hi, b_lo, b_hi)
