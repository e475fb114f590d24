"""`gyrojax.rate_table_plan` (issue 38): how many devices of a lot to put on the rate table for a target width of
the others' predicted scale factors (the population fit's Student-t prediction interval)."""

import math

import numpy as np
import pytest
from scipy import stats

import gyrojax as gj


def test_halfwidth_is_the_population_fits_prediction_interval():
    """t_{K-1} sqrt(s^2 (1 + 1/K) + u^2), and the fewest K that reach the target; measured on 64-device
    vcf-2018 lots (docs/results.md, learned spread ~0.087 %): K = 2 +/- 1.32 %, K = 4 +/- 0.25 % mean half-width."""
    plan = gj.rate_table_plan(0.00087, 0.002, devices=64, own=0.0001)
    k = plan.counts
    expected = stats.t.ppf(0.975, k - 1) * np.sqrt(0.00087**2 * (1 + 1 / k) + 0.0001**2)
    np.testing.assert_allclose(plan.halfwidth, expected, rtol=1e-9)
    assert k[0] == 2 and k[-1] == 63
    assert plan.recommended == int(k[np.argmax(expected <= 0.002)]) == 13  # 12 without the own 0.01 %
    assert plan.halfwidth[plan.counts == plan.recommended][0] <= 0.002 < plan.halfwidth[plan.counts ==
                                                                                        plan.recommended - 1][0]
    assert "13 rate-tabled" in plan.summary() and "fewest" in plan.summary()
    assert plan.report()["recommended"] == 13


def test_an_unreachable_target_is_said():
    plan = gj.rate_table_plan(0.00087, 0.001)
    assert plan.recommended is None
    assert "no count reaches it" in plan.summary()
    assert math.isclose(plan.halfwidth.min(), stats.t.ppf(0.975, 62) * 0.00087 * math.sqrt(1 + 1 / 63), rel_tol=1e-9)


def test_refusals():
    with pytest.raises(ValueError, match="spread must be a positive relative number"):
        gj.rate_table_plan(0.0, 0.002)
    with pytest.raises(ValueError, match="target must be a positive relative number"):
        gj.rate_table_plan(0.001, -1.0)
    with pytest.raises(ValueError, match="devices must be an integer >= 3"):
        gj.rate_table_plan(0.001, 0.002, devices=2)
    with pytest.raises(ValueError, match="own must be >= 0"):
        gj.rate_table_plan(0.001, 0.002, own=-0.1)
