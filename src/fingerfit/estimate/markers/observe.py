"""Marker recordings as a marker fit sees them: each digit's markers in the hand's frame.

The hand carries three or more markers. Their mean positions over the reference
recording are the hand's *shape*; in every frame the rigid fit of that shape to the
visible hand markers (:func:`fingerfit.io.rigid.fit_cluster`) gives the hand's motion
``(R_h, t_h)`` from the reference posture, and each digit marker ``x`` is carried back,
``y = R_h^T (x - t_h)``: tracker coordinates at the reference posture (mm), the frame of
the model (``docs/conventions.md``). A frame whose hand markers cannot be fitted (fewer
than three visible, or on one line) is left out and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...digits import DIGITS, HAND_SENSOR
from ...io.rigid import fit_cluster
from ...session import Recording, Session, sensor_name
from ...transforms import FloatArray


@dataclass(frozen=True)
class DigitMarkers:
    """One digit's markers over the frames of a fit (tracker coordinates at the
    reference posture, mm; frames last).

    Attributes
    ----------
    digit : str
    labels : list of str
        Marker labels, proximal segment first.
    segment : ndarray of int, shape (M,)
        Each marker's segment (0 the digit's first, 2 its distal).
    reference : ndarray, shape (M, 3)
        Each marker's mean position over the reference recording (NaN: never seen there).
    reference_count : ndarray of int, shape (M,)
        Reference frames each marker was seen in.
    position : ndarray, shape (M, 3, n)
        The markers in the moving frames, the hand's motion removed; 0 where not seen.
    present : ndarray of bool, shape (M, n)
    hand : ndarray, shape (H, 3, n)
        The hand's markers carried back the same way (0 where not seen).
    hand_present : ndarray of bool, shape (H, n)
    hand_shape : ndarray, shape (H, 3)
        Their places at the reference posture (:func:`hand_shape`).
    """

    digit: str
    labels: list[str]
    segment: np.ndarray
    reference: FloatArray
    reference_count: np.ndarray
    position: FloatArray
    present: np.ndarray
    hand: FloatArray
    hand_present: np.ndarray
    hand_shape: FloatArray

    @property
    def frames(self) -> int:
        return int(self.present.shape[1])

    def take(self, frames: slice | np.ndarray) -> DigitMarkers:
        """The same markers over ``frames`` only (a slice: views; indices: copies)."""
        return replace(
            self,
            position=self.position[..., frames],
            present=self.present[:, frames],
            hand=self.hand[..., frames],
            hand_present=self.hand_present[:, frames],
        )


def hand_shape(session: Session) -> FloatArray:
    """The hand markers' mean positions ``(H, 3)`` over the reference recording (mm)."""
    ref = session.reference.markers
    pts = np.stack([ref[k] for k in session.marker_map[HAND_SENSOR]], axis=1)
    ok = np.isfinite(pts)
    with np.errstate(invalid="ignore"):  # a marker never seen: NaN (no warning)
        return np.where(ok, pts, 0.0).sum(axis=0) / ok.sum(axis=0)


def carry_back(
    session: Session, recordings: list[Recording], shape: FloatArray
) -> tuple[dict[str, FloatArray], int]:
    """Every marker of ``recordings`` (concatenated) in the hand's frame.

    Parameters
    ----------
    session : Session
    recordings : list of Recording
    shape : ndarray, shape (H, 3)
        :func:`hand_shape`.

    Returns
    -------
    markers : dict[str, ndarray]
        Label -> ``(n, 3)`` mm, tracker coordinates at the reference posture; NaN where
        the marker or the hand's frame is missing (the hand's markers too).
    lost : int
        Frames without a hand frame.
    """
    hand = session.marker_map[HAND_SENSOR]
    out: dict[str, list[FloatArray]] = {}
    lost = 0
    for rec in recordings:
        pts = np.stack([rec.markers[k] for k in hand], axis=1)
        fit = fit_cluster(pts, shape)
        lost += int(np.isnan(fit.translation[:, 0]).sum())
        for label, x in rec.markers.items():
            y = np.einsum("nji,nj->ni", fit.rotation, x - fit.translation)
            out.setdefault(label, []).append(y)
    return {k: np.concatenate(v) for k, v in out.items()}, lost


def digit_markers(
    session: Session, digit: str, moving: dict[str, FloatArray], reference: dict[str, FloatArray]
) -> DigitMarkers:
    """A digit's markers for the fit, from :func:`carry_back` of the moving recordings and
    of the reference recording."""
    labels, segment = [], []
    for s, name in enumerate(DIGITS[digit].segments):
        for label in session.marker_map[sensor_name(digit, name)]:
            labels.append(label)
            segment.append(s)
    ref = np.stack([reference[k] for k in labels])  # (M, n_ref, 3)
    seen = np.isfinite(ref).all(axis=2)
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(ref, axis=1)
    pos, present = _frames_last([moving[k] for k in labels])
    hand, hand_present = _frames_last([moving[k] for k in session.marker_map[HAND_SENSOR]])
    return DigitMarkers(
        digit,
        labels,
        np.array(segment, dtype=np.intp),
        mean,
        seen.sum(axis=1),
        pos,
        present,
        hand,
        hand_present,
        hand_shape(session),
    )


def _frames_last(tracks: list[FloatArray]) -> tuple[FloatArray, np.ndarray]:
    """Tracks ``(n, 3)`` stacked frames last ``(K, 3, n)`` (0 where NaN) and where seen
    ``(K, n)``."""
    pos = np.stack(tracks)
    present = np.isfinite(pos).all(axis=2)
    pos = np.where(present[..., None], pos, 0.0).transpose(0, 2, 1)
    return np.ascontiguousarray(pos), present
