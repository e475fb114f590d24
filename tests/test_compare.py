"""`compare`: where the model fails, and structure tests on residuals ordered by input (synthetic residuals:
no model, no compile)."""

import numpy as np
import pytest

import gyrojax as gj
from gyrojax._diagnose.compare import compare_residuals, runs_test, shape_components, symmetric_parts


RATES = np.array([-200, -100, -50, -20, -10, -5, -2, -1, -0.5, -0.2, -0.1,
                  0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200], dtype=float)


def _lot(noise_seed, shape=None, devices=4, runs=2):
    """A rate-table-like sweep (devices, runs, 22 points) of unit-variance residuals plus `shape(x, d)`."""
    rng = np.random.default_rng(noise_seed)
    x = np.broadcast_to(RATES, (devices, runs, RATES.size)).copy()
    r = rng.normal(size=x.shape)
    if shape is not None:
        for d in range(devices):
            r[d] += shape(x[d], d)
    r -= r.mean(axis=-1, keepdims=True)  # each run's bias, as the fit takes it out
    return {"rate_table": r}, {"rate_table": x}, {"rate_table": np.ones(x.shape, bool)}


DEVICES = ("a", "b", "c", "d")


def test_runs_test_counts_and_standardises():
    # + + - - + -: 4 runs of n1 = 3, n2 = 3: E = 2*9/6 + 1 = 4, Var = 2*9*(18-6)/(36*5) = 1.2
    runs, mean, z = runs_test([1, 1, -1, -1, 1, -1])
    assert runs == 4 and mean == pytest.approx(4.0) and z == pytest.approx(0.0)
    runs, mean, z = runs_test([1] * 5 + [-1] * 5)
    assert runs == 2 and z == pytest.approx((2 - 6) / np.sqrt(2 * 25 * (50 - 10) / (100 * 9)))
    assert runs_test([1, 1, 1])[2] == 0.0  # one sign: nothing to test


def test_shape_components_and_symmetric_parts_of_known_residuals():
    x = RATES
    t = x / 200.0
    comps = shape_components(x, 5.0 * t**3 - 5.0 * np.mean(t**3))
    # an odd cubic has a linear part too (not orthogonal to t) but no even part
    assert abs(comps[1]) < 1e-12 and abs(comps[2]) > 1.0
    odd, even = symmetric_parts(x, 3.0 * t**3)
    assert odd.size == 11 and np.allclose(even, 0.0) and np.allclose(odd, 2 * 3.0 * t[11:] ** 3 / np.sqrt(2))
    # projections of white noise on the orthonormal basis are N(0, 1)
    rng = np.random.default_rng(0)
    samples = np.array([shape_components(x, rng.normal(size=x.size)) for _ in range(4000)])
    np.testing.assert_allclose(samples.var(axis=0), 1.0, atol=0.08)


def test_pure_noise_flags_nothing_and_spreads_the_misfit():
    false_alarms = 0
    for seed in range(40):
        c = compare_residuals(*_lot(seed), devices=DEVICES)
        false_alarms += bool(c.flagged)
    # family-wise alpha 0.01 over 40 lots: about 0.4 expected; 3 or more has probability < 1 %
    assert false_alarms <= 2
    c = compare_residuals(*_lot(1), devices=DEVICES)
    assert {f.test for f in c.findings} == {"runs", "trend", "even bow", "odd cubic", "odd part", "even part",
                                           "sign gain"}
    assert c.points == 4 * 2 * 22 and "no structure in the residuals" in c.summary()
    assert not c.fails and "at the noise level" in c.summary() and "misfit by" not in c.summary()


def test_an_odd_cubic_in_one_device_at_high_rate_is_located_and_named():
    c = compare_residuals(*_lot(3, lambda x, d: 6.0 * (x / 200.0) ** 3 if d == 2 else 0.0), devices=DEVICES)
    flagged = {f.test for f in c.flagged}
    # seed 000's log-spaced rates put 2 points per side above half scale: the cubic shows as odd and as a slope
    assert "odd part" in flagged and flagged & {"odd cubic", "trend"}
    assert "even part" not in flagged and "even bow" not in flagged
    assert c.fails and c.p_value < 1e-6
    worst_device = max(c.by_device, key=lambda g: g.share)
    assert worst_device.label == "c" and worst_device.share > 0.8
    worst_band = max(c.by_band, key=lambda g: g.share)
    assert worst_band.label.startswith("rate_table high |input|")
    assert "rate_table odd part" in c.summary() and "misfit by device: c " in c.summary()


def test_an_even_bow_is_named_even():
    c = compare_residuals(*_lot(4, lambda x, d: 3.0 * (x / 200.0) ** 2), devices=DEVICES)
    flagged = {f.test for f in c.flagged}
    assert {"even bow", "even part"} <= flagged and "odd part" not in flagged


def test_compare_is_public_and_documented():
    assert gj.compare is not None and gj.Comparison is not None
    assert "Bonferroni" in gj.compare.__doc__


# --- every recorded coordinate ---------------------------------------------------------------------------

def _warm_lot(noise_seed, shape=None, order="listed", devices=4, runs=2):
    """A rate-table-like sweep whose points are applied one per 120 s after a 60 s warm-up, in `order`, while
    the die warms by 2 K (tau 300 s): the input, time and temperature coordinates; residuals are unit noise
    plus `shape(x, temperature, time)`, each run's bias removed."""
    rng = np.random.default_rng(noise_seed)
    n = RATES.size
    time = 60.0 + 120.0 * (np.arange(n) + 0.5)
    temp = 25.0 + 2.0 * (1.0 - np.exp(-time / 300.0))
    x = np.empty((devices, runs, n))
    for d in range(devices):
        for k in range(runs):
            x[d, k] = RATES if order == "listed" else rng.permutation(RATES)
    t = np.broadcast_to(time, x.shape)
    T = np.broadcast_to(temp, x.shape)
    r = rng.normal(size=x.shape) + (0.0 if shape is None else shape(x, T, t))
    r -= r.mean(axis=-1, keepdims=True)
    coords = {"rate_table": {"temperature_c": T, "time_s": t,
                             "order": np.broadcast_to(np.arange(n, dtype=float), x.shape)}}
    return ({"rate_table": r}, {"rate_table": x}, {"rate_table": np.ones(x.shape, bool)}), coords


def test_noise_flags_nothing_along_any_coordinate():
    false_alarms = 0
    for seed in range(30):
        arrays, coords = _warm_lot(100 + seed, order="shuffled")
        c = compare_residuals(*arrays, devices=DEVICES, coordinates=coords)
        false_alarms += bool(c.flagged)
        assert {f.coordinate for f in c.findings} == {"input", "temperature_c", "time_s", "order"}
    assert false_alarms <= 2  # family-wise 0.01 over 30 lots: 0.3 expected


def test_a_bias_in_temperature_is_found_along_temperature_not_the_input_when_the_order_is_shuffled():
    """A bias of 4 sigma per kelvin: along the die temperature (and time, which rises with it) it is flagged
    far above anything along the input (an excess that large fails every white-noise test a little, so the
    input's tests are only much weaker), and the comparison says that temperature and time move together but
    the input, applied in shuffled order, does not move with them."""
    arrays, coords = _warm_lot(7, lambda x, T, t: 4.0 * (T - 25.0), order="shuffled")
    c = compare_residuals(*arrays, devices=DEVICES, coordinates=coords)
    flagged = {(f.test, f.coordinate) for f in c.flagged}
    assert ("linear", "temperature_c") in flagged and ("linear", "time_s") in flagged
    best = min(c.flagged, key=lambda f: f.p_value)
    assert best.coordinate in ("temperature_c", "time_s", "order")
    along_input = min((f.p_value for f in c.findings if f.coordinate == "input"), default=1.0)
    assert best.p_value < 1e-10 * along_input
    pairs = {frozenset((k.first, k.second)) for k in c.confounded}
    assert frozenset(("temperature_c", "time_s")) in pairs
    assert not any("input" in p for p in pairs)


def test_an_input_swept_in_time_order_is_reported_confounded_with_time():
    arrays, coords = _warm_lot(8, lambda x, T, t: 4.0 * (T - 25.0))
    c = compare_residuals(*arrays, devices=DEVICES, coordinates=coords)
    pairs = {frozenset((k.first, k.second)) for k in c.confounded}
    assert frozenset(("input", "time_s")) in pairs and frozenset(("input", "temperature_c")) in pairs
    text = c.summary()
    assert "move together in every run" in text and "order='alternating' or 'shuffled'" in text


def test_a_gain_that_differs_for_positive_inputs_is_flagged_as_such():
    """K+ != K-: residual 6 sigma x (x / 200) on positive inputs only (after the fit took the mean gain)."""
    arrays, coords = _warm_lot(9, lambda x, T, t: np.where(x > 0, 6.0 * x / 200.0, 0.0) - 3.0 * x / 200.0,
                               order="shuffled")
    c = compare_residuals(*arrays, devices=DEVICES, coordinates=coords)
    assert ("sign gain", "input") in {(f.test, f.coordinate) for f in c.flagged}
