"""Statistics of the study, as the paper reports them.

Student t-tests (scipy.stats), two-factor ANOVA with interaction (type-II table from
the cells' sufficient statistics, equal to statsmodels' OLS + ``anova_lm``), mean (SD)
and % reduction.

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
    """Two-factor ANOVA with interaction, ``value ~ C(a) * C(b)``, type-II sums of squares.

    Computed from the cells' counts, sums and within-cell sums of squares (sufficient
    statistics), so memory is O(rows + cells), not the O(rows x cells) design matrix of
    an OLS fit: a study's subject factor has one level per subject. The factor with
    more levels is absorbed (Frisch-Waugh-Lovell) and the other's effect solved with a
    (levels - 1)-square system. Equal to statsmodels' ``anova_lm(ols("y ~ C(a) * C(b)"),
    typ=2)`` (tests: to 1e-9, balanced and unbalanced).

    Parameters
    ----------
    data : DataFrame
        ``n`` rows; ``value`` finite floats, ``a`` and ``b`` the two factors' levels.
        Every combination of levels must occur (:func:`two_way_anova_or_skip` checks
        this) and some cell must hold more than one row.
    value, a, b : str
        Column names.

    Returns
    -------
    DataFrame
        Rows ``C(a)``, ``C(b)``, ``C(a):C(b)``, ``Residual``; columns ``sum_sq`` (units of
        ``value`` squared), ``df``, ``F``, ``PR(>F)`` (NaN F and p on ``Residual``).
        ``SS(A) = SS(A | B)``, ``SS(B) = SS(B | A)``, ``SS(AB) = SS(AB | A, B)``.

    Raises
    ------
    FingerfitError
        An empty cell or no residual degrees of freedom.
    """
    y = data[value].to_numpy(dtype=float)
    y = y - y.mean()  # sums of squares do not change; sums stay small
    codes_a, levels_a = pd.factorize(data[a], sort=True)
    codes_b, levels_b = pd.factorize(data[b], sort=True)
    na, nb, n = len(levels_a), len(levels_b), len(y)
    cell = codes_a * nb + codes_b
    count = np.bincount(cell, minlength=na * nb).astype(float)
    if (count == 0).any() or n <= na * nb:
        raise FingerfitError(
            f"the {a} x {b} ANOVA needs every cell filled and a repeated observation"
        )
    mean = (np.bincount(cell, weights=y, minlength=na * nb) / count).reshape(na, nb)
    count = count.reshape(na, nb)
    within = float(np.sum((y - mean.ravel()[cell]) ** 2))  # residual of the full model
    n_a, n_b = count.sum(axis=1), count.sum(axis=0)
    mean_a = (count * mean).sum(axis=1) / n_a
    mean_b = (count * mean).sum(axis=0) / n_b
    # Between cells, within the levels of b (a's and the interaction's share) and of a.
    within_b = float(np.sum(count * (mean - mean_b) ** 2))
    within_a = float(np.sum(count * (mean - mean_a[:, None]) ** 2))

    def given_other(cnt: np.ndarray, dev: np.ndarray, n_other: np.ndarray) -> float:
        """SS of the factor along axis 0 after absorbing the factor along axis 1.

        ``cnt``, ``dev``: counts and cell-mean deviations from the absorbed level's mean,
        ``(k, m)``; the k dummies, centred within each absorbed level, regressed."""
        c = (cnt * dev).sum(axis=1)[:-1]  # one level dropped: the centred dummies sum to 0
        m = np.diag(cnt.sum(axis=1)) - (cnt / n_other) @ cnt.T
        return float(c @ np.linalg.solve(m[:-1, :-1], c))

    if na <= nb:
        ss_a = given_other(count, mean - mean_b, n_b)
        ss_ab = within_b - ss_a
        ss_b = within_a - within_b + ss_a
    else:
        ss_b = given_other(count.T, (mean - mean_a[:, None]).T, n_a)
        ss_ab = within_a - ss_b
        ss_a = within_b - within_a + ss_b
    df = np.array([na - 1, nb - 1, (na - 1) * (nb - 1), n - na * nb], dtype=float)
    ss = np.array([ss_a, ss_b, ss_ab, within])
    with np.errstate(divide="ignore", invalid="ignore"):  # exact data: no residual, F inf
        f = (ss[:3] / df[:3]) / (within / df[3])
    table = pd.DataFrame(
        {
            "sum_sq": ss,
            "df": df,
            "F": [*f, np.nan],
            "PR(>F)": [*stats.f.sf(f, df[:3], df[3]), np.nan],
        },
        index=[f"C({a})", f"C({b})", f"C({a}):C({b})", "Residual"],
    )
    return table
