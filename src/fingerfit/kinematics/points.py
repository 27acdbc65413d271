"""The tips and pads of every digit and variant of a :class:`~.plan.KinematicsPlan`, moved
through their chains together (:func:`fingerfit.transforms.rotate_about_lines` written for
the whole stack at once).

Layout, with ``V`` variants, ``D`` digits and ``m`` frames of a block: ``V * D`` rows, one
per digit and variant (the digits with the longest chain first, then variant by variant),
``L`` steps (the longest chain's axes, distal first; the rows of the digits that have a
step are a leading slice: a finger's four axes end where the thumb's fifth begins), ``k``
points per row (tip, and pad when any digit has one; a digit without a pad carries its tip
twice). A step turns each of its rows by an angle slot of the plan (its cosine and sine
come with it). Every operation on a frame's numbers is the one the per-joint code did, so
the results are the same bits. Lengths mm, tracker coordinates (``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np

from ..model import HandModel
from ..session import HAND_SENSOR
from ..transforms import FloatArray, orthonormal_basis


class PointChain:
    """The point chains of a plan's digits and variants, prepared once.

    Parameters
    ----------
    model : HandModel
    variants : tuple of str
    fingers : list of str
    angle_slots : dict
        Digit -> angle name -> the plan's angle slot it turns by.

    Attributes
    ----------
    row : dict[str, int]
        Digit -> its first row (add the variant's index).
    k : int
        Points per row (1: tips; 2: tips and pads).
    has_pad : ndarray of bool, shape (V * D,)
        Whether the row's second point is a pad.
    """

    def __init__(
        self,
        model: HandModel,
        variants: tuple[str, ...],
        fingers: list[str],
        angle_slots: dict[str, dict[str, int]],
    ) -> None:
        self.model, self.variants, self.fingers = model, tuple(variants), list(fingers)
        p0, r0 = model.reference_poses[HAND_SENSOR]
        self.p0 = p0
        nv = len(self.variants)
        chains = [model.fingers[f].chain()[::-1] for f in self.fingers]  # distal first
        order = sorted(range(len(chains)), key=lambda d: -len(chains[d]))  # longest first
        self.row = {self.fingers[d]: i * nv for i, d in enumerate(order)}  # + variant index
        n_steps = len(chains[order[0]])
        self.rows = [nv * sum(len(c) > i for c in chains) for i in range(n_steps)]
        self.k = 2 if any(model.fingers[f].pad is not None for f in self.fingers) else 1
        slot_of = {(f, name): s for f, names in angle_slots.items() for name, s in names.items()}
        nvd = nv * len(chains)
        basis = np.zeros((n_steps, nvd, 3, 3))
        centre = np.zeros((n_steps, nvd, 3, 1))
        migration = np.zeros((n_steps, nvd, 3, 1))
        moves = np.zeros((n_steps, nvd), dtype=bool)
        turn = np.zeros((n_steps, nvd), dtype=np.intp)
        carry = np.zeros((n_steps, nvd, 3, 3))
        offset = np.zeros((n_steps, nvd, 3, 1))
        variant = np.zeros((n_steps, nvd), dtype=np.intp)
        points = np.empty((nvd, 3, self.k))
        start = np.empty((nvd, 3, self.k, 1))  # the first step's x where its centre is fixed
        to_hand = np.empty((nvd, 3, 3))
        self.has_pad = np.zeros(nvd, dtype=bool)
        hand_offset = np.empty((nvd, 3, 1))
        for f, chain in zip(self.fingers, chains, strict=True):
            fm = model.fingers[f]
            for iv, v in enumerate(self.variants):
                b = self.row[f] + iv
                pts = [fm.tip] + ([fm.pad if fm.pad is not None else fm.tip] * (self.k - 1))
                points[b] = np.array(pts).T
                self.has_pad[b] = fm.pad is not None
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
        self._moves = [bool(moves[i, :r].any()) for i, r in enumerate(self.rows)]
        self._migration = [migration[i] if x else None for i, x in enumerate(self._moves)]
        self._offset = [
            None if i == 0 or self._moves[i] or self._moves[i - 1] else offset[i][:, :, :, None]
            for i in range(n_steps)
        ]
        self._hand_offset = None if any(self._moves) else hand_offset[:, :, None, :]
        self._r0t = r0.T

    def move(self, out: FloatArray, hand: FloatArray, position: FloatArray) -> FloatArray:
        """Points ``(V * D, k, 3, m)`` (mm, tracker coordinates; the rows of the class notes)
        of the angles ``out`` (the slots of the class notes), the hand sensor's rotation rows
        ``hand (9, m)`` and position ``(3, m)`` (mm):
        :func:`~fingerfit.transforms.rotate_about_lines` (which see) with the model's
        constants taken from here, then carried by the hand."""
        m = out.shape[-1]
        # Per step and row: cos, sin, -sin of the angle it turns by, (L, V D, 3, 1, m).
        turns = out[1:, self._turn, self._variant].transpose(1, 2, 0, 3)[:, :, :, None, :]
        moving = any(self._moves)
        theta = out[0, self._turn, self._variant] if moving else None  # (L, V D, m)
        nvd, k = self._points.shape[0], self.k
        y = np.empty((nvd, 3, k, m))
        last = np.empty((nvd, 3, m)) if moving else None  # each row's last centre
        centre = None
        for i, (r, fixed) in enumerate(zip(self.rows, self._offset, strict=True)):
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
                done = self.rows[i + 1] if i + 1 < len(self.rows) else 0
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
