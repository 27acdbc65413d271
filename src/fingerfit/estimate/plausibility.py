"""Physical plausibility: units and the quaternion convention (``docs/plausibility.md``).

A recording in the wrong units or with quaternions in the wrong order fits without any
numerical complaint and gives a plausible-looking wrong model. These checks compare the
data with what a hand can be and with itself:

* **units** -- lengths against physiological bounds (:data:`SEGMENT_FRACTION` of a hand
  length in :data:`HAND_LENGTH_MM`, with the margins :data:`MARGIN`): neighbouring sensor
  distances in every recording, landmark distances, landmarks against the sensors of their
  segments, and the fitted model's segment lengths, finger length, landmark-to-centre and
  sensor-to-centre distances. A length out of bounds names the unit mistake that would
  bring it into range (ratios 1000, 100, 39.37, 25.4, 10, 2.54 and their inverses);
* **quaternion convention** -- the pivot residual: a joint's parent and child sensors must
  agree on one joint centre, ``R_p c_p + t_p = R_c c_c + t_c`` for every grasp frame
  (O'Brien et al. 2000). The residual is also evaluated with the quaternions conjugated,
  in ``x,y,z,w`` order, and both, and an alternative that fits far better is named;
* **a recording against a model** (``fingerfit angles``) -- the same pivot equation with
  the model's centre, and the scale factor that would fit;
* **any joint between two segments** (``fingerfit joint``) -- the distance from the joint
  to the farther segment origin against :data:`JOINT_REACH_MM`, and the pivot residual with
  one position axis negated (a mirrored frame, :data:`MIRRORS`).

Every check returns :class:`Problem` records; :func:`enforce` raises the first as a
:class:`PlausibilityError` (one line) unless ``force``, in which case each is warned about
as a :class:`PlausibilityWarning`. Lengths are mm, positions tracker coordinates, rotation
matrices sensor -> tracker (``docs/conventions.md``); quaternions ``(w, x, y, z)``.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..digits import DIGIT_NAMES, DIGITS
from ..errors import FingerfitError
from ..session import (
    HAND_SENSOR,
    UNITS_TO_MM,
    PoseSeries,
    Recording,
    Session,
    joint_sensors,
    sensor_name,
)
from ..transforms import FloatArray, matrix_from_quat_wxyz, quat_wxyz_from_matrix, relative_pose
from .centre import centre_of_rotation

if TYPE_CHECKING:
    from ..model import HandModel

# --------------------------------------------------------------------------- bounds

#: Segment (link) lengths as fractions of hand length (Buchholz, Armstrong & Goldstein
#: 1992, Ergonomics 35:261, table of link lengths). Fingers: metacarpal, proximal, middle,
#: distal; thumb: metacarpal, proximal, distal.
SEGMENT_FRACTION: dict[str, dict[str, float]] = {
    "thumb": {"metacarpal": 0.251, "proximal": 0.196, "distal": 0.158},
    "index": {"metacarpal": 0.463, "proximal": 0.245, "middle": 0.143, "distal": 0.097},
    "middle": {"metacarpal": 0.446, "proximal": 0.266, "middle": 0.170, "distal": 0.108},
    "ring": {"metacarpal": 0.421, "proximal": 0.244, "middle": 0.165, "distal": 0.107},
    "little": {"metacarpal": 0.414, "proximal": 0.204, "middle": 0.117, "distal": 0.094},
}
#: Hand length (wrist crease to the middle fingertip, mm) spanned by the bounds: from a
#: preschool child's hand to beyond the largest adult hands (``docs/plausibility.md``).
HAND_LENGTH_MM = (90.0, 240.0)
#: Margins on top of the hand-length range: individual proportions, landmark placement and
#: fit error (lower bound x 0.6, upper bound x 1.5).
MARGIN = (0.6, 1.5)
#: Dorsal joint landmark (skin) to the fitted joint centre (inside the finger), at most
#: this (mm). There is no lower bound: the fitted axis passes up to ~5 mm from the true one
#: (95th percentile 3.45 mm, 400 DIPs of a simulated cohort), as far as a small DIP is deep,
#: so a fitted centre may lie at the skin on correct data (``docs/plausibility.md``).
LANDMARK_TO_CENTRE_MAX_MM = 30.0
#: A segment's sensor sits on the skin of its segment: extra distance allowed beyond the
#: segment's own length (sensor height, soft tissue), mm.
SENSOR_HEIGHT_MM = 20.0
#: A joint's pivot residual (RMS, mm) on correct data is below this floor (or, when the
#: tracker is noisier, below ``PIVOT_NOISE_FACTOR`` x the static noise of the reference).
PIVOT_FLOOR_MM = 5.0
PIVOT_NOISE_FACTOR = 5.0
#: An alternative quaternion convention is named when its pooled pivot residual is below
#: this fraction of the as-read one (and the as-read one above ``PIVOT_MIN_MM``).
CONVENTION_RATIO = 0.5
PIVOT_MIN_MM = 1.0
#: ``fingerfit angles``: a recording whose pivot residual against the model's joint centre
#: exceeds this (mm, RMS) does not belong to the model.
RECORDING_RESIDUAL_MM = 10.0
#: Relative tolerance when matching a scale factor to a unit ratio.
SCALE_TOLERANCE = 0.2
#: Any joint between two tracked segments (``fingerfit joint``): plausible distance (mm)
#: from the joint centre to the *farther* of the two segment origins. Measured: 15 mm
#: (index DIP of the simulated hand, sensors mid-phalanx), 23 and 46 mm (PIP, MP),
#: 53-89 mm (hand-turned real Liberty logs), 152 mm (real upper-arm/forearm marker
#: clusters), 250 mm (a real mechanical hinge). A tracked body's sensor or cluster cannot
#: sit within 10 mm of the joint on both sides; 2 m is beyond any limb.
JOINT_REACH_MM = (10.0, 2000.0)

UNIT_NAMES = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches"}


@dataclass(frozen=True)
class Bound:
    """A plausible range ``[lo, hi]`` (mm) and what it is based on."""

    lo: float
    hi: float
    basis: str

    def contains(self, value: float) -> bool:
        """Whether ``value`` (mm) lies in the range (NaN does not)."""
        return bool(self.lo <= value <= self.hi)


def segment_bound(digit: str, segment: str) -> Bound:
    """Plausible length (mm) of one segment of a digit (``SEGMENT_FRACTION`` x hand length).

    Parameters
    ----------
    digit : str
        ``thumb``, ``index``, ``middle``, ``ring`` or ``little``.
    segment : str
        ``metacarpal``, ``proximal``, ``middle`` (fingers only) or ``distal``.
    """
    f = SEGMENT_FRACTION[digit][segment]
    return Bound(
        MARGIN[0] * f * HAND_LENGTH_MM[0],
        MARGIN[1] * f * HAND_LENGTH_MM[1],
        f"Buchholz 1992 fraction {f:.3f} of a {HAND_LENGTH_MM[0]:g}-{HAND_LENGTH_MM[1]:g} mm "
        f"hand, margins x{MARGIN[0]:g}/x{MARGIN[1]:g}",
    )


def finger_length_bound(finger: str) -> Bound:
    """Plausible length (mm) of a digit from its first joint's centre (a finger's MP, the
    thumb's CMC) to its tip: the hand-size check."""
    f = sum(SEGMENT_FRACTION[finger][s] for s in DIGITS[finger].segments)
    return Bound(
        MARGIN[0] * f * HAND_LENGTH_MM[0],
        MARGIN[1] * f * HAND_LENGTH_MM[1],
        f"fraction {f:.3f} of hand length",
    )


def neighbour_bound(finger: str, parent: str, child: str) -> Bound:
    """Plausible median distance (mm) between neighbouring sensor origins.

    Each sensor sits on its own segment, so the distance is at most the two segments'
    lengths plus the sensor heights, and at least a fraction of their mean length.
    """
    kind = {HAND_SENSOR: "metacarpal"} | {
        sensor_name(finger, s): s for s in DIGITS[finger].segments
    }
    fa = SEGMENT_FRACTION[finger][kind[parent]]
    fb = SEGMENT_FRACTION[finger][kind[child]]
    return Bound(
        0.5 * MARGIN[0] * 0.5 * (fa + fb) * HAND_LENGTH_MM[0],
        MARGIN[1] * (fa + fb) * HAND_LENGTH_MM[1] + 2 * SENSOR_HEIGHT_MM,
        "sensors on neighbouring segments",
    )


# --------------------------------------------------------------------------- problems


class PlausibilityError(FingerfitError):
    """The data are physically implausible (wrong units, wrong quaternion convention)."""


class PlausibilityWarning(UserWarning):
    """A plausibility problem that ``force`` let through (stored in the model's warnings)."""


@dataclass(frozen=True)
class Problem:
    """One implausible quantity.

    Attributes
    ----------
    message : str
        One line: the quantity, its value, the plausible range and the likely cause.
    path : Path, optional
        The file at fault.
    field : str, optional
        The field at fault (e.g. ``units``).
    """

    message: str
    path: Path | None = None
    field: str | None = None

    def error(self) -> PlausibilityError:
        """The problem as a one-line :class:`PlausibilityError`."""
        return PlausibilityError(self.message, path=self.path, field=self.field)

    def text(self) -> str:
        """The one line, with the file and field (as the error would print it)."""
        return str(self.error())


def enforce(problems: Sequence[Problem], force: bool) -> list[str]:
    """Refuse on the first problem, or (``force``) warn about each and return their lines.

    Raises
    ------
    PlausibilityError
        The first problem, unless ``force``.
    """
    if problems and not force:
        raise problems[0].error()
    lines = [p.text() + " (continued with --force)" for p in problems]
    for line in lines:
        warnings.warn(line, PlausibilityWarning, stacklevel=2)
    return lines


def fmt_mm(value: float) -> str:
    """A length for messages: 3 significant digits, thousands grouped by a space."""
    if not math.isfinite(value):
        return str(value)
    if abs(value) >= 1000:
        return f"{value:,.0f}".replace(",", " ")
    return f"{value:.3g}"


def _ratio_units(ratio: float) -> list[tuple[str, str]]:
    """Unit pairs ``(a, b)`` with ``UNITS_TO_MM[a] / UNITS_TO_MM[b]`` close to ``ratio``."""
    out = []
    for a, ma in UNITS_TO_MM.items():
        for b, mb in UNITS_TO_MM.items():
            if a != b and abs(math.log(ratio * mb / ma)) < math.log1p(SCALE_TOLERANCE):
                out.append((a, b))
    return out


def explaining_units(value: float, bound: Bound, declared: str) -> list[str]:
    """The units (keys of ``UNITS_TO_MM``) that bring a length ``value`` (mm, read as
    ``declared``) into ``bound``, nearest the middle of the range first (in log; the upper
    end of a range from 0)."""
    fits: list[tuple[float, str]] = []
    # The range's middle in log; a bound with no lower end: its upper end (least change).
    mid = math.sqrt(bound.lo * bound.hi) if bound.lo > 0 else bound.hi
    for actual, mm in UNITS_TO_MM.items():
        if actual == declared or not value > 0:
            continue
        v = value * mm / UNITS_TO_MM[declared]
        if bound.contains(v):
            fits.append((abs(math.log(v / mid)), actual))
    return [u for _, u in sorted(fits)]


def unit_cause(value: float, bound: Bound, declared: str, *, every: bool = False) -> str:
    """The likely cause of a length ``value`` (mm) outside ``bound`` when the data declare
    ``declared`` units: the actual units that bring it nearest the middle of the range
    (:func:`explaining_units`; ``every``: all of them, nearest the middle first -- for wide
    bounds that cannot tell them apart)."""
    fits = explaining_units(value, bound, declared)
    if not fits:
        return "no unit mistake explains it; check the sensor names and the data"
    names = [UNIT_NAMES[u] for u in fits]
    look = " or ".join(names if every else names[:1])
    return f"coordinates look like {look} declared as {UNIT_NAMES[declared]}"


# --------------------------------------------------------------------------- units


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


# --------------------------------------------------------------------------- convention

#: Alternative readings of the stored rotations: what the data would be if the file's
#: quaternions had been written in another convention (``(w, x, y, z)`` arrays).
CONVENTIONS: dict[str, str] = {
    "as read": "w,x,y,z (as declared)",
    "conjugated": "conjugated (transposed rotations)",
    "xyzw": "written in x,y,z,w order",
    "xyzw conjugated": "written in x,y,z,w order and conjugated",
}


def _alternatives(rotation: FloatArray) -> dict[str, FloatArray]:
    """Rotations ``(n, 3, 3)`` under each reading of :data:`CONVENTIONS`.

    A file written ``x,y,z,w`` but read as ``w,x,y,z`` gives ``q_read = (x, y, z, w)``;
    the true quaternion is ``(q_read[3], q_read[0], q_read[1], q_read[2])``.
    """
    swapped = matrix_from_quat_wxyz(np.roll(quat_wxyz_from_matrix(rotation), 1, axis=1))
    return {
        "as read": rotation,
        "conjugated": np.swapaxes(rotation, 1, 2),
        "xyzw": swapped,
        "xyzw conjugated": np.swapaxes(swapped, 1, 2),
    }


@dataclass(frozen=True)
class PivotCheck:
    """Pivot residuals of one joint under each reading of the quaternions.

    Attributes
    ----------
    finger, joint : str
    residual_mm : dict[str, float]
        RMS pivot residual (mm) per key of :data:`CONVENTIONS`.
    noise_mm : float
        Static RMS scatter (mm, 3-D) of the child origin in the parent frame over the
        reference recording (NaN without one).
    frames : int
        Frames used.
    """

    finger: str
    joint: str
    residual_mm: dict[str, float]
    noise_mm: float
    frames: int

    @property
    def threshold_mm(self) -> float:
        """Largest plausible as-read residual (mm): ``max(floor, factor x noise)``."""
        noise = self.noise_mm if math.isfinite(self.noise_mm) else 0.0
        return max(PIVOT_FLOOR_MM, PIVOT_NOISE_FACTOR * noise)


#: Mirrored readings of the positions (a left-handed tracker frame): the position axis
#: negated, by key of :func:`pivot_residuals`' result.
MIRRORS: dict[str, int] = {"x negated": 0, "y negated": 1, "z negated": 2}


def pivot_residuals(
    parent: PoseSeries, child: PoseSeries, max_frames: int = 400, *, mirrored: bool = False
) -> tuple[dict[str, float], int]:
    """RMS pivot residual (mm) of two sensors under each quaternion reading.

    Parameters
    ----------
    parent, child : PoseSeries
        The same frames of both sensors (mm, tracker coordinates).
    max_frames : int
        Evenly subsample longer recordings to this many frames (cost).
    mirrored : bool
        Also evaluate the as-read rotations with one position axis negated (keys of
        :data:`MIRRORS`): positions in a left-handed frame agree with right-handed
        rotations again once the mirrored axis is negated.

    Returns
    -------
    residual_mm : dict[str, float]
        Per key of :data:`CONVENTIONS` (and of :data:`MIRRORS` with ``mirrored``).
    frames : int
        Frames used (both sensors valid).
    """
    ok = np.flatnonzero(_valid(parent) & _valid(child))
    if ok.size > max_frames:
        ok = ok[np.linspace(0, ok.size - 1, max_frames).astype(int)]
    if ok.size < 10:
        return {}, int(ok.size)
    pr, cr = parent.rotation[ok], child.rotation[ok]
    pp, cp = parent.position[ok], child.position[ok]
    pa, ca = _alternatives(pr), _alternatives(cr)
    readings = [(k, pa[k], ca[k], np.ones(3)) for k in CONVENTIONS]
    if mirrored:
        readings += [
            (k, pr, cr, np.where(np.arange(3) == i, -1.0, 1.0)) for k, i in MIRRORS.items()
        ]
    out = {}
    for k, rp, rc, flip in readings:
        r, t = relative_pose(rp, pp * flip, rc, cp * flip)
        out[k] = centre_of_rotation(r, t).rms_mm
    return out, int(ok.size)


def _valid(series: PoseSeries) -> np.ndarray:
    """Frames ``(n,)`` with a sample (readers blank a whole pose when any field is missing)."""
    return np.isfinite(series.position[:, 0]) & np.isfinite(series.rotation[:, 0, 0])


def _concat(recordings: Sequence[Recording], sensor: str, step: int = 1) -> PoseSeries | None:
    if not all(sensor in r.poses for r in recordings):
        return None
    return PoseSeries(
        np.concatenate([r.poses[sensor].position[::step] for r in recordings]),
        np.concatenate([r.poses[sensor].rotation[::step] for r in recordings]),
    )


def convention_checks(session: Session, fingers: Sequence[str]) -> list[PivotCheck]:
    """:class:`PivotCheck` of every joint of ``fingers`` over the grasp recordings."""
    checks = []
    for f in fingers:
        for j, (p, c) in joint_sensors(f).items():
            step = max(1, sum(r.n_frames for r in session.grasp) // 2400)
            ps, cs = _concat(session.grasp, p, step), _concat(session.grasp, c, step)
            if ps is None or cs is None:
                continue
            res, n = pivot_residuals(ps, cs)
            if not res:
                continue
            noise = math.nan
            ref = session.reference.poses
            if p in ref and c in ref:
                ok = ref[p].valid & ref[c].valid
                if ok.sum() > 2:
                    _, t = relative_pose(
                        ref[p].rotation[ok], ref[p].position[ok],
                        ref[c].rotation[ok], ref[c].position[ok],
                    )  # fmt: skip
                    noise = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))
            checks.append(PivotCheck(f, j, res, noise, n))
    return checks


def _pooled_rms(checks: Sequence[PivotCheck], reading: str) -> float:
    """RMS over joints of the pivot residual under one reading of the quaternions (mm)."""
    return float(np.sqrt(np.mean([c.residual_mm[reading] ** 2 for c in checks])))


def convention_problems(checks: Sequence[PivotCheck], path: Path | None = None) -> list[Problem]:
    """Refusals from :func:`convention_checks`.

    First the pooled comparison: when another reading of the quaternions gives a pooled
    RMS residual below ``CONVENTION_RATIO`` x the as-read one, the joint with the largest
    as-read residual is named with that reading. Then every joint whose as-read residual
    exceeds its :attr:`PivotCheck.threshold_mm`.
    """
    if not checks:
        return []

    def pooled(k: str) -> float:
        return _pooled_rms(checks, k)

    read = pooled("as read")
    alt = min((k for k in CONVENTIONS if k != "as read"), key=pooled)
    worst = max(checks, key=lambda c: c.residual_mm["as read"])
    head = (
        f"{worst.finger} {worst.joint}: the sensors do not agree on a joint centre (pivot "
        f"residual {worst.residual_mm['as read']:.1f} mm, expected < {worst.threshold_mm:.3g} mm)"
    )
    if read > PIVOT_MIN_MM and pooled(alt) < CONVENTION_RATIO * read:
        return [
            Problem(
                f"{head}: quaternions look {CONVENTIONS[alt]}, not w,x,y,z (pivot residual "
                f"{worst.residual_mm[alt]:.1f} mm read that way; all joints {read:.1f} -> "
                f"{pooled(alt):.1f} mm RMS)",
                path=path,
            )
        ]
    problems = []
    for c in checks:
        r = c.residual_mm["as read"]
        if r > c.threshold_mm:
            problems.append(
                Problem(
                    f"{c.finger} {c.joint}: the sensors do not agree on a joint centre (pivot "
                    f"residual {r:.1f} mm, expected < {c.threshold_mm:.3g} mm): quaternions may "
                    "be in x,y,z,w order or conjugated, a sensor may have slipped, or the "
                    "sensor names may be swapped",
                    path=path,
                )
            )
    return problems


# --------------------------------------------------------------------------- entry points


def check_session(
    session: Session,
    fingers: Sequence[str],
    reference: dict[str, tuple[FloatArray, FloatArray]],
) -> list[Problem]:
    """Every plausibility check of a session before fitting, most basic first.

    Units of every recording (neighbouring sensors), then landmarks against the sensors
    and the bounds, then the quaternion convention (pivot residuals over the grasp
    recordings). Later groups are skipped once one finds a problem: a unit mistake
    upsets everything after it, and the first cause is the one worth naming.

    Parameters
    ----------
    session : Session
    fingers : sequence of str
        The fingers to fit.
    reference : dict
        Sensor -> mean reference pose ``(position (3,) mm, rotation (3, 3))``.
    """
    base = session.path
    groups: list[Callable[[], list[Problem]]] = [
        lambda: [
            p
            for r in session.recordings()
            for p in check_recording_units(
                r, session.units, fingers, None if base is None else base / r.name
            )
        ],
        lambda: check_landmarks(session, fingers, reference),
        lambda: convention_problems(
            convention_checks(session, fingers),
            None if base is None or not session.grasp else base / session.grasp[0].name,
        ),
    ]
    for group in groups:
        problems = group()
        if problems:
            return problems
    return []


@dataclass(frozen=True)
class RecordingCheck:
    """One joint of a recording compared with a model (``fingerfit angles``).

    Attributes
    ----------
    finger, joint : str
    scale : float
        Factor on the recording's positions that best fits the model's centre
        (1 = same units).
    residual_mm : dict[str, float]
        RMS of ``R c_c + t - c_p`` (mm) with the model's centre, per reading of the
        quaternions (:data:`CONVENTIONS`).
    model_distance_mm : float
        Distance of the child sensor origin from the joint centre in the model.
    """

    finger: str
    joint: str
    scale: float
    residual_mm: dict[str, float]
    model_distance_mm: float


def recording_checks(model: HandModel, recording: Recording) -> list[RecordingCheck]:
    """Compare each joint's sensors in ``recording`` with the model's joint centre.

    For a joint with centre ``c_p`` (parent frame) and ``c_c`` (child frame), every frame
    must satisfy ``R c_c + t = c_p`` with the relative pose ``(R, t)``. The scale
    ``s = sum t . (c_p - R c_c) / sum |t|^2`` fits it with the positions scaled.
    """
    out = []
    for f, fm in model.fingers.items():
        for j, jm in fm.joints.items():
            if jm.parent not in recording.poses or jm.child not in recording.poses:
                continue
            if jm.parent not in model.reference_poses or jm.child not in model.reference_poses:
                continue
            p, c = recording.poses[jm.parent], recording.poses[jm.child]
            ok = np.flatnonzero(_valid(p) & _valid(c))
            if ok.size > 600:
                ok = ok[np.linspace(0, ok.size - 1, 600).astype(int)]
            if ok.size < 2:
                continue
            pp, pr = model.reference_poses[jm.parent]
            cp_, cr = model.reference_poses[jm.child]
            c_p, c_c = pr.T @ (jm.center - pp), cr.T @ (jm.center - cp_)
            pa, ca = _alternatives(p.rotation[ok]), _alternatives(c.rotation[ok])
            res, scale = {}, math.nan
            for k in CONVENTIONS:
                r, t = relative_pose(pa[k], p.position[ok], ca[k], c.position[ok])
                target = c_p - r @ c_c
                if k == "as read":
                    den = float(np.sum(t * t))
                    scale = float(np.sum(t * target) / den) if den > 0 else math.nan
                res[k] = float(np.sqrt(np.mean(np.sum((t - target) ** 2, axis=1))))
            out.append(RecordingCheck(f, j, scale, res, float(np.linalg.norm(c_c))))
    return out


def check_recording(
    model: HandModel, recording: Recording, units: str, path: Path | None = None
) -> list[Problem]:
    """Problems of a recording against a model (units, quaternion convention, identity).

    Parameters
    ----------
    model : HandModel
    recording : Recording
        Positions mm, read in ``units``.
    units : str
        The units the recording was read in (for the cause).
    path : Path, optional
        The recording file, for messages.
    """
    checks = recording_checks(model, recording)
    bad = [c for c in checks if c.residual_mm["as read"] > RECORDING_RESIDUAL_MM]
    if not bad:
        return []
    worst = max(bad, key=lambda c: c.residual_mm["as read"])
    scale = float(np.median([c.scale for c in checks]))
    head = (
        f"{worst.finger} {worst.joint}: the child sensor does not keep its distance from the "
        f"model's joint centre (pivot residual {worst.residual_mm['as read']:.1f} mm, expected "
        f"< {RECORDING_RESIDUAL_MM:g} mm; scale that fits {scale:.3g})"
    )
    pairs = [(a, b) for a, b in _ratio_units(scale) if b == units] if scale > 0 else []
    if pairs and abs(math.log(scale)) > math.log(2.0):
        cause = (
            f"the recording looks like {UNIT_NAMES[pairs[0][0]]} read as {UNIT_NAMES[units]} "
            "(--units)"
        )
    else:
        alt = min((k for k in CONVENTIONS if k != "as read"), key=lambda k: _pooled_rms(checks, k))
        if _pooled_rms(checks, alt) < CONVENTION_RATIO * _pooled_rms(checks, "as read"):
            cause = (
                f"quaternions look {CONVENTIONS[alt]}, not w,x,y,z (residual "
                f"{worst.residual_mm[alt]:.1f} mm read that way)"
            )
        else:
            cause = "is it this subject's recording with the sensors mounted as for the model?"
    return [Problem(f"{head}: {cause}", path=path)]


__all__ = [
    "CONVENTIONS",
    "HAND_LENGTH_MM",
    "JOINT_REACH_MM",
    "MARGIN",
    "MIRRORS",
    "SEGMENT_FRACTION",
    "Bound",
    "PivotCheck",
    "PlausibilityError",
    "PlausibilityWarning",
    "Problem",
    "RecordingCheck",
    "check_landmarks",
    "check_model",
    "check_recording",
    "check_recording_units",
    "check_session",
    "convention_checks",
    "convention_problems",
    "enforce",
    "finger_length_bound",
    "joint_reach_problems",
    "landmark_scale",
    "neighbour_bound",
    "pivot_residuals",
    "recording_checks",
    "segment_bound",
    "unit_cause",
]
