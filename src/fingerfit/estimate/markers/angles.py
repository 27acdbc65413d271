"""Joint angles and fingertips of a marker recording with a model fitted from markers.

The inner step of the bundle adjustment with the model held: per frame, the digit's
angles and the hand's frame that put the model's markers (:attr:`HandModel.markers`)
nearest the measured ones (position-only residuals), each frame solved on its own
(:func:`.frames.solve_frames`: a frame's angles do not depend on the frames solved with
it). Each frame starts from its markers' turns about the model's lines, joint by joint
(:func:`.start.turn_about`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...digits import DIGITS, HAND_SENSOR
from ...errors import FingerfitError
from ...io.rigid import ClusterFit, fit_cluster
from ...model import HandModel
from ...session import Recording, Session
from ...transforms import FloatArray, rotate_about_line
from .chain import HandFrames, Lines, Point, Structure, predict
from .frames import FrameSolution, solve_frames
from .observe import DigitMarkers, carry_back, digit_markers
from .start import turn_about


@dataclass(frozen=True)
class DigitAngles:
    """One digit's angles over a marker recording.

    Attributes
    ----------
    names : list of str
        The chain's angle names, proximal first (``mp_abduction``, ``mp``, ...).
    angles : ndarray, shape (n, L)
        rad; NaN where the frame had no hand frame or none of the digit's markers.
    tip : ndarray, shape (n, 3)
        Fingertip (mm, tracker coordinates).
    rms_mm : float
        RMS residual per coordinate over the recording (mm).
    unconverged : int
        Frames whose solve stopped unconverged (:data:`.frames.MAX_STEPS`); their
        angles are the last iterate's.
    """

    names: list[str]
    angles: FloatArray
    tip: FloatArray
    rms_mm: float
    unconverged: int = 0


def _session_of(model: HandModel, recording: Recording) -> Session:
    """A one-recording marker session with the model's map (for :mod:`.observe`)."""
    mapping: dict[str, list[str]] = {}
    for label, (segment, *_) in model.markers.items():
        mapping.setdefault(segment, []).append(label)
    missing = [k for k in model.markers if k not in recording.markers]
    if missing:
        raise FingerfitError(
            f"marker '{missing[0]}' of the model is not in the recording", path=recording.name
        )
    return Session(
        subject=model.subject,
        hand=model.hand,
        units="mm",
        rate_hz=1.0,
        fingers=list(model.fingers),
        reference=recording,
        grasp=[recording],
        landmarks={},
        marker_map={k: tuple(v) for k, v in mapping.items()},
    )


def marker_angles(model: HandModel, recording: Recording) -> dict[str, DigitAngles]:
    """Every digit's angles and fingertip over a marker recording.

    Parameters
    ----------
    model : HandModel
        Fitted from markers (``model.markers`` not empty).
    recording : Recording
        Marker positions ``(n, 3)`` mm, tracker coordinates, NaN where unseen.

    Returns
    -------
    dict[str, DigitAngles]
    """
    if not model.markers:
        raise FingerfitError("the model has no markers: fit it from a marker session")
    session = _session_of(model, recording)
    shape = np.array([p for _, (s, p, _) in model.markers.items() if s == HAND_SENSOR])
    moving, _ = carry_back(session, [recording], shape)
    labels = session.marker_map[HAND_SENSOR]
    hand = fit_cluster(np.stack([recording.markers[k] for k in labels], axis=1), shape)
    places = {label: p[None] for label, (_, p, _) in model.markers.items()}
    hand_ok = np.isfinite(next(iter(moving.values()))).all(axis=1)
    out = {}
    for d, fm in model.fingers.items():
        # The hand's shape is the model's (the recording's own mean is no reference).
        data = replace(digit_markers(session, d, moving, places), hand_shape=shape)
        chain = fm.chain()
        depth = np.array([len(fm.chain(s + 1)) for s in range(3)])
        names = [j.name for j in chain]
        first = [names.index(j) for j in DIGITS[d].joints]
        structure = Structure(depth, np.array(first))
        lines = Lines(np.array([j.axis for j in chain]), np.array([j.center for j in chain]))
        u = np.array([model.markers[k][1] for k in data.labels])
        slide = np.array([model.markers[k][2] for k in data.labels])
        q = _start(data, structure, lines, u, first)
        start = Point(lines, u, q, HandFrames.identity(data.frames), slide)
        result = solve_frames(data, structure, start)
        seen = hand_ok & data.present.any(axis=0)
        angles = np.where(seen[None], result.q, np.nan).T
        tip = _tip(model, d, structure, lines, result, data, hand, seen)
        count = 3 * int(data.present.sum() + data.hand_present.sum())
        rms = float(np.sqrt(result.cost.sum() / max(count, 1)))
        unconverged = int((~result.converged & seen).sum())
        out[d] = DigitAngles(names, angles, tip, rms, unconverged)
    return out


def _start(
    data: DigitMarkers,
    structure: Structure,
    lines: Lines,
    u: FloatArray,
    first: list[int],
) -> FloatArray:
    """Each frame's start angles ``(L, n)``: each joint's flexion from its child markers'
    turn about its line, the proximal joints undone first; second axes 0."""
    q = np.zeros((structure.levels, data.frames))
    tracks = np.where(data.present[:, None], data.position, np.nan).transpose(0, 2, 1)
    for j, level in enumerate(first):
        a, c = lines.axis[level], lines.centre[level]
        child = np.flatnonzero(data.segment == j)
        ang = np.stack([turn_about(tracks[i], u[i], a, c) for i in child])
        seen = np.isfinite(ang)
        theta = np.where(seen, ang, 0.0).sum(axis=0) / np.maximum(seen.sum(axis=0), 1)
        q[level] = theta
        for i in np.flatnonzero(data.segment > j):
            tracks[i] = rotate_about_line(np.nan_to_num(tracks[i]), c, a, -theta)
            tracks[i][~data.present[i]] = np.nan
    return q


def _tip(
    model: HandModel,
    digit: str,
    structure: Structure,
    lines: Lines,
    result: FrameSolution,
    data: DigitMarkers,
    hand: ClusterFit,
    seen: np.ndarray,
) -> FloatArray:
    """The fingertip ``(n, 3)`` (mm, tracker coordinates): the model's tip moved by the
    chain, the frame's hand correction undone (``y = C^T (y' - h + d) + h``) and carried by
    the hand markers' rigid fit (NaN where not ``seen``)."""
    tip = model.fingers[digit].tip
    p, *_ = predict(structure, lines, np.array([2]), tip[None], result.q)
    pivot = data.hand_shape.mean(axis=0)
    c = result.hand
    y = np.einsum("nji,nj->ni", c.rotation, p[0].T - pivot + c.offset) + pivot
    x = np.einsum("nij,nj->ni", hand.rotation, y) + hand.translation
    x[~seen] = np.nan
    return x


def angles_table(time: FloatArray, result: dict[str, DigitAngles]):
    """The angles table of a marker recording: ``time`` (s), ``<digit>.<angle>`` (deg),
    ``<digit>.tip.x|y|z`` (mm, tracker coordinates) per frame, empty where not solved."""
    import pandas as pd

    cols: dict[str, FloatArray] = {"time": time}
    for d, a in result.items():
        for k, name in enumerate(a.names):
            cols[f"{d}.{name}"] = np.degrees(a.angles[:, k])
        for k, axis in enumerate("xyz"):
            cols[f"{d}.tip.{axis}"] = a.tip[:, k]
    return pd.DataFrame(cols)
