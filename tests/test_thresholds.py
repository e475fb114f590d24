"""Threshold scans (`gyrojax._diagnose.thresholds`): a step of the output or of its gain where a recorded
coordinate passes one value, located from the residuals of lots made by the independent NumPy generator
(`experiments/_discovery_lot.py`), with the step's formula proposed and drafted."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose import thresholds
from gyrojax._diagnose.locate import locate
from gyrojax._diagnose.space import ResidualSpace


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


def test_positions_are_midpoints_with_points_on_either_side():
    real = np.repeat(np.arange(10.0), 2)  # ten values, two points each
    cuts = thresholds.positions(real)
    # midpoints only, and at least MIN_SIDE (3) points below and above each
    assert np.allclose(cuts, np.arange(1.5, 8.0, 1.0))
    assert all(np.sum(real < c) >= thresholds.MIN_SIDE and np.sum(real >= c) >= thresholds.MIN_SIDE for c in cuts)
    many = thresholds.positions(np.linspace(0.0, 1.0, 500))
    assert many.size == thresholds.THRESHOLDS and np.all(np.diff(many) > 0)
    assert thresholds.positions(np.array([1.0, 2.0, 3.0])).size == 0


def test_changes_are_the_step_in_the_chosen_devices():
    x = np.arange(12.0).reshape(2, 1, 6)
    mask = np.ones(x.shape, bool)
    pred = 10.0 * x
    g = thresholds.changes(x, mask, pred, "gain step", [3.0, 8.0], devices=[1])
    assert g.shape == (2, 1, 6, 2)
    assert np.all(g[0] == 0.0)  # device 0 left alone
    assert np.array_equal(g[1, 0, :, 0], pred[1, 0])  # every point of device 1 is above 3
    assert np.array_equal(g[1, 0, :, 1], np.where(x[1, 0] >= 8.0, pred[1, 0], 0.0))
    off = thresholds.changes(x, mask, pred, "offset step", 8.0)
    assert np.array_equal(off[..., 0], (x >= 8.0).astype(float))


def test_the_sign_change_is_the_one_threshold_of_every_unit():
    rates = np.array([-200.0, -1.0, -0.1, 0.1, 1.0, 200.0])
    assert thresholds.is_sign_change(rates, 0.0) and not thresholds.is_sign_change(rates, 0.5)
    volts = np.array([-2.0, -0.01, 0.0, 0.01, 2.0])
    assert thresholds.sign_change(volts, 0.0) == 0.0
    assert thresholds.sign_change(volts, 0.05) == 0.005  # zero below it, as on the other sweep
    assert thresholds.sign_change(volts, -0.05) == -0.005
    # a coordinate of one sign has no sign change (it was an error on an empty side)
    assert thresholds.sign_change(np.array([0.5, 1.0, 2.0]), -0.05) is None


@pytest.fixture(scope="module")
def step_in_temperature():
    # held-out effect: a bias that jumps by the same deg/s in every device when the die passes 28 C
    table, info = discovery_lot("temp_step_bias", snr="mid", design="a", seed=0)
    return table, info, gj.diagnose("paper-qmg", table, progress=False)


def test_a_bias_step_in_temperature_is_located_at_its_threshold(step_in_temperature):
    table, info, d = step_in_temperature
    assert d.selected == ()  # nothing in the library has this shape
    top = d.discrepancy[0]
    assert top.coordinate == "temperature_c" and top.family == "offset step"
    assert set(top.located_on) == {"rate_table", "vcf_static"}  # the generator puts it on both
    shares = dict(top.sweeps)
    assert 0.3 < shares["rate_table"] < 0.7 and 0.3 < shares["vcf_static"] < 0.7
    # the die crosses 28 C between two dwells: the threshold lies within one dwell's temperature step of it
    assert 27.8 < top.location["at"] < 28.3
    lo, hi = top.location["at_range"]
    assert lo <= top.location["at"] <= hi
    # one height for every device (the generator's jump is the same in deg/s, 2 % SF spread in LSB)
    assert top.pooled and "the same in every device" in top.description
    f = d.formula
    assert f is not None and f.complete and [t.name for t in f.terms] == ["step(temperature_c)"]
    j = d.to_json()["discrepancy"][0]
    assert j["family"] == "offset step" and j["location"]["side"] == "at or above"


def test_the_drafted_step_explains_the_lot(step_in_temperature, tmp_path):
    table, info, d = step_in_temperature
    path = tmp_path / "drafted_step.py"
    text = d.draft_effect(path, name="drafted_step")
    assert "jnp.where((T - 25.0) >= 3.0" in text  # the threshold as the scan placed it, 28.09 C (T - 25 C >= 3.09)
    (cls,) = gj.load_effects_module(path)
    try:
        again = gj.diagnose("paper-qmg", table, progress=False)
    finally:
        gj.EFFECTS.pop(cls.name, None)
    assert again.selected == ("drafted_step",) and again.verdict == "explained", again.summary()
    assert 0.7 <= again.final.chi2_red_total <= 1.2


@pytest.mark.slow
def test_a_gain_switch_in_one_device_is_placed_on_that_device():
    # held-out effect on the shuffled-rate protocol (the input does not follow the time): the first device's gain
    # switches at t = 1500 s in every run
    table, info = discovery_lot("gain_step_device", snr="mid", design="c", seed=0)
    fit = gj.identify("paper-qmg", table, progress=False)
    top = locate(fit).locations[0]
    assert top.family == "gain step" and top.coordinate == "time_s"
    assert top.location["devices"] == [fit.devices[0]]
    assert 1440.0 < top.location["at"] <= 1620.0  # the dwells around 1500 s are at 1440 s and 1560 s
    # the guards' per-device descriptions hold no threshold scan
    assert not any(loc.family in thresholds.FAMILIES for loc in locate(fit, pooled=False).locations)


def test_noise_alone_finds_no_threshold():
    table, _ = discovery_lot(None, snr="mid", design="b", seed=1)
    fit = gj.identify("paper-qmg", table, progress=False)
    space = ResidualSpace(fit)
    block = fit.data.blocks["rate_table"]
    mask = np.asarray(block.mask)
    pred = np.asarray(fit.predictions["rate_table"], float)
    for name in ("input", "temperature_c", "time_s"):
        x = np.where(mask, np.asarray(getattr(block, {"input": "inputs", "temperature_c": "temperatures",
                                                      "time_s": "times"}[name]), float), 0.0)
        for family in thresholds.FAMILIES:
            found = thresholds.scan(space, "rate_table", x, mask, pred, family)
            # the look-elsewhere correction keeps the best of ~3 x 21-32 positions at a plain p-value
            assert found is not None and found.p_value > 0.01, (name, family, found.p_value)
