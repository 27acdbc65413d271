"""Simulated skin markers: the optical-capture session of a simulated subject, with truth.

A marker is a point on the skin of one segment (the hand or a digit's phalanx). At the
reference posture it sits at a fixed place above the bone; in motion it moves with its
segment and **slides** over the bone with the joint below it: its position in the segment
is ``u + g theta`` (``theta`` the flexion angle of the segment's proximal joint, rad; the
hand's markers: the fingers' mean MP flexion) with ``g (3,)`` mm/rad drawn per marker and
subject, SD :data:`SLIDE_MM_PER_RAD` along the bone, 0.3 of it across and 0.4 of it
dorsal, scaled by ``SimConfig.sta`` and :data:`SEGMENT_SLIDE` (a marker on the nail
slides least). The camera sees each marker with white noise (SD ``noise_mm`` per axis).

The segments move as the simulated hand does in every world (``truth.frames[...]
["motions"]``), so the markers follow the same motion as the 6-DOF sensors of
:func:`.study.simulate_subject`: a 6-DOF fit and a marker fit of one subject can be
compared.

Layouts (:data:`LAYOUTS`), per digit by segment index (a finger's proximal, middle and
distal phalanx; the thumb's metacarpal, proximal and distal):

- ``todorov``: hand 4, segments 2, 2, 1 (Todorov 2007);
- ``phalanx``: hand 3, one marker per segment;
- ``dfki``: hand 3, one marker on the first segment and one near the tip (the glove of
  ``dfki-ric/hand_embodiment``'s recording).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..digits import DIGITS, HAND_SENSOR
from ..errors import FingerfitError
from ..io.atomic import atomic_write
from ..io.sessiondir import save_session
from ..session import Recording, Session, sensor_name
from ..transforms import FloatArray, unit
from .truth import SimulatedSubject, write_truth
from .truthmodel import truth_model

#: Marker layouts: per layout, the hand's marker count and, per segment (proximal to
#: distal), where along the bone its markers sit (fraction of the segment's length from
#: its proximal joint).
LAYOUTS: dict[str, tuple[int, tuple[tuple[float, ...], ...]]] = {
    "todorov": (4, ((0.3, 0.7), (0.3, 0.7), (0.5,))),
    "phalanx": (3, ((0.5,), (0.5,), (0.5,))),
    "dfki": (3, ((0.5,), (), (0.85,))),
}
#: Marker centre height above the bone line, per segment (mm): skin plus a 3 mm marker.
MARKER_HEIGHT = np.array([9.0, 8.0, 6.5])
#: The hand's markers around the hand sensor's site, in the hand frame (x distal, y to
#: the side, z dorsal; mm): four (Todorov) or three (a cluster).
HAND_MARKERS = {
    4: np.array([[-20.0, -18.0, 0.0], [-20.0, 18.0, 0.0], [20.0, -15.0, 2.0], [25.0, 12.0, 2.0]]),
    3: np.array([[-18.0, -15.0, 0.0], [-18.0, 15.0, 0.0], [22.0, 0.0, 2.0]]),
}
#: SD of a marker's placement about its nominal site (mm, along, across, dorsal).
PLACEMENT_SD = np.array([1.5, 1.0, 0.3])
#: SD of a marker's skin slide along the bone per radian of the joint below (mm/rad).
SLIDE_MM_PER_RAD = 1.0
#: Slide of each segment's markers relative to :data:`SLIDE_MM_PER_RAD` (the distal
#: phalanx's sits on the nail); the hand's markers: 0.4.
SEGMENT_SLIDE = np.array([1.0, 1.0, 0.3])
HAND_SLIDE = 0.4
#: Default camera noise (mm, SD per axis).
NOISE_MM = 0.3


@dataclass(frozen=True)
class MarkerTruth:
    """The true markers of a simulated marker session (tracker coordinates at the
    reference posture, mm).

    Attributes
    ----------
    layout : str
    segment : dict[str, str]
        Marker label -> the sensor name of its segment (``hand``, ``index.proximal``, ...).
    position : dict[str, ndarray]
        Marker label -> ``(3,)`` its place at the reference posture (mm), before sliding.
    slide : dict[str, ndarray]
        Marker label -> ``(3,)`` its skin slide per radian of the joint below (mm/rad).
    noise_mm : float
    distal, square : dict[str, ndarray]
        With the ``coupled`` slide law (:func:`simulate_markers`): marker label -> ``(3,)``
        its slide per radian of the joint beyond its segment (mm/rad) and per radian
        squared of the joint below (mm/rad^2); empty otherwise.
    """

    layout: str
    segment: dict[str, str]
    position: dict[str, FloatArray]
    slide: dict[str, FloatArray]
    noise_mm: float
    distal: dict[str, FloatArray] = field(default_factory=dict)
    square: dict[str, FloatArray] = field(default_factory=dict)


@dataclass
class MarkerSimulation:
    """A simulated marker session and its truth.

    Attributes
    ----------
    session : Session
        The subject's session with marker recordings only (``poses`` empty) and its
        ``marker_map``; landmarks and events as the 6-DOF session's.
    markers : MarkerTruth
    sim : SimulatedSubject
        The 6-DOF session of the same motion and the subject's truth
        (:func:`.truthmodel.truth_model`).
    """

    session: Session
    markers: MarkerTruth
    sim: SimulatedSubject


def marker_label(digit: str, segment: int, k: int) -> str:
    """Label of marker ``k`` of a digit's segment ``segment`` (0 proximal): e.g. ``IND1_2``
    (index, proximal phalanx, second marker); the hand's: ``HAND_1``."""
    return f"{digit[:3].upper()}{segment + 1}_{k + 1}"


def _hand_frame(sim: SimulatedSubject, model) -> tuple[FloatArray, FloatArray]:
    """The hand sensor's site and a hand frame (columns x distal, y, z dorsal) at the
    reference posture, from the digits' first joints and segments."""
    site = sim.truth.mounts[HAND_SENSOR].position
    digits = [d for d in model.fingers if d != "thumb"] or list(model.fingers)
    base = np.mean([next(iter(model.fingers[d].joints.values())).center for d in digits], axis=0)
    dorsal = np.mean(
        [model.fingers[d].frames[model.fingers[d].segments[0]].rotation[:, 2] for d in digits],
        axis=0,
    )
    x = unit(base - site)
    z = unit(dorsal - (dorsal @ x) * x)
    return site, np.column_stack([x, np.cross(z, x), z])


def place_markers(
    sim: SimulatedSubject, layout: str, rng: np.random.Generator, *, slide: float
) -> tuple[dict[str, str], dict[str, FloatArray], dict[str, FloatArray]]:
    """Where each marker of ``layout`` sits on the subject at the reference posture.

    Returns
    -------
    segment, position, slide : dict
        As :class:`MarkerTruth` (``slide`` scaled by ``slide``).
    """
    n_hand, sites = LAYOUTS[layout]
    model = truth_model(sim)
    segment: dict[str, str] = {}
    position: dict[str, FloatArray] = {}
    gains: dict[str, FloatArray] = {}
    sd = SLIDE_MM_PER_RAD * np.array([1.0, 0.3, 0.4])
    site, frame = _hand_frame(sim, model)
    for k, offset in enumerate(HAND_MARKERS[n_hand]):
        label = f"HAND_{k + 1}"
        segment[label] = HAND_SENSOR
        position[label] = site + frame @ (offset + rng.normal(0.0, PLACEMENT_SD))
        gains[label] = frame @ (slide * HAND_SLIDE * rng.normal(0.0, sd))
    for d, dm in model.fingers.items():
        ends = [jm.center for jm in dm.joints.values()] + [dm.tip]
        for s, name in enumerate(dm.segments):
            bone = ends[s + 1] - ends[s]
            x = unit(bone)
            mount = sim.truth.mounts[sensor_name(d, name)].position
            off = mount - ends[s]
            z = unit(off - (off @ x) * x)  # dorsal: where the 6-DOF sensor sits
            seg_frame = np.column_stack([x, np.cross(z, x), z])
            for k, f in enumerate(sites[s]):
                label = marker_label(d, s, k)
                nominal = np.array([0.0, 0.0, MARKER_HEIGHT[s]])
                local = nominal + rng.normal(0.0, PLACEMENT_SD)
                segment[label] = sensor_name(d, name)
                position[label] = ends[s] + f * bone + seg_frame @ local
                gains[label] = seg_frame @ (slide * SEGMENT_SLIDE[s] * rng.normal(0.0, sd))
    return segment, position, gains


def _slide_angle(frames: dict, segment: str) -> FloatArray:
    """The angle ``(n,)`` (rad) a marker on ``segment`` slides with: its proximal joint's
    flexion (the hand: the fingers' mean MP flexion, the thumb's CMC without fingers)."""
    if segment == HAND_SENSOR:
        first = {d: DIGITS[d].joints[0] for d in frames["angles"]}
        fingers = [d for d in first if d != "thumb"] or list(first)
        return np.mean([frames["angles"][d][first[d]] for d in fingers], axis=0)
    digit, name = segment.split(".")
    joint = DIGITS[digit].joints[DIGITS[digit].segments.index(name)]
    return np.asarray(frames["angles"][digit][joint])


def _distal_angle(frames: dict, segment: str) -> FloatArray | None:
    """The flexion ``(n,)`` (rad) of the joint at the distal end of a digit's
    ``segment`` (None for the hand and a distal phalanx)."""
    if segment == HAND_SENSOR:
        return None
    digit, name = segment.split(".")
    k = DIGITS[digit].segments.index(name) + 1
    if k >= len(DIGITS[digit].joints):
        return None
    return np.asarray(frames["angles"][digit][DIGITS[digit].joints[k]])


def _coupled_gains(
    truth: MarkerTruth, rng: np.random.Generator
) -> tuple[dict[str, FloatArray], dict[str, FloatArray]]:
    """The ``coupled`` slide law's extra gains: half the proximal slide's SD per radian of
    the joint beyond the segment, and half per radian squared of the joint below, each
    drawn in the direction of a fresh proximal-like slide."""
    distal, square = {}, {}
    for label, g in truth.slide.items():
        scale = np.linalg.norm(g)
        distal[label] = 0.5 * scale * unit(rng.normal(size=3))
        square[label] = 0.5 * scale * unit(rng.normal(size=3))
    return distal, square


def marker_positions(
    truth: MarkerTruth, frames: dict, rng: np.random.Generator
) -> dict[str, FloatArray]:
    """Measured marker positions of one recording.

    Parameters
    ----------
    truth : MarkerTruth
    frames : dict
        The recording's truth (``SubjectTruth.frames[name]``: ``motions``, ``angles``).
    rng : numpy.random.Generator
        The camera noise.

    Returns
    -------
    dict[str, ndarray]
        Label -> ``(n, 3)`` mm, tracker coordinates.
    """
    out = {}
    for label, seg in truth.segment.items():
        r, t = frames["motions"][seg]
        theta = _slide_angle(frames, seg)
        local = truth.position[label] + theta[:, None] * truth.slide[label]
        if label in truth.square:
            local = local + theta[:, None] ** 2 * truth.square[label]
            beyond = _distal_angle(frames, seg)
            if beyond is not None:
                local = local + beyond[:, None] * truth.distal[label]
        p = np.einsum("nij,nj->ni", r, local) + t
        if truth.noise_mm > 0:
            p += rng.normal(0.0, truth.noise_mm, p.shape)
        out[label] = p
    return out


def simulate_markers(
    sim: SimulatedSubject,
    layout: str = "todorov",
    *,
    seed: int = 0,
    noise_mm: float = NOISE_MM,
    slide: float | None = None,
    slide_law: str = "linear",
) -> MarkerSimulation:
    """Skin markers on a simulated subject: the marker session of the same motion.

    Parameters
    ----------
    sim : SimulatedSubject
        From :func:`.study.simulate_subject` (any world).
    layout : {"todorov", "phalanx", "dfki"}
    seed : int
        The markers' placement, slide and noise draw from ``default_rng(seed)``.
    noise_mm : float
        Camera noise, SD per axis (mm).
    slide : float, optional
        Skin slide scale (0: markers fixed to the bone); default the simulation's
        ``sta``.
    slide_law : {"linear", "coupled"}
        ``linear``: a marker slides in proportion to the flexion of the joint below its
        segment. ``coupled``: also with the joint beyond its segment and with the square
        of the joint below (:func:`_coupled_gains`, its own random stream: the linear
        part is the same as ``linear``'s), a world the marker fit's slide model does not
        contain.

    Returns
    -------
    MarkerSimulation
        Every recording of ``sim.session`` with its markers (``(n, 3)`` mm, tracker
        coordinates) and no poses; ``marker_map`` segment -> labels.
    """
    if layout not in LAYOUTS:
        raise FingerfitError(
            f"must be one of {', '.join(LAYOUTS)}, not {layout!r}", field="--markers"
        )
    rng = np.random.default_rng(seed)
    scale = sim.truth.config.sta if slide is None else slide
    segment, position, gains = place_markers(sim, layout, rng, slide=scale)
    truth = MarkerTruth(layout, segment, position, gains, float(noise_mm))
    if slide_law == "coupled":
        distal, square = _coupled_gains(truth, np.random.default_rng([seed, 1]))
        truth = replace(truth, distal=distal, square=square)
    elif slide_law != "linear":
        raise FingerfitError(f"must be linear or coupled, not {slide_law!r}", field="slide_law")

    def markers(rec: Recording) -> Recording:
        pos = marker_positions(truth, sim.truth.frames[rec.name], rng)
        return Recording(rec.name, rec.time.copy(), {}, markers=pos)

    s = sim.session
    mapping: dict[str, list[str]] = {}
    for label, seg in segment.items():
        mapping.setdefault(seg, []).append(label)
    session = replace(
        s,
        reference=markers(s.reference),
        grasp=[markers(r) for r in s.grasp],
        targets=[markers(r) for r in s.targets],
        test=[markers(r) for r in s.test],
        marker_map={k: tuple(v) for k, v in mapping.items()},
    )
    return MarkerSimulation(session, truth, sim)


def marker_truth_document(truth: MarkerTruth) -> dict:
    """``markers_truth.json``: each marker's segment, place at the reference posture (mm,
    tracker coordinates) and skin slide (mm/rad), the layout and the camera noise."""
    return {
        "format": "fingerfit.markers_truth/1",
        "layout": truth.layout,
        "noise_mm": truth.noise_mm,
        "frame": "tracker coordinates at the reference posture (mm)",
        "markers": {
            label: {
                "segment": truth.segment[label],
                "position": [float(x) for x in truth.position[label]],
                "slide_mm_per_rad": [float(x) for x in truth.slide[label]],
            }
            for label in truth.segment
        },
    }


def write_marker_subject(ms: MarkerSimulation, directory: str | Path) -> Path:
    """Write the marker session folder (TRC recordings, ``markers.toml``, landmarks,
    events), the subject's ``truth.json`` and ``truth/<recording>.csv``, and
    ``markers_truth.json`` (:func:`marker_truth_document`)."""
    directory = Path(directory)
    ms.session.path = directory
    save_session(ms.session, directory)
    write_truth(ms.sim, directory)
    with atomic_write(directory / "markers_truth.json") as fh:
        json.dump(marker_truth_document(ms.markers), fh, indent=1)
    return directory


__all__ = [
    "LAYOUTS",
    "MarkerSimulation",
    "MarkerTruth",
    "marker_label",
    "marker_positions",
    "simulate_markers",
    "write_marker_subject",
]
