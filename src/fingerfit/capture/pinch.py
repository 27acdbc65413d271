"""The pinch protocol's holds: when two digits' pads touch and stay still, found in a
pinch recording to mark them in ``events.csv`` (``docs/lab.md``, *Pinches*).

Each digit's pad point rides on its distal sensor: the ``<digit>.pad`` landmark carried
from the reference posture into that sensor's frame. A hold of the thumb and a finger is a
stretch of at least :data:`MIN_HOLD_S` in which

* the two pad points are within :data:`TOUCH_MM` (pads touching: the two digitised skin
  points nearly meet, up to the stylus's and the skin's few millimetres; a key pinch --
  the thumb's pulp on the side of the index -- leaves the pads centimetres apart), and
* they are still relative to each other: the spread of their difference over
  :data:`STILL_WINDOW_S` around each frame is at most
  :data:`fingerfit.stylus.landmarks.STILL_MM`, white tracker noise taken out
  (:func:`fingerfit.stylus.landmarks.window_spreads`), so the approach and the release
  are left out.

The first and last half-window of each such stretch are left out too: the touch's onset
and release (the pulps compressing, rolling into place) are where a real contact is least
like the fixed contact point the pad fit assumes, and the window cannot place them closer.

Without pad landmarks nothing is found: the nail-edge tips of touching pads are 12-18 mm
apart, no closer than some pads that do not touch, so a tip cannot tell a touch. Holds
can be marked by a key instead (:func:`marked_holds`: a press at the start and one at the
end of each hold, the finger being the one nearest the thumb).
"""

from __future__ import annotations

import numpy as np

from ..session import Recording, TargetEvent
from ..stylus.landmarks import STILL_MM
from ..transforms import FloatArray

#: Pad points closer than this (mm) touch.
TOUCH_MM = 6.0
#: The shortest hold (s) marked.
MIN_HOLD_S = 0.3
#: The window (s) over which the pads must be still around each frame of a hold.
STILL_WINDOW_S = 0.25


def _carried(recording: Recording, digit: str, local: FloatArray) -> FloatArray:
    """A point of ``digit``'s distal segment, ``local`` ``(3,)`` in its sensor's frame
    (mm), in the tracker frame in every frame of ``recording``: ``(n, 3)`` mm."""
    from ..digits import DIGITS

    pose = recording.poses[DIGITS[digit].distal_sensor]
    return np.einsum("nij,j->ni", pose.rotation, local) + pose.position


def _still(rel: FloatArray, k: int) -> np.ndarray:
    """Frames ``(n,)`` whose centred window of ``k`` frames of ``rel (n, 3)`` has a spread
    at most :data:`STILL_MM` (running sums, as :func:`fingerfit.stylus.landmarks.next_take`)."""
    from ..stylus.landmarks import window_spreads

    spreads = window_spreads(rel, k)  # the window ending at each frame
    shift = k // 2
    centred = np.full(rel.shape[0], np.nan)
    centred[: rel.shape[0] - shift] = spreads[shift:]
    return centred <= STILL_MM


def find_holds(
    recording: Recording,
    pads: dict[str, FloatArray],
    rate_hz: float,
    *,
    first: str = "thumb",
) -> list[TargetEvent]:
    """The pad-to-pad holds of digit ``first`` with each other digit (module docstring).

    Parameters
    ----------
    recording : Recording
        A pinch recording (mm, tracker frame).
    pads : dict[str, ndarray]
        Digit -> its pad point ``(3,)`` in its distal sensor's frame (mm).
    rate_hz : float

    Returns
    -------
    list of TargetEvent
        ``(recording, first, digit, start, end)`` rows for ``events.csv``, by start.
    """
    if first not in pads:
        return []
    k = max(3, round(STILL_WINDOW_S * rate_hz))
    shortest = max(1, round(MIN_HOLD_S * rate_hz))
    p0 = _carried(recording, first, pads[first])
    events: list[TargetEvent] = []
    for d in pads:
        if d == first:
            continue
        rel = p0 - _carried(recording, d, pads[d])
        hold = (np.linalg.norm(rel, axis=1) <= TOUCH_MM) & _still(rel, k)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], hold.astype(np.int8), [0]])))
        trim = k // 2
        for a, b in edges.reshape(-1, 2):
            a, b = a + trim, b - trim
            if b - a >= shortest:
                t = recording.time
                events.append(TargetEvent(recording.name, first, d, float(t[a]), float(t[b - 1])))
    return sorted(events, key=lambda e: e.start)


def pad_points(
    landmarks: dict[str, FloatArray], reference: Recording, digits: list[str], kind: str = "pad"
) -> dict[str, FloatArray]:
    """Each digit's pad point ``(3,)`` in its distal sensor's frame (mm): its ``<digit>.pad``
    landmark (``kind``: or another landmark of the distal phalanx, ``tip``) carried from
    the reference posture by the sensor's mean reference pose. Digits without that
    landmark are left out."""
    from ..digits import DIGITS

    out = {}
    for d in digits:
        pad = landmarks.get(f"{d}.{kind}")
        sensor = DIGITS[d].distal_sensor
        if pad is None or sensor not in reference.poses:
            continue
        pos, rot = reference.poses[sensor].mean()
        out[d] = rot.T @ (pad - pos)
    return out


def marked_holds(
    recording: Recording,
    presses: list[float],
    points: dict[str, FloatArray],
    *,
    first: str = "thumb",
) -> tuple[list[TargetEvent], int]:
    """Holds marked by key presses: each pair of presses (start, end; s, the recording's
    time) is a hold of digit ``first`` with the digit whose point (``points``: digit ->
    ``(3,)`` in its distal sensor's frame, mm: the pad landmarks, else the tips) is
    nearest ``first``'s over the pair's frames.

    Returns
    -------
    events : list of TargetEvent
    unpaired : int
        A last press without its end (1) or none (0).
    """
    others = [d for d in points if d != first]
    if first not in points or not others:
        return [], len(presses) % 2
    p0 = _carried(recording, first, points[first])
    dist = {d: np.linalg.norm(p0 - _carried(recording, d, points[d]), axis=1) for d in others}
    events = []
    for a, b in zip(presses[0::2], presses[1::2], strict=False):
        inside = (recording.time >= a) & (recording.time <= b)
        if not inside.any():
            continue
        near = min(others, key=lambda d: float(np.nanmedian(dist[d][inside])))
        events.append(TargetEvent(recording.name, first, near, float(a), float(b)))
    return events, len(presses) % 2
