"""Joint angles and fingertip positions for every frame of a recording.

Two ways to get a joint angle from the two sensors of a joint (the model's
``angle_method``; ``docs/methods.md`` has the measurement that chose the default):

* ``projection`` (paper Fig. 6): the child sensor origin, expressed in the parent
  sensor frame, is projected on the plane normal to the joint axis; the angle
  is measured about the joint centre from its reference-posture projection.
  With ``p0`` the projected reference offset and ``u = a × p0`` this is
  ``theta = atan2(d·u, d·p0)``, ``d = r - c`` -- two dot products per frame.
* ``swing_twist``: the full relative orientation away from the reference
  posture, ``Q = R_p^T R_c R_ref^T`` (parent frame), is split into a twist about
  the joint axis ``a`` and a swing perpendicular to it; the angle is the twist,
  ``theta = 2 atan2(vee(Q - Q^T)·a, 1 + tr Q)`` (no quaternion needed): traces of
  ``Q``, one BLAS product over the whole recording. For a
  two-axis joint ``Q = Rot(b, beta) Rot(a, theta)`` (``b`` the proximal axis, ``a``
  the distal one): ``beta`` turns ``a`` to ``Q a`` about ``b``, and ``theta`` is the
  twist of ``Rot(b, -beta) Q``.

Tip and pad: a product of exponentials at the reference posture. The point is
rotated about each axis of the digit from the distal one to the proximal one
(a finger: DIP, PIP, MP flexion, then the MP ab/adduction of a two-axis model;
the thumb: IP, MCP (ab/adduction, flexion), CMC ab/adduction, CMC flexion --
``docs/conventions.md``), each through its centre (moved by ``theta * migration``
where the model has rolling-contact migration), all in tracker coordinates at the
reference posture, and carried by the hand sensor's motion relative to its
reference pose.

Both run over whole recordings with NumPy; no per-frame Python loop. For a
``swing_twist`` model ``compute_kinematics`` computes the same numbers block by block
in cache (:class:`KinematicsPlan`, which a live stream prepares once; ``docs/performance.md``).
The angle maths of one joint are :mod:`fingerfit.angles`; their names are importable
from here too. Angles rad, lengths mm, tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .angles import (
    projection_angle,
    relative_rotation,
    twist_angle,
    two_axis_angles,
    two_axis_projection_angles,
)
from .model import ANGLE_METHODS, VARIANTS, DigitModel, HandModel
from .session import HAND_SENSOR, UNITS_TO_MM, PoseSeries, Recording
from .transforms import (
    FloatArray,
    orthonormal_basis,
    rotate_about_lines,
    skew,
)


@dataclass(frozen=True)
class FingerMotion:
    """One digit's kinematics under one model variant.

    Attributes
    ----------
    angles : dict[str, ndarray]
        Flexion joints (``mp``, ``pip``, ``dip``; the thumb's ``cmc``, ``mcp``, ``ip``)
        -> ``(n_frames,)`` angles (rad), then ``<joint>_abduction`` (rad) of each
        two-axis joint (:meth:`~fingerfit.model.DigitModel.angle_names`).
    tip : ndarray, shape (n_frames, 3)
        Tip (nail-edge point) in tracker coordinates (mm).
    pad : ndarray, shape (n_frames, 3) or None
        Pad point (on the pulp's skin, ``docs/conventions.md``) in tracker coordinates
        (mm); ``None`` for a model without pads.
    """

    angles: dict[str, FloatArray]
    tip: FloatArray
    pad: FloatArray | None = None


@dataclass(frozen=True)
class Kinematics:
    """Angles and fingertips of a recording.

    Attributes
    ----------
    time : ndarray, shape (n_frames,)
        Seconds.
    motions : dict[str, dict[str, FingerMotion]]
        variant (``user_axis``, ``orthogonal``) -> digit -> motion.
    """

    time: FloatArray
    motions: dict[str, dict[str, FingerMotion]]


def chain_points(
    finger: DigitModel,
    variant: str,
    angles: dict[str, FloatArray],
    points: FloatArray,
    depth: int = 3,
) -> FloatArray:
    """Move reference-posture points through a digit's joint rotations.

    Parameters
    ----------
    finger : DigitModel
    variant : {"user_axis", "orthogonal"}
    angles : dict
        Every axis of the first ``depth`` joints (flexion joints and, for two-axis
        joints, ``<joint>_abduction``) -> ``(n,)`` rad.
    points : ndarray, shape (3,) or (n, 3)
        Points on the segment distal to joint ``depth`` (tracker frame at the
        reference posture, mm); ``depth = 3`` for the distal phalanx.
    depth : int
        Number of joints (from the first) the points are carried by.

    Returns
    -------
    ndarray, shape (n, 3)
        The points with the hand at its reference pose (mm): turned about each axis
        through its centre (moved by ``theta * migration`` where the model has
        rolling-contact migration), distal axes first.
    """
    steps = []
    for jm in reversed(finger.chain(depth)):
        centre = jm.center
        if jm.migration is not None:
            centre = centre + np.multiply.outer(angles[jm.name], jm.migration)
        steps.append((centre, jm.axis_for(variant), angles[jm.name]))
    return rotate_about_lines(points, steps)


def carry_by_hand(
    model: HandModel, hand_rotation: FloatArray, hand_position: FloatArray, points: FloatArray
) -> FloatArray:
    """Carry reference-posture points ``(n, 3)`` by the hand sensor's motion (mm, tracker)."""
    p0, r0 = model.reference_poses[HAND_SENSOR]
    local = (points - p0) @ r0  # r0^T (p - p0), row-wise
    return np.einsum("nij,nj->ni", hand_rotation, local) + hand_position


def finger_angles(
    model: HandModel,
    finger: str,
    recording: Recording,
    variants: tuple[str, ...] = VARIANTS,
    method: str | None = None,
) -> dict[str, dict[str, FloatArray]]:
    """Joint angles of one digit under several model variants (sensor data read once).

    Parameters
    ----------
    model : HandModel
    finger : str
        Digit name.
    recording : Recording
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    method : {"projection", "swing_twist"}, optional
        Default: the model's ``angle_method``.

    Returns
    -------
    dict
        variant -> angle name (:meth:`~fingerfit.model.DigitModel.angle_names`) ->
        ``(n_frames,)`` rad; NaN where a sensor is missing. A two-axis joint
        ``Q = Rot(p, alpha) Rot(d, delta)`` (``p`` its proximal axis, ``d`` its distal one,
        :mod:`fingerfit.digits`) gives ``alpha`` and ``delta`` to the two axes' names.
    """
    method = method or model.angle_method
    if method not in ANGLE_METHODS:
        raise ValueError(f"unknown angle method '{method}' (have: {', '.join(ANGLE_METHODS)})")
    fm = model.fingers[finger]
    out: dict[str, dict[str, FloatArray]] = {v: {} for v in variants}
    for j, jm in fm.joints.items():
        parent, child = recording.pose(jm.parent), recording.pose(jm.child)
        pp, pr = model.reference_poses[jm.parent]
        cp, cr = model.reference_poses[jm.child]
        if method == "swing_twist":
            q = relative_rotation(parent.rotation, child.rotation, pr.T @ cr)
        else:
            r = np.einsum("ni,nij->nj", child.position - parent.position, parent.rotation)
            r0 = pr.T @ (cp - pp)
        for v in variants:
            if j not in fm.second_axes:
                c, a = model.in_parent(finger, j, v)
                if method == "swing_twist":
                    out[v][j] = twist_angle(q, a)
                else:
                    out[v][j] = projection_angle(
                        parent.rotation, parent.position, child.position, c, a, r0
                    )
                continue
            prox, dist = fm.axes(j)
            cb, b = model.in_parent(finger, prox.name, v)
            ca, a = model.in_parent(finger, dist.name, v)
            if method == "swing_twist":
                out[v][prox.name], out[v][dist.name] = two_axis_angles(q, a, b)
            else:
                out[v][prox.name], out[v][dist.name] = two_axis_projection_angles(
                    r, r0, ca, a, cb, b
                )
    # Column order: the flexion angles, then the ab/adductions.
    return {v: {k: d[k] for k in fm.angle_names()} for v, d in out.items()}


def joint_angles(
    model: HandModel,
    finger: str,
    recording: Recording,
    variant: str = "user_axis",
    method: str | None = None,
) -> dict[str, FloatArray]:
    """Joint angles ``(n_frames,)`` rad of digit ``finger`` over ``recording`` (one variant).

    Flexion and, for two-axis joints, ``<joint>_abduction``; computed by ``method``
    (default: the model's ``angle_method``). See :func:`finger_angles`.
    """
    return finger_angles(model, finger, recording, (variant,), method)[variant]


def compute_kinematics(
    model: HandModel,
    recording: Recording,
    variants: tuple[str, ...] = VARIANTS,
    fingers: list[str] | None = None,
) -> Kinematics:
    """Joint angles and fingertips of every frame, for each model variant.

    Parameters
    ----------
    model : HandModel
    recording : Recording
        Must hold the hand sensor and the three sensors of each finger.
    variants : tuple of str
    fingers : list of str, optional
        Default: every finger of the model.

    Returns
    -------
    Kinematics
        Frames with a missing sensor give NaN. Angles by the model's
        ``angle_method``.
    """
    fingers = fingers or list(model.fingers)
    if model.angle_method == "swing_twist" and recording.n_frames > 0:
        return KinematicsPlan(model, tuple(variants), fingers).run(recording)
    hand = recording.pose(HAND_SENSOR)
    motions: dict[str, dict[str, FingerMotion]] = {v: {} for v in variants}
    for f in fingers:
        fm = model.fingers[f]
        angles = finger_angles(model, f, recording, variants)
        for v in variants:
            tip, pad = (
                None
                if point is None
                else carry_by_hand(
                    model, hand.rotation, hand.position, chain_points(fm, v, angles[v], point)
                )
                for point in (fm.tip, fm.pad)
            )
            motions[v][f] = FingerMotion(angles[v], tip, pad)
    return Kinematics(recording.time, motions)


def kinematics_table(kin: Kinematics, units: str = "mm") -> pd.DataFrame:
    """Angles CSV table: ``time``, per digit its angles ``<digit>.<joint>`` (deg; flexion
    joints, then ``<joint>_abduction`` of two-axis joints), ``<digit>.tip.x|y|z`` and,
    for models with pads, ``<digit>.pad.x|y|z`` (``units``); the orthogonal variant's
    columns carry the prefix ``orthogonal.``."""
    scale = UNITS_TO_MM[units]
    cols: dict[str, FloatArray] = {"time": kin.time}
    for v, fingers in kin.motions.items():
        prefix = "" if v == "user_axis" else f"{v}."
        for f, m in fingers.items():
            for j, a in m.angles.items():
                cols[f"{prefix}{f}.{j}"] = np.degrees(a)
            for point, xyz in (("tip", m.tip), ("pad", m.pad)):
                if xyz is not None:
                    for i, c in enumerate("xyz"):
                        cols[f"{prefix}{f}.{point}.{c}"] = xyz[:, i] / scale
    return pd.DataFrame(cols)


# --- Block kernel for swing-twist models (the default) --------------------------------------
# Frames are processed in blocks that stay in cache, with rotations in a rows layout (row
# 3i + k of a rotation is element (i, k); frames last). Every joint of every digit is done
# at once, so a one-frame block (a live stream's) costs a fixed number of NumPy calls, not
# a number per joint, digit and variant: G = R_p^T R_c of all J joints is one einsum over a
# (J, 9, m) layout; then every trace tr(Q C) = tr(G R_ref^T C) of every variant is one
# batched BLAS product with constant weights, one for the two-axis joints and one for the
# hinges (8 and 2 rows per variant and joint). All half angles (the hinges and the distal
# axis of each two-axis joint) are one call, all proximal angles of two-axis joints
# another. The chain needs cos and sin of each angle, which come from the same two numbers
# the angle's atan2 takes, so no cos/sin call is made. The point chains of all digits and
# variants run together, step by step, the digits with the longest chain first: the rows
# of a step's digits are a leading slice (a finger's four axes end where the thumb's fifth
# begins). Every operation on a frame's numbers is the one the per-joint code did, so the
# results are the same bits.
# A block's arrays are J (or V * D) times as large as one joint's, hence blocks of 1024
# frames, not the 16,384 of a joint at a time (on a 100,000-frame whole hand, 2048 was
# slower with both variants, 512 slower with either).

BLOCK_FRAMES = 1024


def _as3(rows: FloatArray) -> FloatArray:
    """``(n, 9, m)`` rows as ``(3 n, 3, m)`` (a view): each rotation's ``(3, 3)`` block."""
    return rows.reshape(-1, 3, rows.shape[-1])


def _product_rows(a: FloatArray, b: FloatArray) -> FloatArray:
    """``A^T B`` for ``(..., 9, m)`` rows of ``A`` and ``B``: ``(..., 9, m)``."""
    shape = (*a.shape[:-2], 3, 3, a.shape[-1])
    return np.einsum("...lim,...lkm->...ikm", a.reshape(shape), b.reshape(shape)).reshape(a.shape)


def _weights(reference: FloatArray, mats: list[FloatArray]) -> FloatArray:
    """Rows ``w_k (9,)`` with ``w_k · vec(G) = tr(G reference^T C_k)``."""
    return np.stack([(reference.T @ c).T.reshape(9) for c in mats])


def _half_angle(y: FloatArray, x: FloatArray, out: FloatArray) -> None:
    """``theta = 2 atan2(y, x)`` with its cosine and sine (1 and 0 where ``x = y = 0``) into
    ``out[0]``, ``out[1]``, ``out[2]`` (``out`` of shape ``(3,) + x.shape``, rad)."""
    theta, cos, sin = out
    np.multiply(x, x, out=cos)
    np.multiply(y, y, out=sin)
    r2 = cos + sin
    cos -= sin
    np.multiply(x, 2.0, out=sin)
    sin *= y
    _divide_by_radius(r2, cos, sin)
    np.arctan2(y, x, out=theta)
    theta *= 2.0


def _full_angle(y: FloatArray, x: FloatArray, out: FloatArray) -> None:
    """``beta = atan2(y, x)`` with its cosine and sine (1 and 0 where ``x = y = 0``) into
    ``out[0]``, ``out[1]``, ``out[2]`` (``out`` of shape ``(3,) + x.shape``, rad)."""
    theta, cos, sin = out
    h = np.hypot(x, y)
    np.copyto(cos, x)
    np.copyto(sin, y)
    _divide_by_radius(h, cos, sin)
    np.arctan2(y, x, out=theta)


def _divide_by_radius(r: FloatArray, cos: FloatArray, sin: FloatArray) -> None:
    """``cos /= r``, ``sin /= r`` in place, then cosine 1 and sine 0 where the radius ``r``
    is zero (no direction, angle 0). The zero radii are replaced by 1 before dividing, so
    no floating-point warning is raised and no ``np.errstate`` is needed; ``r`` is changed.
    """
    zero = r == 0.0
    r += zero
    cos /= r
    sin /= r
    np.copyto(cos, 1.0, where=zero)
    np.copyto(sin, 0.0, where=zero)


class KinematicsPlan:
    """:func:`compute_kinematics` of a ``swing_twist`` model, prepared once for many calls.

    Everything that depends on the model alone (trace weights of every joint, the chain's
    axis bases and their products, the hand sensor's reference pose) is computed here;
    :meth:`run` then does only per-frame work, block by block in cache, every digit and
    variant at once. A live stream builds one plan and runs it on each block of arriving
    frames; ``compute_kinematics`` builds one per call. Both give the same numbers.

    Parameters
    ----------
    model : HandModel
        A ``swing_twist`` model.
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    fingers : list of str, optional
        Digits (default: every digit of the model).

    Notes
    -----
    Layout, with ``J`` joints (the two-axis ones first, then the hinges), ``V`` variants,
    ``D`` digits and ``m`` frames of a block:

    * angle slots ``(4, A, V, m)`` (angle rad, its cosine, its sine, minus its sine): the
      proximal axes of the two-axis joints, their distal axes, then the hinges;
    * the chain: ``V * D`` rows, one per digit and variant (the digits with the longest
      chain first, then variant by variant), ``L`` steps (the longest chain's axes, distal
      first; the rows of the digits that have a step are a leading slice), ``k`` points per
      row (tip, and pad when any digit has one; a digit without a pad carries its tip
      twice).
    """

    def __init__(
        self,
        model: HandModel,
        variants: tuple[str, ...] = VARIANTS,
        fingers: list[str] | None = None,
    ) -> None:
        if model.angle_method != "swing_twist":
            raise ValueError(f"a plan needs a swing_twist model, not {model.angle_method!r}")
        self.model, self.variants = model, tuple(variants)
        self.fingers = list(fingers or model.fingers)
        nv = len(self.variants)
        p0, r0 = model.reference_poses[HAND_SENSOR]
        # Joints: the two-axis ones first, then the hinges; per joint its axis names.
        joints = [
            (f, j, jm, fm.axes(j))
            for f in self.fingers
            for fm in [model.fingers[f]]
            for j, jm in fm.joints.items()
        ]
        joints = [x for x in joints if len(x[3]) == 2] + [x for x in joints if len(x[3]) == 1]
        n2 = sum(len(x[3]) == 2 for x in joints)
        n1 = len(joints) - n2
        # Sensors: the joints' children in joint order (so the children's rows are a
        # slice), then the others (the hand sensor); the joints' parents by index.
        children = [jm.child for _, _, jm, _ in joints]
        parents = [jm.parent for _, _, jm, _ in joints]
        self.sensors = list(dict.fromkeys(children))
        self.sensors += sorted({HAND_SENSOR, *parents} - set(children))
        self._parents = np.array([self.sensors.index(x) for x in parents], dtype=np.intp)
        self._children: slice | np.ndarray = slice(0, len(joints))
        if self.sensors[: len(joints)] != children:  # a sensor the child of two joints
            self._children = np.array([self.sensors.index(x) for x in children], dtype=np.intp)
        self._hand = self.sensors.index(HAND_SENSOR)
        # Trace weights: (n2, 8 V, 9) and (n1, 2 V, 9), variant major in each joint's rows.
        weights = []
        slot: dict[tuple[str, str], int] = {}  # (digit, axis name) -> angle slot
        for i, (f, j, jm, axes) in enumerate(joints):
            pr, cr = model.reference_poses[jm.parent][1], model.reference_poses[jm.child][1]
            mats = []
            for v in self.variants:
                if len(axes) == 2:
                    b = model.in_parent(f, axes[0].name, v)[1]
                    a = model.in_parent(f, axes[1].name, v)[1]
                    ap = a - (a @ b) * b
                    kb = skew(b)
                    xs, ys = (np.eye(3), skew(a).T), (np.eye(3), kb, kb @ kb)
                    mats += [np.outer(a, np.cross(b, ap)), np.outer(a, ap)]
                    mats += [x @ y for x in xs for y in ys]
                else:
                    mats += [np.eye(3), skew(model.in_parent(f, j, v)[1]).T]
            weights.append(_weights(pr.T @ cr, mats))
            if len(axes) == 2:
                slot[f, axes[0].name], slot[f, axes[1].name] = i, n2 + i
            else:
                slot[f, axes[0].name] = n2 + i
        self._n2, self._n1, self._slots = n2, n1, 2 * n2 + n1
        self._w2 = np.array(weights[:n2]).reshape(n2, 8 * nv, 9)
        self._w1 = np.array(weights[n2:]).reshape(n1, 2 * nv, 9)
        # Outputs: angle name -> slot, per digit.
        self._angle_slots = {
            f: {k: slot[f, k] for k in model.fingers[f].angle_names()} for f in self.fingers
        }
        self._build_chain(p0, r0)
        self.p0 = p0

    def _build_chain(self, p0: FloatArray, r0: FloatArray) -> None:
        """The chain's constants, stacked over the batch (see the class notes): per step the
        rows that have it, their bases, carries, offsets (``None`` where a centre migrates),
        centres and migrations and the angle slot each turns by; per row its points and the
        turn to the hand sensor's frame."""
        model, nv = self.model, len(self.variants)
        chains = [model.fingers[f].chain()[::-1] for f in self.fingers]  # distal first
        order = sorted(range(len(chains)), key=lambda d: -len(chains[d]))  # longest first
        self._row = {self.fingers[d]: i * nv for i, d in enumerate(order)}  # + variant index
        n_steps = len(chains[order[0]])
        self._rows = [nv * sum(len(c) > i for c in chains) for i in range(n_steps)]
        self._k = 2 if any(model.fingers[f].pad is not None for f in self.fingers) else 1
        slot_of = {
            (f, name): s for f, names in self._angle_slots.items() for name, s in names.items()
        }
        nvd = nv * len(chains)
        basis = np.zeros((n_steps, nvd, 3, 3))
        centre = np.zeros((n_steps, nvd, 3, 1))
        migration = np.zeros((n_steps, nvd, 3, 1))
        moves = np.zeros((n_steps, nvd), dtype=bool)
        turn = np.zeros((n_steps, nvd), dtype=np.intp)
        carry = np.zeros((n_steps, nvd, 3, 3))
        offset = np.zeros((n_steps, nvd, 3, 1))
        variant = np.zeros((n_steps, nvd), dtype=np.intp)
        points = np.empty((nvd, 3, self._k))
        start = np.empty((nvd, 3, self._k, 1))  # the first step's x where its centre is fixed
        to_hand = np.empty((nvd, 3, 3))
        self._has_pad = np.zeros(nvd, dtype=bool)
        hand_offset = np.empty((nvd, 3, 1))
        for f, chain in zip(self.fingers, chains, strict=True):
            fm = model.fingers[f]
            for iv, v in enumerate(self.variants):
                b = self._row[f] + iv
                pts = [fm.tip] + ([fm.pad if fm.pad is not None else fm.tip] * (self._k - 1))
                points[b] = np.array(pts).T
                self._has_pad[b] = fm.pad is not None
                variant[:, b] = iv
                for i, jm in enumerate(chain):
                    basis[i, b] = orthonormal_basis(jm.axis_for(v))
                    centre[i, b] = jm.center[:, None]
                    if jm.migration is not None:
                        migration[i, b, :, 0], moves[i, b] = jm.migration, True
                    turn[i, b] = slot_of[f, jm.name]
                    if i > 0:
                        carry[i, b] = basis[i, b] @ basis[i - 1, b].T
                        offset[i, b] = basis[i, b] @ (centre[i - 1, b] - centre[i, b])
                d0 = points[b][:, :, None] - centre[0, b][:, None, :]  # (3, k, 1)
                start[b] = (basis[0, b] @ d0.reshape(3, -1)).reshape(d0.shape)
                # The point at the reference posture, then in the hand sensor's frame.
                last = len(chain) - 1
                to_hand[b] = r0.T @ basis[last, b].T
                hand_offset[b] = r0.T @ (centre[last, b] - p0[:, None])
        self._basis, self._carry, self._centre = basis, carry, centre
        self._points, self._start, self._to_hand = points, start, to_hand
        self._turn, self._variant = turn, variant
        # Per step: whether a centre of its rows moves; the offsets where none of them (nor
        # of the step before) does; the migrations where one does.
        self._moves = [bool(moves[i, :r].any()) for i, r in enumerate(self._rows)]
        self._migration = [migration[i] if x else None for i, x in enumerate(self._moves)]
        self._offset = [
            None if i == 0 or self._moves[i] or self._moves[i - 1] else offset[i][:, :, :, None]
            for i in range(n_steps)
        ]
        self._hand_offset = None if any(self._moves) else hand_offset[:, :, None, :]
        self._r0t = r0.T

    def run(self, recording: Recording) -> Kinematics:
        """Angles and tips (and pads) of every frame of ``recording`` (see
        :func:`compute_kinematics`)."""
        n = recording.n_frames
        poses = [recording.pose(s) for s in self.sensors]  # a clear error if one is absent
        nv, nvd, k = len(self.variants), len(self.variants) * len(self.fingers), self._k
        angles: FloatArray | list[list[FloatArray]]
        points: FloatArray | list[list[FloatArray | None]]
        if 0 < n <= BLOCK_FRAMES:  # one block (a live stream's): its arrays are the outputs
            angles, w = self._block(poses, 0, n)
            points = np.ascontiguousarray(np.swapaxes(w, -1, -2))  # (V D, k, n, 3)
        else:
            # One array per output, as a digit's own computation would give: in a few
            # large arrays, NumPy asks the kernel for huge pages (from 4 MB on), whose first
            # touch cost up to 0.1 s of system time per 100,000 whole-hand frames here.
            angles = [[np.empty(n) for _ in range(nv)] for _ in range(self._slots)]
            points = [
                [np.empty((n, 3)) if kk == 0 or self._has_pad[b] else None for kk in range(k)]
                for b in range(nvd)
            ]
            for s in range(0, n, BLOCK_FRAMES):
                e = min(n, s + BLOCK_FRAMES)
                a, w = self._block(poses, s, e)
                for i, row in enumerate(angles):
                    for iv, out in enumerate(row):
                        out[s:e] = a[i, iv]
                for b, row in enumerate(points):
                    for kk, out in enumerate(row):
                        if out is not None:
                            out[s:e] = w[b, kk].T
        motions: dict[str, dict[str, FingerMotion]] = {v: {} for v in self.variants}
        for iv, v in enumerate(self.variants):
            for f in self.fingers:
                b = self._row[f] + iv
                motions[v][f] = FingerMotion(
                    {name: angles[i][iv] for name, i in self._angle_slots[f].items()},
                    points[b][0],
                    points[b][1] if self._has_pad[b] else None,
                )
        return Kinematics(recording.time, motions)

    def _block(self, poses: list[PoseSeries], s: int, e: int) -> tuple[FloatArray, FloatArray]:
        """Frames ``s:e`` of the poses of :attr:`sensors`: angles ``(A, V, m)`` rad (the
        slots of the class notes) and points ``(V * D, k, 3, m)`` mm in tracker coordinates."""
        m, nv, n2, n1 = e - s, len(self.variants), self._n2, self._n1
        # Rows of every sensor, (S, 9, m), written in one pass (``out`` sets the layout:
        # frames last, contiguous); the children's are the first J (a view).
        rows = np.empty((len(poses), 9, m))
        np.concatenate([x.rotation[s:e].transpose(1, 2, 0) for x in poses], out=_as3(rows))
        g = _product_rows(rows[self._parents], rows[self._children])  # (J, 9, m)
        t2 = np.matmul(self._w2, g[:n2]).reshape(n2, nv, 8, m)
        t1 = np.matmul(self._w1, g[n2:]).reshape(n1, nv, 2, m)
        out = np.empty((4, self._slots, nv, m))
        # Two-axis joints: beta turns a to Q a about b; theta is the twist of Rot(b, -beta) Q.
        _full_angle(t2[:, :, 0], t2[:, :, 1], out[:3, :n2])
        cb, sb = out[1, :n2], out[2, :n2]
        c1 = 1.0 - cb
        y, x = np.empty((2, n2 + n1, nv, m))
        np.multiply(sb, t2[:, :, 3], out=x[:n2])
        np.subtract(t2[:, :, 2], x[:n2], out=x[:n2])
        x[:n2] += c1 * t2[:, :, 4]
        x[:n2] += 1.0
        np.multiply(sb, t2[:, :, 6], out=y[:n2])
        np.subtract(t2[:, :, 5], y[:n2], out=y[:n2])
        y[:n2] += c1 * t2[:, :, 7]
        # Hinges: theta = 2 atan2(vee(Q - Q^T) . a, 1 + tr Q).
        np.add(t1[:, :, 0], 1.0, out=x[n2:])
        y[n2:] = t1[:, :, 1]
        _half_angle(y, x, out[:3, n2 : 2 * n2 + n1])
        np.negative(out[2], out=out[3])
        hand = poses[self._hand].position[s:e].T
        return out[0], self._chain(out, rows[self._hand], hand)

    def _chain(self, out: FloatArray, hand: FloatArray, position: FloatArray) -> FloatArray:
        """Points ``(V * D, k, 3, m)`` (mm, tracker coordinates; the rows of the class notes)
        of the angles ``out`` (the slots of the class notes), the hand sensor's rotation rows
        ``hand (9, m)`` and position ``(3, m)`` (mm):
        :func:`~fingerfit.transforms.rotate_about_lines` (which see) with the model's
        constants taken from the plan, then carried by the hand."""
        m = out.shape[-1]
        # Per step and row: cos, sin, -sin of the angle it turns by, (L, V D, 3, 1, m).
        turns = out[1:, self._turn, self._variant].transpose(1, 2, 0, 3)[:, :, :, None, :]
        moving = any(self._moves)
        theta = out[0, self._turn, self._variant] if moving else None  # (L, V D, m)
        nvd, k = self._points.shape[0], self._k
        y = np.empty((nvd, 3, k, m))
        last = np.empty((nvd, 3, m)) if moving else None  # each row's last centre
        centre = None
        for i, (r, fixed) in enumerate(zip(self._rows, self._offset, strict=True)):
            c = self._centre[i, :r]
            if self._migration[i] is not None:
                c = c + self._migration[i][:r] * theta[i, :r, None, :]  # (r, 3, m)
            if i == 0:
                if self._migration[i] is None:
                    x = self._start  # (V D, 3, k, 1)
                else:
                    dd = self._points[:, :, :, None] - c[:, :, None, :]
                    x = np.matmul(self._basis[i], dd.reshape(r, 3, -1)).reshape(dd.shape)
            else:
                x = np.matmul(self._carry[i, :r], y[:r].reshape(r, 3, -1)).reshape(r, 3, k, m)
                if fixed is None:  # a centre moves: basis (c_prev - c) per frame
                    x += np.matmul(self._basis[i, :r], centre[:r] - c)[:, :, None, :]
                else:
                    x += fixed[:r]
            # (y0, y1) = x0 (cos, sin) + x1 (-sin, cos): the same bits as x0 cos - x1 sin.
            np.multiply(x[:, 0:1], turns[i, :r, 0:2], out=y[:r, :2])
            y[:r, :2] += x[:, 1:2] * turns[i, :r, 2::-2]
            y[:r, 2] = x[:, 2]
            if moving:  # the rows whose chain ends here
                done = self._rows[i + 1] if i + 1 < len(self._rows) else 0
                last[done:r] = c[done:]
            centre = c
        local = np.matmul(self._to_hand, y.reshape(nvd, 3, -1)).reshape(y.shape)
        if self._hand_offset is None:
            local += np.matmul(self._r0t, last - self.p0[:, None])[:, :, None, :]
        else:
            local += self._hand_offset
        world = np.einsum("ijm,bjkm->bkim", hand.reshape(3, 3, m), local)
        world += position
        return world
