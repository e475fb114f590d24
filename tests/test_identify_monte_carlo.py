"""Issue 4's Monte Carlo acceptance: over 100 noise draws of one device, identify's reported standard errors
are within 20 % of the scatter of the fitted values, and the scatter within 1.2x of the Cramer-Rao bound
(experiments/identify_monte_carlo.py; all 100 draws are one vmapped, compiled fit)."""

import pytest
from _experiments import load_experiment


pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def monte_carlo():
    return load_experiment("identify_monte_carlo").run(draws=100, sweeps=("rate_table", "vcf_static", "dac"), runs=2,
                                                       seed=0)


def test_every_draw_converges_with_chi2_near_one(monte_carlo):
    assert monte_carlo["converged"] == 100
    # 100 draws x ~150 points: the pooled chi2_red of a correct model is 1 within a few percent
    assert 0.9 < monte_carlo["chi2_red"] < 1.1


@pytest.mark.parametrize("name", ["k_vf", "vcf_gain", "dac_gain_error", "scale_factor"])
def test_reported_errors_match_the_scatter_and_the_scatter_the_bound(monte_carlo, name):
    p = monte_carlo["parameters"][name]
    assert abs(p["reported_over_scatter"] - 1.0) <= 0.2, p
    assert p["scatter_over_crb"] <= 1.2, p
    # and no bias: the mean over the draws within 3 standard errors of the mean of the truth (u = 0)
    if "mean_offset_over_scatter" in p:
        assert abs(p["mean_offset_over_scatter"]) < 3.0, p
