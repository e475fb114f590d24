"""The chi-squared tail probabilities and quantiles every test in the package uses, against scipy."""

import math

import pytest
from scipy.stats import chi2 as scipy_chi2

from gyrojax._numerics.stats import chi2_isf, chi2_sf


@pytest.mark.parametrize("df", [1, 2, 3, 22, 264, 5280, 100000])
@pytest.mark.parametrize("p", [1e-290, 1e-30, 1e-6, 0.01, 0.5, 0.99])
def test_chi2_sf_matches_scipy_from_the_far_tail_to_the_bulk(df, p):
    x = scipy_chi2.isf(p, df)
    assert chi2_sf(x, df) == pytest.approx(scipy_chi2.sf(x, df), rel=2e-10)


@pytest.mark.parametrize("df", [1, 2, 7, 100, 10000])
@pytest.mark.parametrize("alpha", [1e-12, 0.01 / 7, 0.01, 0.5])
def test_chi2_isf_inverts_chi2_sf(df, alpha):
    c = chi2_isf(alpha, df)
    assert c == pytest.approx(scipy_chi2.isf(alpha, df), rel=1e-11)
    assert chi2_sf(c, df) == pytest.approx(alpha, rel=1e-9)


def test_edge_cases():
    assert chi2_sf(5.0, 0) == 1.0  # no degrees of freedom: never rejects
    assert chi2_sf(-3.0, 4) == 1.0 and chi2_sf(0.0, 1) == 1.0
    assert chi2_sf(1e7, 3) == 0.0  # below the smallest double
    assert chi2_sf(2.0, 2) == pytest.approx(math.exp(-1.0), rel=1e-15)  # chi2(2) is exponential
    assert chi2_sf(1.0, 1) == pytest.approx(math.erfc(math.sqrt(0.5)), rel=1e-15)
    with pytest.raises(ValueError, match="df must be an integer >= 1"):
        chi2_sf(1.0, 2.5)
    with pytest.raises(ValueError, match="df must be an integer >= 1"):
        chi2_isf(0.01, 0)
