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
from .session import HAND_SENSOR, UNITS_TO_MM, Recording
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
# Frames are processed in blocks that stay in cache, with rotations in a (9, m) layout
# (row 3i + k is element (i, k)). Per joint: G = R_p^T R_c as nine 3-term sums, then every
# trace tr(Q C) = tr(G R_ref^T C) of every variant in one BLAS product with constant
# weights. The chain needs cos and sin of each angle, which come from the same two numbers
# the angle's atan2 takes, so no cos/sin call is made.

BLOCK_FRAMES = 16384


def _rows(rotation: FloatArray) -> FloatArray:
    """``(m, 3, 3)`` rotations as a contiguous ``(9, m)`` array."""
    return np.ascontiguousarray(rotation.reshape(-1, 9).T)


#: Blocks of at most this many frames (a live stream's) take one einsum per product
#: instead of 27 ufunc calls, whose fixed cost dominates there.
SMALL_BLOCK = 64


def _product_rows(a: FloatArray, b: FloatArray) -> FloatArray:
    """``A^T B`` for ``(9, m)`` rows of ``A`` and ``B``: ``(9, m)``."""
    m = a.shape[1]
    if m <= SMALL_BLOCK:
        return np.einsum("lim,lkm->ikm", a.reshape(3, 3, m), b.reshape(3, 3, m)).reshape(9, m)
    g = np.empty_like(a)
    for i in range(3):
        for k in range(3):
            o = g[3 * i + k]
            np.multiply(a[i], b[k], out=o)
            o += a[3 + i] * b[3 + k]
            o += a[6 + i] * b[6 + k]
    return g


def _weights(reference: FloatArray, mats: list[FloatArray]) -> FloatArray:
    """Rows ``w_k (9,)`` with ``w_k · vec(G) = tr(G reference^T C_k)``."""
    return np.stack([(reference.T @ c).T.reshape(9) for c in mats])


def _half_angle(y: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``theta = 2 atan2(y, x)`` with its cosine and sine (1 and 0 where ``x = y = 0``)."""
    xx, yy = x * x, y * y
    r2 = xx + yy
    cos = np.subtract(xx, yy, out=xx)
    sin = np.multiply(x, 2.0, out=yy)
    sin *= y
    with np.errstate(divide="ignore", invalid="ignore"):  # x = y = 0: set below
        cos /= r2
        sin /= r2
    _no_angle(r2, cos, sin)
    theta = np.arctan2(y, x)
    theta *= 2.0
    return theta, cos, sin


def _full_angle(y: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``beta = atan2(y, x)`` with its cosine and sine (1 and 0 where ``x = y = 0``)."""
    h = np.hypot(x, y)
    with np.errstate(divide="ignore", invalid="ignore"):  # x = y = 0: set below
        cos = x / h
        sin = y / h
    _no_angle(h, cos, sin)
    return np.arctan2(y, x), cos, sin


def _no_angle(r: FloatArray, cos: FloatArray, sin: FloatArray) -> None:
    """Cosine 1 and sine 0 where the radius ``r`` is zero (no direction, angle 0)."""
    zero = r == 0.0
    if zero.any():
        cos[zero] = 1.0
        sin[zero] = 0.0


@dataclass(frozen=True)
class _Step:
    """One turn of a point chain (:func:`_chain`), with everything that depends on the model
    alone computed once: ``basis`` (rows ``e1, e2, a`` of the axis), ``carry`` (this basis
    times the previous one's transpose), ``offset`` (``basis @ (c_prev - c)`` when neither
    centre migrates)."""

    name: str
    centre: FloatArray  # (3, 1)
    migration: FloatArray | None
    basis: FloatArray
    carry: FloatArray | None
    offset: FloatArray | None


class KinematicsPlan:
    """:func:`compute_kinematics` of a ``swing_twist`` model, prepared once for many calls.

    Everything that depends on the model alone (trace weights of every joint, the chain's
    axis bases and their products, the hand sensor's reference pose) is computed here;
    :meth:`run` then does only per-frame work, block by block in cache. A live stream
    builds one plan and runs it on each block of arriving frames; ``compute_kinematics``
    builds one per call. Both give the same numbers.

    Parameters
    ----------
    model : HandModel
        A ``swing_twist`` model.
    variants : tuple of str
        ``user_axis`` and/or ``orthogonal``.
    fingers : list of str, optional
        Digits (default: every digit of the model).
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
        p0, r0 = model.reference_poses[HAND_SENSOR]
        self.sensors = {HAND_SENSOR}
        self.joints: dict[str, list[tuple[list[str], str, str, FloatArray]]] = {}
        self.chains: dict[str, dict[str, dict[str, tuple]]] = {v: {} for v in self.variants}
        for f in self.fingers:
            fm = model.fingers[f]
            joints = []
            for j, jm in fm.joints.items():
                pr, cr = model.reference_poses[jm.parent][1], model.reference_poses[jm.child][1]
                axes = fm.axes(j)
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
                self.sensors |= {jm.parent, jm.child}
                joints.append(
                    ([x.name for x in axes], jm.parent, jm.child, _weights(pr.T @ cr, mats))
                )
            self.joints[f] = joints
            axes_out = fm.chain()[::-1]
            for v in self.variants:
                steps, prev = [], None
                for jm in axes_out:
                    basis = orthonormal_basis(jm.axis_for(v))
                    c = jm.center[:, None]
                    carry = offset = None
                    if prev is not None:
                        carry = basis @ prev.basis.T
                        if prev.migration is None and jm.migration is None:
                            offset = basis @ (prev.centre - c)
                    prev = _Step(jm.name, c, jm.migration, basis, carry, offset)
                    steps.append(prev)
                last = steps[-1]
                # The point at the reference posture, then in the hand sensor's frame.
                to_hand = (r0.T @ last.basis.T, r0.T)
                points = {"tip": fm.tip} | ({} if fm.pad is None else {"pad": fm.pad})
                stacked = np.array(list(points.values())).T  # (3, k)
                self.chains[v][f] = {
                    "steps": steps,
                    "to_hand": to_hand,
                    "points": points,
                    "stacked": stacked,
                }
        self.p0 = p0

    def run(self, recording: Recording) -> Kinematics:
        """Angles and tips (and pads) of every frame of ``recording`` (see
        :func:`compute_kinematics`)."""
        model, variants = self.model, self.variants
        n = recording.n_frames
        hand = recording.pose(HAND_SENSOR)
        for s in self.sensors:
            recording.pose(s)  # a clear error if absent
        angles = {v: {f: {} for f in self.fingers} for v in variants}
        points = {v: {f: {} for f in self.fingers} for v in variants}
        for v in variants:
            for f in self.fingers:
                angles[v][f] = {k: np.empty(n) for k in model.fingers[f].angle_names()}
                points[v][f] = {k: np.empty((n, 3)) for k in self.chains[v][f]["points"]}
        for s in range(0, n, BLOCK_FRAMES):
            e = min(n, s + BLOCK_FRAMES)
            rows = {k: _rows(recording.poses[k].rotation[s:e]) for k in self.sensors}
            h = rows[HAND_SENSOR]
            hp = hand.position[s:e].T
            for f in self.fingers:
                cs: dict[str, dict[str, tuple[FloatArray, FloatArray, FloatArray]]] = {
                    v: {} for v in variants
                }
                for names, parent, child, w in self.joints[f]:
                    t = w @ _product_rows(rows[parent], rows[child])
                    step = 8 if len(names) == 2 else 2
                    for iv, v in enumerate(variants):
                        tv = t[iv * step : (iv + 1) * step]
                        if len(names) == 2:
                            beta, cb, sb = _full_angle(tv[0], tv[1])
                            c1 = 1.0 - cb
                            tr_i = tv[2] - sb * tv[3] + c1 * tv[4]
                            tr_k = tv[5] - sb * tv[6] + c1 * tv[7]
                            cs[v][names[0]] = (beta, cb, sb)
                            cs[v][names[1]] = _half_angle(tr_k, 1.0 + tr_i)
                        else:
                            cs[v][names[0]] = _half_angle(tv[1], 1.0 + tv[0])
                for v in variants:
                    for k, (ang, _, _) in cs[v].items():
                        angles[v][f][k][s:e] = ang
                    chain = self.chains[v][f]
                    rot, r0t = chain["to_hand"]
                    # The digit's points (tip, pad) go through the chain together.
                    y, centre = _chain(chain["steps"], cs[v], chain["stacked"])
                    local = (rot @ y.reshape(3, -1)).reshape(y.shape)
                    local += (r0t @ (centre - self.p0[:, None]))[:, None, :]
                    world = np.einsum("ijm,jkm->kim", h.reshape(3, 3, -1), local)
                    world += hp
                    for k, name in enumerate(chain["points"]):
                        points[v][f][name][s:e] = world[k].T
        motions = {
            v: {
                f: FingerMotion(angles[v][f], points[v][f]["tip"], points[v][f].get("pad"))
                for f in self.fingers
            }
            for v in variants
        }
        return Kinematics(recording.time, motions)


def _chain(
    steps: list[_Step], cs: dict[str, tuple[FloatArray, FloatArray, FloatArray]], points: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Points ``(3, k)`` turned through ``steps`` with each angle's cosine and sine given.

    Returns ``y (3, k, m)``, the coordinates in the last step's basis about its centre, and
    that centre ``(3, 1|m)``: :func:`~fingerfit.transforms.rotate_about_lines` (which
    see) with the model's constants taken from the plan.
    """
    y = centre = None
    k = points.shape[1]
    for st in steps:
        ang, cos, sin = cs[st.name]
        c = st.centre if st.migration is None else st.centre + np.multiply.outer(st.migration, ang)
        if y is None:
            d = points[:, :, None] - c[:, None, :]  # (3, k, 1|m)
            x = np.broadcast_to(
                (st.basis @ d.reshape(3, -1)).reshape(d.shape), (3, k, cos.shape[0])
            )
        else:
            x = (st.carry @ y.reshape(3, -1)).reshape(y.shape)
            x += (st.offset if st.offset is not None else st.basis @ (centre - c))[:, None, :]
        out = np.empty((3, k, cos.shape[0]))
        np.multiply(x[0], cos, out=out[0])
        out[0] -= x[1] * sin
        np.multiply(x[0], sin, out=out[1])
        out[1] += x[1] * cos
        out[2] = x[2]
        y, centre = out, c
    return y, centre
