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

Here the page in order (:func:`write_report`); its sections are made in
:mod:`.report_sections`, its HTML pieces and number formats in :mod:`.report_html`, its
style sheet and viewer script are :mod:`.report_assets`.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from ..estimate.fit import ANGLE_SUMMARY, METHOD_SUMMARY
from ..io.atomic import atomic_write
from .report_assets import CSS, VIEWER_JS
from .report_html import (
    _anova,
    _fmt,
    _img,
    _json_script,
    _linked_img,
    _list,
    _ms,
    _statistic_name,
    _table,
    _table_parts,
    _ttest,
)
from .report_sections import (
    _TARGET_NOTE,
    _headline,
    _problems,
    _subjects_table,
    _thumb,
    _truth,
    _viewer_data,
    _whole_hand,
)

if TYPE_CHECKING:
    from .results import StudyResult


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
