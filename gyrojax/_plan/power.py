r"""Power of a chi-squared test against a noncentral alternative, in plain NumPy.

A test statistic that is chi2(df) under the null is, when an effect leaves a noncentrality lambda (its
expected chi2 after the nuisance parameters took what they could), noncentral chi2(df, lambda):

    P(X > x) = sum_j Pois(j; lambda / 2) Q(df / 2 + j, x / 2)

with Q the regularised upper incomplete gamma function (`gyrojax/_numerics/stats.py`). The power at level alpha is
P(X > c) with c the (1 - alpha) quantile of chi2(df).
"""

from .._numerics.stats import check_df, chi2_isf, ncx2_sf


def power(nc: float, df: int, alpha: float = 0.01) -> float:
    """Probability that a chi2(`df`) test at level `alpha` rejects when the effect leaves noncentrality
    `nc` (its expected chi2)."""
    df = check_df(df)
    return ncx2_sf(chi2_isf(float(alpha), df), df, max(float(nc), 0.0))


def required_noncentrality(df: int, target: float = 0.9, alpha: float = 0.01) -> float:
    """The smallest noncentrality at which a chi2(`df`) test at level `alpha` has power `target`
    (bisection; power rises monotonically with the noncentrality)."""
    df = check_df(df)
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
