"""Anderson mixing of an adjustment's steps.

The marker adjustment (:func:`.bundle.adjust`) converges linearly: near its minimum each
Gauss-Newton step leaves a fixed fraction of the distance (a slow mode, often one that
overshoots and turns back). Anderson's mixing (type II, Walker and Ni 2011) treats the
adjustment as a fixed-point iteration ``x -> x + f(x)``, ``f`` the Levenberg-Marquardt
step, and takes the combination of its last steps that the recent history says lands
nearest a fixed point:

``x' = x_k + f_k - (dX + dF) gamma``, ``gamma = argmin |W (f_k - dF gamma)|``,

``dX`` and ``dF`` the differences of the last points and steps. ``W`` weighs the global
coordinates by their information (:func:`information_weights`), so that the combination
is chosen in the units of the cost, not in a mix of radians and millimetres; the
frames' coordinates move with the same ``gamma``. The mixed point is a proposal only:
the adjustment keeps it when it lowers the cost below the plain step's, and forgets the
history whenever it has to damp a step.
"""

from __future__ import annotations

import numpy as np

from ...transforms import FloatArray

#: The number of past steps mixed into the next one.
MEMORY = 5


class Mixer:
    """The recent points and steps of an iteration, and their mixing.

    Parameters
    ----------
    weights : ndarray, shape (P,)
        Each global coordinate's weight in the least-squares choice of the mixing
        (:func:`information_weights`).
    memory : int
        How many differences of past steps to mix.
    """

    def __init__(self, weights: FloatArray, memory: int = MEMORY) -> None:
        self.weights = weights
        self.memory = memory
        self._points: list[tuple[FloatArray, FloatArray]] = []
        self._steps: list[tuple[FloatArray, FloatArray]] = []

    def forget(self) -> None:
        """Drop the history (after a damped step: the iteration's map changed)."""
        self._points.clear()
        self._steps.clear()

    def propose(
        self, point: tuple[FloatArray, FloatArray], step: tuple[FloatArray, FloatArray]
    ) -> tuple[FloatArray, FloatArray] | None:
        """Record ``point`` (global ``(P,)`` and per-frame ``(n, K)`` coordinates) and
        its plain ``step`` (the same shapes); return the mixed point, or None while there
        is no history to mix."""
        self._points.append(point)
        self._steps.append(step)
        del self._points[: -(self.memory + 1)]
        del self._steps[: -(self.memory + 1)]
        if len(self._points) < 2:
            return None
        dxg = np.diff(np.stack([p[0] for p in self._points]), axis=0)  # (m, P)
        dxf = np.diff(np.stack([p[1] for p in self._points]), axis=0)  # (m, n, K)
        dfg = np.diff(np.stack([s[0] for s in self._steps]), axis=0)
        dff = np.diff(np.stack([s[1] for s in self._steps]), axis=0)
        gamma = np.linalg.lstsq((dfg * self.weights).T, step[0] * self.weights, rcond=1e-12)[
            0
        ]  # (m,)
        g = point[0] + step[0] - gamma @ (dxg + dfg)
        f = point[1] + step[1] - np.tensordot(gamma, dxf + dff, axes=1)
        return g, f


def information_weights(diagonal: FloatArray, sizes: list[tuple[int, int]]) -> FloatArray:
    """Weights of packed coordinates from the normal matrix's diagonal.

    Parameters
    ----------
    diagonal : ndarray, shape (U,)
        The information of each unknown (the normal matrix's diagonal), in its units.
    sizes : list of (int, int)
        Consecutive groups: ``(k, c)`` takes ``k`` unknowns of the diagonal, whose group
        is packed as ``c`` coordinates (a line's direction: 2 unknowns, 3 coordinates).

    Returns
    -------
    ndarray, shape (P,)
        The square root of each group's largest information, for each of its coordinates.
    """
    out, at = [], 0
    for k, c in sizes:
        out.append(np.full(c, np.sqrt(max(float(diagonal[at : at + k].max()), 0.0))))
        at += k
    return np.concatenate(out)
