"""The digits of a model as kinematic chains, stacked for batched evaluation over frames.

A digit under one model variant is a chain of axes (a finger: the MP's two axes in the
model's order, PIP, DIP; the thumb: the CMC's two axes, the MCP's one or two, IP), each a
rotation about a fixed line of the reference posture, ``T_k(q) x = Rot(a_k, q)(x - c_k(q))
+ c_k(q)`` with ``c_k(q) = c_k + q m_k`` (``m_k`` the rolling-contact migration, zero for a
fixed centre). Its segment ``s`` and every point on it move by the product of the axes
proximal to it, ``A_s(q) = T_1 ∘ ... ∘ T_{d_s}``, proximal first: the map
:func:`fingerfit.kinematics.chain_points` applies, written here for all digits at once,
with what inverse kinematics needs beside it (each segment's motion and each axis's line
where the chain puts it).

Everything is in **tracker coordinates at the reference posture** (mm), i.e. relative to
the hand sensor carried back to its reference pose (``docs/conventions.md``); angles rad.
Arrays put **frames last** (``m`` frames of a block contiguous), so that every operation
runs over whole rows of frames; chains are padded to the longest one with axes that never
turn (their angle stays 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import HandModel
from ..session import HAND_SENSOR
from ..transforms import FloatArray, skew

#: Segments (and sensors) per digit.
SEGMENTS = 3
_EYE = np.eye(3)[..., None]  # (3, 3, 1): the identity of every frame


def matmul_rows(a: FloatArray, b: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """Per-frame products of matrices, frames last: ``a (..., i, j, m)`` times
    ``b (..., j, k, m)`` (either may be ``(..., j, k, 1)``, broadcast) -> ``(..., i, k, m)``,
    stored frames last (into ``out`` when given): ``j`` products over whole rows of frames
    (faster than ``matmul`` over strided 3 x 3 matrices)."""
    if out is None:
        shape = np.broadcast_shapes(a.shape[:-3], b.shape[:-3])
        out = np.empty((*shape, a.shape[-3], b.shape[-2], max(a.shape[-1], b.shape[-1])))
    if a.shape[-1] == 1 and b.shape[-1] == 1:  # one frame (live): one small matmul
        np.matmul(a[..., 0], b[..., 0], out=out[..., 0])
        return out
    np.multiply(a[..., :, 0, None, :], b[..., None, 0, :, :], out=out)
    for j in range(1, a.shape[-2]):
        out += a[..., :, j, None, :] * b[..., None, j, :, :]
    return out


def matvec_rows(a: FloatArray, v: FloatArray) -> FloatArray:
    """Per-frame ``a v``, frames last: ``a (..., 3, 3, m)``, ``v (..., 3, m)`` (either with
    ``m`` 1, broadcast) -> ``(..., 3, m)``: three products over whole rows of frames."""
    out = a[..., :, 0, :] * v[..., None, 0, :]
    out += a[..., :, 1, :] * v[..., None, 1, :]
    out += a[..., :, 2, :] * v[..., None, 2, :]
    return out


@dataclass(frozen=True)
class ChainPose:
    """Chains posed at angles ``q`` (``D`` chains, ``L`` levels, ``S`` segments, ``m``
    frames; mm, tracker coordinates at the reference posture; frames last).

    Attributes
    ----------
    rotation : ndarray, shape (D, L + 1, 3, 3, m)
        Accumulated rotation of each level (level 0: identity; level ``k``: the product of
        the first ``k`` axes' rotations).
    translation : ndarray, shape (D, L + 1, 3, m)
        Accumulated translation of each level (mm).
    axes : ndarray, shape (D, L, 3, m)
        Each axis's direction where the proximal axes put it (unit).
    centres : ndarray, shape (D, L, 3, m)
        A point of each axis's line (its centre, moved by migration) where the proximal
        axes put it (mm).
    migration : ndarray, shape (D, L, 3, m) or None
        ``d/dq_k`` of a point's position from the centre's migration (mm/rad), where the
        proximal axes put it; None when no centre migrates.
    segment_rotation : ndarray, shape (D, S, 3, 3, m)
        Each segment's rotation from the reference posture.
    sensor_position : ndarray, shape (D, S, 3, m)
        Predicted sensor origins (mm).
    """

    rotation: FloatArray
    translation: FloatArray
    axes: FloatArray
    centres: FloatArray
    migration: FloatArray | None
    segment_rotation: FloatArray
    sensor_position: FloatArray


class Chains:
    """The chains of a model's digits under some variants, stacked (``D`` chains).

    Parameters
    ----------
    model : HandModel
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    digits : list of str
        Digits of the model.

    Attributes
    ----------
    keys : list of (str, str)
        ``(variant, digit)`` of each chain, variant major.
    names : list of list of str
        Per chain, the angle name of each level, proximal to distal (``mp_abduction``,
        ``mp``, ``pip``, ``dip``; ``cmc``, ``cmc_abduction``, ...).
    L : int
        Levels of the longest chain.
    levels : ndarray of int, shape (D,)
        Axes of each chain (at most ``L``).
    active : ndarray of bool, shape (D, L)
        Real (not padding) levels.
    sensors : list of list of str
        Per chain, the sensor of each segment, proximal to distal.
    depth : ndarray of int, shape (D, S)
        Axes moving each segment: segment ``s`` moves with the first ``depth[d, s]`` axes.
    moves : ndarray of bool, shape (D, L, S)
        Whether level ``k`` moves segment ``s``.
    sensor_position : ndarray, shape (D, S, 3)
    sensor_rotation : ndarray, shape (D, S, 3, 3)
        The sensors' reference poses (mm; sensor -> tracker).
    tip, pad : ndarray, shape (D, 3)
        The distal segment's tip and pad points (mm; a digit without a pad: its tip).
    """

    def __init__(self, model: HandModel, variants: tuple[str, ...], digits: list[str]) -> None:
        self.model = model
        self.keys = [(v, d) for v in variants for d in digits]
        chains = [model.fingers[d].chain() for _, d in self.keys]
        n_chain = len(chains)
        self.L = L = max(len(c) for c in chains)
        self.names = [[jm.name for jm in c] for c in chains]
        self.levels = np.array([len(c) for c in chains], dtype=np.intp)
        self.active = np.arange(L)[None, :] < self.levels[:, None]
        axis = np.zeros((n_chain, L, 3))
        axis[..., 2] = 1.0  # padding: any unit axis (its angle stays 0)
        centre = np.zeros((n_chain, L, 3))
        migration = np.zeros((n_chain, L, 3))
        self.sensors: list[list[str]] = []
        self.depth = np.zeros((n_chain, SEGMENTS), dtype=np.intp)
        self.sensor_position = np.zeros((n_chain, SEGMENTS, 3))
        self.sensor_rotation = np.zeros((n_chain, SEGMENTS, 3, 3))
        self.tip = np.zeros((n_chain, 3))
        self.pad = np.zeros((n_chain, 3))
        self.has_pad = np.zeros(n_chain, dtype=bool)
        for i, ((v, d), chain) in enumerate(zip(self.keys, chains, strict=True)):
            fm = model.fingers[d]
            for k, jm in enumerate(chain):
                axis[i, k] = jm.axis_for(v)
                centre[i, k] = jm.center
                if jm.migration is not None:
                    migration[i, k] = jm.migration
            names = []
            for s, jm in enumerate(fm.joints.values()):
                names.append(jm.child)
                self.depth[i, s] = len(fm.chain(s + 1))
                p, r = model.reference_poses[jm.child]
                self.sensor_position[i, s], self.sensor_rotation[i, s] = p, r
            self.sensors.append(names)
            self.tip[i] = fm.tip
            if fm.pad is not None:
                self.pad[i], self.has_pad[i] = fm.pad, True
            else:
                self.pad[i] = fm.tip
        self._set_lines(axis, centre, migration)
        self.hand_position, self.hand_rotation = model.reference_poses[HAND_SENSOR]

    @classmethod
    def from_lines(
        cls,
        axis: FloatArray,
        centre: FloatArray,
        depth: np.ndarray,
        points: FloatArray | None = None,
    ) -> Chains:
        """Bare chains from their lines, without a model (a fit that moves the lines).

        Parameters
        ----------
        axis, centre : ndarray, shape (D, L, 3)
            Each level's unit direction and a point of its line (mm, tracker coordinates
            at the reference posture); fixed centres.
        depth : ndarray of int, shape (D, S)
            Axes moving each segment (:attr:`depth`).
        points : ndarray, shape (D, S, 3), optional
            A point of each segment (mm; :attr:`ChainPose.sensor_position` moves them);
            default the origin.

        Returns
        -------
        Chains
            Enough for :meth:`pose` (no model, sensors, tips or variants).
        """
        self = cls.__new__(cls)
        n_chain, L = axis.shape[:2]
        self.L, self.depth = L, np.asarray(depth, dtype=np.intp)
        self.levels = np.full(n_chain, L, dtype=np.intp)
        self.active = np.ones((n_chain, L), dtype=bool)
        self.sensor_position = (
            np.zeros((n_chain, self.depth.shape[1], 3)) if points is None else np.asarray(points)
        )
        self._set_lines(np.asarray(axis, dtype=float), np.asarray(centre, dtype=float), None)
        return self

    def _set_lines(
        self, axis: FloatArray, centre: FloatArray, migration: FloatArray | None
    ) -> None:
        """The lines' arrays :meth:`pose` uses (``axis``, ``centre``, ``migration``
        ``(D, L, 3)``)."""
        n_chain, L = axis.shape[:2]
        if migration is None:
            migration = np.zeros_like(axis)
        self.axis, self.centre = axis, centre
        self.migration = migration if np.any(migration) else None
        k = skew(axis.reshape(-1, 3)).reshape(n_chain, L, 3, 3)
        self._skew, self._skew2 = k[..., None], (k @ k)[..., None]  # (D, L, 3, 3, 1)
        self._axis, self._centre = axis[..., None], centre[..., None]  # (D, L, 3, 1)
        self._migration = None if self.migration is None else self.migration[..., None]
        # K c, K^2 c (and K m, K^2 m) of each level: (D, L, 3, 1).
        self._kc = k @ centre[..., None]
        self._k2c = k @ k @ centre[..., None]
        self._km = k @ migration[..., None]
        self._k2m = k @ k @ migration[..., None]
        self.moves = np.arange(L)[None, :, None] < self.depth[:, None, :]  # (D, L, S)
        self._rows = np.arange(n_chain)[:, None]
        self._sensor_position = self.sensor_position[..., None]  # (D, S, 3, 1)

    @property
    def size(self) -> int:
        """Number of chains ``D``."""
        return len(self.keys)

    def pose(self, q: FloatArray) -> ChainPose:
        """The chains at angles ``q``.

        Parameters
        ----------
        q : ndarray, shape (D, L, m)
            Angle of every level (rad; padding levels 0).

        Returns
        -------
        ChainPose
        """
        n_chain, L, m = q.shape
        s, c = np.sin(q)[:, :, None, :], 1.0 - np.cos(q)[:, :, None, :]  # (D, L, 1, m)
        rot = self._skew * s[:, :, None]
        rot += self._skew2 * c[:, :, None]
        rot += _EYE  # (D, L, 3, 3, m): Rodrigues, R = I + s K + c K^2
        # T_k x = R_k x + v_k with v = (I - R) c~ = -(s K c~ + c K^2 c~), c~ = c + q m.
        v = self._kc * s
        v += self._k2c * c
        if self._migration is not None:
            kcm = self._km * s
            kcm += self._k2m * c  # (R - I) m
            v += q[:, :, None, :] * kcm
        v *= -1.0
        acc = np.empty((n_chain, L + 1, 3, 3, m))
        acc[:, 0] = _EYE
        for k in range(L):
            matmul_rows(acc[:, k], rot[:, k], out=acc[:, k + 1])
        prox = acc[:, :L]
        trans = np.zeros((n_chain, L + 1, 3, m))
        step = matvec_rows(prox, v)
        for k in range(L):
            np.add(trans[:, k], step[:, k], out=trans[:, k + 1])
        axes = matvec_rows(prox, self._axis)
        centres = matvec_rows(prox, self._centre)
        if self._migration is not None:
            centres += matvec_rows(prox, self._migration) * q[:, :, None, :]
        centres += trans[:, :L]
        mig = None
        if self._migration is not None:  # a point's d/dq_k from migration: prox (I - R_k) m
            mig = matvec_rows(prox, kcm)
            mig *= -1.0
        seg_rot = acc[self._rows, self.depth]  # (D, S, 3, 3, m)
        seg_pos = matvec_rows(seg_rot, self._sensor_position)
        seg_pos += trans[self._rows, self.depth]
        return ChainPose(acc, trans, axes, centres, mig, seg_rot, seg_pos)

    def points(self, pose: ChainPose, points: FloatArray) -> FloatArray:
        """Points of each chain's distal segment ``(D, k, 3)`` (mm, reference posture) moved
        by the chain: ``(D, k, 3, m)`` mm, tracker coordinates at the reference posture."""
        last = self.depth[:, -1]
        rows = self._rows[:, 0]
        r = pose.rotation[rows, last]  # (D, 3, 3, m)
        t = pose.translation[rows, last]  # (D, 3, m)
        return matvec_rows(r[:, None], points[..., None]) + t[:, None]
