"""Landmarks digitised with the stylus: which the session needs, which segment carries
each, how a take is found and averaged, and where the landmark sits at the reference
posture (``docs/lab.md``, *Landmarks*).

* **Segment**: a joint's dorsal landmark rides on the joint's parent segment (``mp`` on
  the hand, ``pip`` on the proximal phalanx, ``dip`` on the middle one; the thumb's
  ``cmc`` on the hand, ``mcp`` on the metacarpal, ``ip`` on the proximal phalanx), the
  ``tip`` and ``pad`` on the distal phalanx, a ``target.<label>`` on nothing (tracker
  frame). A take is the stylus tip expressed in that segment's sensor frame, so the hand
  may rest anywhere while the landmarks are taken: each is carried to the reference
  posture by that sensor's mean pose in the reference recording.
* **A take**: the stylus tip still for :data:`WINDOW_S` -- the window's spread (how far
  its tip wanders, the tracker's white noise left out: see
  :func:`window_spreads`) at most :data:`STILL_MM` --, or the window ending at a key
  press, refused as shaky when its spread is over :data:`MAX_SPREAD_MM`. The take is the window's mean. The next
  take of the same landmark waits until the tip has been lifted :data:`LIFT_MM` away.
* **The landmark**: the mean of its takes (default :data:`TAKES`); its spread is the RMS
  distance of the takes from that mean, its uncertainty the standard error
  ``spread / sqrt(takes - 1)`` (mm), which ``landmarks.csv`` keeps in its ``sd`` column.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..digits import DIGITS
from ..transforms import FloatArray

#: Seconds of stillness that make a take, and the window a key press averages.
WINDOW_S = 0.5
#: The largest spread (mm) a take's window may have (a key press's window over it is
#: refused as shaky).
MAX_SPREAD_MM = 0.5
#: The spread (mm) under which the stylus counts as held still (the still trigger):
#: tighter than :data:`MAX_SPREAD_MM`, so that the window leaves out the end of the
#: approach, whose slow last millimetre would pull the take towards where it came from.
STILL_MM = 0.2
#: How far (mm) the tip must leave a take before the next take of the landmark.
LIFT_MM = 10.0
#: The parts a window is cut into to measure its spread (:func:`window_spreads`).
PARTS = 5
#: Placements of each landmark, averaged.
TAKES = 3


def landmark_segment(name: str) -> str | None:
    """The sensor whose frame carries landmark ``name`` (None: the tracker frame)."""
    if name.startswith("target."):
        return None
    digit, what = name.split(".", 1)
    d = DIGITS[digit]
    if what in ("tip", "pad"):
        return d.distal_sensor
    return d.joint_sensors()[what][0]


def landmark_names(
    digits: list[str], *, pads: bool = False, targets: tuple[str, ...] = ()
) -> list[str]:
    """The landmarks to digitise, in order: each digit's dorsal joint points and tip
    (``landmarks.csv``'s names), then with ``pads`` each digit's pad, then the targets
    ``target.<label>``."""
    names = [f"{d}.{k}" for d in digits for k in DIGITS[d].landmarks]
    if pads:
        names += [f"{d}.pad" for d in digits]
    return names + [f"target.{t}" for t in targets]


def tip_points(
    stylus_position: FloatArray,
    stylus_rotation: FloatArray,
    tip_offset: FloatArray,
    segment: tuple[FloatArray, FloatArray] | None,
) -> FloatArray:
    """The stylus tip ``(n, 3)`` mm in a segment sensor's frame (or the tracker frame).

    Parameters
    ----------
    stylus_position, stylus_rotation : ndarray, shapes (n, 3), (n, 3, 3)
        Stylus sensor poses (tracker frame, mm; sensor -> tracker).
    tip_offset : ndarray, shape (3,)
        The tip in the stylus sensor frame (mm).
    segment : (position (n, 3), rotation (n, 3, 3)) or None
        The segment sensor's poses; None: the tracker frame.
    """
    tip = np.einsum("nij,j->ni", stylus_rotation, tip_offset) + stylus_position
    if segment is None:
        return tip
    pos, rot = segment
    return np.einsum("nji,nj->ni", rot, tip - pos)


def window_spread(points: FloatArray) -> float:
    """A window's spread (mm): how far the tip wanders in ``points`` ``(n, 3)``, white
    tracker noise left out (:func:`window_spreads` over the whole window; missing points
    dropped). NaN with fewer than :data:`PARTS` complete points."""
    ok = np.isfinite(points).all(axis=1)
    p = points[ok]
    if p.shape[0] < PARTS:
        return float("nan")
    return float(window_spreads(p, p.shape[0])[-1])


def window_spreads(points: FloatArray, k: int) -> FloatArray:
    """The spread (mm) of every window of ``k`` frames of ``points`` ``(n, 3)``, ending
    at each frame ``(n,)``: NaN before the first full window or where a point is missing.

    A window is cut into :data:`PARTS` equal parts; the spread is the RMS distance of the
    parts' means from their mean, less what the tracker's white noise leaves in them
    (its variance from the successive differences, whose mean square is twice it, over
    the frames of a part): slow wandering and drift count, noise does not, whatever the
    tracker's noise. Running sums: no loop over frames.
    """
    n = points.shape[0]
    out = np.full(n, np.nan)
    length = k // PARTS
    if length < 2 or n < PARTS * length:
        return out
    k = PARTS * length
    ok = np.isfinite(points).all(axis=1)
    p = np.where(ok[:, None], points, 0.0)
    c1 = np.concatenate([np.zeros((1, 3)), np.cumsum(p, axis=0)])
    d = np.zeros(n)
    d[1:] = (np.diff(p, axis=0) ** 2).sum(axis=1)
    cd = np.concatenate([[0.0], np.cumsum(d)])
    cok = np.concatenate([[0], np.cumsum(~ok)])
    end = np.arange(k, n + 1)
    means = np.stack(
        [(c1[end - j * length] - c1[end - (j + 1) * length]) / length for j in range(PARTS)]
    )  # (parts, windows, 3)
    total = ((means - means.mean(axis=0)) ** 2).sum(axis=2).mean(axis=0)
    noise = (cd[end] - cd[end - k + 1]) / (k - 1) / 2.0  # per frame, 3-D
    spread = np.sqrt(np.maximum(total - noise / length * (PARTS - 1) / PARTS, 0.0))
    spread[(cok[end] - cok[end - k]) > 0] = np.nan
    out[k - 1 :] = spread
    return out


def next_take(
    points: FloatArray,
    rate_hz: float,
    *,
    start: int = 0,
    lifted_from: FloatArray | None = None,
    lift_points: FloatArray | None = None,
    window_s: float = WINDOW_S,
    max_spread_mm: float = STILL_MM,
    lift_mm: float = LIFT_MM,
) -> tuple[int, int] | None:
    """The first still window of the tip ``points`` ``(n, 3)`` (mm, the landmark's
    segment frame) ending at or after frame ``start``, after the tip has left
    ``lifted_from`` ``(3,)`` (the previous take) by ``lift_mm``: measured on
    ``lift_points`` ``(n, 3)`` (the same frames in the frame ``lifted_from`` is in, e.g.
    the tracker's; default ``points``).

    Returns
    -------
    (first, end) or None
        The window's frames ``points[first:end]``; None: no take yet.
    """
    k = max(3, round(window_s * rate_hz))
    n = points.shape[0]
    begin = start
    if lifted_from is not None:
        lp = points if lift_points is None else lift_points
        away = np.linalg.norm(lp[start:] - lifted_from, axis=1) > lift_mm
        hit = np.flatnonzero(away)
        if hit.size == 0:
            return None
        begin = start + int(hit[0])
    if n < begin + k:
        return None
    # Only the frames from ``begin`` on: each window looked at lies within them, and a
    # live capture calls this for every block (the earlier frames were looked at then).
    spreads = window_spreads(points[begin:], k)
    still = np.flatnonzero(spreads[k - 1 :] <= max_spread_mm)
    if still.size == 0:
        return None
    end = begin + k - 1 + int(still[0]) + 1
    return end - k, end


@dataclass(frozen=True)
class Landmark:
    """A digitised landmark.

    Attributes
    ----------
    name : str
        ``landmarks.csv``'s name.
    segment : str or None
        The sensor whose frame carries it (None: the tracker frame).
    takes : ndarray, shape (m, 3)
        Each take's mean tip, in the segment's frame (mm).
    spreads : ndarray, shape (m,)
        Each take's window spread (mm).
    """

    name: str
    segment: str | None
    takes: FloatArray
    spreads: FloatArray

    @property
    def local(self) -> FloatArray:
        """The mean of the takes ``(3,)``, segment frame, mm."""
        return self.takes.mean(axis=0)

    @property
    def spread_mm(self) -> float:
        """RMS distance of the takes from their mean (mm)."""
        return float(np.sqrt(((self.takes - self.local) ** 2).sum(axis=1).mean()))

    @property
    def sd_mm(self) -> float:
        """The landmark's uncertainty (mm): the standard error of the mean of the takes,
        ``spread / sqrt(takes - 1)`` (NaN for one take)."""
        m = self.takes.shape[0]
        return float("nan") if m < 2 else self.spread_mm / np.sqrt(m - 1)

    def at_reference(self, reference: dict[str, tuple[FloatArray, FloatArray]]) -> FloatArray:
        """The landmark ``(3,)`` in the tracker frame at the reference posture (mm), from
        ``reference``: sensor -> its mean pose (position ``(3,)`` mm, rotation ``(3, 3)``)."""
        if self.segment is None:
            return self.local
        pos, rot = reference[self.segment]
        return rot @ self.local + pos
