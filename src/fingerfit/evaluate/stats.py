"""Statistics of the study, as the paper reports them.

Student t-tests (scipy.stats), two-factor ANOVA with interaction
(statsmodels OLS + type-II ANOVA table), mean (SD) and % reduction.
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
    """Mean, sample SD and count of finite values."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return Summary(
        float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else float("nan"), int(v.size)
    )


def reduction_percent(new: float, old: float) -> float:
    """How much ``new`` is below ``old``, in % of ``old`` (positive = smaller)."""
    return 100.0 * (old - new) / old


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
