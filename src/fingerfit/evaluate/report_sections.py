"""The sections of the study report made from a :class:`~.results.StudyResult`: headline,
problems (failed sessions, events not evaluated, warnings), subjects, ground truth, thumb,
whole hand and pinches, and the data of the 3D view."""

from __future__ import annotations

import html
import math
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..digits import DIGIT_NAMES, DIGITS, FINGERS, second_axis
from .pinch import pinch_labels
from .report_html import _fmt, _img, _list, _ms, _pct, _table, _ttest
from .stats import moments_at

if TYPE_CHECKING:
    from .results import StudyResult


def _viewer_data(result: StudyResult) -> Iterator[tuple[str, dict]]:
    """Per subject, one at a time (subject ID, its data): the digits in one frame, the
    proximal-phalanx frame of its first finger.

    Origin at that finger's MP centre (mm), x along its proximal phalanx (a thumb alone:
    its metacarpal frame, origin at its CMC centre); every digit of the subject is drawn
    in this frame so several digits keep their places on the hand. Each digit carries its
    flexion axes (user and orthogonal), second axes, tip, pad point and landmarks.
    """
    for s in result.subjects:
        first = next((f for f in s.model.fingers if f in FINGERS), next(iter(s.model.fingers)))
        fm0 = s.model.fingers[first]
        origin = next(iter(fm0.joints.values())).center
        rot = fm0.frames[fm0.segments[0]].rotation  # columns x, y, z (tracker)

        def loc(p, origin=origin, rot=rot):
            return ((np.asarray(p) - origin) @ rot).round(3).tolist()

        fingers = []
        for f, fm in s.model.fingers.items():
            joints = list(fm.joints.values())
            fingers.append(
                {
                    "name": f,
                    "centres": [loc(j.center) for j in joints],
                    "tip": loc(fm.tip),
                    "pad": None if fm.pad is None else loc(fm.pad),
                    "axes": [(j.axis @ rot).round(4).tolist() for j in joints],
                    "orthogonal": [(j.orthogonal_axis @ rot).round(4).tolist() for j in joints],
                    "landmarks": [loc(s.session.landmark(f"{f}.{k}")) for k in DIGITS[f].landmarks],
                    "second_axes": [
                        [loc(ab.center), (ab.axis @ rot).round(4).tolist()]
                        for ab in fm.second_axes.values()
                    ],
                }
            )
        seg, joint = fm0.segments[0], next(iter(fm0.joints)).upper()
        yield (
            s.subject,
            {
                "frame": f"{s.subject}: {first} proximal-phalanx frame, origin at the {first} MP "
                "centre, x along the phalanx (mm)"
                if first in FINGERS
                else f"{s.subject}: {first} {seg} frame, origin at the {first} {joint} centre, "
                f"x along the {seg} (mm)",
                "fingers": fingers,
            },
        )


_TARGET_NOTE = (
    "Targets are the session's stylus landmarks <code>target.&lt;name&gt;</code>; each touch "
    "is an interval of <code>events.csv</code> and its error is the distance from the mean "
    "fingertip over the touch to the target. In sessions written by <code>fingerfit "
    "simulate</code>, targets t000 … t120 lie on a straight edge and the number is the "
    "distance along the edge from the first target in mm."
)


def _headline(sm: dict) -> str:
    paper = sm["paper"]
    rows = []
    for key, name in (
        ("max_flexion", "grasp: maximal flexion (vs distal sensor)"),
        ("targets", "target reaching (vs stylus targets)"),
    ):
        if key not in sm:
            continue
        h, pp = sm[key], paper[key]
        rows.append(
            f"<tr><td>{name}</td><td class=num>{h['user_axis']['n']}</td>"
            f"<td class=num>{_ms(h['user_axis'])}</td><td class=num>{_ms(h['orthogonal'])}</td>"
            f"<td class=num>{_pct(h['reduction_percent'])}</td>"
            f"<td class=num>{_pct(h['sd_reduction_percent'])}</td>"
            f"<td>{html.escape(_ttest(h['paired_t_test']))}</td>"
            f"<td>{pp['user_axis'][0]} ({pp['user_axis'][1]}) vs {pp['orthogonal'][0]} "
            f"({pp['orthogonal'][1]}), −{pp['reduction_percent']} %</td></tr>"
        )
    return (
        "<table><tr><th>fingertip error</th><th>n</th><th>user-axis model, mean (SD) mm</th>"
        "<th>orthogonal model, mean (SD) mm</th><th>mean reduction</th><th>SD reduction</th>"
        "<th>paired t-test</th><th>paper: user-axis vs orthogonal, mean (SD) mm</th></tr>"
        + "".join(rows)
        + "</table>"
    )


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _not_evaluated(sm: dict) -> str:
    """The touch events of a digit the model lacks: how many, and whose."""
    ne = sm["events_not_evaluated"]

    def counts(d: dict) -> str:
        return (
            f"{_count(d['target_touches'], 'target touch', 'target touches')} and "
            f"{_count(d['pinches'], 'pinch', 'pinches')}"
        )

    return (
        f"<p class=warn>{counts(ne)} were not evaluated: the model lacks their digit. They "
        "are in no number of this report; each is listed under <a href='#skipped'>Statistics "
        "not computed</a>.</p>"
        + _list([f"{subject}: {counts(d)}" for subject, d in ne["per_subject"].items()])
    )


def _problems(result: StudyResult) -> list[str]:
    """Failed sessions, events not evaluated and forced-fit warnings, each naming the
    subject."""
    sm = result.summary
    parts = []
    if result.failures:
        parts += [
            "<h2 id=failed>Sessions that failed</h2>",
            f"<p class=warn>{len(result.failures)} session(s) could not be fitted and are not "
            "in any number of this report (<code>--keep-going</code>):</p>",
            _list([f.message for f in result.failures]),
        ]
    if sm.get("events_not_evaluated"):
        parts += ["<h2 id=not-evaluated>Events not evaluated</h2>", _not_evaluated(sm)]
    if sm.get("warnings"):
        parts += [
            "<h2 id=warnings>Warnings</h2>",
            "<p class=warn>These models were fitted past plausibility or quality checks "
            "(<code>--force</code>); their numbers below may be wrong:</p>",
            _list([f"{subj}: {w}" for subj, ws in sm["warnings"].items() for w in ws]),
        ]
    return parts


def _subjects_table(result: StudyResult) -> str:
    sm = result.summary
    touches = result.tables.moments(  # one row per touch: the distal sensor's
        "targets", ["subject"], ["error_mm"], lambda c: c[c["source"] == "reference"]
    )
    rows = [
        {
            "subject": s.subject,
            "fingers": ", ".join(s.model.fingers),
            "grasp cycles at max. flexion (n)": str(
                sm["max_flexion"]["per_subject"][s.subject]["n"]
            ),
            "target touches (n)": str(moments_at(touches, "error_mm", s.subject).rows),
            "ground truth": "yes" if s.truth is not None else "no",
            "warnings (n)": str(len(s.warnings)),
        }
        for s in result.subjects
    ]
    return _table(pd.DataFrame(rows))


def _joint_order(joints: list[str]) -> list[str]:
    """Joint (axis) names proximal to distal, digit by digit (thumb first), each second
    axis after its joint; names not in :data:`~fingerfit.digits.DIGITS` last, as given."""
    order = [name for d in DIGIT_NAMES for j in DIGITS[d].joints for name in (j, second_axis(j))]
    rank = {name: i for i, name in enumerate(dict.fromkeys(order))}
    return sorted(joints, key=lambda j: rank.get(j, len(rank)))


def _split_key(key: str) -> tuple[str, str]:
    """``recording/variant`` (a key of ``summary.json``) as (recording, variant)."""
    recording, _, variant = key.rpartition("/")
    return recording, variant


def _truth(result: StudyResult) -> list[str]:
    """Axes and fingertips against ground truth, as ``summary.json`` has them
    (``truth``: per joint over every digit; the fingers' tips per recording and model)."""
    sm, fig = result.summary, result.figures
    tr = sm["truth"]
    axis_err, centre = tr["axis_error_deg"], tr["centre_to_axis_mm"]
    axes_t = pd.DataFrame(
        [
            {
                "joint": str(j).upper(),
                "axis error, mean (deg)": _fmt(axis_err[j]["mean"]),
                "axis error, max (deg)": _fmt(axis_err[j]["max"]),
                "centre to true axis, mean (mm)": _fmt(centre[j]["mean"]),
                "centre to true axis, max (mm)": _fmt(centre[j]["max"]),
            }
            for j in _joint_order(list(axis_err))
        ]
    )
    rank = {"user_axis": "0", "orthogonal": "1"}
    keys = sorted(
        tr["fingertip_mm"], key=lambda k: (_split_key(k)[0], rank.get(_split_key(k)[1], k))
    )
    tips_t = pd.DataFrame(
        [
            {
                "recording": _split_key(k)[0],
                "model": _split_key(k)[1].replace("_", "-") + " model",
                "fingertip error, mean (mm)": _fmt(tr["fingertip_mm"][k]["mean"]),
                "95th percentile (mm)": _fmt(tr["fingertip_mm"][k]["p95"]),
            }
            for k in keys
        ]
    )
    subj = tr["subjects"]
    parts = [
        "<h2>Against ground truth (simulated sessions)</h2>",
        "<p>What the paper could not measure: the fitted axes against the true ones and the "
        "fingertip against the true fingertip on every recording "
        f"({len(subj)} subject{'s' if len(subj) != 1 else ''} with ground truth: "
        f"{html.escape(', '.join(subj))}). Axes: every digit's. Fingertip errors: the "
        "fingers' (the thumb's are in its section, every digit's under Whole hand), mean "
        "over subjects of each recording's mean and 95th percentile.</p>",
    ]
    if "truth" in fig:
        parts.append(_img(fig["truth"], "true fingertip error"))
    parts.append(_table(axes_t))
    if keys:
        parts.append(_table(tips_t))
    return parts


_MODEL_NAMES = {"reference": "distal sensor", "user_axis": "user-axis model"}


def _model_name(v: str) -> str:
    return _MODEL_NAMES.get(v, v.replace("_", "-") + " model")


def _thumb(result: StudyResult) -> list[str]:
    """The thumb's section: tip at maximal flexion, tip and axes against truth, CMC/MCP
    geometry (the offset and angle between the two axes of each two-axis joint)."""
    sm, fig, tables = result.summary, result.figures, result.tables
    th = sm["thumb"]
    parts = [
        "<h2 id=thumb>Thumb</h2>",
        "<p>The thumb's CMC turns about two axes (flexion-extension proximal, in the "
        "trapezium; ab/adduction distal, in the base of the metacarpal) that neither "
        "intersect nor stand perpendicular; the MCP has a second axis where the evidence "
        "supports one; the IP is a hinge. The orthogonal model makes each flexion axis "
        "perpendicular to its bone and each second axis perpendicular to the bone and the "
        "orthogonal flexion axis (the robot convention). Subjects with a thumb: "
        f"{html.escape(', '.join(th['subjects']))}.</p>",
    ]
    rows = []
    if "max_flexion" in th:
        h = th["max_flexion"]
        rows.append(("grasp: maximal flexion (vs distal sensor)", h))
    for rec, h in th.get("truth_tip", {}).items():
        rows.append((f"{rec}: against ground truth (mean per subject)", h))
    if rows:
        parts.append(
            _table(
                pd.DataFrame(
                    [
                        {
                            "thumb tip error": name,
                            "n": str(h["user_axis"]["n"]),
                            "user-axis model, mean (SD) mm": _ms(h["user_axis"]),
                            "orthogonal model, mean (SD) mm": _ms(h["orthogonal"]),
                            "mean reduction": _pct(h["reduction_percent"]),
                            "paired t-test": _ttest(h["paired_t_test"]),
                        }
                        for name, h in rows
                    ]
                )
            )
        )
    if "thumb" in fig:
        parts.append(_img(fig["thumb"], "thumb tip error against truth"))
    if th.get("truth_axes"):
        parts += [
            "<p>Every thumb axis against the true one (parent sensor frame):</p>",
            _table(
                pd.DataFrame(
                    [
                        {
                            "axis": j.upper().replace("_ABDUCTION", " ab/adduction"),
                            "subjects (n)": str(v["n"]),
                            "axis error, mean (deg)": _fmt(v["axis_error_deg"]["mean"]),
                            "axis error, max (deg)": _fmt(v["axis_error_deg"]["max"]),
                            "centre to true axis, mean (mm)": _fmt(v["centre_to_axis_mm"]["mean"]),
                            "centre to true axis, max (mm)": _fmt(v["centre_to_axis_mm"]["max"]),
                        }
                        for j, v in th["truth_axes"].items()
                    ]
                )
            ),
        ]
    geo = tables.get("thumb_geometry")
    if geo is not None and not geo.empty:
        parts += [
            "<p>Two-axis joints: the shortest distance between the two axis lines and the "
            "angle between them, per subject (true: the simulator's, where known).</p>",
            _table(
                pd.DataFrame(
                    {
                        "subject": geo["subject"],
                        "joint": geo["joint"].str.upper(),
                        "axis offset (mm)": geo["axis_offset_mm"].map(_fmt),
                        "true axis offset (mm)": geo["true_axis_offset_mm"].map(_fmt),
                        "angle between axes (deg)": geo["axes_angle_deg"].map(_fmt),
                        "true angle between axes (deg)": geo["true_axes_angle_deg"].map(_fmt),
                    }
                )
            ),
        ]
    return parts


def _per_variant(
    items: list[tuple[tuple[str, ...], float | None]], keys: list[str]
) -> pd.DataFrame:
    """One row per group of ``keys`` (in order of first appearance), one column per model
    variant: ``items`` are ((key values..., variant), value) as ``summary.json`` nests
    them."""
    rows: dict[tuple[str, ...], dict[str, float]] = {}
    for (*row, variant), value in items:
        rows.setdefault(tuple(row), {})[variant] = math.nan if value is None else value
    return pd.DataFrame([{**dict(zip(keys, r, strict=True)), **v} for r, v in rows.items()])


def _whole_hand(result: StudyResult) -> list[str]:
    """The whole hand: every digit's tip and every joint angle against truth, and pinches."""
    sm, fig, tables = result.summary, result.figures, result.tables
    parts = [
        "<h2 id=wholehand>Whole hand</h2>",
        "<p class=note>The 3D view of the whole hand (every digit, its second axes and pad "
        "points) is <a href='#view3d'>below</a>.</p>",
    ]
    truth = sm.get("truth", {})
    w = _per_variant(
        [
            ((f, *_split_key(k)), v["mean"])
            for f, by_key in truth.get("tip_mm_per_digit", {}).items()
            for k, v in by_key.items()
        ],
        ["finger", "recording"],
    )
    if set(("user_axis", "orthogonal")) <= set(w.columns):
        parts += [
            "<p>Tip error of every digit against ground truth (mean over subjects of each "
            "recording's mean):</p>",
            _table(
                pd.DataFrame(
                    {
                        "digit": w["finger"],
                        "recording": w["recording"],
                        "user-axis model (mm)": w["user_axis"].map(_fmt),
                        "orthogonal model (mm)": w["orthogonal"].map(_fmt),
                    }
                )
            ),
        ]
    w = _per_variant(
        [
            ((f, j, variant), v["mean"])
            for f, by_joint in truth.get("angle_error_deg", {}).items()
            for j, by_variant in by_joint.items()
            for variant, v in by_variant.items()
        ],
        ["finger", "joint"],
    )
    if not w.empty:
        parts += [
            "<p>Every joint angle against the true angle (mean |error| over all recordings "
            "with ground truth and subjects):</p>",
            _table(
                pd.DataFrame(
                    {
                        "digit": w["finger"],
                        "angle": w["joint"].str.upper().str.replace("_ABDUCTION", " ab/adduction"),
                        "user-axis model (deg)": w.get("user_axis", pd.Series(dtype=float)).map(
                            _fmt
                        ),
                        "orthogonal model (deg)": w.get("orthogonal", pd.Series(dtype=float)).map(
                            _fmt
                        ),
                    }
                )
            ),
        ]
    if "pinch" in sm:
        pn = sm["pinch"]
        parts += [
            "<h3 id=pinch>Pinches</h3>",
            "<p>During each pinch event (<code>events.csv</code> rows whose target is a digit) "
            "the distance between the two digits' tip points (nail edges, 12-18 mm apart when "
            "the pads touch) and the gap between their pad points (fitted to the session's "
            "pinch holds where it has them, else the digitised pulp skin points; pads that "
            "touch have gap 0). Tip-distance error: mean over the event's frames of |model "
            "distance - true distance|; pads to true contact: mean distance of the two pad "
            "points from where the pulps truly touch (simulated sessions only). Distal "
            "sensor: each digit's distal sensor carrying the model's tip and pad points.</p>",
        ]
        if "pinch" in fig:
            parts.append(_img(fig["pinch"], "pinch tip distance and pad gap"))
        parts.append(
            _table(
                pd.DataFrame(
                    [
                        {
                            "source": _model_name(src),
                            "events (n)": str(v["pad_gap"]["n"] or v["tip_distance_error"]["n"]),
                            "tip-distance error, mean (SD) mm": _ms(v["tip_distance_error"]),
                            "pad gap, mean (SD) mm": _ms(v["pad_gap"]),
                            "true pad gap, mean (SD) mm": _ms(v["true_pad_gap"]),
                            "pads to true contact, mean (SD) mm": _ms(v["pad_to_contact"]),
                        }
                        for src, v in pn["per_source"].items()
                    ]
                )
            )
        )
        values = ["tip_distance_mm", "true_tip_distance_mm", "tip_distance_error_mm", "pad_gap_mm"]
        per = tables.moments("pinch", ["kind", "finger", "target", "source"], values)
        per = pd.DataFrame(
            {v: [moments_at(per, v, k).mean for k in per.index] for v in values},
            index=per.index,
        ).reset_index()
        parts += [
            _table(
                pd.DataFrame(
                    {
                        "pinch": pinch_labels(per),
                        "source": per["source"].map(_model_name),
                        "tip distance (mm)": per["tip_distance_mm"].map(_fmt),
                        "true tip distance (mm)": per["true_tip_distance_mm"].map(_fmt),
                        "tip-distance error (mm)": per["tip_distance_error_mm"].map(_fmt),
                        "pad gap (mm)": per["pad_gap_mm"].map(_fmt),
                    }
                )
            ),
            f"<p>Tip-distance error, user-axis vs orthogonal model: "
            f"{html.escape(_ttest(pn['paired_t_test']))}.</p>",
        ]
    return parts
