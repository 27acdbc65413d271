"""The kinematics of a ``swing_twist`` model prepared once for many calls (a live stream's
blocks, a long recording's): every joint, digit and variant of a block of frames at once.

Frames are processed in blocks that stay in cache, with rotations in a rows layout (row
3i + k of a rotation is element (i, k); frames last). Every joint of every digit is done
at once, so a one-frame block (a live stream's) costs a fixed number of NumPy calls, not
a number per joint, digit and variant: G = R_p^T R_c of all J joints is one einsum over a
(J, 9, m) layout; then every trace tr(Q C) = tr(G R_ref^T C) of every variant is one
batched BLAS product with constant weights, one for the two-axis joints and one for the
hinges (8 and 2 rows per variant and joint). All half angles (the hinges and the distal
axis of each two-axis joint) are one call, all proximal angles of two-axis joints
another. The chain needs cos and sin of each angle, which come from the same two numbers
the angle's atan2 takes, so no cos/sin call is made. The point chains of all digits and
variants run together, step by step, the digits with the longest chain first: the rows
of a step's digits are a leading slice (a finger's four axes end where the thumb's fifth
begins). Every operation on a frame's numbers is the one the per-joint code did, so the
results are the same bits.
A block's arrays are J (or V * D) times as large as one joint's, hence blocks of 1024
frames, not the 16,384 of a joint at a time (on a 100,000-frame whole hand, 2048 was
slower with both variants, 512 slower with either).
"""

from __future__ import annotations

import numpy as np

from ..model import VARIANTS, HandModel
from ..session import HAND_SENSOR, PoseSeries, Recording
from ..transforms import FloatArray, skew
from .points import PointChain
from .results import FingerMotion, Kinematics

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
    Layout, with ``J`` joints (the two-axis ones first, then the hinges), ``V`` variants and
    ``m`` frames of a block: angle slots ``(4, A, V, m)`` (angle rad, its cosine, its sine,
    minus its sine): the proximal axes of the two-axis joints, their distal axes, then the
    hinges. The tips and pads: :class:`~.points.PointChain`.
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
        self.points = PointChain(model, self.variants, self.fingers, self._angle_slots)

    def run(self, recording: Recording) -> Kinematics:
        """Angles and tips (and pads) of every frame of ``recording`` (see
        :func:`compute_kinematics`)."""
        n = recording.n_frames
        poses = [recording.pose(s) for s in self.sensors]  # a clear error if one is absent
        nv, nvd, k = len(self.variants), len(self.variants) * len(self.fingers), self.points.k
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
                [np.empty((n, 3)) if kk == 0 or self.points.has_pad[b] else None for kk in range(k)]
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
                b = self.points.row[f] + iv
                motions[v][f] = FingerMotion(
                    {name: angles[i][iv] for name, i in self._angle_slots[f].items()},
                    points[b][0],
                    points[b][1] if self.points.has_pad[b] else None,
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
        return out[0], self.points.move(out, rows[self._hand], hand)
