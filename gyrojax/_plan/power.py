r"""Power of a chi-squared test against a noncentral alternative, in plain NumPy.

A test statistic that is chi2(df) under the null is, when an effect leaves a noncentrality lambda (its
expected chi2 after the nuisance parameters took what they could), noncentral chi2(df, lambda):

    P(X > x) = sum_j Pois(j; lambda / 2) Q(df / 2 + j, x / 2)

with Q the regularised upper incomplete gamma function. For integer df, Q is exact from
Q(1/2, y) = erfc(sqrt(y)) or Q(1, y) = exp(-y) and the upward recurrence
Q(a + 1, y) = Q(a, y) + y^a exp(-y) / Gamma(a + 1) (a sum of positive terms: stable). The power at level
alpha is P(X > c) with c the (1 - alpha) quantile of chi2(df).
"""

import functools
import math

import numpy as np


def _check_df(df) -> int:
    if isinstance(df, bool) or not float(df).is_integer() or df < 1:
        raise ValueError(f"df must be an integer >= 1, got {df!r}.")
    return int(df)


def _upper_gamma(df: int, y: float, count: int) -> np.ndarray:
    """Q(df/2 + j, y) for j = 0 .. count - 1 (integer df)."""
    base = 0.5 if df % 2 else 1.0
    first = math.erfc(math.sqrt(y)) if df % 2 else math.exp(-y)
    n = (df - 1) // 2 + count  # recurrence steps from `base` to the last a needed
    a = base + np.arange(n, dtype=float)
    if y > 0:
        terms = np.exp(a * math.log(y) - y - np.array([math.lgamma(v + 1.0) for v in a]))
    else:
        terms = np.zeros(n)
    q = first + np.concatenate([[0.0], np.cumsum(terms)])
    return np.minimum(q[(df - 1) // 2:(df - 1) // 2 + count], 1.0)


def chi2_sf(x: float, df: int) -> float:
    """Survival function of the chi-squared distribution with integer `df`."""
    df = _check_df(df)
    return float(_upper_gamma(df, max(float(x), 0.0) / 2.0, 1)[0])


def ncx2_sf(x: float, df: int, nc: float) -> float:
    """Survival function of the noncentral chi-squared distribution (integer `df` >= 1, noncentrality `nc` >= 0):
    the Poisson mixture of central chi-squared survival functions over the Poisson weights' bulk (mean +/- 12
    standard deviations; the rest is below 1e-30)."""
    df = _check_df(df)
    if not nc >= 0:
        raise ValueError(f"ncx2_sf: the noncentrality must be >= 0, got {nc!r}.")
    x = max(float(x), 0.0)
    m = 0.5 * float(nc)
    if m == 0.0:
        return chi2_sf(x, df)
    if m > 1e6 and x < m:  # the mean df + nc is more than ~700 standard deviations above x
        return 1.0
    width = 12.0 * math.sqrt(m) + 12.0
    j0, j1 = max(0, int(m - width)), int(m + width) + 1
    q = _upper_gamma(df, 0.5 * x, j1)[j0:]
    j = np.arange(j0, j1, dtype=float)
    log_w = -m + j * math.log(m) - np.array([math.lgamma(k + 1.0) for k in j])
    return float(min(np.sum(np.exp(log_w) * q), 1.0))


@functools.lru_cache(maxsize=256)
def chi2_isf(alpha: float, df: int) -> float:
    """The (1 - `alpha`) quantile of chi2(`df`) (bisection)."""
    lo, hi = 0.0, max(10.0 * df, 100.0)
    while chi2_sf(hi, df) > alpha:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_sf(mid, df) > alpha else (lo, mid)
        if hi - lo < 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


def power(nc: float, df: int, alpha: float = 0.01) -> float:
    """Probability that a chi2(`df`) test at level `alpha` rejects when the effect leaves noncentrality
    `nc` (its expected chi2)."""
    df = _check_df(df)
    return ncx2_sf(chi2_isf(float(alpha), df), df, max(float(nc), 0.0))


def required_noncentrality(df: int, target: float = 0.9, alpha: float = 0.01) -> float:
    """The smallest noncentrality at which a chi2(`df`) test at level `alpha` has power `target`
    (bisection; power rises monotonically with the noncentrality)."""
    df = _check_df(df)
    if not 0.0 < target < 1.0:
        raise ValueError(f"the target power must be in (0, 1), got {target!r}.")
    c = chi2_isf(float(alpha), df)
    lo, hi = 0.0, 10.0 + 4.0 * df
    while ncx2_sf(c, df, hi) < target:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ncx2_sf(c, df, mid) < target else (lo, mid)
        if hi - lo < 1e-9 * hi:
            break
    return hi
