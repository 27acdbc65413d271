"""HTML pieces of the study report: tables with reader's column names, numbers to the
measurement's precision (0.1 mm, 0.1 deg, whole percent, ``p < 0.001`` or three
decimals), statistics by name, embedded images and JSON safe inside ``<script>``."""

from __future__ import annotations

import base64
import html
import json
import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pandas as pd


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
