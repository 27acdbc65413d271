"""The study's statistics, gathered chunk by chunk, against scipy/statsmodels on whole tables.

Three realistic whole-hand subjects (thumb, index, middle: targets, pinches, ground truth).
"""

from __future__ import annotations

from unittest import mock

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from fingerfit.digits import FINGERS
from fingerfit.estimate import FitOptions
from fingerfit.evaluate.gather import StudyTables, study_tables
from fingerfit.evaluate.subject import evaluate_subject
from fingerfit.evaluate.summary import summarize_study
from fingerfit.io.sessiondir import load_session
from fingerfit.simulate import write_subject

from .conftest import subject

HAND = ("thumb", "index", "middle")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    root = tmp_path_factory.mktemp("summary")
    out = []
    for i, seed in enumerate((2, 3, 4)):
        folder = write_subject(subject("realistic", seed, HAND), root / f"W{i}")
        toml = folder / "session.toml"
        toml.write_text(toml.read_text().replace('subject = "S01"', f'subject = "W{i}"'))
        with np.errstate(all="ignore"):
            out.append(evaluate_subject(load_session(folder), FitOptions()))
    return out


def _numbers(node, where=""):
    """Every number of a summary with its dotted key (``created`` left out)."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k != "created":
                yield from _numbers(v, f"{where}.{k}")
    elif isinstance(node, list | tuple):
        for i, v in enumerate(node):
            yield from _numbers(v, f"{where}[{i}]")
    else:
        yield where, node


def test_statistics_do_not_depend_on_the_chunks(results) -> None:
    whole, _ = summarize_study(results, FitOptions())  # one chunk
    tables = StudyTables(chunk=1)  # a chunk per subject, arriving in another order
    for i in (2, 0, 1):
        tables.add(i, results[i])
    chunked, _ = summarize_study(results, FitOptions(), tables=tables.finish(range(3)))
    a, b = dict(_numbers(whole)), dict(_numbers(chunked))
    assert list(a) == list(b)  # the same statistics, keys in the same order
    for key, v in a.items():
        if isinstance(v, float):
            assert b[key] == pytest.approx(v, rel=1e-11, nan_ok=True), key
        else:
            assert b[key] == v, key
    assert len(a) > 500


def _pairs(wide: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    ok = wide[["user_axis", "orthogonal"]].notna().all(axis=1)
    return wide.loc[ok, "user_axis"].to_numpy(), wide.loc[ok, "orthogonal"].to_numpy()


def _check_t(got: dict, ref) -> None:
    assert got["t"] == pytest.approx(ref.statistic, rel=1e-10)
    assert got["p"] == pytest.approx(ref.pvalue, rel=1e-8)


def test_statistics_are_scipys_on_the_whole_tables(results) -> None:
    sm, tables = summarize_study(results, FitOptions())
    # Maximal flexion, the four fingers: headline, paired t-test, model x subject ANOVA.
    flex = tables["max_flexion"]
    flex = flex[flex["finger"].isin(FINGERS)].astype({"subject": str})
    mf = sm["max_flexion"]
    assert mf["user_axis"]["mean_mm"] == pytest.approx(flex["user_axis"].mean(), rel=1e-12)
    assert mf["orthogonal"]["sd_mm"] == pytest.approx(flex["orthogonal"].std(), rel=1e-12)
    _check_t(mf["paired_t_test"], stats.ttest_rel(*_pairs(flex)))
    s1 = flex[flex["subject"] == "W1"]
    _check_t(mf["per_subject"]["W1"]["paired_t_test"], stats.ttest_rel(*_pairs(s1)))
    smf = pytest.importorskip("statsmodels.formula.api")
    from statsmodels.stats.anova import anova_lm

    long = flex.melt(["subject"], ["user_axis", "orthogonal"], var_name="model", value_name="y")
    ref = anova_lm(smf.ols("y ~ C(model) * C(subject)", data=long).fit(), typ=2)
    got = mf["anova_model_x_subject"]
    for row in ("C(model)", "C(subject)", "C(model):C(subject)"):
        assert got[row]["F"] == pytest.approx(ref.loc[row, "F"], rel=1e-9), row
    # Axis quality: Student's t between joints.
    dist = tables["axis_quality"]
    ref = stats.ttest_ind(
        *(dist.loc[dist["joint"] == j, "distance_mm"].dropna() for j in ("dip", "pip"))
    )
    _check_t(sm["axis_quality"]["t_tests"]["dip_vs_pip"], ref)
    # Targets: one row per subject, digit and target (the mean of its touches).
    wide = tables["targets"].pivot_table(
        index=["subject", "finger", "target"], columns="source", values="error_mm", observed=True
    )
    tg = sm["targets"]
    _check_t(tg["paired_t_test"], stats.ttest_rel(*_pairs(wide)))
    assert tg["reference"]["mean_mm"] == pytest.approx(wide["reference"].mean(), rel=1e-12)
    per_target = wide.reset_index().groupby("target", observed=True).size()
    assert {t: v["n"] for t, v in tg["per_target"].items()} == per_target.to_dict()
    # The thumb's tip against truth: per recording, one mean per subject.
    tt = tables["truth_fingertip"]
    tt = tt[tt["finger"] == "thumb"].astype({"recording": str})
    recordings = list(dict.fromkeys(tt["recording"]))
    assert list(sm["thumb"]["truth_tip"]) == recordings  # order of appearance
    r = recordings[-1]
    w = tt[tt["recording"] == r].pivot_table(
        index="subject", columns="variant", values="mean_mm", observed=True
    )
    h = sm["thumb"]["truth_tip"][r]
    _check_t(h["paired_t_test"], stats.ttest_rel(*_pairs(w)))
    ratio = w["user_axis"].mean() / w["orthogonal"].mean()
    assert h["orthogonal_ratio"] == pytest.approx(ratio, rel=1e-12)
    # Pinches: one row per event, the mean of its digits' rows.
    pin = tables["pinch"]
    w = pin.pivot_table(
        index=["subject", "recording", "target", "start"],
        columns="source",
        values="tip_distance_error_mm",
        observed=True,
    )
    _check_t(sm["pinch"]["paired_t_test"], stats.ttest_rel(*_pairs(w)))
    for src, g in pin.groupby("source", observed=True):
        got = sm["pinch"]["per_source"][str(src)]["pad_gap"]
        assert got["mean_mm"] == pytest.approx(g["pad_gap_mm"].mean(), rel=1e-12, nan_ok=True)
    # Truth: per joint, mean and max over every digit.
    ta = tables["truth_axes"]
    g = ta[ta["joint"] == "pip"]["axis_error_deg"]
    assert sm["truth"]["axis_error_deg"]["pip"]["mean"] == pytest.approx(g.mean(), rel=1e-12)
    assert sm["truth"]["axis_error_deg"]["pip"]["max"] == g.max()


def test_statistics_never_make_a_whole_table(results) -> None:
    """Every statistic reads the tables chunk by chunk: the study process never holds a
    whole table for them (a thousand subjects' tables are tens of MB as DataFrames)."""
    tables = study_tables(results)
    made = AssertionError("a whole table was made")
    with mock.patch.object(StudyTables, "__getitem__", side_effect=made):
        summary, _ = summarize_study(results, FitOptions(), tables=tables)
        assert {"truth_axes", "pinch", "thumb_geometry"} <= set(tables)
    assert {"truth", "thumb", "pinch", "targets"} <= set(summary)
