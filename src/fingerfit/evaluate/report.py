"""The self-contained HTML report of a study.

Figures are embedded as base64 PNG, tables are HTML, and an interactive 3D
view (plain JavaScript on a canvas, no external files) shows each subject's
fitted finger: bones, joint centres, user axes (blue) and orthogonal axes
(red), in the finger's own frame (origin at the MP centre, x along the
proximal phalanx, mm).
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..estimate.fit import ANGLE_SUMMARY, METHOD_SUMMARY
from ..io.atomic import atomic_write

if TYPE_CHECKING:
    from .study import StudyResult

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;margin:.8em 0;font-size:.9em}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
img{max-width:100%;border:1px solid #eee}.note{color:#555;font-size:.9em}
#view{border:1px solid #ccc;background:#fcfcfc;cursor:grab}code{background:#f4f4f4;padding:0 .2em}
"""

VIEWER_JS = """
const data = JSON.parse(document.getElementById('model-data').textContent);
const cv = document.getElementById('view'), ctx = cv.getContext('2d');
const sel = document.getElementById('subject');
for (const s of Object.keys(data)) { const o = document.createElement('option'); o.textContent = s; sel.appendChild(o); }
let yaw = -0.5, pitch = 0.35, zoom = 1, drag = null, mid = [0, 0, 0];
function fit() {  // centre the subject's finger(s) and fill the canvas
  const pts = data[sel.value].flatMap(f => [...f.centres, f.tip]);
  mid = [0, 1, 2].map(k => pts.reduce((a, p) => a + p[k], 0) / pts.length);
  const r = Math.max(...pts.map(p => Math.hypot(p[0] - mid[0], p[1] - mid[1], p[2] - mid[2])));
  zoom = 0.42 * Math.min(cv.width, cv.height) / Math.max(r, 1);
}
function proj(p) {
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const q = [p[0] - mid[0], p[1] - mid[1], p[2] - mid[2]];
  const x = cy * q[0] - sy * q[1], y0 = sy * q[0] + cy * q[1];
  const y = cp * y0 - sp * q[2], z = sp * y0 + cp * q[2];
  return [cv.width / 2 + zoom * x, cv.height / 2 - zoom * z, y];
}
function line(a, b, color, w) { const p = proj(a), q = proj(b); ctx.strokeStyle = color; ctx.lineWidth = w;
  ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke(); }
function dot(a, color, r) { const p = proj(a); ctx.fillStyle = color; ctx.beginPath();
  ctx.arc(p[0], p[1], r, 0, 6.3); ctx.fill(); }
function draw() {
  ctx.clearRect(0, 0, cv.width, cv.height);
  line([0,0,0],[25,0,0],'#bbb',1); line([0,0,0],[0,25,0],'#bbb',1); line([0,0,0],[0,0,25],'#bbb',1);
  for (const f of data[sel.value]) {
    const pts = [...f.centres, f.tip];
    for (let i = 0; i < 3; i++) line(pts[i], pts[i + 1], '#888', 5);
    for (let i = 0; i < 3; i++) {
      const c = f.centres[i];
      for (const [ax, col] of [[f.axes[i], '#1f77b4'], [f.orthogonal[i], '#d62728']])
        line(c.map((v, k) => v - 18 * ax[k]), c.map((v, k) => v + 18 * ax[k]), col, 2);
      dot(c, '#000', 3.5);
    }
    if (f.abduction) { const [c, ax] = f.abduction;
      line(c.map((v, k) => v - 18 * ax[k]), c.map((v, k) => v + 18 * ax[k]), '#9467bd', 2); }
    for (const l of f.landmarks) dot(l, '#2ca02c', 2.5);
    dot(f.tip, '#ff7f0e', 4);
  }
}
cv.onmousedown = e => drag = [e.clientX, e.clientY, yaw, pitch];
window.onmouseup = () => drag = null;
window.onmousemove = e => { if (!drag) return; yaw = drag[2] + (e.clientX - drag[0]) / 150;
  pitch = drag[3] + (e.clientY - drag[1]) / 150; draw(); };
cv.onwheel = e => { e.preventDefault(); zoom *= e.deltaY < 0 ? 1.1 : 0.9; draw(); };
sel.onchange = () => { fit(); draw(); }; fit(); draw();
"""


def _img(path: Path) -> str:
    b64 = base64.b64encode(path.read_bytes()).decode()
    return f'<img alt="{html.escape(path.stem)}" src="data:image/png;base64,{b64}">'


def _table(df: pd.DataFrame, digits: int = 2) -> str:
    return df.to_html(index=False, float_format=lambda v: f"{v:.{digits}f}", border=0, escape=True)


def _ms(d: dict) -> str:
    return f"{d['mean_mm']:.1f} ({d['sd_mm']:.1f})"


def _p(v: float) -> str:
    return "p < 0.001" if v < 0.001 else f"p = {v:.3f}"


def _viewer_data(result: StudyResult) -> dict:
    out = {}
    for s in result.subjects:
        fingers = []
        for f, fm in s.model.fingers.items():
            origin = fm.joints["mp"].center
            rot = fm.frames["proximal"].rotation  # columns x, y, z (tracker)

            def loc(p, origin=origin, rot=rot):
                return ((np.asarray(p) - origin) @ rot).round(3).tolist()

            joints = list(fm.joints.values())
            fingers.append(
                {
                    "name": f,
                    "centres": [loc(j.center) for j in joints],
                    "tip": loc(fm.tip),
                    "axes": [(j.axis @ rot).round(4).tolist() for j in joints],
                    "orthogonal": [(j.orthogonal_axis @ rot).round(4).tolist() for j in joints],
                    "landmarks": [
                        loc(s.session.landmark(f"{f}.{k}")) for k in ("mp", "pip", "dip", "tip")
                    ],
                    "abduction": None
                    if fm.abduction is None
                    else [loc(fm.abduction.center), (fm.abduction.axis @ rot).round(4).tolist()],
                }
            )
        out[s.subject] = fingers
    return out


def write_report(result: StudyResult, path: Path) -> Path:
    """Write ``report.html`` (self-contained) for a study result."""
    sm, fig, tables = result.summary, result.figures, result.tables
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
            f"<tr><td>{name}</td><td>{_ms(h['user_axis'])}</td><td>{_ms(h['orthogonal'])}</td>"
            f"<td>{h['reduction_percent']:.0f} %</td><td>{h['sd_reduction_percent']:.0f} %</td>"
            f"<td>{_p(h['paired_t_test']['p'])}</td>"
            f"<td>{pp['user_axis'][0]} ({pp['user_axis'][1]}) vs {pp['orthogonal'][0]} "
            f"({pp['orthogonal'][1]}), −{pp['reduction_percent']} %</td></tr>"
        )
    headline = (
        "<table><tr><th>fingertip error, mean (SD) mm</th><th>user-axis</th><th>orthogonal</th>"
        "<th>mean reduction</th><th>SD reduction</th><th>paired t-test</th><th>paper</th></tr>"
        + "".join(rows)
        + "</table>"
    )
    aq = sm["axis_quality"]
    aq_rows = "".join(
        f"<tr><td>{j.upper()}</td><td>{v['mean_mm']:.2f}</td><td>{v['sd_mm']:.2f}</td>"
        f"<td>{v['n']}</td></tr>"
        for j, v in aq["per_joint"].items()
    )
    tt = "; ".join(
        f"{k.replace('_', ' ').upper()}: t = {v['t']:.2f}, {_p(v['p'])}"
        for k, v in aq["t_tests"].items()
    )
    parts = [
        f"<h1>fingerfit study — {len(result.subjects)} subject(s)</h1>",
        f"<p class=note>fingerfit {html.escape(sm['fingerfit_version'])}, method <code>{html.escape(sm['method'])}"
        f"</code>, created {html.escape(sm['created'])}. Lengths in mm, tracker coordinates; angles in degrees. "
        "Tables as CSV beside this file.</p>",
        "<h2>Headline</h2>",
        headline,
        "<h2>Methods and parameters</h2>",
        "<p>Per subject: reference poses = mean over the static reference recording; per joint, grasp cycles are "
        "found from the joint's own angular speed (static holds excluded); a centre of rotation per cycle from the "
        "two 6-DOF sensors (O'Brien et al. 2000, untruncated least squares) for the axis-quality figures; "
        f"the axis by method <code>{html.escape(sm['method'])}</code>: "
        f"{html.escape(METHOD_SUMMARY.get(sm['method'], sm['method']))}; the joint centre where the axis meets "
        "the sagittal plane through the dorsal stylus landmarks. The orthogonal model uses the same centres and "
        "lengths with each flexion axis made perpendicular to its bone. Joint angles by "
        + "; ".join(html.escape(ANGLE_SUMMARY.get(m, m)) for m in sm["angle_methods"])
        + "; fingertips by forward kinematics from the hand sensor. Reference fingertip = distal sensor pose "
        "carrying the stylus-measured tip vector. Statistics: Student t-tests (scipy), two-factor ANOVA with "
        "interaction (statsmodels, type II).</p>",
        f"<p class=note>Subjects: {', '.join(html.escape(s) for s in sm['subjects'])}. See docs/methods.md for "
        "equations and docs/conventions.md for frames and units.</p>",
        "<h2>Axis quality (Fig. 8)</h2>",
        _img(fig["fig08"]),
        "<table><tr><th>joint</th><th>mean distance (mm)</th><th>SD</th><th>n</th></tr>"
        + aq_rows
        + "</table>",
        f"<p>t-tests between joints: {tt}. Paper: DIP 0.2 (0.1) mm, PIP 0.3 (0.1) mm, MP larger.</p>",
        "<h2>Grasp: fingertip trajectories (Fig. 9)</h2>",
        *[_img(p) for k, p in fig.items() if k.startswith("fig09")],
        "<h2>Grasp: error at maximal flexion (Fig. 10)</h2>",
        _img(fig["fig10"]),
    ]
    per = pd.DataFrame(
        [
            {
                "subject": s,
                "user-axis mean mm": v["user_axis_mean_mm"],
                "orthogonal mean mm": v["orthogonal_mean_mm"],
                "reduction %": v["reduction_percent"],
                "paired t p": v["paired_t_test"]["p"],
            }
            for s, v in sm["max_flexion"]["per_subject"].items()
        ]
    )
    parts.append(_table(per, 3))
    if "anova_model_x_subject" in sm["max_flexion"]:
        a = sm["max_flexion"]["anova_model_x_subject"]
        parts.append(
            "<p>Two-factor ANOVA (model × subject): "
            + "; ".join(
                f"{k}: F = {v['F']:.2f}, {_p(v['p'])}" for k, v in a.items() if v["F"] is not None
            )
            + "</p>"
        )
    if "targets" in sm:
        tg = sm["targets"]
        parts += ["<h2>Target reaching (Figs. 11–12)</h2>", _img(fig["fig11"]), _img(fig["fig12"])]
        pt = pd.DataFrame(
            [
                {
                    "target": t,
                    **{
                        f"{k} mean (SD) mm": f"{v[k]['mean_mm']:.1f} ({v[k]['sd_mm']:.1f})"
                        for k in ("reference", "user_axis", "orthogonal")
                    },
                }
                for t, v in tg["per_target"].items()
            ]
        )
        parts.append(_table(pt))
        parts.append(f"<p>Distal-sensor reference: {_ms(tg['reference'])} mm.</p>")
        for key, name in (
            ("anova_model_x_target", "model × target"),
            ("anova_model_x_subject", "model × subject"),
        ):
            if key in tg:
                parts.append(
                    f"<p>Two-factor ANOVA ({name}): "
                    + "; ".join(
                        f"{k}: F = {v['F']:.2f}, {_p(v['p'])}"
                        for k, v in tg[key].items()
                        if v["F"] is not None
                    )
                    + "</p>"
                )
    if "truth" in sm:
        parts += [
            "<h2>Against ground truth (simulated sessions)</h2>",
            "<p>What the paper could not measure: the fitted axes against the true ones and the fingertip "
            "against the true fingertip on every recording.</p>",
            _img(fig["truth"]),
            _table(
                tables["truth_axes"]
                .groupby("joint")[["axis_error_deg", "centre_to_axis_mm"]]
                .agg(["mean", "max"])
                .reset_index()
                .set_axis(
                    [
                        "joint",
                        "axis error mean (deg)",
                        "axis error max (deg)",
                        "centre→true axis mean (mm)",
                        "centre→true axis max (mm)",
                    ],
                    axis=1,
                )
            ),
            _table(
                tables["truth_fingertip"]
                .groupby(["recording", "variant"])[["mean_mm", "p95_mm"]]
                .mean()
                .reset_index()
            ),
        ]
    parts += [
        "<h2>Fitted models</h2>",
        _table(
            tables["models"].drop(
                columns=["center_x", "center_y", "center_z", "axis_x", "axis_y", "axis_z"]
            )
        ),
        "<h2>3D view of the fitted fingers</h2>",
        "<p class=note>Drag to rotate, wheel to zoom. Grey: bones; black: joint centres; blue: fitted (user) "
        "axes; red: orthogonal axes; purple: MP ab/adduction axis (two-axis models); green: stylus landmarks; orange: fingertip. Frame: origin at the MP "
        "centre, x along the proximal phalanx (mm).</p>",
        "<p>subject <select id=subject></select></p><canvas id=view width=760 height=460></canvas>",
        f"<script type='application/json' id='model-data'>{json.dumps(_viewer_data(result))}</script>",
        f"<script>{VIEWER_JS}</script>",
    ]
    doc = (
        f"<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>fingerfit study</title>"
        f"<style>{CSS}</style></head><body>{''.join(parts)}</body></html>"
    )
    with atomic_write(path, encoding="utf-8") as fh:
        fh.write(doc)
    return path
