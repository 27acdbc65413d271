"""Report layout: every study figure is readable -- no two text labels overlap, every axis
is labelled with its unit (and frame where it has one) -- for a two-subject mixed study
and for a one-subject study; numbers in the report carry the measurement's precision."""

from __future__ import annotations

import dataclasses
import itertools
import re

import matplotlib.pyplot as plt
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from fingerfit.estimate import FitOptions
from fingerfit.evaluate import run_study
from fingerfit.evaluate.report_html import _p, _pct, _ttest
from fingerfit.evaluate.study import figure_builders
from fingerfit.evaluate.subject import evaluate_subject
from fingerfit.evaluate.summary import summarize_study
from fingerfit.io.sessiondir import load_session, save_session
from fingerfit.simulate import write_subject

from .conftest import subject


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """P01 (realistic: targets, test, truth) and P02 (exact: grasp only)."""
    root = tmp_path_factory.mktemp("layout")
    p01 = write_subject(subject("realistic", 2), root / "P01")
    toml = p01 / "session.toml"
    toml.write_text(toml.read_text().replace('subject = "S01"', 'subject = "P01"'))
    exact = subject("exact", 11).session
    bare = dataclasses.replace(exact, subject="P02", targets=[], test=[], events=[], path=None)
    p02 = save_session(bare, root / "P02")
    return run_study([p01, p02], root / "out", FitOptions(method="tang2018"))


def _full(study) -> list:
    """The study's subjects with their per-frame arrays (the study keeps compact ones)."""
    opts = FitOptions(method="tang2018")
    return [evaluate_subject(load_session(s.session.path), opts) for s in study.subjects]


def _texts(fig: Figure) -> list[Text]:
    """Every drawn, non-empty text of a figure (tick labels only for ticks in view)."""
    hidden: set[int] = set()
    for ax in fig.axes:
        for axis, (lo, hi) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            lo, hi = min(lo, hi), max(lo, hi)
            for tick in [*axis.get_major_ticks(), *axis.get_minor_ticks()]:
                if not lo - 1e-9 * (hi - lo) <= tick.get_loc() <= hi + 1e-9 * (hi - lo):
                    hidden.update((id(tick.label1), id(tick.label2)))
    return [
        t
        for t in fig.findobj(Text)
        if t.get_visible() and t.get_text().strip() and id(t) not in hidden
    ]


def overlaps(fig: Figure) -> list[tuple[str, str]]:
    """Pairs of text labels whose drawn extents overlap (by more than half a pixel)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in _texts(fig)]
    bad = []
    for (a, ba), (b, bb) in itertools.combinations(boxes, 2):
        inter = Bbox.intersection(ba, bb)
        if inter is not None and inter.width > 0.5 and inter.height > 0.5:
            bad.append((a, b))
    return bad


def test_overlap_check_detects_overlap() -> None:
    fig, ax = plt.subplots()
    ax.text(0.5, 0.5, "first label")
    ax.text(0.52, 0.5, "second label")
    ax.text(0.1, 0.1, "")  # empty strings are ignored
    try:
        assert ("first label", "second label") in overlaps(fig)
    finally:
        plt.close(fig)


def _check_figures(subjects, tables) -> set[str]:
    built = figure_builders(subjects, tables)
    for key, (_name, build) in built.items():
        fig = build()
        try:
            assert overlaps(fig) == [], key
            for ax in fig.axes:
                xl, yl = ax.get_xlabel(), ax.get_ylabel()
                assert xl and yl, (key, xl, yl)
                assert "(mm)" in yl, (key, yl)
                if key.startswith("fig09"):
                    assert "hand-sensor" in xl and "(mm)" in xl and "hand-sensor" in yl
                if key == "fig11":
                    assert "tracker" in xl and "(mm)" in xl and "tracker" in yl
        finally:
            plt.close(fig)
    return set(built)


def test_figures_of_a_mixed_study_have_no_overlapping_labels(mixed) -> None:
    keys = _check_figures(_full(mixed), mixed.tables)
    assert keys == {"fig08", "fig09_P01", "fig09_P02", "fig10", "fig11", "fig12", "truth"}


def test_figures_of_a_one_subject_study_have_no_overlapping_labels(mixed) -> None:
    one = [s for s in _full(mixed) if s.subject == "P01"]
    _summary, tables = summarize_study(one, FitOptions(method="tang2018"))
    assert _check_figures(one, tables) == {
        "fig08",
        "fig09_P01",
        "fig10",
        "fig11",
        "fig12",
        "truth",
    }


def test_number_formats() -> None:
    assert _p(0.0) == "p < 0.001" and _p(0.00099) == "p < 0.001"
    assert _p(0.0123) == "p = 0.012" and _p(float("nan")) == "p undefined"
    assert _pct(77.201) == "77 %" and _pct(None) == "—"
    assert _ttest({"t": -2.345, "p": 0.04, "df": 9.0}) == "t(9) = -2.35, p = 0.040"
    assert _ttest({"skipped": "needs at least 2 pairs, has 1"}).startswith("not computed")


def test_report_precision_and_names(mixed) -> None:
    html = mixed.report.read_text()
    body = re.sub(r"<script.*?</script>", "", html, flags=re.S)
    body = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", body)
    assert not re.search(r"p [=<] ?0\.000\b", body)
    assert not re.search(r"\d\.\d{2,} ?%", body)  # whole percent
    cells = re.findall(r"<td class=num>([^<]*)</td>", body)
    for c in cells:  # 0.1 mm / 0.1 deg / counts / whole percent
        assert re.fullmatch(r"-?\d+(\.\d)?( \(\d+\.\d\))?|—( \(—\))?|\d+\.\d \(—\)|-?\d+ %", c), c
    for raw in ("user_axis", "tilt_from_orthogonal_deg", "segment_length_mm", "mean_mm", "p95_mm"):
        assert f"<th>{raw}" not in body
    assert "t000 … t120" in body  # target names explained
    assert "3D view" in body and "10 mm" in html and "triad" in html


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """One realistic thumb + index subject (truth, targets, pinches)."""
    root = tmp_path_factory.mktemp("whole")
    w01 = write_subject(subject("realistic", 2, ("thumb", "index")), root / "W01")
    toml = w01 / "session.toml"
    toml.write_text(toml.read_text().replace('subject = "S01"', 'subject = "W01"'))
    return run_study([w01], root / "out", FitOptions())


def test_whole_hand_figures_have_no_overlapping_labels(whole) -> None:
    subjects = [
        evaluate_subject(load_session(s.session.path), FitOptions()) for s in whole.subjects
    ]
    keys = _check_figures(subjects, whole.tables)
    assert {"thumb", "pinch", "fig10", "truth"} <= keys
    fig = figure_builders(subjects, whole.tables)["fig08"][1]()
    try:  # Fig. 8 gains a panel of the thumb's joints
        assert len(fig.axes) == 3 and "thumb" in fig.axes[2].get_title(loc="left")
    finally:
        plt.close(fig)


def test_whole_hand_report_has_thumb_pinch_and_3d_view(whole) -> None:
    import json

    html = whole.report.read_text()
    for anchor in ("id=thumb", "id=wholehand", "id=pinch", "id=view3d"):
        assert anchor in html, anchor
    body = re.sub(r"<script.*?</script>", "", html, flags=re.S)
    body = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", body)
    for text in ("CMC ab/adduction", "tip-distance error", "pad gap", "thumb tip error"):
        assert text in body, text
    for c in re.findall(r"<td class=num>([^<]*)</td>", body):
        assert re.fullmatch(r"-?\d+(\.\d)?( \(\d+\.\d\))?|—( \(—\))?|\d+\.\d \(—\)|-?\d+ %", c), c
    for raw in ("user_axis", "tip_distance_error_mm", "pad_gap_mm", "axis_offset_mm"):
        assert f"<th>{raw}" not in body
    data = json.loads(re.search(r"id='model-data'>(.*?)</script>", html, flags=re.S).group(1))
    digits = {f["name"]: f for f in data["W01"]["fingers"]}
    assert set(digits) == {"thumb", "index"}
    thumb = digits["thumb"]
    assert len(thumb["centres"]) == 3 and len(thumb["second_axes"]) >= 1  # CMC ab/adduction
    assert thumb["pad"] is not None and digits["index"]["pad"] is not None
    assert "index proximal-phalanx frame" in data["W01"]["frame"]
    assert "f.pad" in html  # the viewer draws the pads
    assert {"thumb", "pinch"} <= set(whole.summary)


def test_report_truth_numbers_are_the_summary_s(whole) -> None:
    """The ground-truth tables of the report show ``summary.json``'s numbers (read, not
    computed again): every joint's axis error, the fingers' tips, every digit's tip and
    angle errors."""
    from fingerfit.evaluate.report_html import _fmt

    html = whole.report.read_text()
    body = re.sub(r"<script.*?</script>", "", html, flags=re.S)
    rows = [
        [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", r)]
        for r in re.findall(r"<tr>(.*?)</tr>", body, flags=re.S)
    ]
    tr = whole.summary["truth"]
    for j, v in tr["axis_error_deg"].items():
        c = tr["centre_to_axis_mm"][j]
        want = [j.upper(), _fmt(v["mean"]), _fmt(v["max"]), _fmt(c["mean"]), _fmt(c["max"])]
        assert want in rows, want
    assert tr["fingertip_mm"]
    for key, v in tr["fingertip_mm"].items():
        rec, _, variant = key.rpartition("/")
        want = [rec, variant.replace("_", "-") + " model", _fmt(v["mean"]), _fmt(v["p95"])]
        assert want in rows, want
    for digit, by_key in tr["tip_mm_per_digit"].items():
        for rec in {k.rpartition("/")[0] for k in by_key}:
            u, o = (by_key.get(f"{rec}/{m}", {}).get("mean") for m in ("user_axis", "orthogonal"))
            assert [digit, rec, _fmt(u), _fmt(o)] in rows, (digit, rec)
    for digit, by_joint in tr["angle_error_deg"].items():
        for j, by_variant in by_joint.items():
            name = j.upper().replace("_ABDUCTION", " ab/adduction")
            u, o = (by_variant.get(m, {}).get("mean") for m in ("user_axis", "orthogonal"))
            assert [digit, name, _fmt(u), _fmt(o)] in rows, (digit, j)


def test_viewer_json_is_made_one_subject_at_a_time_with_the_same_text() -> None:
    """The 3D view's data are written subject by subject, as ``json.dumps`` of the whole
    object would write them, with ``<`` and ``>`` escaped inside the script element."""
    import json

    from fingerfit.evaluate.report_html import _json_script

    data = {
        "S</script>": {"frame": "é, ü", "tip": [1.5, -0.25, 1e-7], "pad": None},
        "S2": {"fingers": [{"name": "index", "centres": [[0.0, 1.0, 2.0]]}]},
    }
    want = json.dumps(data).replace("<", "\\u003c").replace(">", "\\u003e")
    assert "".join(_json_script(data.items())) == want and "</script>" not in want
    assert "".join(_json_script({}.items())) == "{}"


def test_fig9_drawn_on_the_kept_figure_is_the_fresh_figure_byte_for_byte() -> None:
    import io

    import numpy as np

    from fingerfit.evaluate import figures

    def tips(seed: int, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        rng = np.random.default_rng(seed)
        ref = np.cumsum(rng.normal(0.0, 0.4, (n, 3)), axis=0) + np.array([80.0, -20.0, 10.0])
        got = {"reference": ref}
        for k, src in enumerate(("user_axis", "orthogonal")):
            got[src] = ref + rng.normal(0.0, 1.0 + 3.0 * k, (n, 3))
        got["user_axis"][5:9] = np.nan  # a gap in one line
        return np.arange(n) / (60.0 + 60.0 * seed), got

    subjects = [("S01 (index)", *tips(1, 600)), ("S02 (ring)", *tips(2, 900))]
    fresh = []
    for label, t, p in subjects:
        png = io.BytesIO()
        figures.save_to(figures.make_trajectories(t, p, label), png, tight=False)
        fresh.append(png.getvalue())
    assert fresh[0] != fresh[1]
    # Kept figure: first made, then given the other subject's data, then the first's again.
    for k in (0, 1, 0):
        label, t, p = subjects[k]
        assert figures.trajectories_png(t, p, label) == fresh[k]
