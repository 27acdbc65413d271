"""Pinches: the thumb's tip and pad against another digit's during each touch event.

A pinch is a row of ``events.csv`` whose ``target`` names a digit
(:attr:`fingerfit.session.TargetEvent.is_pinch`): the pads of ``finger`` and
``target`` touch during ``[start, end]``. For every such event and every source the
evaluation gives, over the event's frames:

* **tip distance**: the distance between the two digits' tip points (nail-edge
  points), mm. With ground truth (simulated sessions) also the true distance and the
  **tip-distance error**, the mean over the event's frames of
  ``|d_model(t) - d_true(t)|`` (mm), and its signed mean (bias);
* **pad gap**: the distance between the two digits' pad points (the pulp's skin
  points), mm. Pads that touch have gap 0; with ground truth the true gap (the
  simulator's skin points) is given beside it.

Sources: ``reference`` (each digit's distal sensor carrying the model's tip and pad
points, as the fingers' reference fingertip), ``user_axis`` and ``orthogonal``
(the model variants' forward kinematics from the hand sensor). Real sessions (no
truth) report the distances and the model's pad gap alone.

Lengths mm, tracker coordinates.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..kinematics import compute_kinematics
from ..model import VARIANTS, HandModel
from ..session import Session
from ..transforms import FloatArray
from .fingertip import sensor_carried
from .truth import Truth

PINCH_COLUMNS = [
    "recording",
    "finger",
    "target",
    "kind",
    "start",
    "end",
    "frames",
    "source",
    "tip_distance_mm",
    "true_tip_distance_mm",
    "tip_distance_error_mm",
    "tip_distance_bias_mm",
    "pad_gap_mm",
    "true_pad_gap_mm",
    "pad_contact_mm",
]


def _kind(truth: Truth | None, recording: str, target: str, start: float) -> str:
    """The simulator's kind of a touch (``tip_pinch``, ``opposition``), or ``pinch``."""
    if truth is not None:
        for c in truth.document.get("contacts", []):
            if (
                c.get("recording") == recording
                and c.get("target") == target
                and abs(float(c.get("start", np.inf)) - start) < 1e-3
            ):
                return str(c.get("kind", "pinch"))
    return "pinch"


def _mean(x: FloatArray) -> float:
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else float("nan")


def _points(
    model: HandModel, session: Session, recording: str, digits: list[str]
) -> dict[str, dict[str, tuple[FloatArray, FloatArray | None]]]:
    """Source -> digit -> (tip ``(n, 3)``, pad ``(n, 3)`` or None) over one recording."""
    rec = session.recording(recording)
    kin = compute_kinematics(model, rec, fingers=digits)
    out: dict[str, dict[str, tuple[FloatArray, FloatArray | None]]] = {"reference": {}}
    for d in digits:
        fm = model.fingers[d]
        pad = None if fm.pad is None else sensor_carried(model, d, rec, fm.pad)
        out["reference"][d] = (sensor_carried(model, d, rec, fm.tip), pad)
    for v in VARIANTS:
        out[v] = {d: (kin.motions[v][d].tip, kin.motions[v][d].pad) for d in digits}
    return out


def _truth_frames(truth: Truth | None, session: Session, recording: str, n: int) -> bool:
    """Whether the truth has this recording, checked to have its ``n`` frames."""
    if truth is None or recording not in truth.tips:
        return False
    got = next(iter(truth.tips[recording].values())).shape[0]
    if got != n:
        raise FingerfitError(
            f"has {got} rows but the recording has {n} frames",
            path=None if session.path is None else session.path / "truth" / recording,
        )
    return True


def evaluate_pinches(
    model: HandModel, session: Session, truth: Truth | None = None
) -> pd.DataFrame:
    """Tip distances and pad gaps during every pinch event, per source.

    Parameters
    ----------
    model : HandModel
    session : Session
        Its pinch events (``target`` a digit) are evaluated; an event whose digit the
        model lacks is not (:func:`fingerfit.evaluate.fingertip.skipped_events` lists it).
    truth : Truth, optional
        Ground truth (simulated sessions): true tips and pads per frame.

    Returns
    -------
    DataFrame
        One row per pinch event and source (``reference``, ``user_axis``,
        ``orthogonal``), columns :data:`PINCH_COLUMNS`: ``kind`` (the simulator's
        ``tip_pinch``/``opposition``, else ``pinch``), ``start``/``end`` (s), ``frames``
        in the event, means over those frames (mm) of the tip distance, the true tip
        distance, ``|model - true|`` (error) and ``model - true`` (bias), the pad gap, the
        true pad gap and ``pad_contact_mm``, the mean distance of the two pad points from
        the true point where the pulps touch (truth ``<a>.contact.<b>``). NaN where there
        is no truth or the model has no pads.

    Raises
    ------
    FingerfitError
        A truth file whose rows do not match its recording's frames, named.
    """
    rows = []
    cache: dict[str, dict[str, dict[str, tuple[FloatArray, FloatArray | None]]]] = {}
    pinches = [e for e in session.events if e.is_pinch]
    for ev in pinches:
        a, b = ev.finger, ev.target
        if a not in model.fingers or b not in model.fingers:
            continue  # listed by skipped_events
        if ev.recording not in cache:
            digits = sorted(
                {d for e in pinches if e.recording == ev.recording for d in (e.finger, e.target)}
                & set(model.fingers)
            )
            cache[ev.recording] = _points(model, session, ev.recording, digits)
        rec = session.recording(ev.recording)
        k = (rec.time >= ev.start) & (rec.time <= ev.end)
        has_truth = _truth_frames(truth, session, ev.recording, rec.time.size)
        true_tip = true_gap = contact = None
        if has_truth:
            assert truth is not None
            tt = truth.tips[ev.recording]
            true_tip = np.linalg.norm(tt[a][k] - tt[b][k], axis=1)
            tp = truth.pads.get(ev.recording, {})
            if a in tp and b in tp:
                true_gap = np.linalg.norm(tp[a][k] - tp[b][k], axis=1)
            tc = truth.contacts.get(ev.recording, {})
            contact = tc.get((a, b), tc.get((b, a)))
            if contact is not None:
                contact = contact[k]
        kind = _kind(truth, ev.recording, b, ev.start)
        for src, pts in cache[ev.recording].items():
            (tip_a, pad_a), (tip_b, pad_b) = pts[a], pts[b]
            d = np.linalg.norm(tip_a[k] - tip_b[k], axis=1)
            gap = (
                np.full(d.shape, np.nan)
                if pad_a is None or pad_b is None
                else np.linalg.norm(pad_a[k] - pad_b[k], axis=1)
            )
            nan = np.full(d.shape, np.nan)
            diff = nan if true_tip is None else d - true_tip
            off = (
                nan
                if contact is None or pad_a is None or pad_b is None
                else 0.5
                * (
                    np.linalg.norm(pad_a[k] - contact, axis=1)
                    + np.linalg.norm(pad_b[k] - contact, axis=1)
                )
            )
            rows.append(
                (
                    ev.recording,
                    a,
                    b,
                    kind,
                    float(ev.start),
                    float(ev.end),
                    int(k.sum()),
                    src,
                    _mean(d),
                    _mean(nan if true_tip is None else true_tip),
                    _mean(np.abs(diff)),
                    _mean(diff),
                    _mean(gap),
                    _mean(nan if true_gap is None else true_gap),
                    _mean(off),
                )
            )
    return pd.DataFrame(rows, columns=PINCH_COLUMNS)


def pinch_labels(pinches: pd.DataFrame, sep: str = " ") -> pd.Series:
    """``<kind><sep><finger>-<target>`` for each row of a table with the columns
    :data:`PINCH_COLUMNS` (text or, in a study's table, categorical columns)."""
    text = pinches[["kind", "finger", "target"]].astype(str)
    return text["kind"] + sep + text["finger"] + "-" + text["target"]
