"""Statistics of the study, as the paper reports them.

Student t-tests (equal to scipy.stats' ``ttest_rel`` / ``ttest_ind``), two-factor ANOVA
with interaction (type-II table, equal to statsmodels' OLS + ``anova_lm``), mean (SD) and
% reduction — all from :class:`Moments` (count, mean, sum of squared deviations, min, max),
which merge (:func:`merge_moments`), so a study gathers them chunk by chunk.

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
    return summary_of(Moments.of(values))


def summary_of(m: Moments) -> Summary:
    """:class:`Summary` of values given by their moments."""
    return Summary(
        m.mean if m.n else float("nan"),
        float(np.sqrt(m.m2 / (m.n - 1))) if m.n > 1 else float("nan"),
        m.n,
    )


@dataclass(frozen=True)
class Moments:
    """Count, mean, sum of squared deviations from the mean, min and max of the finite
    values of a set, and how many values (finite or not) it has (``rows``).

    Enough for means, SDs, t-tests and ANOVA cells; two sets' moments merge into those
    of their union (:func:`merge_moments`), so statistics can be gathered chunk by chunk.
    """

    n: int
    mean: float
    m2: float
    min: float
    max: float
    rows: int

    @classmethod
    def of(cls, values) -> Moments:
        """The moments of an array of values (any shape; NaN and inf not counted): the
        one group of :func:`table_moments` over them."""
        table = pd.DataFrame({"v": np.asarray(values, dtype=float).ravel()})
        return moments_at(table_moments(table, [], ["v"]), "v")


MOMENT_FIELDS = ("n", "mean", "m2", "min", "max", "rows")


def table_moments(table: pd.DataFrame, keys: list[str], values: list[str]) -> pd.DataFrame:
    """:class:`Moments` of columns of ``table`` per group of rows.

    Parameters
    ----------
    table : DataFrame
    keys : list of str
        Grouping columns (groups in order of first appearance); ``[]``: one group, key 0.
    values : list of str
        Numeric columns (NaN and inf not counted).

    Returns
    -------
    DataFrame
        Index: the groups' keys; columns ``(value, field)`` with ``field`` in
        :data:`MOMENT_FIELDS`. Merge several with :func:`merge_moments`.
    """
    if keys:
        groups = table.groupby(keys, sort=False, observed=True, dropna=False)
        ids, index = groups.ngroup().to_numpy(), groups.size().index
    else:
        ids, index = np.zeros(len(table), dtype=np.intp), pd.Index([0])
    k = len(index)
    x = table[values].to_numpy(dtype=float).T  # (values, rows)
    finite = np.isfinite(x)
    x = np.where(finite, x, 0.0)
    n = np.stack([np.bincount(ids, w, k) for w in finite.astype(float)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.stack([np.bincount(ids, w, k) for w in x]) / n
    dev = np.where(finite, x - mean[:, ids], 0.0)
    m2 = np.stack([np.bincount(ids, w * w, k) for w in dev])
    lo, hi = np.full((len(values), k), np.inf), np.full((len(values), k), -np.inf)
    for v in range(len(values)):
        np.minimum.at(lo[v], ids[finite[v]], x[v, finite[v]])
        np.maximum.at(hi[v], ids[finite[v]], x[v, finite[v]])
    empty = n == 0
    lo[empty], hi[empty] = np.nan, np.nan
    rows = np.bincount(ids, minlength=k).astype(float)
    fields = {"n": n, "mean": mean, "m2": m2, "min": lo, "max": hi}
    columns = {}
    for i, v in enumerate(values):
        for f in MOMENT_FIELDS:
            columns[(v, f)] = rows if f == "rows" else fields[f][i]
    out = pd.DataFrame(columns, index=index)
    out.columns = pd.MultiIndex.from_tuples(out.columns)
    return out


def empty_moments(keys: list[str], values: list[str]) -> pd.DataFrame:
    """A moments table (:func:`table_moments`) without groups."""
    columns = pd.MultiIndex.from_tuples([(v, f) for v in values for f in MOMENT_FIELDS])
    if len(keys) > 1:
        index = pd.MultiIndex.from_tuples([], names=keys)
    else:
        index = pd.Index([], name=keys[0] if keys else None)
    return pd.DataFrame(index=index, columns=columns, dtype=float)


def merge_moments(m: pd.DataFrame, levels: list[str] | None = None) -> pd.DataFrame:
    """Merge rows of a moments table (:func:`table_moments`) into the moments of their union.

    Parameters
    ----------
    m : DataFrame
        Moments, e.g. the tables of several chunks concatenated.
    levels : list of str, optional
        Index levels that name the merged groups (order of first appearance); default
        all of them (the same key in several chunks). ``[]``: everything, key 0.

    Returns
    -------
    DataFrame
        The same columns, one row per merged group (Chan, Golub and LeVeque's pairwise
        update: ``m2 = sum(m2_i + n_i (mean_i - mean)^2)``).
    """
    if levels is None:
        levels = list(m.index.names)
    by = [m.index.get_level_values(k) for k in levels] if levels else np.zeros(len(m), int)
    out = {}
    for v in dict.fromkeys(c[0] for c in m.columns):
        n, mean = m[(v, "n")].astype(float), m[(v, "mean")]
        weighted = (n * mean).where(n > 0, 0.0)
        total = n.groupby(by, sort=False).transform("sum")
        grand = weighted.groupby(by, sort=False).transform("sum") / total.where(total > 0)
        dev = (n * (mean - grand) ** 2).where(n > 0, 0.0)
        g = lambda s: s.groupby(by, sort=False)  # noqa: E731
        merged = {
            "n": g(n).sum(),
            "mean": g(grand).first(),
            "m2": g(m[(v, "m2")] + dev).sum(),
            "min": g(m[(v, "min")]).min(),
            "max": g(m[(v, "max")]).max(),
            "rows": g(m[(v, "rows")]).sum(),
        }
        for f, col in merged.items():
            out[(v, f)] = col
    result = pd.DataFrame(out)
    result.columns = pd.MultiIndex.from_tuples(result.columns)
    if levels:
        result.index.names = levels
    return result


def moments_at(m: pd.DataFrame, value: str, key=None) -> Moments:
    """The :class:`Moments` of column ``value`` of one row of a moments table (``key``:
    its index; default the only row). A missing key: the moments of no values."""
    if key is None:
        pos = 0 if len(m) == 1 else None
    else:
        try:
            pos = m.index.get_loc(key)
        except KeyError:
            pos = None
    if pos is None:
        return Moments(0, float("nan"), 0.0, float("nan"), float("nan"), 0)
    first = m.columns.get_loc((value, MOMENT_FIELDS[0]))  # the fields side by side
    n, mean, m2, lo, hi, rows = m.to_numpy(dtype=float)[pos, first : first + len(MOMENT_FIELDS)]
    nan = float("nan")
    return Moments(int(n), float(mean) if n else nan, float(m2), float(lo), float(hi), int(rows))


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


def _two_sided(t: float, df: float) -> float:
    return float(2 * stats.t.sf(abs(t), df))


def paired_ttest_of(d: Moments) -> TTest | Skipped:
    """Paired two-sided t-test from the moments of the differences ``a - b``, or why not
    (fewer than 2 pairs; all differences equal)."""
    if d.n < 2:
        return Skipped(f"needs at least 2 pairs, has {d.n}")
    if d.max == d.min:
        return Skipped("all differences are equal, so t is undefined")
    t = d.mean / np.sqrt(d.m2 / (d.n - 1) / d.n)
    return TTest(float(t), _two_sided(t, d.n - 1), float(d.n - 1), "paired")


def independent_ttest_of(a: Moments, b: Moments) -> TTest | Skipped:
    """Student's two-sample two-sided t-test (equal variances, as the paper) from the two
    groups' moments, or why not (fewer than 2 values per group; no spread in either)."""
    if min(a.n, b.n) < 2:
        return Skipped(f"needs at least 2 values per group, has {a.n} and {b.n}")
    if a.max == a.min and b.max == b.min:
        return Skipped("no spread within either group, so t is undefined")
    df = a.n + b.n - 2
    t = (a.mean - b.mean) / np.sqrt((a.m2 + b.m2) / df * (1 / a.n + 1 / b.n))
    return TTest(float(t), _two_sided(t, df), float(df), "independent")


def _pairs(a, b) -> np.ndarray:
    """``a - b`` where both are finite, shape ``(n,)``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    return a[ok] - b[ok]


def paired_ttest_or_skip(a, b) -> TTest | Skipped:
    """Paired two-sided t-test of ``a - b`` over the pairs where both values are finite,
    or why not (:func:`paired_ttest_of`).

    Parameters
    ----------
    a, b : array_like, shape (n,)
        Paired values (e.g. user-axis and orthogonal error of one cycle, mm).
    """
    return paired_ttest_of(Moments.of(_pairs(a, b)))


def paired_ttest(a, b) -> TTest:
    """:func:`paired_ttest_or_skip` for data that supports it (else FingerfitError)."""
    return _or_raise(paired_ttest_or_skip(a, b))


def independent_ttest_or_skip(a, b) -> TTest | Skipped:
    """Student's two-sample t-test over the finite values, or why not
    (:func:`independent_ttest_of`)."""
    return independent_ttest_of(Moments.of(a), Moments.of(b))


def independent_ttest(a, b) -> TTest:
    """:func:`independent_ttest_or_skip` for data that supports it (else FingerfitError)."""
    return _or_raise(independent_ttest_or_skip(a, b))


def _or_raise(result: TTest | Skipped) -> TTest:
    if isinstance(result, Skipped):
        raise FingerfitError(f"t-test not computed: {result.reason}")
    return result


def two_way_anova_or_skip(data: pd.DataFrame, value: str, a: str, b: str) -> pd.DataFrame | Skipped:
    """:func:`two_way_anova` over the rows with a finite ``value``, or why not
    (:func:`two_way_anova_of_cells`)."""
    return two_way_anova_of_cells(table_moments(data, [a, b], [value]), value, a, b)


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
    result = two_way_anova_or_skip(data, value, a, b)
    if isinstance(result, Skipped):
        raise FingerfitError(f"the {a} x {b} ANOVA is not computed: {result.reason}")
    return result


def two_way_anova_of_cells(
    cells: pd.DataFrame, value: str, a: str, b: str
) -> pd.DataFrame | Skipped:
    """:func:`two_way_anova` from the moments of ``value`` in each cell, or why not.

    Parameters
    ----------
    cells : DataFrame
        Moments (:func:`table_moments` by ``[a, b]``, possibly several chunks' merged by
        :func:`merge_moments`); index levels: the levels of ``a`` and ``b``.
    value, a, b : str
        The value's and the factors' names.

    Returns
    -------
    DataFrame or Skipped
        The ANOVA table; skipped when a factor has fewer than two levels, a combination
        of levels has no observation, or no cell has a replicate (no residual degrees
        of freedom).
    """
    cells = cells[cells[(value, "n")] > 0]
    codes_a, levels_a = pd.factorize(cells.index.get_level_values(0), sort=True)
    codes_b, levels_b = pd.factorize(cells.index.get_level_values(1), sort=True)
    na, nb = len(levels_a), len(levels_b)
    for f, k in ((a, na), (b, nb)):
        if k < 2:
            return Skipped(f"needs at least 2 levels of {f}, has {k}")
    if len(cells) < na * nb:
        return Skipped(f"{na * nb - len(cells)} of the {na * nb} {a} x {b} cells are empty")
    cell = codes_a * nb + codes_b
    count = np.zeros(na * nb)
    count[cell] = cells[(value, "n")].to_numpy(dtype=float)
    n = int(count.sum())
    if n <= na * nb:
        return Skipped(f"no repeated observations within the {a} x {b} cells")
    mean = np.zeros(na * nb)
    mean[cell] = cells[(value, "mean")].to_numpy(dtype=float)
    mean = (mean - count @ mean / n).reshape(na, nb)  # centred: sums of squares stay small
    count = count.reshape(na, nb)
    within = float(cells[(value, "m2")].sum())  # residual of the full model
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
