"""Statistics of the study, as the paper reports them.

Student t-tests (scipy.stats), two-factor ANOVA with interaction
(statsmodels OLS + type-II ANOVA table), mean (SD) and % reduction.

A statistic the data cannot support (a t-test with fewer than two values, an
ANOVA with one level of a factor or no replicates in its cells) is not computed:
the ``*_or_skip`` functions return :class:`Skipped` with the reason instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from ..errors import FingerfitError


@dataclass(frozen=True)
class Summary:
    """Mean and sample SD (ddof = 1) of a set of errors (mm)."""

    mean: float
    sd: float
    n: int

    def __str__(self) -> str:
        return f"{self.mean:.1f} ({self.sd:.1f})"


def summarize(values) -> Summary:
    """Mean, sample SD and count of the finite values (NaN mean with none, NaN SD with one)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return Summary(
        float(v.mean()) if v.size else float("nan"),
        float(v.std(ddof=1)) if v.size > 1 else float("nan"),
        int(v.size),
    )


def reduction_percent(new: float, old: float) -> float:
    """How much ``new`` is below ``old``, in % of ``old`` (positive = smaller).

    NaN when ``old`` is zero or either value is not finite.
    """
    if not (np.isfinite(new) and np.isfinite(old)) or old == 0:
        return float("nan")
    return 100.0 * (old - new) / old


@dataclass(frozen=True)
class Skipped:
    """A statistic that was not computed, and why (one line, for the report and summary)."""

    reason: str

    def as_dict(self) -> dict:
        """``{"skipped": reason}``, the form stored in ``summary.json``."""
        return {"skipped": self.reason}


@dataclass(frozen=True)
class TTest:
    """A t-test result: statistic, two-sided p-value, degrees of freedom."""

    t: float
    p: float
    df: float
    kind: str


def paired_ttest(a, b) -> TTest:
    """Paired two-sided t-test of ``a - b`` (same subjects/cycles)."""
    res = stats.ttest_rel(np.asarray(a, float), np.asarray(b, float))
    return TTest(float(res.statistic), float(res.pvalue), float(len(a) - 1), "paired")


def independent_ttest(a, b) -> TTest:
    """Student's two-sample two-sided t-test (equal variances, as the paper)."""
    res = stats.ttest_ind(np.asarray(a, float), np.asarray(b, float))
    return TTest(float(res.statistic), float(res.pvalue), float(len(a) + len(b) - 2), "independent")


def _finite(values) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    return v[np.isfinite(v)]


def paired_ttest_or_skip(a, b) -> TTest | Skipped:
    """:func:`paired_ttest` over the pairs where both values are finite, or why not.

    Parameters
    ----------
    a, b : array_like, shape (n,)
        Paired values (e.g. user-axis and orthogonal error of one cycle, mm).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    n = int(ok.sum())
    if n < 2:
        return Skipped(f"needs at least 2 pairs, has {n}")
    d = a[ok] - b[ok]
    if np.ptp(d) == 0:
        return Skipped("all differences are equal, so t is undefined")
    return paired_ttest(a[ok], b[ok])


def independent_ttest_or_skip(a, b) -> TTest | Skipped:
    """:func:`independent_ttest` over the finite values, or why not (fewer than 2 per group)."""
    a, b = _finite(a), _finite(b)
    if min(a.size, b.size) < 2:
        return Skipped(f"needs at least 2 values per group, has {a.size} and {b.size}")
    if np.ptp(a) == 0 and np.ptp(b) == 0:
        return Skipped("no spread within either group, so t is undefined")
    return independent_ttest(a, b)


def two_way_anova_or_skip(data: pd.DataFrame, value: str, a: str, b: str) -> pd.DataFrame | Skipped:
    """:func:`two_way_anova` over the rows with a finite ``value``, or why not.

    Skipped when a factor has fewer than two levels, a combination of levels has no
    observation, or no cell has a replicate (no residual degrees of freedom).
    """
    df = data[[value, a, b]]
    df = df[np.isfinite(df[value].to_numpy(dtype=float))].astype({value: float})
    for f in (a, b):
        n = df[f].nunique()
        if n < 2:
            return Skipped(f"needs at least 2 levels of {f}, has {n}")
    cells = df.groupby([a, b]).size()
    n_cells = df[a].nunique() * df[b].nunique()
    if len(cells) < n_cells:
        return Skipped(f"{n_cells - len(cells)} of the {n_cells} {a} x {b} cells are empty")
    if len(df) <= n_cells:
        return Skipped(f"no repeated observations within the {a} x {b} cells")
    return two_way_anova(df, value, a, b)


def two_way_anova(data: pd.DataFrame, value: str, a: str, b: str) -> pd.DataFrame:
    """Two-factor ANOVA with interaction: ``value ~ C(a) * C(b)``.

    Returns
    -------
    DataFrame
        Rows ``C(a)``, ``C(b)``, ``C(a):C(b)``, ``Residual``; columns ``sum_sq``,
        ``df``, ``F``, ``PR(>F)`` (statsmodels type-II table).
    """
    try:
        import statsmodels.formula.api as smf
        from statsmodels.stats.anova import anova_lm
    except ImportError as exc:  # pragma: no cover - depends on the installed extras
        raise FingerfitError(
            "the study's ANOVA needs statsmodels: pip install 'fingerfit[stats]'"
        ) from exc
    df = data[[value, a, b]].rename(columns={value: "y", a: "fa", b: "fb"})
    fit = smf.ols("y ~ C(fa) * C(fb)", data=df).fit()
    table = anova_lm(fit, typ=2)
    return table.rename(index=lambda s: s.replace("fa", a).replace("fb", b))
