"""A curve shared by every device (`pooled` descriptions): one coefficient per knot for the lot, so that a narrow
feature the same in every device (a dead band around zero rate) is described on fine knots without paying their
degrees of freedom once per device."""

import os
import sys

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.descriptions import KNOTS, coordinates, device_spline_basis, spline_basis, spread
from gyrojax._diagnose.locate import locate
from gyrojax._diagnose.space import ResidualSpace


sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "experiments"))
from _discovery_lot import discovery_lot  # noqa: E402


@pytest.fixture(scope="module")
def null_fit():
    table, _ = discovery_lot(None, snr="mid", design="a", seed=0)
    return gj.identify("paper-qmg", table, progress=False)


def _input_gain_columns(space, fit, knots=12):
    block = fit.data.blocks["rate_table"]
    mask = np.asarray(block.mask)
    hats = spline_basis(np.where(mask, coordinates(block)["input"], 0.0), mask, knots=knots, signed=True)
    return space.columns({"rate_table": hats * np.asarray(fit.predictions["rate_table"], float)[..., None]})


def test_pooled_score_is_one_fit_for_every_device(null_fit):
    space = ResidualSpace(null_fit)
    cols = _input_gain_columns(space, null_fit)
    own, pooled = space.score(cols), space.score(cols, pooled=True)
    # nested in the per-device fit: never more chi2, never more directions
    assert pooled.statistic <= own.statistic + 1e-9 and pooled.df < own.df
    assert np.allclose(pooled.coefficients, pooled.coefficients[0])
    # residuals that are exactly one shared curve beyond the span: both fits take all of it
    shared = space.project(cols) @ np.linspace(-1.0, 1.0, cols.shape[-1])
    space.residuals = shared
    a, b = space.score(cols), space.score(cols, pooled=True)
    assert b.statistic == pytest.approx(float(np.sum(shared**2)), rel=1e-8)
    assert a.statistic == pytest.approx(b.statistic, rel=1e-8)
    # a mask of no pooled column is the per-device fit; a mixed one lies between the two
    none = space.score(cols, pooled=np.zeros(cols.shape[-1], bool))
    assert none.statistic == pytest.approx(a.statistic, rel=1e-12) and none.df == a.df
    half = np.arange(cols.shape[-1]) < cols.shape[-1] // 2
    assert b.df < space.score(cols, pooled=half).df < a.df


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_a_dead_band_is_located_on_the_input_around_zero(seed):
    # the independent generator's held-out dead band: the rate loop loses a share of the rate for |rate| <= 0.5 deg/s
    table, info = discovery_lot("dead_band", snr="mid", design="a", seed=seed)
    fit = gj.identify("paper-qmg", table, progress=False)
    # what the guards read: the per-device descriptions alone
    assert not any(loc.pooled for loc in locate(fit, pooled=False).locations)
    first = locate(fit).locations[0]
    assert first.pooled and first.coordinate == "input" and first.located_on == ("rate_table",)
    lo, hi = first.location["interval"]
    assert -0.5 <= lo < 0 < hi <= 0.5
    # most of the misfit in excess of the noise: 0.65-1.0 of it on design a, seeds 0-4
    assert first.share > 0.6 and "the same in every device" in first.description


def test_a_coordinate_that_tells_devices_apart_gets_each_devices_own_knots(null_fit):
    # the drive frequency: ~54 Hz over the lot, under 1 Hz within a device; on the lot's quantiles a device's
    # curve along it has at most 3 directions (a line, or a line and one kink), on its own knots KNOTS
    block = null_fit.data.blocks["rate_table"]
    mask = np.asarray(block.mask)
    f = np.where(mask, coordinates(block)["drive_freq_hz"], 0.0)
    _, within_device, lot = spread(f, mask)
    assert within_device < 0.1 * lot
    lot_knots, own = spline_basis(f, mask), device_spline_basis(f, mask)
    assert max(np.linalg.matrix_rank(lot_knots[d][mask[d]]) for d in range(mask.shape[0])) <= 3
    assert [np.linalg.matrix_rank(own[d][mask[d]]) for d in range(mask.shape[0])] == [KNOTS] * mask.shape[0]
    assert np.allclose(own.sum(axis=-1)[mask], 1.0) and not np.any(own[~mask])  # hat functions, zero off the data


@pytest.mark.slow
def test_a_ripple_along_the_drive_frequency_is_named_with_the_temperature_it_follows():
    # the blind set's DDS ripple, a rate gain sin(2 pi f / 0.4 Hz) along the drive frequency: within a device the
    # frequency follows the die temperature by the TCF, so a curve along one is a curve along the other
    from _discovery_blind import BLIND  # noqa: F401  (registers the blind set)

    table, _ = discovery_lot("rate_gain_drive_ripple", snr="mid", design="a", seed=0)
    first = locate(gj.identify("paper-qmg", table, progress=False)).locations[0]
    assert first.located_on == ("rate_table",) and first.share > 0.5
    assert {first.coordinate, *first.confounded_with} >= {"temperature_c", "drive_freq_hz"}
