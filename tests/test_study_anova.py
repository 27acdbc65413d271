"""The study's two-way ANOVA from sufficient statistics: statsmodels' type-II table, small memory."""

from __future__ import annotations

import itertools
import tracemalloc

import numpy as np
import pandas as pd
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.evaluate.stats import (
    independent_ttest_or_skip,
    merge_moments,
    moments_at,
    paired_ttest_or_skip,
    table_moments,
    two_way_anova,
    two_way_anova_or_skip,
)


def _statsmodels_anova(data: pd.DataFrame, value: str, a: str, b: str) -> pd.DataFrame:
    """The reference: OLS on the full dummy design and statsmodels' type-II table."""
    smf = pytest.importorskip("statsmodels.formula.api")
    from statsmodels.stats.anova import anova_lm

    df = data[[value, a, b]].rename(columns={value: "y", a: "fa", b: "fb"})
    table = anova_lm(smf.ols("y ~ C(fa) * C(fb)", data=df).fit(), typ=2)
    return table.rename(index=lambda s: s.replace("fa", a).replace("fb", b))


def _design(rng: np.random.Generator, na: int, nb: int, balanced: bool) -> pd.DataFrame:
    """Cells with 1-5 replicates (or 3 each), main effects, an interaction and noise (mm)."""
    rows = []
    for i in range(na):
        for j in range(nb):
            reps = 3 if balanced else int(rng.integers(1, 6))
            for _ in range(reps):
                mean = 4.0 + 0.8 * i + 0.1 * j + 0.3 * ((i * j) % 3)
                rows.append((f"m{i}", f"S{j:03d}", rng.normal(mean, 1.0)))
    return pd.DataFrame(rows, columns=["model", "subject", "error"])


@pytest.mark.parametrize(
    ("na", "nb", "balanced"),
    [(2, 2, True), (2, 17, False), (2, 40, True), (3, 9, False), (12, 2, False), (5, 4, False)],
)
def test_equals_statsmodels_type_ii(na: int, nb: int, balanced: bool) -> None:
    data = _design(np.random.default_rng(na * 100 + nb), na, nb, balanced)
    ours = two_way_anova(data, "error", "model", "subject")
    ref = _statsmodels_anova(data, "error", "model", "subject")
    assert list(ours.index) == list(ref.index)
    assert list(ours.columns) == list(ref.columns)
    np.testing.assert_allclose(ours.to_numpy(), ref.to_numpy(), rtol=1e-9, atol=0)
    assert np.isfinite(ours["F"].iloc[:3]).all() and (ours["sum_sq"] > 0).all()


def test_by_hand_unbalanced_two_by_two() -> None:
    # Cells (a1,b1) = [1, 3], (a1,b2) = [5], (a2,b1) = [2], (a2,b2) = [10, 12]: SS_E = 2 + 2 = 4.
    # Additive fit (type II) by hand: with d = a2 - a1 and the b effect absorbed, the
    # weights are n_a1b * n_a2b / n_b = 2/3 in both b levels, contrasts 2-2 = 0 and 11-5 = 6,
    # so SS(a | b) = (2/3 * 0 + 2/3 * 6)^2 / (2/3 + 2/3) = 12; likewise within a1 and a2 the
    # b contrasts are 5-2 = 3 and 11-2 = 9 with weights 2/3, so SS(b | a) = 8^2 / (4/3) = 48.
    data = pd.DataFrame(
        {
            "y": [1.0, 3.0, 5.0, 2.0, 10.0, 12.0],
            "a": ["a1", "a1", "a1", "a2", "a2", "a2"],
            "b": ["b1", "b1", "b2", "b1", "b2", "b2"],
        }
    )
    table = two_way_anova(data, "y", "a", "b")
    assert table.loc["C(a)", "sum_sq"] == pytest.approx(12.0, rel=1e-12)
    assert table.loc["C(b)", "sum_sq"] == pytest.approx(48.0, rel=1e-12)
    assert table.loc["Residual", "sum_sq"] == pytest.approx(4.0, rel=1e-12)
    assert table.loc["Residual", "df"] == 2.0
    assert table.loc["C(a)", "F"] == pytest.approx(12.0 / (4.0 / 2.0), rel=1e-12)


def test_memory_does_not_hold_a_design_matrix() -> None:
    """A 1000-subject model x subject ANOVA (2 x 1000 cells, 40 rows per cell, 80,000 rows):
    the OLS design would be 80,000 x 2,000 floats (1.3 GB); here a few arrays of n."""
    rng = np.random.default_rng(7)
    n_subjects, reps = 1000, 40
    subject = np.repeat([f"S{j:04d}" for j in range(n_subjects)], 2 * reps)
    model = np.tile(np.repeat(["orthogonal", "user_axis"], reps), n_subjects)
    data = pd.DataFrame(
        {"error": rng.normal(3.0, 1.0, subject.size), "model": model, "subject": subject}
    )
    tracemalloc.start()
    try:
        table = two_way_anova_or_skip(data, "error", "model", "subject")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert isinstance(table, pd.DataFrame)
    assert table.loc["Residual", "df"] == subject.size - 2 * n_subjects
    assert peak < 40e6, peak  # measured: 5.5 MB (statsmodels: the 1.3 GB design and more)


def test_empty_cell_is_refused_not_solved() -> None:
    data = pd.DataFrame(
        {"y": [1.0, 2.0, 3.0, 4.0], "a": ["x", "x", "y", "y"], "b": ["p", "q", "p", "p"]}
    )
    with pytest.raises(
        FingerfitError, match="ANOVA is not computed: 1 of the 4 a x b cells are empty"
    ):
        two_way_anova(data, "y", "a", "b")
    assert "cells are empty" in two_way_anova_or_skip(data, "y", "a", "b").reason


def _values(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(3.0, 2.0, n)
    v[rng.random(n) < 0.1] = np.nan
    v[rng.random(n) < 0.03] = np.inf  # not counted either
    return v


def test_moments_of_chunks_merge_to_the_moments_of_the_whole() -> None:
    rng = np.random.default_rng(7)
    n = 400
    table = pd.DataFrame(
        {
            "g": rng.choice(["c", "a", "b", "d"], n, p=[0.5, 0.3, 0.19, 0.01]),
            "x": _values(rng, n),
            "y": _values(rng, n) * 1e3 + 1e6,  # a large offset: the merge must not lose it
        }
    )
    whole = table_moments(table, ["g"], ["x", "y"])
    cuts = np.sort(rng.choice(np.arange(1, n), 9, replace=False))
    bounds = [0, *cuts, n]
    parts = [
        table_moments(table.iloc[i:j], ["g"], ["x", "y"]) for i, j in itertools.pairwise(bounds)
    ]
    merged = merge_moments(pd.concat(parts))
    assert list(merged.index) == list(dict.fromkeys(table["g"]))  # order of first appearance
    pd.testing.assert_frame_equal(merged, whole.loc[merged.index], rtol=1e-12, check_dtype=False)
    for g, rows in table.groupby("g"):  # against the definition
        for v in ("x", "y"):
            m, finite = moments_at(merged, v, g), rows[v][np.isfinite(rows[v])]
            assert (m.n, m.rows) == (len(finite), len(rows))
            assert m.mean == pytest.approx(finite.mean(), rel=1e-13)
            assert m.m2 == pytest.approx(((finite - finite.mean()) ** 2).sum(), rel=1e-9)
            assert (m.min, m.max) == (finite.min(), finite.max())
    everything = moments_at(merge_moments(merged, levels=[]), "x")
    assert everything.n == np.isfinite(table["x"]).sum()
    assert moments_at(merged, "x", "absent").n == 0


def test_t_tests_from_moments_are_scipys() -> None:
    from scipy import stats

    rng = np.random.default_rng(8)
    a, b = _values(rng, 60), _values(rng, 60) + 0.4
    ok = np.isfinite(a) & np.isfinite(b)
    ours, ref = paired_ttest_or_skip(a, b), stats.ttest_rel(a[ok], b[ok])
    assert (ours.t, ours.p, ours.df) == pytest.approx((ref.statistic, ref.pvalue, ok.sum() - 1))
    ours = independent_ttest_or_skip(a, b)
    ref = stats.ttest_ind(a[np.isfinite(a)], b[np.isfinite(b)])
    assert (ours.t, ours.p) == pytest.approx((ref.statistic, ref.pvalue), rel=1e-12)
    assert paired_ttest_or_skip([1.0, 2.0], [0.0, 1.0]).reason.startswith("all differences")
    assert independent_ttest_or_skip([1.0], [2.0, 3.0]).reason.endswith("has 1 and 2")
