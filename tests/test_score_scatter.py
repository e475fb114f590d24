"""Score tests read against the residuals' own scatter where it exceeds the stated uncertainties
(`gyrojax._numerics.stats.score_p_value`, used by every probe, candidate and flexible description): noise stated
too small makes any column block remove ~df s^2, which a chi2 reading takes for a shape."""

import os
import sys

import numpy as np
import pytest
from scipy import stats

import gyrojax as gj
from gyrojax._diagnose.probes import score_columns
from gyrojax._numerics.stats import chi2_sf, score_p_value


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def test_the_reading_is_the_chi2_test_at_or_below_the_stated_scatter_and_the_f_test_above():
    assert score_p_value(20.0, 6, 100.0, 100.0) == chi2_sf(20.0, 6)
    assert score_p_value(20.0, 6, 80.0, 100.0) == chi2_sf(20.0, 6)  # a scatter below sigma finds no more
    assert score_p_value(40.0, 6, 200.0, 100.0) == pytest.approx(stats.f.sf(40.0 / 6 / 2.0, 6, 100), rel=1e-10)
    assert score_p_value(0.0, 0, 200.0, 100.0) == 1.0


@pytest.mark.parametrize("scale, chi2_rate", [(1.0, 0.01), (1.5, 0.28)])
def test_false_alarms_stay_at_alpha_whatever_the_noise_scale(scale, chi2_rate):
    rng = np.random.default_rng(0)
    rows, k, draws = 200, 6, 2000
    base = rng.normal(size=(1, rows, 3))
    hits_f = hits_chi2 = 0
    for _ in range(draws):
        r = scale * rng.normal(size=(1, rows))
        r -= (base[0] @ np.linalg.lstsq(base[0], r[0], rcond=None)[0])[None]  # residuals of a fit
        sc = score_columns(base, rng.normal(size=(1, rows, k)), r)
        hits_f += sc.p_value < 0.01
        hits_chi2 += chi2_sf(sc.statistic, sc.df) < 0.01
    # the F reading holds alpha (binomial sd 0.0022 at 2000 draws); the chi2 reading of 1.5x noise alarms ~28 %
    assert abs(hits_f / draws - 0.01) < 0.008
    assert hits_chi2 / draws == pytest.approx(chi2_rate, abs=0.04)


@pytest.mark.slow
def test_noise_stated_too_small_is_said_and_no_shape_is_found():
    table, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    cols = {k: np.array(v) for k, v in table.columns.items()}
    cols["output_sigma"] = 0.7 * cols["output_sigma"]
    d = gj.diagnose("paper-qmg", gj.Table.from_columns(cols, source="<sigma understated>"), progress=False)
    assert d.selected == () and d.verdict == "unexplained"
    assert d.remaining == ()  # a chi2 reading located 21 % of the misfit 'along time_s, run by run', 8 LSB
    assert "scatter 1.41 times the stated uncertainties with no shape" in d.verdict_text()
