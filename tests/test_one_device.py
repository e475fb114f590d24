"""A misfit carried by one device, a gain per run on one sweep, a step at zero on sweeps of other input units:
lots of the independent NumPy generator's fresh effects (`experiments/_discovery_lot.py`, `FRESH`), each of a
shape the diagnosis was not written for."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


@pytest.fixture(scope="module")
def one_device_tempco():
    # the third device's rate and VCF gain follow the die temperature; the other five have no tempco at all
    table, info = discovery_lot("gain_tempco_one_device", snr="mid", design="a", seed=0)
    return table, info, gj.diagnose("paper-qmg", table, progress=False)


def test_a_tempco_of_one_device_is_not_the_lots_reference_drift(one_device_tempco):
    table, info, d = one_device_tempco
    assert d.selected == () and d.verdict == "unexplained", d.summary()
    (why,) = [r for r in d.rejected if r.effect == "vref_drift"]
    assert why.kind == "in one device only" and "disc-a-02" in why.reason
    top = d.discrepancy[0]
    assert top.coordinate == "temperature_c" and set(top.located_on) == {"rate_table", "vcf_static"}
    assert top.location["devices"] == ["disc-a-02"]
    # the size is that device's, not the lot's mean (which divides it by six): truth 18 ppm/K on design a
    assert top.size["unit"] == "ppm/K" and "disc-a-02" in top.size["measure"]
    truth = 1e6 * info["size"]
    assert abs(top.size["value"] - truth) < 3.0 * top.size["stderr"] + 0.05 * truth, (top.size, truth)
    assert [t.name for t in d.formula.terms] == ["lin(temperature_c)*model"]


def test_the_guard_leaves_an_effect_of_every_device_alone():
    # a reference drift with a 50 % part-to-part spread: every device carries it, and it is confirmed
    table, _ = discovery_lot("vref_drift_spread", snr="mid", design="a", seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert "vref_drift" in d.selected, d.summary()
    assert not any(r.kind == "in one device only" for r in d.rejected)
    # the same shape kept in one device (another seed) is refused, naming that device
    one, _ = discovery_lot("gain_tempco_one_device", snr="mid", design="a", seed=1)
    d1 = gj.diagnose("paper-qmg", one, progress=False)
    assert "vref_drift" not in d1.selected
    (why,) = [r for r in d1.rejected if r.effect == "vref_drift"]
    assert why.kind == "in one device only" and "disc-a-02" in why.reason


def test_a_gain_per_run_on_one_sweep_is_placed_on_the_run():
    # the VCF gain changes from power-on to power-on (random sign per device); the rate table is untouched. A
    # curve along dT/dt in every device (7 df each) fits as well as a gain per run (1 df each): the simpler one
    table, _ = discovery_lot("vcf_gain_per_run", snr="mid", design="b", seed=1)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ()
    top = d.discrepancy[0]
    assert top.coordinate == "run" and list(top.located_on) == ["vcf_static"]
    assert "dtemperature_dt" in top.confounded_with
    assert [t.name for t in d.formula.terms] == ["per_run(1)*model"]


def test_a_step_at_zero_input_joins_sweeps_of_other_units():
    # a bias +c warming, -c cooling; on this protocol the die warms while the rates are negative: a step of the
    # output at input 0 on the rate table (deg/s) and the VCF (V) alike, their zero being one value
    table, _ = discovery_lot("bias_sign_dtdt", snr="mid", design="a", seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    top = d.discrepancy[0]
    assert top.family == "offset step" and top.location["at"] == 0.0
    assert set(top.located_on) == {"rate_table", "vcf_static"}
    assert "dtemperature_dt" in top.confounded_with
    assert top.share > 0.9
    f = d.formula
    assert f.complete and [t.name for t in f.terms] == ["sign(input)"]
    assert set(f.terms[0].sweeps) == {"rate_table", "vcf_static"}
    assert np.isfinite(f.stderr[0]) and abs(f.coefficients[0]) > 5 * f.stderr[0]


def test_bias_jumps_at_their_own_times_in_two_devices_are_one_location():
    # run 1 of the second device jumps at 900 s, of the fourth at 2100 s (two charging events), on both sweeps
    table, _ = discovery_lot("bias_steps_two_devices", snr="mid", design="a", seed=0)
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ()
    top = d.discrepancy[0]
    assert top.family == "step" and top.coordinate == "time_s" and top.share > 0.9
    assert set(top.located_on) == {"rate_table", "vcf_static"}
    steps = dict(zip(map(tuple, top.location["runs"]), top.location["at_each"]))
    # the first dwell after each jump (dwells every 120 s from 120 s)
    assert steps == {("disc-a-01", 1): 960.0, ("disc-a-03", 1): 2160.0}
    assert "960 in disc-a-01 run 1" in top.description
