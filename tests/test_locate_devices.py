"""Misfits that are properties of runs and devices: an offset of one device's readings the same in all its runs
(coordinate `device`), and a curve along the input that differs from run to run (`gain in each run`), on lots of
the independent generator's sealed set (plain NumPy, written without reading the diagnosis's code)."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.descriptions import coordinates, describe, in_each_run, spline_basis
from gyrojax._diagnose.locate import locate
from gyrojax._diagnose.space import ResidualSpace
from gyrojax._model.fitdata import fit_data


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
import _discovery_sealed  # noqa: E402, F401  (registers the sealed set)
from _discovery_lot import discovery_lot  # noqa: E402


def test_a_curve_in_each_run_is_the_shared_curve_split_by_run():
    table, _ = discovery_lot(None, snr="mid", design="a", n_devices=2, n_runs=2, seed=0)
    block = fit_data(table).blocks["rate_table"]
    mask = np.asarray(block.mask)
    hats = spline_basis(np.where(mask, coordinates(block)["input"], 0.0), mask, signed=True)
    pred = np.ones(mask.shape)
    (offset_name, offset), (gain_name, _) = in_each_run(hats, pred, mask.shape)
    assert (offset_name, gain_name) == ("offset in each run", "gain in each run")
    k = hats.shape[-1]
    assert offset.shape == (*mask.shape, 2 * k)
    # run r's columns are the shared curve on run r's points and zero on the other run's
    assert np.allclose(offset[:, 0, :, :k], hats[:, 0]) and not np.any(offset[:, 1, :, :k])
    assert np.allclose(offset[:, 1, :, k:], hats[:, 1]) and not np.any(offset[:, 0, :, k:])
    assert np.allclose(offset.reshape(*mask.shape, 2, k).sum(axis=-2), hats)


def test_an_offset_of_one_devices_dac_readings_is_a_property_of_that_device():
    # a thermal EMF at the bench scanner's relay of the first device: a constant offset on its DAC readings in every
    # run (the DAC sweep is read without a turn-on bias, so nothing in the baseline takes it)
    name = "dac_scanner_emf_one_device"
    table, _ = discovery_lot(name, snr="mid", design="a", seed=0)
    null, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    diff = np.asarray(table.columns["output"]) - np.asarray(null.columns["output"])
    hit = diff != 0
    offset = float(np.unique(diff[hit])[0])
    assert np.allclose(diff[hit], offset) and len(set(np.asarray(table.columns["device"])[hit])) == 1
    d = gj.diagnose("paper-qmg", table, progress=False)
    assert d.selected == ()
    top = d.remaining[0]
    assert (top.coordinate, top.family, top.located_on) == ("device", "offset per device", ("dac",))
    assert "a property of the device" in top.shape
    # the runs that carry it are the first device's, and its size is the offset, within 3 standard errors
    assert {dev for dev, _ in top.location["runs"]} == {d.baseline.devices[0]}
    assert abs(abs(top.size["value"]) - abs(offset)) < 3 * top.size["stderr"]
    # the closed form is an offset on the DAC sweep (each device its own; the lot's mean is not the device's)
    assert [t.name for t in d.formula.terms] == ["offset"] and d.formula.complete
    assert d.formula.terms[0].sweeps == ("dac",)


@pytest.mark.slow
def test_a_compression_in_one_run_is_described_as_a_curve_along_the_input_that_differs_between_runs():
    # the supply sagged in run 0 only: the feedback amplifier's cubic compression, -c W s^3, in that run alone
    table, _ = discovery_lot("compression_first_run_supply", snr="mid", design="a", seed=1)
    fit = gj.identify("paper-qmg", table, progress=False)
    descs = {(d.coordinate, d.family, d.pooled): d for d in describe(ResidualSpace(fit))[0]
             if d.sweep == "rate_table"}
    each, shared = descs[("input", "gain in each run", True)], descs[("input", "gain", True)]
    assert each.p_value < 1e-10
    # beyond the curve shared by the runs, the run-to-run difference is there: about half the misfit sits in run 0
    # and none in run 1, so the shared curve takes about half of it
    assert ResidualSpace(fit).with_columns(shared.columns).score(each.columns, True).p_value < 1e-6
    # on this protocol the input follows the time, and dT/dt differs by run: a curve along one is a curve along the
    # other, and the location names both
    first = locate(fit).locations[0]
    assert {first.coordinate, *first.confounded_with} >= {"input", "dtemperature_dt"}
    assert "rate_table" in first.located_on
