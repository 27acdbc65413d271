"""The ground truth of a simulated subject and its files.

:class:`SubjectTruth` holds the true geometry, sensor mounts and per-frame truth of every
recording; :class:`SimulatedSubject` pairs it with the measured session.
:func:`write_truth` saves ``truth.json`` (:func:`truth_document`) and
``truth/<recording>.csv`` (:func:`truth_table`); :func:`relative_truth_in_parent` gives a
true joint centre and axis in its parent sensor's frame.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..io.atomic import atomic_write
from ..session import HAND_SENSOR, JOINTS, SEGMENTS, Session, sensor_name
from ..transforms import FloatArray, apply_inverse_pose, quat_wxyz_from_matrix
from . import motion as mo
from . import myohand as mh
from . import wholehand as wh
from .anatomy import FingerAnatomy
from .config import SimConfig
from .sensors import SensorMount
from .thumb import THUMB_KEYS, Pad, ThumbAnatomy

TRUTH_FORMAT = "fingerfit.truth/1"


@dataclass
class SubjectTruth:
    """Ground truth of one simulated subject (mm, rad, tracker coordinates).

    Attributes
    ----------
    fingers : dict[str, FingerAnatomy]
        True geometry at the reference posture (the four fingers only).
    mounts : dict[str, SensorMount]
        True sensor poses at the reference posture (before artefact and noise), thumb
        sensors included.
    frames : dict[str, dict]
        Per recording: ``time`` ``(n,)``, ``angles[digit][key]`` ``(n,)`` rad,
        ``tip[digit]`` and ``pad[digit]`` (pulp centre) ``(n, 3)`` mm, ``sensors[name]``
        noise-free ``(position (n, 3), rotation (n, 3, 3))``, ``motions[name]`` the
        segment motions ``(R (n, 3, 3), t (n, 3))`` relative to the reference posture
        (``hand``: the hand's own, without its sensor's skin artefact).
    config : SimConfig
    thumb : ThumbAnatomy or None
        The thumb's true geometry (None without a thumb).
    pads : dict[str, Pad]
        Every digit's pad (pulp centre, half-thickness, skin point).
    contacts : list of dict
        Every touch of the thumb (:func:`.wholehand.contact_truth`).
    myohand : MyoHandSubject or None
        The subject's MyoHand parameters (``world="myohand"`` only).
    """

    fingers: dict[str, FingerAnatomy]
    mounts: dict[str, SensorMount]
    frames: dict[str, dict] = field(default_factory=dict)
    config: SimConfig = field(default_factory=SimConfig)
    thumb: ThumbAnatomy | None = None
    pads: dict[str, Pad] = field(default_factory=dict)
    contacts: list[dict] = field(default_factory=list)
    myohand: mh.MyoHandSubject | None = None


@dataclass
class SimulatedSubject:
    """A simulated session, its truth and, with ``SimConfig.stylus_recordings``, its
    stylus recordings (:class:`fingerfit.simulate.stylus.StylusSession`)."""

    session: Session
    truth: SubjectTruth
    stylus: Any = None


def truth_document(sim: SimulatedSubject) -> dict:
    """``truth.json`` content: true geometry at the reference posture (tracker and sensor frames)."""
    truth = sim.truth
    ref_sensor = {name: (m.position, m.rotation) for name, m in truth.mounts.items()}
    fingers = {}
    for f, anat in truth.fingers.items():
        joints = {}
        parents = [HAND_SENSOR] + [sensor_name(f, s) for s in SEGMENTS]
        for i, j in enumerate(JOINTS):
            pp, pr = ref_sensor[parents[i]]
            joints[j] = {
                "center": anat.centre[i].tolist(),
                "axis": anat.axis[i].tolist(),
                "rolling_mm_per_rad": anat.rolling[i].tolist(),
                "parent_sensor": parents[i],
                "center_in_parent": (pr.T @ (anat.centre[i] - pp)).tolist(),
                "axis_in_parent": (pr.T @ anat.axis[i]).tolist(),
            }
        fingers[f] = {
            "joints": joints,
            "mp_abduction": {
                "point": anat.abduction_point.tolist(),
                "axis": anat.abduction_axis.tolist(),
            },
            "segment_lengths": dict(zip(SEGMENTS, anat.lengths.tolist(), strict=True)),
            "tip": anat.tip.tolist(),
            "landmarks": {k: v.tolist() for k, v in anat.landmarks.items()},
        }
        if anat.order != FingerAnatomy.order:
            fingers[f]["axis_order"] = {"mp": list(anat.order)}
        if f in truth.pads:
            fingers[f].update(_pad_document(truth.pads[f]))
    if truth.thumb is not None:
        thumb = wh.thumb_document(truth.thumb, ref_sensor)
        thumb.update(_pad_document(truth.thumb.pad))
        fingers = {"thumb": thumb, **fingers}
    config = asdict(truth.config)
    if config["world"] == "default":
        del config["world"]  # truth.json of the default world as before the field existed
    if config["mp_axis_tilt_deg"] is None:
        del config["mp_axis_tilt_deg"]  # likewise
    doc = {
        "format": TRUTH_FORMAT,
        "subject": sim.session.subject,
        "units": "mm",
        "frame": "tracker coordinates at the reference posture; *_in_parent: parent sensor frame",
        "config": config,
        "sensors": {
            name: {"position": p.tolist(), "quat_wxyz": quat_wxyz_from_matrix(r).tolist()}
            for name, (p, r) in ref_sensor.items()
        },
        "fingers": fingers,
        "contacts": truth.contacts,
        **({"stylus": sim.stylus.truth} if sim.stylus is not None else {}),
    }
    if truth.myohand is not None:
        doc["myohand"] = truth.myohand.document()
    return doc


def _pad_document(pad: Pad) -> dict:
    return {
        "pad": pad.surface.tolist(),
        "pad_center": pad.centre.tolist(),
        "pad_half_thickness_mm": pad.half_thickness,
    }


def truth_table(frames: dict, pads: dict[str, Pad] | None = None) -> pd.DataFrame:
    """Per-frame truth of one recording (tracker coordinates, mm; angles deg).

    Columns: ``time``; per digit ``<digit>.<angle>`` (``mp``, ``mp_abduction``, ``pip``,
    ``dip``; the thumb's ``cmc``, ``cmc_abduction``, ``mcp``, ``mcp_abduction``, ``ip``)
    and ``<digit>.tip.x|y|z``; with ``pads``, ``<digit>.pad.x|y|z`` (the pulp's skin
    point, as the ``<digit>.pad`` landmark) and, with the thumb,
    ``thumb.pad_distance.<finger>``: thumb to finger pulp centre (pads touch at the sum
    of the half-thicknesses) and ``thumb.contact.<finger>.x|y|z``: the point of the thumb's
    pulp surface on the line between the two pulp centres, where the pulps touch during
    that finger's pad-to-pad events (every frame; meaningful while they touch).
    """
    cols: dict[str, FloatArray] = {"time": frames["time"]}
    for f, ang in frames["angles"].items():
        for k in THUMB_KEYS if f == "thumb" else mo.ANGLE_KEYS:
            cols[f"{f}.{k}"] = np.degrees(ang[k])
        for i, c in enumerate("xyz"):
            cols[f"{f}.tip.{c}"] = frames["tip"][f][:, i]
        if pads and f in pads and f in frames.get("pad", {}):
            # Skin point = centre moved palmar by the half-thickness, carried by the
            # distal segment: centre + R (surface - centre).
            r = frames["motions"][f"{f}.distal"][0]
            skin = frames["pad"][f] + r @ (pads[f].surface - pads[f].centre)
            for i, c in enumerate("xyz"):
                cols[f"{f}.pad.{c}"] = skin[:, i]
    if "thumb" in frames["angles"] and pads:
        for f in frames["angles"]:
            if f != "thumb" and f in frames.get("pad", {}):
                line = frames["pad"][f] - frames["pad"]["thumb"]
                dist = np.linalg.norm(line, axis=1)
                cols[f"thumb.pad_distance.{f}"] = dist
                contact = frames["pad"]["thumb"] + pads["thumb"].half_thickness * (
                    line / dist[:, None]
                )
                for i, c in enumerate("xyz"):
                    cols[f"thumb.contact.{f}.{c}"] = contact[:, i]
    return pd.DataFrame(cols)


def write_truth(sim: SimulatedSubject, directory: str | Path) -> None:
    """Write ``truth.json`` and ``truth/<recording>.csv`` into ``directory``."""
    directory = Path(directory)
    with atomic_write(directory / "truth.json") as fh:
        json.dump(truth_document(sim), fh, indent=1)
    for name, frames in sim.truth.frames.items():
        with atomic_write(directory / "truth" / name, newline="") as fh:
            truth_table(frames, sim.truth.pads).to_csv(fh, index=False, lineterminator="\n")


def relative_truth_in_parent(
    sim: SimulatedSubject, finger: str, joint: str
) -> tuple[FloatArray, FloatArray]:
    """True joint centre ``(3,)`` mm and axis ``(3,)`` in the parent sensor frame at reference.

    For the thumb, ``joint`` is any of ``cmc``, ``cmc_abduction``, ``mcp``,
    ``mcp_abduction``, ``ip``; the centre of a second axis is the point of its line
    nearest the flexion axis.
    """
    if finger == "thumb":
        th = sim.truth.thumb
        if th is None:
            raise ValueError("the simulated subject has no thumb")
        flexion = joint.removesuffix("_abduction")
        parent = {"cmc": HAND_SENSOR, "mcp": "thumb.metacarpal", "ip": "thumb.proximal"}[flexion]
        m = sim.truth.mounts[parent]
        c = apply_inverse_pose(m.rotation[None], m.position[None], th.axis_point[joint][None])[0]
        return c, m.rotation.T @ th.axis[joint]
    i = JOINTS.index(joint)
    parent = HAND_SENSOR if i == 0 else sensor_name(finger, SEGMENTS[i - 1])
    m = sim.truth.mounts[parent]
    anat = sim.truth.fingers[finger]
    c = apply_inverse_pose(m.rotation[None], m.position[None], anat.centre[i][None])[0]
    return c, m.rotation.T @ anat.axis[i]
