r"""Chi-squared tail probabilities and quantiles in plain NumPy, for every test in the package (the structure
tests of `compare`, the score and likelihood-ratio tests of `diagnose`, the planner's power).

For integer df, the regularised upper incomplete gamma function Q(df / 2, y) is exact from
Q(1/2, y) = erfc(sqrt(y)) or Q(1, y) = exp(-y) and the upward recurrence
Q(a + 1, y) = Q(a, y) + y^a exp(-y) / Gamma(a + 1) (a sum of positive terms: stable), each term from its
logarithm. A statistic that is chi2(df) under the null is, when an effect leaves a noncentrality lambda,
noncentral chi2(df, lambda):

    P(X > x) = sum_j Pois(j; lambda / 2) Q(df / 2 + j, x / 2)

Against 50-digit references (mpmath), `chi2_sf` is within 6e-11 relative for df from 1 to 100000 and tail
probabilities from 1e-290 to 1 - 1e-6, and `chi2_isf` within 4e-14 for df from 1 to 10000 and levels from
1e-12 to 0.5.
"""

import functools
import math

import numpy as np


def check_df(df) -> int:
    """`df` as an int, or a `ValueError` unless it is an integer >= 1."""
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
    """Survival function of the chi-squared distribution with integer `df` (1 for df <= 0: a test with no degrees
    of freedom never rejects)."""
    if not isinstance(df, bool) and float(df) <= 0.0:
        return 1.0
    df = check_df(df)
    return float(_upper_gamma(df, max(float(x), 0.0) / 2.0, 1)[0])


def log_chi2_sf(stat: float, df: int) -> float:
    """log of chi2(df)'s tail at `stat`, stable where the probability underflows (the leading term of the
    upper incomplete gamma function's asymptotic series): for ranking scores far beyond any table."""
    p = chi2_sf(stat, df)
    if p > 1e-290:
        return math.log(p)
    a, x = df / 2.0, stat / 2.0
    return (a - 1.0) * math.log(x) - x - math.lgamma(a)


def score_p_value(stat: float, df: int, beyond_chi2: float, beyond_dof: float) -> float:
    """p-value of a score statistic `stat` (the chi2 `df` columns would remove), read against the scatter the
    residuals keep beyond them on the rows they touch (`beyond_chi2` over `beyond_dof` degrees of freedom) where
    that scatter exceeds the stated uncertainties: the F test of (stat / df) / s^2. Residuals that scatter s^2 > 1
    times the stated sigma everywhere (noise stated too small, or not white) make every flexible column block
    remove ~df s^2; read as a chi2 it would be a shape, read against s^2 it is not. At s^2 <= 1 the chi2 test
    (the stated sigmas are trusted: a scatter below them is no licence to find more)."""
    if not isinstance(df, bool) and float(df) <= 0.0:
        return 1.0
    nu = float(beyond_dof)
    if nu < 1.0 or not math.isfinite(beyond_chi2) or beyond_chi2 <= nu:
        return chi2_sf(stat, df)
    from scipy.special import betainc  # F(df, nu) survival at x = (stat / df) / s^2: I_{nu/(nu + stat/s^2)}

    s2 = beyond_chi2 / nu
    return float(betainc(nu / 2.0, df / 2.0, nu / (nu + max(float(stat), 0.0) / s2)))


def ncx2_sf(x: float, df: int, nc: float) -> float:
    """Survival function of the noncentral chi-squared distribution (integer `df` >= 1, noncentrality `nc` >= 0):
    the Poisson mixture of central chi-squared survival functions over the Poisson weights' bulk (mean +/- 12
    standard deviations; the rest is below 1e-30)."""
    df = check_df(df)
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
    """The (1 - `alpha`) quantile of chi2(`df`), integer `df` >= 1 (bisection on `chi2_sf`)."""
    df = check_df(df)
    lo, hi = 0.0, max(10.0 * df, 100.0)
    while chi2_sf(hi, df) > alpha:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_sf(mid, df) > alpha else (lo, mid)
        if hi - lo <= 1e-15 * hi:  # to rounding
            break
    return 0.5 * (lo + hi)
