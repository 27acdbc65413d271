"""Plausibility of the units: sensor distances, landmarks and the fitted model's lengths
against the bounds of :mod:`.bounds`, and a joint's reach (``fingerfit joint``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...digits import DIGIT_NAMES, DIGITS
from ...session import HAND_SENSOR, PoseSeries, Recording, Session, joint_sensors, sensor_name
from ...transforms import FloatArray
from .bounds import (
    JOINT_REACH_MM,
    LANDMARK_TO_CENTRE_MAX_MM,
    SEGMENT_FRACTION,
    SENSOR_HEIGHT_MM,
    UNIT_NAMES,
    Bound,
    finger_length_bound,
    neighbour_bound,
    segment_bound,
)
from .problems import Problem, _ratio_units, explaining_units, fmt_mm, unit_cause

if TYPE_CHECKING:
    from ...model import HandModel


def _median_distance(a: PoseSeries, b: PoseSeries, max_frames: int = 1000) -> float:
    ok = np.flatnonzero(np.isfinite(a.position[:, 0]) & np.isfinite(b.position[:, 0]))
    if not ok.size:
        return math.nan
    if ok.size > max_frames:
        ok = ok[:: ok.size // max_frames + 1]
    return float(np.median(np.linalg.norm(a.position[ok] - b.position[ok], axis=1)))


def check_recording_units(
    recording: Recording, units: str, fingers: Iterable[str] = DIGIT_NAMES, path: Path | None = None
) -> list[Problem]:
    """Median distances between neighbouring sensors of every finger against the bounds.

    Parameters
    ----------
    recording : Recording
        Positions mm (already converted from ``units``).
    units : str
        Units the file was read in (``UNITS_TO_MM`` key), for the cause.
    fingers : iterable of str
    path : Path, optional
        The file, for the message (default: the recording's name).
    """
    problems = []
    for finger in fingers:
        for parent, child in joint_sensors(finger).values():
            if parent not in recording.poses or child not in recording.poses:
                continue
            d = _median_distance(recording.poses[parent], recording.poses[child])
            b = neighbour_bound(finger, parent, child)
            if math.isfinite(d) and not b.contains(d):
                problems.append(
                    Problem(
                        f"distance between sensors {parent} and {child} {fmt_mm(d)} mm (median; "
                        f"plausible {b.lo:.3g}-{b.hi:.3g} mm): {unit_cause(d, b, units)}",
                        path=path or Path(recording.name),
                        field="units",
                    )
                )
    return problems


def _landmark_points(session: Session, fingers: Sequence[str]) -> dict[str, FloatArray] | None:
    names = [f"{f}.{k}" for f in fingers for k in DIGITS[f].landmarks]
    if any(n not in session.landmarks for n in names):
        return None  # the fit reports the missing landmark
    return {n: np.asarray(session.landmarks[n], float) for n in names}


def landmark_scale(session: Session, fingers: Sequence[str], reference: dict) -> float:
    """Scale factor ``s`` that best maps the landmarks onto the sensors (translation free).

    Correspondences: each segment sensor's origin at the reference posture and the
    midpoint of its segment's two landmarks; ``s = sum(dl . dp) / sum(dl . dl)`` with
    ``dl``, ``dp`` the deviations from their centroids. ``s`` near 1: same units; near 10:
    landmarks 10x too small (e.g. centimetres in a millimetre session).
    """
    lm = _landmark_points(session, fingers) or {}
    pairs = []
    for f in fingers:
        ends = DIGITS[f].landmarks
        for i, seg in enumerate(DIGITS[f].segments):
            s = sensor_name(f, seg)
            a, b = f"{f}.{ends[i]}", f"{f}.{ends[i + 1]}"
            if s in reference and a in lm and b in lm:
                pairs.append((0.5 * (lm[a] + lm[b]), reference[s][0]))
    if len(pairs) < 2:
        return math.nan
    lmk = np.array([p[0] for p in pairs])
    sen = np.array([p[1] for p in pairs])
    dl, dp = lmk - lmk.mean(axis=0), sen - sen.mean(axis=0)
    den = float(np.sum(dl * dl))
    return float(np.sum(dl * dp) / den) if den > 0 else math.nan


#: Sensors named in another order fit the landmarks at most this fraction of the distance
#: of the names as given: refused as swapped. Correct simulated sessions (6 whole hands,
#: default noise): every other order is at least 3.4 times worse than the names as given.
SWAP_RATIO = 0.5


def _swapped_sensors(
    digit: str, lm: dict[str, FloatArray], reference: dict, path: Path | None
) -> Problem | None:
    """A digit's segment sensors in the wrong order: each sensor at the reference posture
    is nearest its own segment's landmark midpoint; another assignment of the names that
    fits less than :data:`SWAP_RATIO` of the distance means swapped names (two
    neighbouring sensors swapped are otherwise plausible everywhere)."""
    dg = DIGITS[digit]
    names = [dg.sensor(s) for s in dg.segments]
    if any(n not in reference for n in names):
        return None
    ends = [lm[f"{digit}.{k}"] for k in dg.landmarks]
    mids = np.array([0.5 * (ends[i] + ends[i + 1]) for i in range(3)])
    pos = np.array([reference[n][0] for n in names])
    dist = np.linalg.norm(pos[:, None, :] - mids[None, :, :], axis=2)  # sensor x segment
    given = float(np.trace(dist))
    best, order = min(
        (float(dist[range(3), list(p)].sum()), p)
        for p in itertools.permutations(range(3))
        if p != (0, 1, 2)
    )
    if best >= SWAP_RATIO * given:
        return None
    moved = [f"{names[i]} on the {dg.segments[order[i]]}" for i in range(3) if order[i] != i]
    return Problem(
        f"{digit} sensors look swapped: {', '.join(moved)} would lie {fmt_mm(best)} mm in all "
        f"from their segments' landmark midpoints, against {fmt_mm(given)} mm as named; "
        "check the sensor names (--map)",
        path=path,
    )


def check_landmarks(
    session: Session, fingers: Sequence[str], reference: dict[str, tuple[FloatArray, FloatArray]]
) -> list[Problem]:
    """Landmarks against their segments' sensors, then landmark distances against the bounds.

    Parameters
    ----------
    session : Session
    fingers : sequence of str
    reference : dict
        Sensor -> mean reference pose ``(position (3,) mm, rotation (3, 3))``.
    """
    lm = _landmark_points(session, fingers)
    if lm is None:
        return []
    path = None if session.path is None else session.path / "landmarks.csv"
    problems = []
    far = []
    for f in fingers:
        ends = DIGITS[f].landmarks
        for i, seg in enumerate(DIGITS[f].segments):
            s = sensor_name(f, seg)
            if s not in reference:
                continue
            mid = 0.5 * (lm[f"{f}.{ends[i]}"] + lm[f"{f}.{ends[i + 1]}"])
            d = float(np.linalg.norm(reference[s][0] - mid))
            limit = 0.5 * segment_bound(f, seg).hi + SENSOR_HEIGHT_MM
            if d > limit:
                far.append((d, limit, f, seg, s))
    if far:
        d, limit, f, seg, s = max(far)
        scale = landmark_scale(session, fingers, reference)
        pairs = _ratio_units(scale) if math.isfinite(scale) and scale > 0 else []
        pairs = [(a, b) for a, b in pairs if b == session.units]
        if pairs:
            cause = (
                f"landmarks look like {UNIT_NAMES[pairs[0][0]]} while the recordings are "
                f"{UNIT_NAMES[session.units]} (scale {scale:.3g} fits them to the sensors)"
            )
        else:
            cause = (
                f"the landmarks do not lie on the sensed fingers (best scale {scale:.3g}); "
                "were they digitised in another frame or posture?"
            )
        problems.append(
            Problem(
                f"{f} {seg} landmarks' midpoint lies {fmt_mm(d)} mm from sensor {s} at the "
                f"reference posture (plausible < {limit:.3g} mm): {cause}",
                path=path,
            )
        )
        return problems
    swapped = [p for f in fingers if (p := _swapped_sensors(f, lm, reference, path))]
    if swapped:
        return swapped
    for f in fingers:
        ends = DIGITS[f].landmarks
        for i, seg in enumerate(DIGITS[f].segments):
            a, b = f"{f}.{ends[i]}", f"{f}.{ends[i + 1]}"
            d = float(np.linalg.norm(lm[b] - lm[a]))
            bound = segment_bound(f, seg)
            if not bound.contains(d):
                problems.append(
                    Problem(
                        f"{f} {seg} segment {fmt_mm(d)} mm between landmarks {a} and {b} "
                        f"(plausible {bound.lo:.3g}-{bound.hi:.3g} mm): "
                        f"{unit_cause(d, bound, session.units)}",
                        path=path,
                    )
                )
    return problems


def check_model(model: HandModel, session: Session | None = None) -> list[Problem]:
    """A fitted model's lengths against the bounds.

    Segment lengths, finger length (hand size), sensor-to-joint-centre distances at the
    reference posture and, with the session, dorsal landmark to joint centre.

    Parameters
    ----------
    model : HandModel
        mm, tracker coordinates at the reference posture.
    session : Session, optional
        For the landmarks and the path in messages.
    """
    units = model.session_units
    path = None if session is None else session.path
    problems = []
    for f, fm in model.fingers.items():
        if f not in SEGMENT_FRACTION:
            continue
        for seg, length in fm.segment_lengths.items():
            b = segment_bound(f, seg)
            if not b.contains(length):
                problems.append(
                    Problem(
                        f"{f} {seg} segment {fmt_mm(length)} mm (plausible {b.lo:.3g}-"
                        f"{b.hi:.3g} mm): {unit_cause(length, b, units)}",
                        path=path,
                    )
                )
        total = float(sum(fm.segment_lengths.values()))
        b = finger_length_bound(f)
        if not b.contains(total):
            problems.append(
                Problem(
                    f"{f} {'finger ' if f != 'thumb' else ''}length "
                    f"({DIGITS[f].joints[0].upper()} centre to tip) {fmt_mm(total)} mm (plausible "
                    f"{b.lo:.3g}-{b.hi:.3g} mm): {unit_cause(total, b, units)}",
                    path=path,
                )
            )
        kinds = {HAND_SENSOR: "metacarpal"} | {sensor_name(f, s): s for s in DIGITS[f].segments}
        for j, jm in fm.joints.items():
            for sensor in (jm.parent, jm.child):
                if sensor not in model.reference_poses:
                    continue
                d = float(np.linalg.norm(model.reference_poses[sensor][0] - jm.center))
                limit = segment_bound(f, kinds[sensor]).hi + SENSOR_HEIGHT_MM
                if d > limit:
                    b = Bound(0.0, limit, "")
                    problems.append(
                        Problem(
                            f"{f} {j} centre lies {fmt_mm(d)} mm from sensor {sensor} "
                            f"(plausible < {limit:.3g} mm): {unit_cause(d, b, units)}",
                            path=path,
                        )
                    )
        problems += _landmark_to_centre_problems(model, session, f, units, path)
    return problems


def _landmark_to_centre_problems(
    model: HandModel, session: Session | None, digit: str, units: str, path: Path | None
) -> list[Problem]:
    """Each dorsal landmark of ``digit`` at most :data:`LANDMARK_TO_CENTRE_MAX_MM` from its
    fitted joint centre. A unit mistake is named only when it brings every one of the
    digit's distances into range and more than one is out: one distance alone is a
    landmark on another joint or a poorly determined axis (units are checked before the
    fit, on the recordings and the landmarks)."""
    if session is None:
        return []
    dist = {
        j: float(np.linalg.norm(session.landmarks[f"{digit}.{j}"] - jm.center))
        for j, jm in model.fingers[digit].joints.items()
        if f"{digit}.{j}" in session.landmarks
    }
    b = Bound(0.0, LANDMARK_TO_CENTRE_MAX_MM, "dorsal skin to joint centre")
    out = {j: d for j, d in dist.items() if not b.contains(d)}
    if not out:
        return []
    cause = (
        "the landmark and the fitted axis disagree: check that the landmark was digitised "
        "on this joint, and the joint's axis quality"
    )
    if len(out) > 1 and len(out) == len(dist):
        # The unit each distance would name; one unit for all of them is a unit mistake.
        named = {tuple(explaining_units(d, b, units)[:1]) for d in out.values()}
        if len(named) == 1 and named != {()}:
            cause = unit_cause(next(iter(out.values())), b, units)
    return [
        Problem(
            f"{digit} {j} landmark-to-centre distance {fmt_mm(d)} mm (plausible < "
            f"{b.hi:g} mm): {cause}",
            path=path,
        )
        for j, d in out.items()
    ]


def joint_reach_problems(
    reach_mm: float, units: str, path: Path | None = None, field: str | None = "units"
) -> list[Problem]:
    """Units of any joint between two segments: the farther segment origin's distance.

    Parameters
    ----------
    reach_mm : float
        Distance (mm, as converted from ``units``) from the joint centre to the farther of
        the two segment frame origins (``max(|c_parent|, |c_child|)`` with the centre in
        each segment's frame).
    units : str
        The units the positions were declared in (``UNITS_TO_MM`` key), for the cause.
    path : Path, optional
    field : str, optional
        The field named in the message (the CLI: ``--units``).

    Returns
    -------
    list of Problem
        One problem when ``reach_mm`` lies outside :data:`JOINT_REACH_MM`, naming the unit
        mistake that would bring it into range (:func:`unit_cause`).
    """
    b = Bound(*JOINT_REACH_MM, "segment origin to joint centre")
    if not math.isfinite(reach_mm) or b.contains(reach_mm):
        return []
    return [
        Problem(
            f"the joint centre lies {fmt_mm(reach_mm)} mm from the farther segment origin "
            f"(plausible {b.lo:g}-{b.hi:g} mm): {unit_cause(reach_mm, b, units, every=True)}",
            path=path,
            field=field,
        )
    ]
