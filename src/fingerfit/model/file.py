"""The model file ``fingerfit.model/1`` (JSON): write it, read it back with one-line errors
naming the field at fault. The file is self-contained: :mod:`fingerfit.kinematics` needs
nothing else. See ``docs/formats.md``.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..digits import ABDUCTION_FIRST, DIGIT_NAMES, DIGITS, FLEXION_FIRST, second_axis
from ..errors import FingerfitError
from ..io.atomic import atomic_write
from ..io.hygiene import MAX_COORDINATE_MM
from ..transforms import FloatArray, matrix_from_quat_wxyz, quat_wxyz_from_matrix
from .hand import (
    ANGLE_METHODS,
    PAD_SOURCES,
    VARIANTS,
    DigitModel,
    HandModel,
    JointModel,
    JointQuality,
    PinchContact,
    SegmentFrame,
)
from .tracking import AngleRange, SensorSpread, TrackingStats

FORMAT = "fingerfit.model/1"
#: Largest coordinate or length accepted from a model file (mm): the readers' limit,
#: :data:`fingerfit.io.hygiene.MAX_COORDINATE_MM` (1000 km).
MAX_MODEL_MM = MAX_COORDINATE_MM


def _v(x: FloatArray) -> list[float]:
    return [float(v) for v in np.asarray(x).ravel()]


def _joint_doc(j: JointModel, model: HandModel) -> dict[str, Any]:
    pp, pr = model.reference_poses[j.parent]
    doc: dict[str, Any] = {
        "parent": j.parent,
        "child": j.child,
        "center": _v(j.center),
        "axis": _v(j.axis),
        "orthogonal_axis": _v(j.orthogonal_axis),
        "in_parent": {
            "center": _v(pr.T @ (j.center - pp)),
            "axis": _v(pr.T @ j.axis),
            "orthogonal_axis": _v(pr.T @ j.orthogonal_axis),
        },
        "quality": j.quality.__dict__,
    }
    if j.migration is not None:
        doc["migration_mm_per_rad"] = _v(j.migration)
        doc["in_parent"]["migration_mm_per_rad"] = _v(pr.T @ j.migration)
    return doc


def model_to_dict(model: HandModel) -> dict[str, Any]:
    """The JSON document of a model (see ``docs/formats.md``)."""
    fingers = {}
    for fname, f in model.fingers.items():
        joints = {jname: _joint_doc(j, model) for jname, j in f.joints.items()}
        joints |= {second_axis(j): _joint_doc(ab, model) for j, ab in f.second_axes.items()}
        dp, dr = model.reference_poses[f.joints[DIGITS[fname].joints[-1]].child]
        fingers[fname] = {
            "joints": joints,
            "axis_order": {j: [a.name for a in f.axes(j)] for j in f.second_axes},
            "tip": _v(f.tip),
            "tip_in_distal": _v(dr.T @ (f.tip - dp)),
            **({"tip_sd_mm": float(f.tip_sd_mm)} if f.tip_sd_mm is not None else {}),
            **(
                {"pad": _v(f.pad), "pad_in_distal": _v(dr.T @ (f.pad - dp))}
                if f.pad is not None
                else {}
            ),
            **({"pad_source": f.pad_source} if f.pad_source is not None else {}),
            "segment_lengths": {k: float(v) for k, v in f.segment_lengths.items()},
            "frames": {
                k: {
                    "origin": _v(fr.origin),
                    "x": _v(fr.rotation[:, 0]),
                    "y": _v(fr.rotation[:, 1]),
                    "z": _v(fr.rotation[:, 2]),
                }
                for k, fr in f.frames.items()
            },
        }
    return {
        "format": FORMAT,
        "fingerfit_version": model.version,
        "method": model.method,
        "angle_method": model.angle_method,
        "units": "mm",
        "frame": "tracker coordinates at the reference posture; in_parent: the joint's parent sensor frame",
        "angle_units": "deg in quality figures",
        "quaternion_order": "w,x,y,z (sensor -> tracker)",
        "subject": model.subject,
        "hand": model.hand,
        "session_units": model.session_units,
        "reference_poses": {
            k: {"position": _v(p), "quat_wxyz": _v(quat_wxyz_from_matrix(r))}
            for k, (p, r) in model.reference_poses.items()
        },
        "fingers": fingers,
        "warnings": list(model.warnings),
        **(
            {
                "pinch_contacts": [
                    {
                        "digits": list(c.digits),
                        "events": c.events,
                        "frames": c.frames,
                        "contact_mm": {k: float(v) for k, v in c.contact_mm.items()},
                    }
                    for c in model.pinch_contacts
                ]
            }
            if model.pinch_contacts
            else {}
        ),
        **({"tracking": _tracking_doc(model.tracking)} if model.tracking is not None else {}),
        **({"markers": _markers_doc(model)} if model.markers else {}),
    }


def _markers_doc(model: HandModel) -> dict[str, Any]:
    """The ``markers`` entry: each skin marker's segment and place (tracker coordinates
    at the reference posture, and in its segment's frame)."""
    out = {}
    for label, (segment, position, slide) in model.markers.items():
        p, r = model.reference_poses[segment]
        out[label] = {
            "segment": segment,
            "position": _v(position),
            "in_segment": _v(r.T @ (position - p)),
            "slide_mm_per_rad": _v(slide),
        }
    return out


def _markers(
    r: _Reader, doc: dict[str, Any], poses: dict
) -> dict[str, tuple[str, FloatArray, FloatArray]]:
    """The optional ``markers`` entry (a model from 6-DOF sensors: none)."""
    if "markers" not in doc:
        return {}
    mdoc = r.get(doc, "markers", "")
    if not isinstance(mdoc, dict):
        raise r.err("markers", "must be an object")
    out = {}
    for label, m in mdoc.items():
        w = f"markers.{label}"
        segment = r.str_(m, "segment", w, tuple(poses))
        out[label] = (segment, r.vec(m, "position", w), r.vec(m, "slide_mm_per_rad", w))
    return out


def _tracking_doc(t: TrackingStats) -> dict[str, Any]:
    """The ``tracking`` entry: calibration statistics for tracking (``docs/formats.md``)."""
    return {
        "recordings": list(t.recordings),
        "frames": t.frames,
        "sensors": {
            v: {
                k: {
                    "position_mm": float(x.position_mm),
                    "orientation_deg": float(x.orientation_deg),
                    "frames": x.frames,
                }
                for k, x in sensors.items()
            }
            for v, sensors in t.sensors.items()
        },
        "angles": {
            v: {
                d: {
                    k: {
                        "low_deg": float(a.low_deg),
                        "high_deg": float(a.high_deg),
                        "speed_deg_s": float(a.speed_deg_s),
                    }
                    for k, a in angles.items()
                }
                for d, angles in digits.items()
            }
            for v, digits in t.angles.items()
        },
    }


def save_model(model: HandModel, path: str | Path) -> Path:
    """Write ``model`` as JSON, atomically. Returns the path."""
    path = Path(path)
    with atomic_write(path) as fh:
        json.dump(model_to_dict(model), fh, indent=1)
    return path


class _Reader:
    """Typed access to a JSON document with errors naming the field path."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def err(self, where: str, msg: str) -> FingerfitError:
        return FingerfitError(msg, path=self.path, field=where)

    def get(self, d: Any, key: str, where: str) -> Any:
        if not isinstance(d, dict):
            raise self.err(where, "must be an object")
        if key not in d:
            raise self.err(f"{where}.{key}".lstrip("."), "missing")
        return d[key]

    def vec(self, d: Any, key: str, where: str, n: int = 3, unit: bool = False) -> FloatArray:
        w = f"{where}.{key}".lstrip(".")
        v = self.get(d, key, where)
        if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
            raise self.err(w, f"must be a list of {n} numbers")
        a = np.array([self.number(x, w) for x in v])
        if not np.isfinite(a).all():
            raise self.err(w, "must be finite")
        if np.abs(a).max() > MAX_MODEL_MM:
            raise self.err(
                w, f"implausible value {np.abs(a).max():.6g} (more than {MAX_MODEL_MM:g})"
            )
        if unit and abs(np.linalg.norm(a) - 1.0) > 1e-6:
            raise self.err(w, f"must have unit length (has {np.linalg.norm(a):.6g})")
        return a

    def number(self, x: Any, where: str) -> float:
        """A JSON number as a float (NaN and infinities kept; huge integers refused)."""
        if not _is_number(x):
            raise self.err(where, "must be a number")
        try:
            return float(x)
        except OverflowError:
            raise self.err(where, "number too large") from None

    def numbers(self, v: Any, where: str, kind: type = float) -> list:
        """A list of JSON numbers (``kind`` int: whole numbers >= 0)."""
        if not isinstance(v, list):
            raise self.err(where, "must be a list of numbers")
        return [self.count(x, where) if kind is int else self.number(x, where) for x in v]

    def count(self, x: Any, where: str) -> int:
        """A whole number >= 0."""
        if not isinstance(x, int) or isinstance(x, bool) or x < 0:
            raise self.err(where, "must be a whole number >= 0")
        return x

    def str_(self, d: Any, key: str, where: str, allowed: tuple[str, ...] | None = None) -> str:
        v = self.get(d, key, where)
        if not isinstance(v, str) or (allowed is not None and v not in allowed):
            raise self.err(
                f"{where}.{key}".lstrip("."),
                f"must be one of {allowed}" if allowed else "must be a string",
            )
        return v


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _quality(r: _Reader, q: Any, where: str) -> JointQuality:
    """A joint's quality record, every field type-checked (unknown keys ignored)."""
    if not isinstance(q, dict):
        raise r.err(where, "must be an object")
    out: dict[str, Any] = {}
    for key in JointQuality.__dataclass_fields__:
        w = f"{where}.{key}"
        if key not in q:
            if key in ("cycles", "rom_deg", "centre_distance_mm", "conditioning", "spread_mm",
                       "residual_mm"):  # fmt: skip
                raise r.err(w, "missing")
            continue
        v = q[key]
        if key in ("cycles", "rejected_frames"):
            out[key] = r.count(v, w)
        elif key == "rejected_cycles":
            out[key] = r.numbers(v, w, int)
        elif key in ("rom_deg", "centre_distance_mm", "conditioning", "residual_mm"):
            out[key] = r.numbers(v, w)
        elif key == "notes":
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise r.err(w, "must be a list of strings")
            out[key] = list(v)
        elif key in ("pooled_conditioning", "model_choice", "axis_ci_deg") and v is None:
            out[key] = None
        elif key == "model_choice":
            out[key] = _model_choice(r, v, w)
        else:
            out[key] = r.number(v, w)
    return JointQuality(**out)


def _model_choice(r: _Reader, v: Any, where: str) -> dict:
    """A joint's ``model_choice`` record, type-checked."""
    if not isinstance(v, dict):
        raise r.err(where, "must be an object")
    chosen = v.get("chosen")
    if chosen not in ("hinge", "two_axis"):
        raise r.err(f"{where}.chosen", "must be 'hinge' or 'two_axis'")
    out: dict[str, Any] = {"chosen": chosen}
    for key in ("held_out_hinge_mm", "held_out_two_axis_mm"):
        out[key] = r.number(r.get(v, key, where), f"{where}.{key}")
    out["folds"] = r.count(r.get(v, "folds", where), f"{where}.folds")
    candidate = v.get("two_axis_candidate", True)
    if not isinstance(candidate, bool):
        raise r.err(f"{where}.two_axis_candidate", "must be true or false")
    out["two_axis_candidate"] = candidate
    if "order" in v:  # files before the order was chosen have neither
        out["order"] = r.str_(v, "order", where, (ABDUCTION_FIRST, FLEXION_FIRST))
    for key in ("held_out_two_axis_by_order_mm", "held_out_orientation_by_order_deg"):
        if key not in v:
            continue
        by = v[key]
        if not isinstance(by, dict) or not set(by) <= {ABDUCTION_FIRST, FLEXION_FIRST}:
            raise r.err(f"{where}.{key}", "must map abduction_first/flexion_first to numbers")
        out[key] = {k: r.number(x, f"{where}.{key}.{k}") for k, x in by.items()}
    return out


def _load_joint(r: _Reader, jd: Any, name: str, wj: str, poses: dict) -> JointModel:
    """One joint entry, checked: sensors known, unit axes, parent-frame values consistent."""
    parent, child = r.str_(jd, "parent", wj), r.str_(jd, "child", wj)
    for s in (parent, child):
        if s not in poses:
            raise r.err(wj, f"sensor '{s}' has no entry in reference_poses")
    j = JointModel(
        name,
        parent,
        child,
        r.vec(jd, "center", wj),
        r.vec(jd, "axis", wj, unit=True),
        r.vec(jd, "orthogonal_axis", wj, unit=True),
        _quality(r, r.get(jd, "quality", wj), f"{wj}.quality"),
        r.vec(jd, "migration_mm_per_rad", wj) if "migration_mm_per_rad" in jd else None,
    )
    pp, pr = poses[parent]
    ip = r.get(jd, "in_parent", wj)
    checks = [
        ("center", pr.T @ (j.center - pp)),
        ("axis", pr.T @ j.axis),
        ("orthogonal_axis", pr.T @ j.orthogonal_axis),
    ]
    if j.migration is not None:
        checks.append(("migration_mm_per_rad", pr.T @ j.migration))
    for key, val in checks:
        if np.abs(r.vec(ip, key, f"{wj}.in_parent") - val).max() > 1e-6:
            raise r.err(f"{wj}.in_parent.{key}", "disagrees with the tracker-frame value")
    return j


def load_model(path: str | Path) -> HandModel:
    """Read and validate a ``fingerfit.model/1`` file.

    Files written before the optional fields existed (``angle_method``, a joint's
    ``migration_mm_per_rad``, a digit's ``pad``) load with their defaults: projection
    angles, fixed centres, no pad. A finger's second MP axis is read from
    ``joints.mp_abduction`` or, in older files, from ``abduction``; a stated
    ``axis_order`` must be the digit's (:mod:`fingerfit.digits`).

    Raises
    ------
    FingerfitError
        Naming the file and the field path (e.g. ``fingers.index.joints.pip.axis``)
        of the first problem: a missing key, a wrong shape, a non-unit axis, or
        parent-frame values inconsistent with the tracker-frame ones.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise FingerfitError("file not found", path=path) from None
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None
    except UnicodeDecodeError as exc:
        raise FingerfitError(f"not UTF-8 text (byte {exc.start})", path=path) from None
    except json.JSONDecodeError as exc:
        raise FingerfitError(f"not valid JSON ({exc.msg})", path=path, line=exc.lineno) from None
    except RecursionError:
        raise FingerfitError("not valid JSON (nested too deeply)", path=path) from None
    r = _Reader(path)
    fmt = r.str_(doc, "format", "")
    if fmt != FORMAT:
        raise r.err("format", f"unsupported format '{fmt}' (expected '{FORMAT}')")
    if r.str_(doc, "units", "") != "mm":
        raise r.err("units", "must be 'mm'")
    poses = {}
    pdoc = r.get(doc, "reference_poses", "")
    if not isinstance(pdoc, dict):
        raise r.err("reference_poses", "must be an object")
    for name, p in pdoc.items():
        w = f"reference_poses.{name}"
        q = r.vec(p, "quat_wxyz", w, n=4)
        if abs(np.linalg.norm(q) - 1) > 1e-6:
            raise r.err(f"{w}.quat_wxyz", "must be a unit quaternion")
        poses[name] = (r.vec(p, "position", w), matrix_from_quat_wxyz(q))
    fingers = {}
    fdoc = r.get(doc, "fingers", "")
    if not isinstance(fdoc, dict) or not fdoc:
        raise r.err("fingers", "must be a non-empty object")
    for fname, fd in fdoc.items():
        fingers[fname] = _load_digit(r, fd, fname, poses)
    return HandModel(
        subject=r.str_(doc, "subject", ""),
        hand=r.str_(doc, "hand", "", ("left", "right")),
        session_units=r.str_(doc, "session_units", "", ("mm", "cm", "m", "in")),
        method=r.str_(doc, "method", ""),
        reference_poses=poses,
        fingers=fingers,
        version=str(doc.get("fingerfit_version", "unknown")),
        angle_method=(
            r.str_(doc, "angle_method", "", ANGLE_METHODS)
            if "angle_method" in doc
            else "projection"
        ),
        warnings=_warnings(r, doc),
        pinch_contacts=_pinch_contacts(r, doc, fingers),
        tracking=_tracking(r, doc, fingers, poses),
        markers=_markers(r, doc, poses),
    )


def _load_digit(r: _Reader, fd: Any, fname: str, poses: dict) -> DigitModel:
    """One digit entry of a model file, checked (see :func:`load_model`)."""
    wf = f"fingers.{fname}"
    if fname not in DIGIT_NAMES:
        raise r.err(wf, f"unknown digit (expected one of {', '.join(DIGIT_NAMES)})")
    digit = DIGITS[fname]
    jdoc = r.get(fd, "joints", wf)
    joints = {
        j: _load_joint(r, r.get(jdoc, j, f"{wf}.joints"), j, f"{wf}.joints.{j}", poses)
        for j in digit.joints
    }
    seconds = {}
    for j in digit.second_axes:
        name = second_axis(j)
        if isinstance(jdoc, dict) and name in jdoc:
            seconds[j] = _load_joint(r, jdoc[name], name, f"{wf}.joints.{name}", poses)
        elif j == "mp" and isinstance(fd, dict) and "abduction" in fd:  # files before 0.2
            seconds[j] = _load_joint(r, fd["abduction"], name, f"{wf}.abduction", poses)
    unknown = set(jdoc) - set(digit.joints) - {second_axis(j) for j in digit.second_axes}
    if unknown:
        raise r.err(f"{wf}.joints.{sorted(unknown)[0]}", f"not a joint of the {fname}")
    for j in digit.required_second:
        if j not in seconds:
            raise r.err(f"{wf}.joints.{second_axis(j)}", "missing (a two-axis joint)")
    lengths_doc = r.get(fd, "segment_lengths", wf)
    lengths = {}
    for s in digit.segments:
        v = r.get(lengths_doc, s, f"{wf}.segment_lengths")
        if not _is_number(v) or not (0 < v <= MAX_MODEL_MM):
            raise r.err(f"{wf}.segment_lengths.{s}", "must be a positive number (mm)")
        lengths[s] = float(v)
    frames = {}
    for s in digit.segments:
        fr = r.get(r.get(fd, "frames", wf), s, f"{wf}.frames")
        w = f"{wf}.frames.{s}"
        rot = np.column_stack([r.vec(fr, k, w, unit=True) for k in "xyz"])
        frames[s] = SegmentFrame(r.vec(fr, "origin", w), rot)
    pad = r.vec(fd, "pad", wf) if "pad" in fd else None
    source = r.str_(fd, "pad_source", wf, PAD_SOURCES) if "pad_source" in fd else None
    if source is not None and pad is None:
        raise r.err(f"{wf}.pad_source", "given without a pad")
    model = DigitModel(fname, joints, r.vec(fd, "tip", wf), lengths, frames, seconds, pad, source)
    if "tip_sd_mm" in fd:
        sd = r.number(fd["tip_sd_mm"], f"{wf}.tip_sd_mm")
        if not (0 <= sd <= MAX_MODEL_MM):
            raise r.err(f"{wf}.tip_sd_mm", "must be a non-negative number (mm)")
        model = replace(model, tip_sd_mm=sd)
    order = fd.get("axis_order", {})
    chosen = {}
    for j in seconds:
        usual = [a.name for a in model.axes(j)]
        if j not in order or order[j] == usual:
            continue
        if order[j] != usual[::-1] or j in digit.required_second:
            either = "" if j in digit.required_second else f" or {usual[::-1]}"
            raise r.err(
                f"{wf}.axis_order.{j}",
                f"must be {usual}{either} (proximal first; docs/conventions.md)",
            )
        chosen[j] = FLEXION_FIRST if usual[0] == second_axis(j) else ABDUCTION_FIRST
    return replace(model, axis_order=chosen) if chosen else model


def _pinch_contacts(
    r: _Reader, doc: dict[str, Any], fingers: dict[str, DigitModel]
) -> tuple[PinchContact, ...]:
    """The optional ``pinch_contacts`` list (older files and sessions without pinches: none)."""
    items = doc.get("pinch_contacts", [])
    if not isinstance(items, list):
        raise r.err("pinch_contacts", "must be a list")
    out = []
    for i, c in enumerate(items):
        w = f"pinch_contacts[{i}]"
        digits = r.get(c, "digits", w)
        if not (
            isinstance(digits, list)
            and len(digits) == 2
            and all(d in fingers and fingers[d].pad is not None for d in digits)
            and digits[0] != digits[1]
        ):
            raise r.err(f"{w}.digits", "must be two different digits of the model with pads")
        mm = r.get(c, "contact_mm", w)
        if not isinstance(mm, dict) or set(mm) != set(VARIANTS):
            raise r.err(f"{w}.contact_mm", f"must give {' and '.join(VARIANTS)}")
        contact = {}
        for k in VARIANTS:
            v = r.number(mm[k], f"{w}.contact_mm.{k}")
            if not (math.isfinite(v) and 0 <= v <= MAX_MODEL_MM):
                raise r.err(f"{w}.contact_mm.{k}", "must be a finite distance >= 0 (mm)")
            contact[k] = v
        out.append(
            PinchContact(
                (digits[0], digits[1]),
                r.count(r.get(c, "events", w), f"{w}.events"),
                r.count(r.get(c, "frames", w), f"{w}.frames"),
                contact,
            )
        )
    return tuple(out)


def _warnings(r: _Reader, doc: dict[str, Any]) -> tuple[str, ...]:
    """The optional ``warnings`` list of strings (older files: none)."""
    w = doc.get("warnings", [])
    if not isinstance(w, list) or not all(isinstance(x, str) for x in w):
        raise r.err("warnings", "must be a list of strings")
    return tuple(w)


def _tracking(
    r: _Reader, doc: dict[str, Any], fingers: dict[str, DigitModel], poses: dict
) -> TrackingStats | None:
    """The optional ``tracking`` entry (older files: none), every figure checked: a spread
    for every sensor of the model's digits and a range for every angle, per variant."""
    if "tracking" not in doc:
        return None
    t = doc["tracking"]
    recordings = r.get(t, "recordings", "tracking")
    if not isinstance(recordings, list) or not all(isinstance(x, str) for x in recordings):
        raise r.err("tracking.recordings", "must be a list of strings")
    frames = r.count(r.get(t, "frames", "tracking"), "tracking.frames")
    sensors: dict[str, dict[str, SensorSpread]] = {}
    angles: dict[str, dict[str, dict[str, AngleRange]]] = {}
    sdoc, adoc = r.get(t, "sensors", "tracking"), r.get(t, "angles", "tracking")
    needed = [jm.child for fm in fingers.values() for jm in fm.joints.values()]
    for v in VARIANTS:
        vs = r.get(sdoc, v, "tracking.sensors")
        sensors[v] = {}
        for name in needed:
            w = f"tracking.sensors.{v}.{name}"
            x = r.get(vs, name, f"tracking.sensors.{v}")
            pos = r.number(r.get(x, "position_mm", w), f"{w}.position_mm")
            rot = r.number(r.get(x, "orientation_deg", w), f"{w}.orientation_deg")
            for key, val in (("position_mm", pos), ("orientation_deg", rot)):
                if not (math.isfinite(val) and 0 < val <= MAX_MODEL_MM):
                    raise r.err(f"{w}.{key}", "must be a positive finite number")
            sensors[v][name] = SensorSpread(pos, rot, r.count(r.get(x, "frames", w), f"{w}.frames"))
        va = r.get(adoc, v, "tracking.angles")
        angles[v] = {}
        for d, fm in fingers.items():
            da = r.get(va, d, f"tracking.angles.{v}")
            angles[v][d] = {}
            for k in fm.angle_names():
                w = f"tracking.angles.{v}.{d}.{k}"
                x = r.get(da, k, f"tracking.angles.{v}.{d}")
                lo = r.number(r.get(x, "low_deg", w), f"{w}.low_deg")
                hi = r.number(r.get(x, "high_deg", w), f"{w}.high_deg")
                sp = r.number(r.get(x, "speed_deg_s", w), f"{w}.speed_deg_s")
                if not (-360 <= lo <= 0 <= hi <= 360):
                    raise r.err(w, "needs -360 <= low_deg <= 0 <= high_deg <= 360")
                if not (math.isfinite(sp) and sp > 0):
                    raise r.err(f"{w}.speed_deg_s", "must be a positive finite number")
                angles[v][d][k] = AngleRange(lo, hi, sp)
    return TrackingStats(tuple(recordings), frames, sensors, angles)
