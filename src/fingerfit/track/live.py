"""Tracking one frame at a time: a live stream's frames with a missing sensor.

A stream cannot look ahead, so its frames are solved as they come (a filter): each frame
on its own, with the prior toward the angles of the frame before it (the temporal prior of
:mod:`.recording`, looking back only). A frame starts from its own direct angles where its
sensors give them and from the previous frame's elsewhere; a few Gauss-Newton steps follow
(:func:`~.solver.solve_frames`). A joint the frame's sensors do not determine (the digit's
distal sensor missing) keeps the previous frame's angle; a digit without the hand sensor or
without any of its sensors is not solved (its values are held by the stream).
"""

from __future__ import annotations

import numpy as np

from ..kinematics import FingerMotion, Kinematics
from ..model import HandModel
from ..session import HAND_SENSOR, Recording
from ..transforms import FloatArray
from .chains import ChainPose, Chains
from .packed import diagonal, pairs
from .solver import RIDGE, Observed, gauss_newton_step, solve_frames
from .weights import TrackOptions, chain_weights

#: What a digit's values in a streamed frame come from (the ``<digit>.source`` channel).
FROM_SENSORS, FROM_MODEL, HELD = 0, 1, 2
#: Gauss-Newton steps per frame (a frame starts within one frame's motion of its solution:
#: one step leaves an error of the order of the square of that motion; a second step
#: changed no angle by 0.01 deg on the benchmark's recordings).
LIVE_ITERATIONS = 1
#: A step that moved no angle more than this (rad) ends the frame's iterations.
CONVERGED = 1e-4


class LiveTracker:
    """The model's solution of streamed frames with a missing sensor, one at a time.

    Parameters
    ----------
    model : HandModel
        With calibration statistics (``model.tracking``).
    variants : tuple of str
        The variants the stream computes (``user_axis``; ``orthogonal`` too when a robot
        follows it).
    digits : list of str, optional
        Default: every digit of the model.
    options : TrackOptions, optional
    """

    def __init__(
        self,
        model: HandModel,
        variants: tuple[str, ...] = ("user_axis",),
        digits: list[str] | None = None,
        options: TrackOptions | None = None,
    ) -> None:
        self.model = model
        self.digits = list(digits or model.fingers)
        self.chains = chains = Chains(model, tuple(variants), self.digits)
        self.weights = chain_weights(model, chains, options or TrackOptions())
        self.sensors = sorted({s for row in chains.sensors for s in row})
        index = {s: i for i, s in enumerate(self.sensors)}
        self._table = np.array([[index[s] for s in row] for row in chains.sensors])
        self._r0t = np.swapaxes(chains.sensor_rotation, -1, -2)  # (D, S, 3, 3)
        self._mid = 0.5 * (self.weights.low + self.weights.high)  # (D, L)
        self._last: FloatArray | None = None  # (D, L) rad: the previous frame's angles
        self._info: FloatArray | None = None  # (D, P): their information (1/rad^2)
        self._pending: tuple[Kinematics, float] | None = None
        self._pose: ChainPose | None = None  # the chains posed at _last, when solved there
        self._points = np.stack([chains.tip, chains.pad], axis=1)  # (D, 2, 3)
        self._blank: Kinematics | None = None
        # A chain computed directly: its angles as precise as the calibration's spread makes
        # them, taken as the sensors' orientation spread (1/rad^2) on every angle.
        spread = np.min(self.weights.orientation, axis=1)  # (D,)
        rows, cols = pairs(chains.L)
        self._direct_info = np.where(rows == cols, spread[:, None], 0.0)
        self._pair_active = chains.active[:, :, None] & chains.active[:, None, :]
        self._speed2 = np.nan_to_num(self.weights.speed**2, nan=1e12, posinf=1e12)
        self._time = 0.0
        self._digit = [d for _, d in chains.keys]

    def reset(self) -> None:
        """Forget the previous frame (after a silence: no prior across the gap)."""
        self._last = self._pending = self._pose = None

    def observe(self, rec: Recording) -> Observed:
        """The one frame of ``rec`` relative to the hand sensor (:func:`~.solver.observe`,
        for one frame: every sensor at once)."""
        hand = rec.poses[HAND_SENSOR]
        n = len(self.sensors)
        pos = np.full((n, 3), np.nan)
        rot = np.full((n, 3, 3), np.nan)
        for i, s in enumerate(self.sensors):
            p = rec.poses.get(s)
            if p is not None:
                pos[i], rot[i] = p.position[0], p.rotation[0]
        back = self.chains.hand_rotation @ hand.rotation[0].T  # R_h0 R_h^T
        rel_p = (pos - hand.position[0]) @ back.T + self.chains.hand_position
        rel_r = back @ rot  # (K, 3, 3)
        p = rel_p[self._table]  # (D, S, 3)
        r = rel_r[self._table] @ self._r0t  # the segment's rotation R R_0^T
        present = np.isfinite(p).all(axis=-1) & np.isfinite(r).all(axis=(-2, -1))
        p[~present] = 0.0
        r[~present] = np.eye(3)
        return Observed(p[..., None], r[..., None], present[..., None])

    def step(self, rec: Recording, kin: Kinematics) -> dict[str, int]:
        """Solve the one frame of ``rec`` where its sensors are incomplete, in place.

        Parameters
        ----------
        rec : Recording
            One frame (mm, tracker coordinates; NaN where a sensor is missing).
        kin : Kinematics
            The direct computation of ``rec`` (every variant of the tracker): the digits
            with a missing sensor have NaN there. Their angles, tips and pads are replaced
            by the model's solution.

        Returns
        -------
        dict
            Digit -> :data:`FROM_SENSORS`, :data:`FROM_MODEL` or :data:`HELD` (the hand
            sensor or every sensor of the digit missing: left NaN).
        """
        chains = self.chains
        t = float(rec.time[0])
        if self._pending is not None:  # the last frame computed directly, not yet read
            kin0, t0 = self._pending
            self._pending = None
            self._remember(self._direct(kin0), t0, True)
        direct = self._direct(kin)
        hand_ok = bool(np.isfinite(rec.poses[HAND_SENSOR].position[0]).all()) and bool(
            np.isfinite(rec.poses[HAND_SENSOR].rotation[0]).all()
        )
        complete = np.isfinite(direct).all(axis=1)
        status = dict.fromkeys(self.digits, FROM_SENSORS)
        if complete.all() or not hand_ok:
            if not hand_ok:
                status = {d: HELD for d, ok in zip(self._digit, complete, strict=True) if not ok}
                status = {d: status.get(d, FROM_SENSORS) for d in self.digits}
            self._remember(np.where(np.isfinite(direct), direct, self._last_or(direct)), t, hand_ok)
            return status
        obs = self.observe(rec)
        some = obs.present[..., 0].any(axis=1)  # (D,): any sensor of the chain
        last = self._last_or(self._mid)
        q0 = np.where(np.isfinite(direct), direct, last)[..., None]
        prior = None
        if self._last is not None:
            prior = (self._last[..., None], self._prior_information(t))
        if prior is None:  # no frame before (the first, or after a silence): from afar
            sol = solve_frames(chains, self.weights, obs, q0)
            q, info = sol.q, sol.hessian
            info[:, diagonal(chains.L)] += RIDGE
        else:
            # From the previous frame's solution when its pose is at hand (every chain was
            # solved there), else from this frame's direct angles and the previous ones.
            q, pose = (self._last[..., None], self._pose) if self._pose is not None else (q0, None)
            for _ in range(LIVE_ITERATIONS):
                q, info, moved = gauss_newton_step(chains, self.weights, obs, q, prior, pose)
                pose = None
                if moved <= CONVERGED:
                    break
        pose = chains.pose(q)
        q = q[..., 0]
        solve = ~complete & some
        local = chains.points(pose, self._points)[..., 0]  # (D, 2, 3)
        hand = rec.poses[HAND_SENSOR]
        p0, r0 = chains.hand_position, chains.hand_rotation
        world = (local - p0) @ r0 @ hand.rotation[0].T + hand.position[0]  # carried by the hand
        for i, (v, d) in enumerate(chains.keys):
            if complete[i]:
                continue
            if not solve[i]:
                status[d] = HELD
                continue
            status[d] = FROM_MODEL
            m = kin.motions[v][d]
            for k, name in enumerate(chains.names[i]):
                m.angles[name][0] = q[i, k]
            m.tip[0] = world[i, 0]
            if m.pad is not None:
                m.pad[0] = world[i, 1]
        best = np.where(complete[:, None], direct, np.where(solve[:, None], q, last))
        self._remember(best, t, True, info[..., 0], complete | ~solve)
        self._pose = pose if (solve.all() and self._last is best) else None
        return status

    def blank(self, rec: Recording) -> Kinematics:
        """A frame's kinematics with every value NaN (the tracker's variants and digits), for
        a frame in which no digit has all its sensors: :meth:`step` fills it (its arrays are
        the same every call)."""
        if self._blank is None:
            motions = {}
            for v, d in self.chains.keys:
                pad = self.model.fingers[d].pad is not None
                angles = {k: np.empty(1) for k in self.model.fingers[d].angle_names()}
                motions.setdefault(v, {})[d] = FingerMotion(
                    angles, np.empty((1, 3)), np.empty((1, 3)) if pad else None
                )
            self._blank = Kinematics(np.empty(1), motions)
        kin = self._blank
        for ms in kin.motions.values():
            for m in ms.values():
                for a in m.angles.values():
                    a[0] = np.nan
        kin.time[0] = rec.time[0]
        return kin

    def remember(self, kin: Kinematics, t: float) -> None:
        """A frame computed directly from every sensor (``kin``, one frame at ``t`` s): the
        next frame's prior (read only when a frame needs it)."""
        self._pending = (kin, t)

    def _direct(self, kin: Kinematics) -> FloatArray:
        """The one frame of ``kin`` as the chains' angles ``(D, L)`` rad (padding 0; NaN
        where a sensor was missing)."""
        chains = self.chains
        direct = np.zeros((chains.size, chains.L))
        for i, (v, d) in enumerate(chains.keys):
            angles = kin.motions[v][d].angles
            row = direct[i]
            for k, name in enumerate(chains.names[i]):
                row[k] = angles[name][0]
        return direct

    def _last_or(self, default: FloatArray) -> FloatArray:
        return default if self._last is None else self._last

    def _remember(
        self,
        q: FloatArray,
        t: float,
        ok: bool,
        info: FloatArray | None = None,
        direct: np.ndarray | None = None,
    ) -> None:
        """The frame's angles ``q (D, L)`` at ``t`` s as the next frame's prior centre, with
        their information (``info (D, P)``, the chains solved; the chains computed
        directly from their sensors, ``direct``, are taken as known to the sensors'
        precision: their information is the calibration's)."""
        self._pose = None
        if not (ok and np.isfinite(q).all()):
            return
        self._last, self._time = q, t
        if info is None:
            info = np.broadcast_to(self._direct_info, self._direct_info.shape)
        else:
            info = np.where(direct[:, None], self._direct_info, info)
        self._info = info

    def _prior_information(self, t: float) -> FloatArray:
        """The prior of the frame at ``t`` s: the previous frame's angles, their covariance
        grown by the motion of ``t - t_prev`` (a joint moving at its calibration speed),
        inverted: ``(P + Q)^-1`` as an upper triangle ``(D, P, 1)`` (a Kalman filter's
        prediction; the information of an angle the data leave open stays small)."""
        chains = self.chains
        L = chains.L
        rows, cols = pairs(L)
        full = np.zeros((chains.size, L, L))
        full[:, rows, cols] = self._info
        full[:, cols, rows] = self._info
        dt = max(t - self._time, 1e-6)
        growth = np.minimum(self._speed2 * (dt * dt), 1e12)  # Q, the diagonal (D, L)
        # (P + Q)^-1 = (P (I + F Q))^-1 = (I + F Q)^-1 F, F = P^-1 the information: one
        # solve instead of two inversions.
        full_q = full * growth[:, None, :]
        full_q[:, np.arange(L), np.arange(L)] += 1.0
        info = np.linalg.solve(full_q, full)
        info *= self._pair_active  # padding levels: no prior
        return info[:, rows, cols][..., None]
