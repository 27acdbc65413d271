"""The HTML report of a study.

The study-wide figures are embedded as base64 PNG; each subject's Fig. 9 is linked
(the PNG beside the report, so the report of a large cohort stays small), tables are HTML with reader's column names and
units, and an interactive 3D view (plain JavaScript on a canvas, no external files)
shows each subject's fitted fingers: bones, joint centres, user axes (blue) and
orthogonal axes (red), in the proximal-phalanx frame of the subject's first finger
(origin at its MP centre, x along the phalanx, mm), with an axis triad and a 10 mm
scale bar. Numbers carry the measurement's precision (0.1 mm, 0.1 deg, whole
percent, ``p < 0.001`` or three decimals); statistics that were not computed,
failed sessions and forced-fit warnings are listed by name.
"""

from __future__ import annotations

import base64
import html
import json
import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

import numpy as np
import pandas as pd

from ..digits import DIGITS, FINGERS
from ..estimate.fit import ANGLE_SUMMARY, METHOD_SUMMARY
from ..io.atomic import atomic_write
from .pinch import pinch_labels
from .stats import moments_at

if TYPE_CHECKING:
    from .gather import StudyTables
    from .results import StudyResult

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.8em 0;font-size:.9em}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:left;vertical-align:top}th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
img{max-width:100%;border:1px solid #eee}figure{margin:.8em 0}.note{color:#555;font-size:.9em}
.warn{color:#8a4b00;font-weight:600}
#view{border:1px solid #ccc;background:#fcfcfc;cursor:grab}code{background:#f4f4f4;padding:0 .2em}
"""

VIEWER_JS = """
const data = JSON.parse(document.getElementById('model-data').textContent);
const cv = document.getElementById('view'), ctx = cv.getContext('2d');
const sel = document.getElementById('subject');
for (const s of Object.keys(data)) { const o = document.createElement('option'); o.textContent = s; sel.appendChild(o); }
let yaw = -0.5, pitch = 0.35, zoom = 1, drag = null, off = [0, 0];
function rot(q) {  // view rotation of a vector (mm): screen right, depth, screen up
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const x = cy * q[0] - sy * q[1], y0 = sy * q[0] + cy * q[1];
  return [x, cp * y0 - sp * q[2], sp * y0 + cp * q[2]];
}
function proj(p) { const r = rot(p); return [cv.width / 2 + off[0] + zoom * r[0], cv.height / 2 + off[1] - zoom * r[2]]; }
function points() { return data[sel.value].fingers.flatMap(f => [...f.centres, f.tip, ...(f.pad ? [f.pad] : []), ...f.landmarks]); }
function fit() {  // frame the hand: every centre, tip and landmark fills ~80 % of the canvas
  const r = points().map(rot);
  const lo = [0, 2].map(k => Math.min(...r.map(p => p[k]))), hi = [0, 2].map(k => Math.max(...r.map(p => p[k])));
  zoom = 0.8 * Math.min(cv.width / Math.max(hi[0] - lo[0], 1), cv.height / Math.max(hi[1] - lo[1], 1));
  off = [-zoom * (lo[0] + hi[0]) / 2, zoom * (lo[1] + hi[1]) / 2];
}
function line(a, b, color, w) { const p = proj(a), q = proj(b); ctx.strokeStyle = color; ctx.lineWidth = w;
  ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke(); }
function dot(a, color, r) { const p = proj(a); ctx.fillStyle = color; ctx.beginPath();
  ctx.arc(p[0], p[1], r, 0, 6.3); ctx.fill(); }
function text(s, x, y, color) { ctx.fillStyle = color; ctx.fillText(s, x, y); }
function triad() {  // the frame's axes, bottom left, rotating with the view
  const o = [55, cv.height - 55], cols = ['#c0392b', '#27ae60', '#2c3e8f'];
  ctx.font = '13px sans-serif'; ctx.textAlign = 'center'; ctx.textBaseline = 'middle';
  for (let k = 0; k < 3; k++) {
    const e = [0, 0, 0]; e[k] = 1; const r = rot(e);
    const p = [o[0] + 36 * r[0], o[1] - 36 * r[2]];
    ctx.strokeStyle = cols[k]; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(o[0], o[1]);
    ctx.lineTo(p[0], p[1]); ctx.stroke();
    text('xyz'[k], o[0] + 48 * r[0], o[1] - 48 * r[2], cols[k]);
  }
}
function scalebar() {  // 10 mm at the current zoom, bottom right
  const L = 10 * zoom, x1 = cv.width - 30, x0 = x1 - L, y = cv.height - 30;
  ctx.strokeStyle = '#000'; ctx.lineWidth = 2; ctx.beginPath();
  ctx.moveTo(x0, y - 5); ctx.lineTo(x0, y); ctx.lineTo(x1, y); ctx.lineTo(x1, y - 5); ctx.stroke();
  ctx.font = '13px sans-serif'; ctx.textAlign = 'center'; ctx.textBaseline = 'bottom';
  text('10 mm', (x0 + x1) / 2, y - 6, '#000');
}
function draw() {
  ctx.clearRect(0, 0, cv.width, cv.height);
  const d = data[sel.value];
  for (const f of d.fingers) {
    const pts = [...f.centres, f.tip];
    for (let i = 0; i < 3; i++) line(pts[i], pts[i + 1], '#888', 5);
    for (let i = 0; i < 3; i++) {
      const c = f.centres[i];
      for (const [ax, col] of [[f.axes[i], '#1f77b4'], [f.orthogonal[i], '#d62728']])
        line(c.map((v, k) => v - 12 * ax[k]), c.map((v, k) => v + 12 * ax[k]), col, 2);
      dot(c, '#000', 3.5);
    }
    for (const [c, ax] of f.second_axes)
      line(c.map((v, k) => v - 12 * ax[k]), c.map((v, k) => v + 12 * ax[k]), '#9467bd', 2);
    for (const l of f.landmarks) dot(l, '#2ca02c', 2.5);
    if (f.pad) { line(f.tip, f.pad, '#e377c2', 1); dot(f.pad, '#e377c2', 3.5); }
    dot(f.tip, '#ff7f0e', 4);
    const t = proj(f.tip); ctx.font = '13px sans-serif'; ctx.textAlign = 'left';
    ctx.textBaseline = 'middle'; text(f.name, t[0] + 8, t[1], '#333');
  }
  triad(); scalebar();
  ctx.font = '12px sans-serif'; ctx.textAlign = 'left'; ctx.textBaseline = 'top';
  text(d.frame, 10, 10, '#555');
}
cv.onmousedown = e => drag = [e.clientX, e.clientY, yaw, pitch];
window.onmouseup = () => drag = null;
window.onmousemove = e => { if (!drag) return; yaw = drag[2] + (e.clientX - drag[0]) / 150;
  pitch = drag[3] + (e.clientY - drag[1]) / 150; draw(); };
cv.onwheel = e => { e.preventDefault(); zoom *= e.deltaY < 0 ? 1.1 : 0.9; draw(); };
cv.ondblclick = () => { fit(); draw(); };
sel.onchange = () => { fit(); draw(); }; fit(); draw();
"""


def _img(path: Path, alt: str) -> str:
    b64 = base64.b64encode(path.read_bytes()).decode()
    return f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}"></figure>'


def _linked_img(path: Path, report: Path, alt: str) -> str:
    """A figure linked by its path relative to the report (not read, not embedded)."""
    rel = quote(Path(os.path.relpath(path, report.parent)).as_posix())
    return (
        f'<figure><a href="{html.escape(rel)}"><img alt="{html.escape(alt)}" '
        f'src="{html.escape(rel)}" loading="lazy"></a></figure>'
    )


_NUMERIC = re.compile(r"^[-−+]?\d|^—$")


def _cell(v: object, tag: str) -> str:
    text = "—" if v is None or (isinstance(v, float) and not np.isfinite(v)) else str(v)
    cls = " class=num" if tag == "td" and _NUMERIC.match(text) else ""
    return f"<{tag}{cls}>{html.escape(text)}</{tag}>"


def _rows(df: pd.DataFrame) -> str:
    return "".join(
        "<tr>" + "".join(_cell(v, "td") for v in row) + "</tr>"
        for row in df.itertuples(index=False)
    )


def _table(df: pd.DataFrame) -> str:
    """An HTML table of pre-formatted cells: numbers right-aligned, text left-aligned."""
    return "".join(_table_parts([df]))


def _table_parts(frames: Iterable[pd.DataFrame]) -> Iterator[str]:
    """:func:`_table` of the rows of several tables with the same columns, piece by piece
    (a table of every subject is never one string; no tables: an empty table)."""
    k = -1
    for k, df in enumerate(frames):
        if k == 0:
            head = "".join(_cell(c, "th") for c in df.columns)
            yield f"<table><thead><tr>{head}</tr></thead><tbody>"
        yield _rows(df)
    if k < 0:
        yield "<table><thead><tr></tr></thead><tbody>"
    yield "</tbody></table>"


def _fmt(v: float | None, digits: int = 1, unit: str = "") -> str:
    """A number to ``digits`` decimals (with ``unit``), or an em dash when undefined."""
    if v is None or not np.isfinite(v):
        return "—"
    return f"{v:.{digits}f}{unit}"


def _ms(d: dict) -> str:
    """Mean (SD) to 0.1 mm."""
    return f"{_fmt(d['mean_mm'])} ({_fmt(d['sd_mm'])})"


def _pct(v: float | None) -> str:
    """A percentage to the whole percent."""
    return _fmt(v, 0, " %")


def _p(v: float | None) -> str:
    """A p-value: ``p < 0.001`` or three decimals."""
    if v is None or not np.isfinite(v):
        return "p undefined"
    return "p < 0.001" if v < 0.001 else f"p = {v:.3f}"


def _ttest(d: dict) -> str:
    """A t-test as ``t(df) = 2.31, p = 0.041``, or why it was not computed."""
    if "skipped" in d:
        return f"not computed: {d['skipped']}"
    return f"t({d['df']:.0f}) = {_fmt(d['t'], 2)}, {_p(d['p'])}"


def _factor(name: str) -> str:
    return re.sub(r"C\((\w+)\)", r"\1", name).replace(":", " × ")


def _anova(d: dict, name: str) -> str:
    """One paragraph: the ANOVA's effects with F and p, or why it was not computed."""
    if "skipped" in d:
        return f"<p>Two-factor ANOVA ({name}): not computed: {html.escape(d['skipped'])}.</p>"
    resid = d.get("Residual", {}).get("df")
    effects = "; ".join(
        f"{html.escape(_factor(k))}: F({v['df']:.0f}, {_fmt(resid, 0)}) = {_fmt(v['F'], 2)}, "
        f"{_p(v['p'])}"
        for k, v in d.items()
        if k != "Residual" and v["F"] is not None
    )
    return f"<p>Two-factor ANOVA ({name}): {effects}.</p>"


_STAT_NAMES = {
    "axis_quality.t_tests.dip_vs_pip": "axis quality: t-test DIP vs PIP",
    "axis_quality.t_tests.mp_vs_dip": "axis quality: t-test MP vs DIP",
    "axis_quality.t_tests.mp_vs_pip": "axis quality: t-test MP vs PIP",
    "max_flexion.paired_t_test": "maximal flexion: paired t-test, all subjects",
    "max_flexion.anova_model_x_subject": "maximal flexion: ANOVA model × subject",
    "targets.paired_t_test": "target reaching: paired t-test",
    "targets.anova_model_x_target": "target reaching: ANOVA model × target",
    "targets.anova_model_x_subject": "target reaching: ANOVA model × subject",
}


def _statistic_name(key: str) -> str:
    """A reader's name for a ``summary.json`` statistic key."""
    m = re.fullmatch(r"max_flexion\.per_subject\.(.+)\.paired_t_test", key)
    if m:
        return f"maximal flexion: paired t-test, subject {m.group(1)}"
    return _STAT_NAMES.get(key, key)


def _list(items: list[str]) -> str:
    return "<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + "</ul>"


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


def write_report(result: StudyResult, path: Path) -> Path:
    """Write ``report.html`` for a study result.

    Study-wide figures are embedded; each subject's Fig. 9 is linked relative to
    ``path`` (the study writes it beside the report).

    Numbers are shown to the precision of the measurement: 0.1 mm, 0.1 deg, whole
    percent, p as ``p < 0.001`` or three decimals. Statistics that were not computed
    are listed with the reason.
    """
    sm, fig, tables = result.summary, result.figures, result.tables
    n_subj = len(result.subjects)
    one = n_subj == 1
    aq = sm["axis_quality"]
    aq_table = pd.DataFrame(
        [
            {
                "joint": j.upper(),
                "cycles (n)": str(v["n"]),
                "mean distance (mm)": _fmt(v["mean_mm"]),
                "SD (mm)": _fmt(v["sd_mm"]),
            }
            for j, v in aq["per_joint"].items()
        ]
    )
    tt = "; ".join(
        f"{k.split('_vs_')[0].upper()} vs {k.split('_vs_')[1].upper()}: {_ttest(v)}"
        for k, v in aq["t_tests"].items()
    )
    parts = [
        f"<h1>fingerfit study — {n_subj} subject{'' if one else 's'}</h1>",
        f"<p class=note>fingerfit {html.escape(sm['fingerfit_version'])}, method "
        f"<code>{html.escape(sm['method'])}</code>"
        + (" (<b>forced</b>: <code>--force</code>)" if sm.get("forced") else "")
        + f", created {html.escape(sm['created'])}. Lengths in mm (tracker coordinates unless "
        "a figure says otherwise), angles in degrees. Tables as CSV beside this file.</p>",
        *_problems(result),
        "<h2>Headline</h2>",
        _headline(sm),
    ]
    if one:
        parts.append(
            "<p class=note>One subject: statistics between subjects (ANOVA with subject as a "
            "factor) are not computed; see <a href='#skipped'>Statistics not computed</a>.</p>"
        )
    if "targets" not in sm:
        parts.append(
            "<p class=note>No session has target recordings, so target reaching "
            "(Figs. 11–12) is not evaluated.</p>"
        )
    parts += [
        "<h2>Methods and parameters</h2>",
        "<p>Per subject: reference poses = mean over the static reference recording; per joint, "
        "grasp cycles are found from the joint's own angular speed (static holds excluded); a "
        "centre of rotation per cycle from the two 6-DOF sensors (O'Brien et al. 2000, "
        "untruncated least squares) for the axis-quality figures; "
        f"the axis by method <code>{html.escape(sm['method'])}</code>: "
        f"{html.escape(METHOD_SUMMARY.get(sm['method'], sm['method']))}; the thumb's CMC, "
        "whatever the method, as a saddle joint: two non-intersecting axes from all its "
        "calibration frames; the joint centre where "
        "the axis meets the sagittal plane through the dorsal stylus landmarks. The orthogonal "
        "model uses the same centres and lengths with each flexion axis made perpendicular to "
        "its bone (a second axis also perpendicular to the orthogonal flexion axis). Joint "
        "angles by "
        + "; ".join(html.escape(ANGLE_SUMMARY.get(m, m)) for m in sm["angle_methods"])
        + "; fingertips by forward kinematics from the hand sensor. Reference fingertip = "
        "distal sensor pose carrying the stylus-measured tip vector. Pad points: fitted to "
        "the session's pinch holds where it has pinch events (touching pulps coincide), else "
        "the digitised pad landmark or the pulp geometry. Statistics: Student "
        "t-tests (scipy), two-factor ANOVA with interaction (type II, from the cells' "
        "sums, equal to statsmodels' anova_lm).</p>",
        _subjects_table(result),
        "<p class=note>See docs/methods.md for equations and docs/conventions.md for frames "
        "and units.</p>",
        "<h2>Axis quality (Fig. 8)</h2>",
        _img(fig["fig08"], "Fig. 8 axis quality"),
        _table(aq_table),
        f"<p>Student t-tests between joints: {html.escape(tt)}. Paper: DIP 0.2 (0.1) mm, "
        "PIP 0.3 (0.1) mm, MP larger.</p>",
        "<h2>Grasp: fingertip trajectories (Fig. 9)</h2>",
        *[_linked_img(p, path, f"Fig. 9 {k[6:]}") for k, p in fig.items() if k.startswith("fig09")],
        "<h2>Grasp: error at maximal flexion (Fig. 10)</h2>",
        _img(fig["fig10"], "Fig. 10 maximal flexion")
        if "fig10" in fig
        else "<p class=note>No finger in this study: Fig. 10 is the fingers'; the thumb's "
        "tip at maximal flexion is in the <a href='#thumb'>Thumb</a> section.</p>",
    ]
    mf = sm["max_flexion"]
    per = pd.DataFrame(
        [
            {
                "subject": s,
                "cycles (n)": str(v["n"]),
                "user-axis error, mean (mm)": _fmt(v["user_axis_mean_mm"]),
                "orthogonal error, mean (mm)": _fmt(v["orthogonal_mean_mm"]),
                "reduction (%)": _fmt(v["reduction_percent"], 0),
                "paired t-test": _ttest(v["paired_t_test"]),
            }
            for s, v in mf["per_subject"].items()
        ]
    )
    parts += [_table(per), _anova(mf["anova_model_x_subject"], "model × subject")]
    if "targets" in sm:
        tg = sm["targets"]
        without = [s for s in sm["subjects"] if s not in tg["subjects"]]
        parts += [
            "<h2>Target reaching (Figs. 11–12)</h2>",
            f"<p class=note>{_TARGET_NOTE}"
            + (
                f" Subjects without target recordings (not included): "
                f"{html.escape(', '.join(without))}."
                if without
                else ""
            )
            + "</p>",
            _img(fig["fig11"], "Fig. 11 target offsets"),
            _img(fig["fig12"], "Fig. 12 target errors"),
        ]
        pt = pd.DataFrame(
            [
                {
                    "target": t,
                    "touches (n)": str(v["n"]),
                    **{
                        f"{name}, mean (SD) mm": _ms(v[k])
                        for k, name in (
                            ("reference", "distal sensor"),
                            ("user_axis", "user-axis model"),
                            ("orthogonal", "orthogonal model"),
                        )
                    },
                }
                for t, v in tg["per_target"].items()
            ]
        )
        parts += [
            _table(pt),
            f"<p>Distal-sensor reference over all touches: {_ms(tg['reference'])} mm.</p>",
            _anova(tg["anova_model_x_target"], "model × target"),
            _anova(tg["anova_model_x_subject"], "model × subject"),
        ]
    if "truth" in sm:
        parts += _truth(result)
    if "thumb" in sm:
        parts += _thumb(result)
    if "thumb" in sm or "pinch" in sm:
        parts += _whole_hand(result)
    models = (
        pd.DataFrame(
            {
                "subject": m["subject"],
                "finger": m["finger"],
                "joint": m["joint"].astype(str).str.upper(),
                "axis tilt from orthogonal (deg)": m["tilt_from_orthogonal_deg"].map(_fmt),
                "segment length (mm)": m["segment_length_mm"].map(_fmt),
            }
        )
        for m in tables.chunks("models")
    )
    parts += [
        "<h2>Fitted models</h2>",
        _table_parts(models),
        "<h2 id=skipped>Statistics not computed</h2>",
        _list([f"{_statistic_name(d['statistic'])}: {d['reason']}" for d in sm["skipped"]])
        if sm["skipped"]
        else "<p>None: every statistic had enough data.</p>",
        "<h2 id=view3d>3D view of the fitted hand</h2>",
        "<p class=note>Drag to rotate, wheel to zoom. Grey: bones; black: joint centres; blue: "
        "fitted (user) flexion axes; red: orthogonal axes; purple: second (ab/adduction) axes "
        "(finger MP, thumb CMC and MCP); green: stylus landmarks; orange: tip (nail-edge "
        "point); pink: pad point (pulp), joined to the tip. Frame: the proximal-phalanx frame "
        "of the subject's first finger, origin at its MP centre, x along the phalanx (a thumb "
        "alone: its metacarpal frame, origin at the CMC centre; axes in "
        "the triad bottom left); the bar bottom right is 10 mm at the current zoom. "
        "Double-click to re-frame.</p>",
        "<p>subject <select id=subject></select></p><canvas id=view width=900 height=560></canvas>",
        "<script type='application/json' id='model-data'>",
        _json_script(_viewer_data(result)),
        "</script>",
        f"<script>{VIEWER_JS}</script>",
    ]
    with atomic_write(path, encoding="utf-8") as fh:
        fh.write(
            "<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>fingerfit study"
            f"</title><style>{CSS}</style></head><body>"
        )
        for part in parts:  # written as made: the page is never one string
            fh.writelines([part] if isinstance(part, str) else part)
        fh.write("</body></html>")
    return path


def _json_script(items: Iterable[tuple[str, object]]) -> Iterator[str]:
    """The JSON object of ``items`` (key, value), safe inside a ``<script>`` element (no
    ``</script>`` in subject names): the text of ``json.dumps(dict(items))``, piece by
    piece, made one item at a time (a thousand subjects' viewer data are never Python
    objects, nor one string, all at once)."""
    yield "{"
    for k, (key, value) in enumerate(items):
        piece = f"{', ' if k else ''}{json.dumps(key)}: {json.dumps(value)}"
        yield piece.replace("<", "\\u003c").replace(">", "\\u003e")
    yield "}"


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


def _truth(result: StudyResult) -> list[str]:
    sm, fig, tables = result.summary, result.figures, result.tables
    values = ["axis_error_deg", "centre_to_axis_mm"]
    axes = tables.moments("truth_axes", ["joint"], values)  # every digit's
    axes_t = pd.DataFrame(
        [
            {
                "joint": str(j).upper(),
                "axis error, mean (deg)": _fmt(moments_at(axes, values[0], j).mean),
                "axis error, max (deg)": _fmt(moments_at(axes, values[0], j).max),
                "centre to true axis, mean (mm)": _fmt(moments_at(axes, values[1], j).mean),
                "centre to true axis, max (mm)": _fmt(moments_at(axes, values[1], j).max),
            }
            for j in axes.index
        ]
    )
    tips = tables.moments("truth_fingertip", ["recording", "variant"], ["mean_mm", "p95_mm"])
    rank = {"user_axis": "0", "orthogonal": "1"}
    tips_t = pd.DataFrame(
        [
            {
                "recording": str(r),
                "model": str(v).replace("_", "-") + " model",
                "fingertip error, mean (mm)": _fmt(moments_at(tips, "mean_mm", (r, v)).mean),
                "95th percentile (mm)": _fmt(moments_at(tips, "p95_mm", (r, v)).mean),
            }
            for r, v in sorted(tips.index, key=lambda k: (str(k[0]), rank.get(k[1], str(k[1]))))
        ]
    )
    subj = sm["truth"]["subjects"]
    parts = [
        "<h2>Against ground truth (simulated sessions)</h2>",
        "<p>What the paper could not measure: the fitted axes against the true ones and the "
        "fingertip against the true fingertip on every recording "
        f"({len(subj)} subject{'s' if len(subj) != 1 else ''} with ground truth: "
        f"{html.escape(', '.join(subj))}). Fingertip errors: mean over subjects of each "
        "recording's mean and 95th percentile.</p>",
    ]
    if "truth" in fig:
        parts.append(_img(fig["truth"], "true fingertip error"))
    return [*parts, _table(axes_t), _table(tips_t)]


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


def _means(tables: StudyTables, name: str, keys: list[str], value: str) -> pd.DataFrame:
    """Mean of ``value`` per group of ``keys``, read chunk by chunk: one row per group of
    all keys but the last, one column per level of the last, as
    ``table.groupby(keys, sort=False)[value].mean().unstack(keys[-1])`` (rows ordered by
    each key's order of first appearance, the first key first)."""
    m = tables.moments(name, keys, [value])
    rows: dict[tuple, dict] = {}
    for k in m.index:
        *row, column = (str(x) for x in k)
        rows.setdefault(tuple(row), {})[column] = moments_at(m, value, k).mean
    rank = [
        {x: i for i, x in enumerate(dict.fromkeys(r[j] for r in rows))}
        for j in range(len(keys) - 1)
    ]
    order = sorted(rows, key=lambda r: [rank[j][x] for j, x in enumerate(r)])
    return pd.DataFrame([{**dict(zip(keys, r, strict=False)), **rows[r]} for r in order])


def _whole_hand(result: StudyResult) -> list[str]:
    """The whole hand: every digit's tip and every joint angle against truth, and pinches."""
    sm, fig, tables = result.summary, result.figures, result.tables
    parts = [
        "<h2 id=wholehand>Whole hand</h2>",
        "<p class=note>The 3D view of the whole hand (every digit, its second axes and pad "
        "points) is <a href='#view3d'>below</a>.</p>",
    ]
    w = _means(tables, "truth_fingertip", ["finger", "recording", "variant"], "mean_mm")
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
    w = _means(tables, "truth_angles", ["finger", "joint", "variant"], "mean_abs_deg")
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
