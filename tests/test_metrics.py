"""Scale-factor metrics against closed forms and independent NumPy computations."""

import json
import math
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gyrojax import DataError, Table, fit_scale_factor
from gyrojax.metrics import asymmetry, metrics_report, rate_bandwidth, repeatability


RATES = np.array([-200, -100, -50, -20, -10, -5, -2, -1, -0.5, -0.2, -0.1,
                  0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200], dtype=float)


def numpy_nonlinearity(x, y, w=None):
    """Independent reference: np.polyfit (weights multiply residuals, so pass 1/sigma)."""
    k, b = np.polyfit(x, y, 1, w=w)
    r = y - (k * x + b)
    fs = abs(k) * np.max(np.abs(x))
    return k, b, 1e6 * np.max(np.abs(r)) / fs, 1e6 * np.sqrt(np.mean(r**2)) / fs


def test_straight_line_is_exact():
    fit = fit_scale_factor(RATES, 13709.853 * RATES - 4.25)
    assert float(fit.scale_factor) == pytest.approx(13709.853, rel=1e-14)
    assert float(fit.bias) == pytest.approx(-4.25, rel=1e-9)
    assert float(fit.nonlinearity_max_ppm) < 1e-7
    assert float(fit.n_points) == 22


def test_cubic_matches_numpy_and_closed_form():
    # y = x (1 + c x^2) on a symmetric grid: the fit has zero bias, and the residual is odd.
    x = np.linspace(-200, 200, 41)
    c = 1e-8
    y = x * (1 + c * x**2)
    fit = fit_scale_factor(x, y)
    k, b, nl_max, nl_rms = numpy_nonlinearity(x, y)
    assert float(fit.scale_factor) == pytest.approx(k, rel=1e-12)
    assert abs(float(fit.bias)) < 1e-9
    assert float(fit.nonlinearity_max_ppm) == pytest.approx(nl_max, rel=1e-9)
    assert float(fit.nonlinearity_rms_ppm) == pytest.approx(nl_rms, rel=1e-9)
    # Closed form: K = 1 + c sum x^4 / sum x^2; the largest residual is at the ends, c 200^3 - (K-1) 200.
    kk = 1 + c * np.sum(x**4) / np.sum(x**2)
    assert float(fit.scale_factor) == pytest.approx(kk, rel=1e-13)
    r_end = c * 200**3 - (kk - 1) * 200
    assert float(fit.nonlinearity_max_ppm) == pytest.approx(1e6 * abs(r_end) / (kk * 200), rel=1e-9)


def test_full_scale_conventions():
    rng = np.random.default_rng(3)
    x = RATES
    y = -0.008 * x + 1e-5 * rng.normal(size=x.size)
    half = fit_scale_factor(x, y, full_scale="half_range")
    span = fit_scale_factor(x, y, full_scale="span")
    out = fit_scale_factor(x, y, full_scale="output")
    assert float(half.full_scale) == pytest.approx(abs(float(half.scale_factor)) * 200, rel=1e-14)
    assert float(span.nonlinearity_rms_ppm) == pytest.approx(float(half.nonlinearity_rms_ppm) / 2, rel=1e-12)
    assert float(out.full_scale) == pytest.approx(np.max(np.abs(y)), rel=1e-15)
    with pytest.raises(ValueError, match="full_scale must be one of half_range, span, output"):
        fit_scale_factor(x, y, full_scale="fs")


def test_weighted_fit_matches_numpy():
    rng = np.random.default_rng(4)
    sigma = rng.uniform(0.5, 5.0, RATES.size)
    y = 100.0 * RATES + 3 + 2e-3 * RATES**2 + sigma * rng.normal(size=RATES.size)
    fit = fit_scale_factor(RATES, y, sigmas=sigma)
    k, b, _, _ = numpy_nonlinearity(RATES, y, w=1 / sigma)
    assert float(fit.scale_factor) == pytest.approx(k, rel=1e-12)
    assert float(fit.bias) == pytest.approx(b, rel=1e-10)
    unweighted = fit_scale_factor(RATES, y)
    assert abs(float(unweighted.scale_factor) - k) > 1e-6  # the weights matter here
    with pytest.raises(DataError, match="every sigma must be positive"):
        fit_scale_factor(RATES, y, sigmas=np.where(RATES > 100, 0.0, 1.0))


def test_masked_batch_equals_separate_fits_and_padding_is_inert():
    rng = np.random.default_rng(5)
    x = np.zeros((3, 8))
    y = np.zeros((3, 8))
    mask = np.zeros((3, 8), dtype=bool)
    sizes = [8, 5, 0]  # the last sweep is pure padding
    for i, m in enumerate(sizes):
        x[i, :m] = np.sort(rng.uniform(-100, 100, m))
        y[i, :m] = (i + 1) * x[i, :m] + 1e-3 * x[i, :m] ** 3
        mask[i, :m] = True
    x[1, 5:] = np.nan  # garbage in masked places must not leak
    y[1, 5:] = np.inf
    fit = fit_scale_factor(x, y, mask=mask)
    for i, m in enumerate(sizes[:2]):
        _, _, nl_max, nl_rms = numpy_nonlinearity(x[i, :m], y[i, :m])
        assert float(fit.nonlinearity_max_ppm[i]) == pytest.approx(nl_max, rel=1e-9)
        assert float(fit.nonlinearity_rms_ppm[i]) == pytest.approx(nl_rms, rel=1e-9)
    assert np.isnan(fit.scale_factor[2]) and np.isnan(fit.nonlinearity_max_ppm[2])

    # Gradients stay finite through masked garbage.
    grad = jax.grad(lambda yy: jnp.nansum(fit_scale_factor(x, yy, mask=mask).nonlinearity_rms_ppm))(y)
    assert np.all(np.isfinite(grad[mask])) and np.all(grad[~mask] == 0)


def test_gradient_matches_finite_differences():
    x = RATES
    y0 = 0.01 * x + 1e-9 * x**3 + 1e-6 * np.cos(x)

    def f(y):
        return fit_scale_factor(x, y).nonlinearity_rms_ppm

    g = jax.grad(f)(y0)
    e = np.zeros_like(y0)
    e[4] = 1e-7
    fd = (f(y0 + e) - f(y0 - e)) / 2e-7
    assert float(g[4]) == pytest.approx(float(fd), rel=1e-5)


def test_too_few_points():
    with pytest.raises(DataError, match=r"a sweep at batch index \(1,\) has fewer than 3 valid points"):
        fit_scale_factor(np.ones((2, 4)) * np.arange(4.0), np.arange(8.0).reshape(2, 4),
                         mask=np.array([[True] * 4, [True, True, False, False]]))
    jitted = eqx.filter_jit(lambda x, y, m: fit_scale_factor(x, y, mask=m).scale_factor)
    with pytest.raises(Exception, match="fewer than 3 valid points"):
        jitted(jnp.arange(4.0), jnp.arange(4.0), jnp.array([True, True, False, False])).block_until_ready()


@pytest.mark.parametrize("common_bias", [True, False])
def test_asymmetry_two_slope_line(common_bias):
    k_pos, k_neg, bias = 1.0003, 0.9999, 0.7
    y = np.where(RATES > 0, k_pos * RATES, k_neg * RATES) + bias
    expected = 1e6 * (k_pos - k_neg) / ((k_pos + k_neg) / 2)  # 400.02 ppm
    got = float(asymmetry(RATES, y, common_bias=common_bias))
    assert got == pytest.approx(expected, rel=1e-9)
    # Sign: the same relative asymmetry with a negative scale factor.
    assert float(asymmetry(RATES, -y, common_bias=common_bias)) == pytest.approx(expected, rel=1e-9)


def test_asymmetry_dac_word_magnitudes():
    # DAC words reach 2.7e6: the common-bias normal equations are scaled, so ppm accuracy survives.
    words = RATES * 13725.8
    y = np.where(words > 0, 6.0e-7 * words, 5.999e-7 * words) - 7e-6
    assert float(asymmetry(words, y)) == pytest.approx(1e6 * 0.001e-7 / 5.9995e-7, rel=1e-7)


def test_asymmetry_models_differ_on_a_curve_and_one_sided_is_nan():
    # On a symmetric grid an even term gives the same K+ - K- either way; on a lopsided one it does not.
    x = RATES[RATES < 60]
    y = x + 1e-5 * x**2
    common, separate = float(asymmetry(x, y)), float(asymmetry(x, y, common_bias=False))
    assert common > 0 and separate > 0 and abs(common - separate) > 1.0
    y = RATES + 1e-5 * RATES**2
    assert float(asymmetry(RATES, y)) == pytest.approx(float(asymmetry(RATES, y, common_bias=False)), rel=1e-9)
    assert np.isnan(asymmetry(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0])))
    with pytest.raises(DataError, match="at least 2 positive and 2 negative"):
        asymmetry(np.array([-1.0, 1.0, 2.0, 3.0]), np.array([-1.0, 1.0, 2.0, 3.0]), common_bias=False)


def test_repeatability():
    assert float(repeatability(np.array([1.0, 1.001, 0.999]))) == pytest.approx(1000.0, rel=1e-9)
    assert float(repeatability(np.array([1.0, 1.001, 0.999]), ddof=0)) == pytest.approx(
        1000.0 * math.sqrt(2 / 3), rel=1e-9)
    sf = np.array([[13709.0, 13725.0, 13700.0], [-2.0, -2.002, 0.0]])
    mask = np.array([[True, True, True], [True, True, False]])
    rep = repeatability(sf, mask=mask)
    assert float(rep[0]) == pytest.approx(1e6 * np.std(sf[0], ddof=1) / np.mean(sf[0]), rel=1e-12)
    assert float(rep[1]) == pytest.approx(1e6 * np.std([2, 2.002], ddof=1) / 2.001, rel=1e-12)
    assert np.isnan(repeatability(np.array([5.0])))  # one run shows no repeatability


def test_bandwidth_first_order():
    fc = 100.0
    f = np.geomspace(1, 1000, 31)[::-1]  # any order
    h = 1 / (1 + 1j * f / fc)
    res = rate_bandwidth(f, 3.0 * np.abs(h), phase_deg=np.degrees(np.angle(h)))
    # The response is a curve in (log f, dB); interpolation between points 1/10 decade apart is close.
    # G0 is the 1 Hz amplitude, 1e-4 dB below DC: the crossing is at fc to well under the interpolation error.
    assert float(res.bandwidth_hz) == pytest.approx(fc, rel=5e-3)
    assert float(res.phase_deg) == pytest.approx(-45.0, abs=0.5)
    assert float(res.low_frequency_gain) == pytest.approx(3.0 / math.sqrt(1 + 1e-4), rel=1e-12)


def test_bandwidth_passes_over_a_resonant_peak():
    # Open-loop rate response: a second-order peak at 77 Hz with Q = 3, then roll-off.
    f = np.geomspace(1, 2000, 200)
    f0, q = 77.0, 3.0
    h = 1 / (1 - (f / f0) ** 2 + 1j * f / (f0 * q))
    res = rate_bandwidth(f, np.abs(h))
    exact_f = np.geomspace(80, 400, 200001)
    exact = exact_f[np.argmax(np.abs(1 / (1 - (exact_f / f0) ** 2 + 1j * exact_f / (f0 * q))) < 1 / math.sqrt(2))]
    assert float(res.bandwidth_hz) == pytest.approx(exact, rel=2e-3)
    assert float(res.bandwidth_hz) > f0


def test_bandwidth_never_crosses_and_masks():
    f = np.array([1.0, 10.0, 100.0])
    with pytest.raises(DataError, match=r"never falls below its low-frequency gain / sqrt\(2\)"):
        rate_bandwidth(f, np.array([1.0, 0.9, 0.8]))
    amp = np.array([[1.0, 0.9, 0.1], [1.0, 0.1, 0.0]])
    res = rate_bandwidth(np.stack([f, f]), amp, mask=np.array([[True, True, True], [True, True, False]]))
    assert float(res.bandwidth_hz[1]) == pytest.approx(10 ** (math.log10(1 / math.sqrt(2)) / -1.0), rel=1e-12)
    assert np.isnan(res.phase_deg[0])


# ---------------------------------------------------------------------------------------------------------------
# The report.


def lot_table():
    rows = []
    sfs = {("A", 0): 13709.0, ("A", 1): 13720.0, ("A", 2): 13700.0, ("B", 0): -13690.0}
    for (dev, run), sf in sfs.items():
        for r in RATES:
            rows.append({"device": dev, "run": run, "sweep": "rate_table", "input": r,
                         "output": sf * r * (1 + 1e-9 * r**2) + 5.0 + run})
    for k, r in enumerate(RATES):
        word = int(round(-r * 13725.8))
        rows.append({"device": "A", "run": 0, "sweep": "dac", "input": word,
                     "output": word * 5 / 2**23 * (1 + 1e-4 * (k % 2)), "rate_dps": r})
    for f in [1, 10, 30, 60, 100, 110, 120, 130, 150, 300, 1000]:
        rows.append({"device": "B", "run": 0, "sweep": "vcf_dynamic", "input": f,
                     "output": 50 / math.hypot(1, f / 120), "phase_deg": -math.degrees(math.atan(f / 120))})
    return Table.from_records(rows, source="lot.csv"), sfs


def test_metrics_report_structure_and_values():
    table, sfs = lot_table()
    report = metrics_report(table)
    json.dumps(report.to_json())  # JSON-ready
    keys = [(p.device, p.run, p.sweep) for p in report.points]
    assert keys == [("A", 0, "rate_table"), ("A", 1, "rate_table"), ("A", 2, "rate_table"),
                    ("B", 0, "rate_table"), ("A", 0, "dac"), ("B", 0, "vcf_dynamic")]
    first = report.points[0]
    k, b, nl_max, nl_rms = numpy_nonlinearity(RATES, table["output"][:22])
    assert first.scale_factor == pytest.approx(k, rel=1e-12)
    assert first.bias == pytest.approx(b, rel=1e-9)
    assert first.nonlinearity_max_ppm == pytest.approx(nl_max, rel=1e-9)
    assert first.nonlinearity_rms_ppm == pytest.approx(nl_rms, rel=1e-9)
    assert abs(first.asymmetry_ppm) < 1e-6  # odd cubic: symmetric
    assert first.vs_rate is None and "nonlinearity_max_ppm_vs_rate" not in first.to_json()
    dac = report.points[4]
    assert dac.scale_factor == pytest.approx(5 / 2**23, rel=1e-4)
    assert dac.vs_rate.scale_factor == pytest.approx(-13725.8 * 5 / 2**23, rel=1e-4)
    k_rate, _, max_rate, rms_rate = numpy_nonlinearity(RATES, table["output"][88:110])
    assert dac.vs_rate.nonlinearity_max_ppm == pytest.approx(max_rate, rel=1e-9)
    assert dac.vs_rate.nonlinearity_rms_ppm == pytest.approx(rms_rate, rel=1e-9)
    dyn = report.points[5]
    assert dyn.scale_factor is None and dyn.bandwidth.bandwidth_hz == pytest.approx(120, rel=2e-3)
    assert dyn.bandwidth.phase_deg_at_bandwidth == pytest.approx(-45, abs=0.3)
    assert dyn.bandwidth.low_frequency_gain == pytest.approx(50 / math.hypot(1, 1 / 120), rel=1e-12)

    devices = {(d.device, d.sweep): d for d in report.devices}
    a_sf = [p.scale_factor for p in report.points[:3]]
    assert devices[("A", "rate_table")].repeatability_ppm == pytest.approx(
        1e6 * np.std(a_sf, ddof=1) / np.mean(a_sf), rel=1e-10)
    assert devices[("A", "rate_table")].n_runs == 3
    assert devices[("B", "rate_table")].repeatability_ppm is None
    assert ("B", "vcf_dynamic") not in devices


def test_metrics_report_names_a_short_sweep():
    table, _ = lot_table()
    rows = [i for i in range(len(table)) if not (table["device"][i] == "A" and table["run"][i] == 1)]
    rows += [i for i in range(len(table)) if table["device"][i] == "A" and table["run"][i] == 1][:2]
    short = table.select(rows)
    first = len(short) - 1  # the two kept points are the last rows, 1-based
    with pytest.raises(DataError, match=re.escape(f"lot.csv: device 'A', run 1, sweep 'rate_table' (data row {first} "
                                                  f"to data row {first + 1}) has 2 points; a scale factor with a "
                                                  "nonlinearity needs at least 3")):
        metrics_report(short)


def test_metrics_report_refusals():
    table, _ = lot_table()
    with pytest.raises(DataError, match=re.escape("column 'output_sigma': weighted=True needs a positive "
                                                  "output_sigma")):
        metrics_report(table, weighted=True)
    cols = table.columns
    rate = cols["rate_dps"].copy()
    rate[90] = np.nan
    cols["rate_dps"] = rate
    with pytest.raises(DataError, match=re.escape("data row 91, column 'rate_dps': rate_dps is given for some "
                                                  "points of device 'A', run 0, sweep 'dac'")):
        metrics_report(Table(cols, source="lot.csv"))


def test_jax_and_numpy_paths_agree():
    # NumPy in, NumPy out (no compilation: fast reports); JAX in, JAX out (jit, vmap, grad).
    rng = np.random.default_rng(8)
    x = np.stack([RATES, RATES, 2 * RATES])
    y = x * (1 + 1e-8 * x**2) + rng.normal(size=x.shape)
    mask = np.ones(x.shape, dtype=bool)
    mask[2, -3:] = False
    ref = fit_scale_factor(x, y, mask=mask)
    assert isinstance(ref.scale_factor, np.ndarray)

    @eqx.filter_jit
    def run(x, y, mask):
        fit = fit_scale_factor(x, y, mask=mask)
        return fit, asymmetry(x, y, mask=mask), repeatability(fit.scale_factor[:2])

    fit, asym, rep = run(jnp.asarray(x), jnp.asarray(y), jnp.asarray(mask))
    assert isinstance(fit.scale_factor, jax.Array)
    for name in ("scale_factor", "bias", "nonlinearity_max_ppm", "nonlinearity_rms_ppm", "full_scale"):
        np.testing.assert_allclose(getattr(fit, name), getattr(ref, name), rtol=1e-12, err_msg=name)
    np.testing.assert_allclose(asym, asymmetry(x, y, mask=mask), rtol=1e-9)
    np.testing.assert_allclose(rep, repeatability(ref.scale_factor[:2]), rtol=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# Outputs that do not change with the input: no number that was not measured.


@pytest.mark.parametrize("level", [0.0, 5.0, 0.1, 13771.123])
def test_constant_outputs_give_slope_zero_and_no_nonlinearity(level):
    # Before: 0.1 gave a round-off slope of -8e-35 and a "nonlinearity" of 5.6e21 ppm, asymmetry -2.9e6 ppm.
    y = np.full(RATES.shape, level)
    for xp in (np, jnp):
        fit = fit_scale_factor(xp.asarray(RATES), xp.asarray(y))
        assert float(fit.scale_factor) == 0.0
        assert float(fit.bias) == level
        assert math.isnan(float(fit.nonlinearity_max_ppm)) and math.isnan(float(fit.nonlinearity_rms_ppm))
        assert math.isnan(float(asymmetry(xp.asarray(RATES), xp.asarray(y))))
        assert math.isnan(float(asymmetry(xp.asarray(RATES), xp.asarray(y), common_bias=False)))


def test_constant_outputs_under_jit_and_grad():
    @jax.jit
    def nl(scale):
        return fit_scale_factor(jnp.asarray(RATES), scale * jnp.full(RATES.shape, 0.1)).scale_factor

    assert float(nl(1.0)) == 0.0
    assert float(jax.grad(nl)(1.0)) == 0.0


def test_metrics_report_says_why_a_number_is_missing():
    rows = [{"device": "A", "run": r, "sweep": "rate_table", "input": x, "output": 0.1 * x if r == 1 else 3.0 * x}
            for r in (0, 1) for x in (-10.0, -5.0, 0.0, 5.0, 10.0)]
    rows += [{"device": "B", "run": 0, "sweep": "rate_table", "input": x, "output": 2.0 * x} for x in (1.0, 2.0, 3.0)]
    # a quadrature injection whose outputs do not change: a slope of 0, measured (its sign is no convention)
    rows += [{"device": "C", "run": 0, "sweep": "quadrature_injection", "input": x, "output": 0.1}
             for x in (-1.0, 0.0, 1.0)]
    report = metrics_report(Table.from_records(rows, source="flat.csv"))
    json.dumps(report.to_json(), allow_nan=False)
    good, straight, one_sided, flat = report.points
    assert good.not_applicable == {} and straight.not_applicable == {}
    assert flat.scale_factor == 0.0 and flat.nonlinearity_max_ppm is None and flat.asymmetry_ppm is None
    assert flat.not_applicable["nonlinearity_max_ppm"].startswith("not a measurement on a quadrature_injection")
    assert set(flat.not_applicable) == {"nonlinearity_max_ppm", "nonlinearity_rms_ppm", "asymmetry_ppm"}
    assert one_sided.not_applicable == {
        "asymmetry_ppm": "the sweep lacks positive or negative inputs; an asymmetry needs both signs"}
    dev = {d.device: d for d in report.devices}
    assert dev["A"].repeatability_ppm is not None  # 3 and 0.1: measured, enormous
    assert dev["B"].not_applicable == {"repeatability_ppm": "1 run: a repeatability needs at least 2"}
    opposite = [dict(r, output=float(r["input"]) * (1.0 if r["run"] == 0 else -1.0)) for r in rows[:10]]
    (d,) = metrics_report(Table.from_records(opposite)).devices
    assert d.repeatability_ppm is None and "mean scale factor is 0" in d.not_applicable["repeatability_ppm"]
