"""The discovery benchmark on the new user's protocol (`experiments/simulate_protocol_benchmark.py`): a lot from
`gyrojax.simulate_table` with a hidden effect written onto its outputs by hand. The generator's own contract: each
effect changes only the sweeps it declares, at the size whose chi2 beyond the baseline's free biases and gains is
the target, and an effect whose sweeps a protocol lacks is refused with its name."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._cli.demo_job import DEMO_LOT


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
import simulate_protocol_benchmark as spb  # noqa: E402


@pytest.fixture(scope="module")
def clean():
    # the demo lot's shape (its compiled programs are shared with the demo's tests), protocol 0's campaign
    return gj.simulate_table(gj.paper_qmg(), **{**DEMO_LOT, "seed": 11}, progress=False)


@pytest.mark.parametrize("name", [h.name for h in spb.HAND])
def test_each_effect_changes_its_sweeps_at_the_target_chi2(clean, name):
    hand = spb.HAND_BY_NAME[name]
    table, info = spb.hidden_lot(clean, hand, 300.0)
    delta = np.asarray(table.columns["output"]) - np.asarray(clean.columns["output"])
    sweeps = np.asarray(clean.columns["sweep"])
    assert not np.any(delta[~np.isin(sweeps, hand.sweeps)])  # nothing outside its declared sweeps
    assert np.all(np.isfinite(delta))
    c = {k: np.asarray(v) for k, v in clean.columns.items()}
    assert sum(spb.beyond_baseline(c, delta).values()) == pytest.approx(300.0, rel=1e-9)
    assert set(info["visible_sweeps"]) <= set(hand.sweeps) and info["visible_sweeps"]
    assert info["class"] == "outside" and info["library"] is None


def test_a_biases_chi2_beyond_the_baseline_leaves_out_the_turn_on_biases(clean):
    # a constant per (device, run, sweep) is a turn-on bias: nothing beyond the baseline
    c = {k: np.asarray(v) for k, v in clean.columns.items()}
    timed = np.isfinite(np.asarray(c["time_s"], dtype=float))
    offsets = np.where(timed, 3.0 * np.asarray(c["run"], dtype=float) + 1.0, 0.0) * c["output_sigma"]
    assert sum(spb.beyond_baseline(c, offsets).values()) == pytest.approx(0.0, abs=1e-12)
    # a bias in time is not
    bias = np.where(timed, np.nan_to_num(c["time_s"]) / 3600.0, 0.0) * c["output_sigma"]
    assert sum(spb.beyond_baseline(c, bias).values()) > 1.0


def test_an_effect_with_no_chi2_beyond_the_baseline_is_refused_by_name(clean):
    flat = spb.Hand("run_offset", ("rate_table",), "run", None,
                    lambda c: np.where(np.asarray(c["sweep"]) == "rate_table", 1.0, 0.0), "a turn-on bias")
    with pytest.raises(ValueError, match="run_offset: leaves no chi2 beyond the baseline"):
        spb.hidden_lot(clean, flat, 300.0)


@pytest.mark.slow
def test_a_vcf_only_tempco_on_a_warming_die_is_proposed_as_the_linear_term(clean):
    # the die moves 25.4 -> 27 C: a gain quadratic in the temperature removes chi2 ~5 more than the linear one,
    # neither standing beyond the other; the formula says the simpler, and its size is the truth's
    table, info = spb.hidden_lot(clean, spb.HAND_BY_NAME["vcf_gain_tempco_only"], 300.0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == () and d.verdict == "unexplained", d.summary()
    top = d.discrepancy[0]
    assert top.coordinate == "temperature_c" and top.located_on == ("vcf_static",)
    assert [t.name for t in d.formula.terms] == ["lin(temperature_c)*model"]
    assert abs(d.formula.coefficients[0] - info["size"]) < 3.0 * d.formula.stderr[0]
