"""Each marker predicted from the others: out-of-sample evidence on a model's choice.

A model with more per-frame unknowns (a second axis's angle in every frame) fits the
markers it was fitted to better whatever the truth: its angles take some of their noise
and of the skin's slide, which is not white noise, so a test of the drop in cost that
rests on a noise model cannot tell that from a joint's motion. Held out, a marker is
predicted from the other markers of its frame (the frame's angles and hand correction
solved again without it, the model held: :func:`.frames.solve_frames`); a per-frame
unknown that followed the noise of the markers it saw moves the prediction away from the
marker it did not see, and one that follows a joint's motion brings it closer. The
marker fit reports this for a second MP axis (:func:`.fit.fit_digit`); it does not
decide by it (``docs/markers.md``: the measured trade).

A marker is held out only where another marker on its segment still shows the
segment's pose (:func:`holdable`), so that the frame's solve without it is nearly the
fit's. The model's lines and places are the fit's, from every frame: a few dozen global
unknowns against thousands of frames, which the held-out marker's own frames barely
move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from ...transforms import FloatArray
from .chain import Point, Structure, marker_residuals
from .frames import solve_frames
from .observe import DigitMarkers

#: About this many frames of the fit (every ``k``-th) are predicted: about as many
#: predictions per held-out marker, a fraction of a second of frame solves.
HELD_OUT_FRAMES = 1000
#: The predicted frames' differences are averaged over this many runs of consecutive
#: frames (batch means): the skin's slide makes neighbouring frames' errors alike, and
#: the batches' spread gives the mean's standard error honestly.
BATCHES = 20


def holdable(data: DigitMarkers) -> np.ndarray:
    """The markers ``(M,)`` that can be held out: each shares its segment with another
    marker, which still shows the segment's pose. A marker alone on its segment held out
    leaves its joint's angles seen only through the joints beyond (or, on the last
    segment, not at all): the prediction then measures how well a weaker problem than
    the fit's is solved, which can favour the model with fewer angles where the truth
    has more (``docs/markers.md``, measured)."""
    return np.bincount(data.segment)[data.segment] >= 2


def held_out_errors(
    data: DigitMarkers, structure: Structure, point: Point, frames: np.ndarray
) -> FloatArray:
    """Each holdable marker's squared prediction error over ``frames``.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
        The model's chain.
    point : Point
        The fitted model (lines, places, slides: tracker coordinates at the reference
        posture, mm, mm/rad) and every frame's fitted angles (rad) and hand correction,
        where each frame's solve without the marker starts.
    frames : ndarray of int, shape (n,)
        The frames predicted.

    Returns
    -------
    ndarray, shape (P, n)
        Per holdable marker (:func:`holdable`, in the order of ``data.labels``): its
        squared distance (mm^2) from where the model puts it with its frame solved
        without it; NaN where it was not seen.
    """
    part, here = data.take(frames), point.take(frames)
    out = []
    for i in np.flatnonzero(holdable(data)):
        present = part.present.copy()
        present[i] = False
        solved = solve_frames(replace(part, present=present), structure, here)
        at = replace(here, q=solved.q, hand=solved.hand)
        r = marker_residuals(part, structure, at).r[i]  # (3, n), 0 where unseen
        out.append(np.where(part.present[i], np.einsum("cn,cn->n", r, r), np.nan))
    return np.array(out).reshape(-1, len(frames))


@dataclass(frozen=True)
class HeldOutComparison:
    """Two models' held-out predictions of the same markers and frames.

    Attributes
    ----------
    gain_mm2 : float
        The mean squared prediction error of the first model less the second's, per
        prediction (mm^2): positive where the second predicts better.
    se_mm2 : float
        Its standard error (batch means over :data:`BATCHES` runs of frames).
    t : float
        ``gain_mm2 / se_mm2``.
    worse : bool
        The second model predicts worse beyond the 95 % interval of the gain (Student's
        t with ``BATCHES - 1`` degrees of freedom).
    predictions : int
        Markers predicted (marker-frames).
    """

    gain_mm2: float
    se_mm2: float
    t: float
    worse: bool
    predictions: int


def compare_held_out(
    data: DigitMarkers,
    first: tuple[Structure, Point],
    second: tuple[Structure, Point],
) -> HeldOutComparison:
    """The held-out predictions (:func:`held_out_errors`) of two fitted models of one
    digit's markers compared, frame by frame, over about :data:`HELD_OUT_FRAMES` frames.

    Parameters
    ----------
    data : DigitMarkers
    first, second : tuple of (Structure, Point)
        Each model's chain and fitted point (as :func:`held_out_errors`).

    Returns
    -------
    HeldOutComparison
    """
    step = max(1, math.ceil(data.frames / HELD_OUT_FRAMES))
    frames = np.arange(0, data.frames, step)
    d = held_out_errors(data, *first, frames) - held_out_errors(data, *second, frames)
    seen = np.isfinite(d)
    per_frame = np.where(seen, d, 0.0).sum(axis=0)
    count = seen.sum(axis=0)
    batches = np.array_split(np.arange(len(frames)), BATCHES)
    n = np.array([count[b].sum() for b in batches])
    means = np.array([per_frame[b].sum() for b in batches]) / np.maximum(n, 1)
    ok = n > 0
    gain = float(per_frame.sum() / max(int(count.sum()), 1))
    se = float(np.std(means[ok], ddof=1) / math.sqrt(ok.sum())) if ok.sum() > 1 else math.inf
    t = gain / se if se > 0 else math.copysign(math.inf, gain) if gain else 0.0
    limit = float(stats.t.ppf(0.975, max(int(ok.sum()) - 1, 1)))
    return HeldOutComparison(gain, se, t, t < -limit, int(count.sum()))


__all__ = ["HeldOutComparison", "compare_held_out", "held_out_errors", "holdable"]
