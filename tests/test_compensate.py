"""Compensation: polynomial, seed 000's composite method, model-based; held-out judging; CLI; Table 3 script."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _experiments import load_experiment

import gyrojax as gj
from gyrojax._compensate.balance import describing_weight, fundamental
from gyrojax._compensate.composite import side_segment_starts
from gyrojax._compensate.model import _fit_arrays
from gyrojax._presets import QMG_QUADRATURE_DPS
from gyrojax.cli import main


TYPICAL_INL = {3: -1063.6, 5: 3418.6}  # gyrojax.effects.DacInl.typical(): LSB coefficients of u^3 and u^5
TCF = -30e-6  # paper_qmg's silicon TCF, 1/K


def _device(table):
    return str(table["device"][0])


def _load_experiment():
    return load_experiment("seed000_table3_compensation")


EXPERIMENT = _load_experiment()


@pytest.fixture(scope="module")
def warmup_table():
    """Noise-free paper-like device: typical DAC INL, three runs each warming up by the same rise, the first one
    slowly (it sweeps through its warm-up). The same device and protocol as the Table 3 experiment, so the
    compiled sweep is shared."""
    gyro = gj.add_effect(gj.paper_qmg(), "dac_inl", 1.0)
    protocol = EXPERIMENT.protocol(EXPERIMENT.WARMUP_RISE_K)
    table = gj.simulate_table(gyro, runs=3, noise_free=True, protocol=protocol)
    return gj.Table(table.columns, source="warmup.csv")


# ---------------------------------------------------------------------------------------------------------------
# polynomial


def test_polynomial_is_exact_on_polynomial_data():
    y = np.linspace(-2.5e6, 2.7e6, 23)
    a = np.array([0.3, 190.0, -0.8, 2.5])  # deg/s per (y / max|y|)^k
    u = y / np.max(np.abs(y))
    rate = a[0] + a[1] * u + a[2] * u**2 + a[3] * u**3
    sol = gj.compensation.PolynomialCompensator(order=3).fit(gj.compensation.RatePoints(rate, y))
    np.testing.assert_allclose(np.asarray(sol.coefficients), a, rtol=1e-10, atol=1e-10)
    y_new = np.array([-1.9e6, 0.0, 1.23e6])
    u_new = y_new / np.max(np.abs(y))
    np.testing.assert_allclose(np.asarray(sol.rate(y_new)),
                               a[0] + a[1] * u_new + a[2] * u_new**2 + a[3] * u_new**3, rtol=1e-12, atol=1e-10)
    # a cubic cannot hold a quintic: order 3 leaves a residual that order 5 removes
    rate5 = rate + 0.4 * u**5
    points = gj.compensation.RatePoints(rate5, y)
    res3 = rate5 - np.asarray(gj.compensation.PolynomialCompensator(order=3).fit(points).rate(y))
    res5 = rate5 - np.asarray(gj.compensation.PolynomialCompensator(order=5).fit(points).rate(y))
    assert np.max(np.abs(res3)) > 1e-2 and np.max(np.abs(res5)) < 1e-10


def test_polynomial_refuses_bad_settings_and_too_few_points():
    with pytest.raises(ValueError, match="order must be an integer >= 1, got 0"):
        gj.compensation.PolynomialCompensator(order=0)
    with pytest.raises(ValueError, match="needs at least 5 distinct training outputs, got 4"):
        gj.compensation.PolynomialCompensator(order=3).fit(
            gj.compensation.RatePoints([1.0, 2, 3, 4], [10.0, 20, 30, 40]))


# ---------------------------------------------------------------------------------------------------------------
# composite (seed 000 Fig. 7)


@pytest.mark.parametrize("errors,starts", [
    ([0, 0, 0, 0, 1, 3, 6, 10, 15, 21], [0, 3]),      # flat, then 6 accelerating steps: a boundary at point 3
    ([0, 0, 0, 0, 0, 0, 1, 3, 6], [0]),                # only 3 positive second differences: no boundary
    ([0, 1, 3, 6, 10, 10, 10, 11, 13, 16, 20], [0, 6]),  # the counter resets on the plateau, then runs again
    ([0, -1, -3, -6, -10, -15], [0, 1]),               # accelerating from point 1 (the first second difference)
])
def test_composite_counter_rule(errors, starts):
    assert side_segment_starts(np.asarray(errors, dtype=float), threshold=4) == starts


def test_composite_counter_threshold_is_configurable():
    e = np.array([0, 0, 0, 0, 0, 0, 1, 3, 6.0])
    assert side_segment_starts(e, threshold=3) == [0, 5]
    with pytest.raises(ValueError, match="threshold must be an integer >= 1, got 0"):
        gj.compensation.CompositeCompensator(threshold=0)


def _piecewise_points(f_hz, bias):
    """Calibrated outputs u (LSB) whose rate is a different cubic of u on each side of zero, measured at drive
    frequencies f_hz (so the raw output is (u + bias) f / k_t with k_t the mean training frequency 4634 Hz)."""
    rates_u = 1.0e4 * np.asarray(gj.sweeps.DING_ZHOU_2025_RATES_DPS)
    s = rates_u / 2.0e6
    rate = np.where(s >= 0, 200 * s + 0.3 * s**2 - 0.9 * s**3, 200 * s - 0.2 * s**2 + 0.5 * s**3)
    return rate, (rates_u + bias) * f_hz / 4634.0


def test_composite_is_exact_on_a_piecewise_cubic_with_its_own_calibration():
    n = len(gj.sweeps.DING_ZHOU_2025_RATES_DPS)
    f_train = np.concatenate([np.full(n, 4634.0 * (1 + 2e-4)), np.full(n, 4634.0 * (1 - 2e-4))])  # mean 4634
    rate_a, out_a = _piecewise_points(f_train[:n], 50.0)
    rate_b, out_b = _piecewise_points(f_train[n:], 50.0)
    train = gj.compensation.RatePoints(np.concatenate([rate_a, rate_b]), np.concatenate([out_a, out_b]),
                                       drive_freq_hz=f_train, run=np.repeat([0, 1], n))
    sol = gj.compensation.CompositeCompensator().fit(train)
    assert float(sol.k_t_hz) == pytest.approx(4634.0, rel=1e-15)
    assert sol.summary()["segments_dps"] == [[float(rate_a.min()), float(rate_a[rate_a < 0].max())],
                                             [float(rate_a[rate_a > 0].min()), float(rate_a.max())]]
    # training points and a held-out run 900 ppm hotter in drive frequency: exact (the SF tracks f exactly)
    for f in (f_train[:n], np.full(n, 4634.0 * (1 - 9e-4))):
        rate, out = _piecewise_points(f, 50.0)
        np.testing.assert_allclose(np.asarray(sol.rate(out, drive_freq_hz=f)), rate, rtol=1e-9, atol=1e-9)
    # the Hermite bridge across zero is C1: value and slope match the segment cubics at both ends
    lo, hi = float(sol.edges[0]), float(sol.edges[1])
    eps = 1e-7 * (hi - lo)

    def curve(u):
        return sol.error_curve(u[None])[0]

    for edge in (lo, hi):
        a, b = jnp.asarray(edge - eps), jnp.asarray(edge + eps)
        dl, dr = float(jax.grad(curve)(a)), float(jax.grad(curve)(b))
        assert abs(float(curve(b) - curve(a))) <= 2 * eps * max(abs(dl), abs(dr)) * 1.001 + 1e-12
        assert dl == pytest.approx(dr, rel=1e-5)
    with pytest.raises(ValueError, match=r"rate\(\) needs drive_freq_hz="):
        sol.rate(out_a)


@pytest.mark.slow
def test_composite_removes_the_warmup_and_most_of_the_inl(warmup_table):
    res = gj.compensate(warmup_table, method="composite", train_runs=[0, 1])
    held = [r for r in res.runs if not r.used_for_training]
    assert [r.run for r in held] == [2]
    before, after = held[0].nonlinearity_max_ppm_before, held[0].nonlinearity_max_ppm_after
    assert 440 < before < 520 and after < 6.0  # a cubic per side of a u^3 + u^5 INL leaves ~4 ppm
    dev = res.devices[0]
    # the initial calibration takes out the run-to-run SF change that tracks the drive frequency
    assert dev.repeatability_ppm_before > 50 and dev.repeatability_ppm_after < 1.0


# ---------------------------------------------------------------------------------------------------------------
# model


def test_describing_function_matches_the_carrier_samples():
    """D(W) against the in-phase fundamental of the INL applied to the instantaneous samples W sin + Q cos."""
    assert describing_weight(3) == 0.75 and describing_weight(5) == 0.625 and describing_weight(4) == 0.0
    theta = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    inl = {2: 11.4, 3: -1063.6, 4: 250.0, 5: 3418.6}  # DAC LSB at u = code / 2^15
    for q in (0.0, 4.0e5):
        spec = gj.compensation.ModelCompensator(inl_orders=(2, 3, 4, 5), quadrature_lsb=q)
        for w in (-2.7e6, 1.0e5, 2.7e6):
            u = (w * np.sin(theta) + q * np.cos(theta)) / 2.0**23
            inl_words = 256.0 * sum(c * u**n for n, c in inl.items())  # DAC LSB -> 24-bit word LSB
            expected = w + 2 * np.mean(inl_words * np.sin(theta))
            got = fundamental(jnp.asarray(w), jnp.asarray(list(inl.values())), spec)
            assert float(got) == pytest.approx(expected, rel=1e-13, abs=1e-7)


@pytest.mark.slow
def test_model_recovers_inl_and_tcf_on_noise_free_data(warmup_table):
    res = gj.compensate(warmup_table, method="model", train_runs=[0, 1])
    sol = res.solutions[_device(warmup_table)]
    inl = dict(zip(sol.inl_orders, np.asarray(sol.inl_lsb)))
    # paper-qmg carries a 10 deg/s quadrature word Q beside the rate word; left out of the model (the default),
    # the u^5 term's (W^2 + Q^2)^2 W moves 2 (rho5/rho3) c5 (Q/H)^2 onto the u^3 coefficient
    q_over_h = QMG_QUADRATURE_DPS * float(sol.sf_ref) / 2.0**23
    shift = 2 * (0.625 / 0.75) * TYPICAL_INL[5] * q_over_h**2
    assert 1.4 < shift < 1.6
    assert inl[3] == pytest.approx(TYPICAL_INL[3] + shift, abs=0.05)  # DAC LSB (37 LSB at 200 deg/s)
    assert inl[5] == pytest.approx(TYPICAL_INL[5], abs=0.5)
    # the fitted TCF is relative to the drive frequency at the mean training temperature, the preset's at 25 C
    t_ref = float(sol.t_ref_c)
    assert float(sol.tcf_per_k) == pytest.approx(TCF / (1 + TCF * (t_ref - 25.0)), rel=1e-7)
    assert bool(sol.converged) and sol.unidentifiable == ()
    held = next(r for r in res.runs if r.run == 2)
    # left: beta held at 1 (the DAC hold makes it 1.00007) and the unmodelled quadrature's A^2 = W^2 + Q^2
    assert not held.used_for_training and held.nonlinearity_max_ppm_after < 0.01
    assert held.nonlinearity_max_ppm_before > 400
    assert res.devices[0].repeatability_ppm_after < 0.01 and res.devices[0].repeatability_ppm_before > 50
    # the output model (Newton on the balance) and its inverse are each other's
    pts = gj.compensation.rate_points(warmup_table, _device(warmup_table))
    y = sol.output(pts.rate_dps, drive_freq_hz=pts.drive_freq_hz)
    np.testing.assert_allclose(np.asarray(sol.rate(y, drive_freq_hz=pts.drive_freq_hz)), pts.rate_dps,
                               rtol=1e-12, atol=1e-9)


@pytest.mark.slow
def test_model_identifies_the_frequency_exponent_and_reports_even_orders(warmup_table):
    cfg = gj.compensation.ModelCompensator(inl_orders=(2, 3, 5), frequency_exponent=None)
    sol = gj.compensate(warmup_table, method=cfg, train_runs=[0, 1]).solutions[_device(warmup_table)]
    # SF tracks w_d (Eq. 2); the DAC hold's sinc gain adds 2 (w T/2)^2 / 6 ~ 7e-5 to the exponent
    assert float(sol.frequency_exponent) == pytest.approx(1.0, abs=2e-4)
    assert float(sol.stderr["frequency_exponent"]) < 1e-3
    # even INL terms never reach the carrier fundamental: reported, held at zero, never guessed
    assert sol.unidentifiable == ("inl_u2_lsb",) and float(sol.inl_lsb[0]) == 0.0
    assert sol.summary()["parameters"]["inl_u2_lsb"]["stderr"] is None
    assert float(sol.inl_lsb[2]) == pytest.approx(TYPICAL_INL[5], abs=0.5)


@pytest.mark.slow
def test_model_fit_is_differentiable_in_the_data(warmup_table):
    """d(fitted u^3 INL)/d(outputs) by forward mode through the Levenberg-Marquardt optimum (implicit
    differentiation) against central finite differences."""
    pts = gj.compensation.rate_points(warmup_table, _device(warmup_table))
    pts = pts.select(np.isin(pts.run, [0, 1]))
    n = len(pts)
    data = {"x": jnp.asarray(pts.rate_dps), "y": jnp.asarray(pts.output), "f": jnp.asarray(pts.drive_freq_hz),
            "temp": jnp.asarray(pts.temperature_c), "sigma": jnp.ones(n),
            "run_index": jnp.asarray(np.repeat([0, 1], n // 2)), "beta0": jnp.asarray(1.0)}
    free = (True, False) + (True,) * 7  # the default: beta held at 1, everything else fitted

    def inl3(y):
        return _fit_arrays(gj.compensation.ModelCompensator(), 2, True, free, {**data, "y": y})["theta"][2]

    direction = jnp.asarray(np.random.default_rng(3).normal(size=n))  # LSB
    _, tangent = jax.jvp(inl3, (data["y"],), (direction,))
    fd = (inl3(data["y"] + direction) - inl3(data["y"] - direction)) / 2.0
    assert float(tangent) == pytest.approx(float(fd), rel=1e-5)
    assert abs(float(tangent)) > 0.1


def test_model_refuses_bad_settings():
    with pytest.raises(ValueError, match=r"inl_orders must be a non-empty tuple of distinct integers >= 2"):
        gj.compensation.ModelCompensator(inl_orders=(1, 3))
    with pytest.raises(ValueError, match="word_bits must be an integer >= dac_bits"):
        gj.compensation.ModelCompensator(dac_bits=16, word_bits=12)
    pts = gj.compensation.RatePoints([1.0, 2.0, 3.0, 4.0], [10.0, 20.0, 30.0, 40.0], drive_freq_hz=[4634.0] * 4)
    with pytest.raises(ValueError, match="needs at least 5 distinct training rates"):
        gj.compensation.ModelCompensator().fit(pts)
    with pytest.raises(ValueError, match="needs drive_freq_hz on every point; 4 of 4"):
        gj.compensation.ModelCompensator().fit(
            gj.compensation.RatePoints([1.0, 2.0, 3.0, 4.0], [10.0, 20.0, 30.0, 40.0]))


# ---------------------------------------------------------------------------------------------------------------
# compensate(): held-out judging and errors


@pytest.mark.slow
def test_compensate_flags_training_runs_and_defaults_to_the_first(warmup_table):
    res = gj.compensate(warmup_table, method="polynomial")
    assert [(r.run, r.used_for_training) for r in res.runs] == [(0, True), (1, False), (2, False)]
    dev = res.devices[0]
    assert dev.train_runs == (0,) and dev.held_out_runs == (1, 2)
    # a fixed polynomial cannot change the ratio of two runs' scale factors: repeatability stays
    assert dev.repeatability_ppm_after == pytest.approx(dev.repeatability_ppm_before, rel=0.02)
    # trained on the warm-up run, it bakes that run's drift in: worse on the settled held-out runs
    train, held = res.runs[0], res.runs[1]
    assert held.nonlinearity_max_ppm_after > 2 * train.nonlinearity_max_ppm_after
    assert dev.worst_nonlinearity_max_ppm_held_out_after == max(r.nonlinearity_max_ppm_after
                                                                   for r in res.runs[1:])
    rec = res.runs[1]
    assert max(abs(v) for v in rec.residuals_ppm_after) == pytest.approx(rec.nonlinearity_max_ppm_after)
    json.dumps(res.to_json(), allow_nan=False)


@pytest.mark.slow
def test_compensate_errors(warmup_table):
    with pytest.raises(gj.DataError, match=r"train_runs names run 7, which device 'paper-qmg.*' does not have "
                                           r"\(its rate_table runs: 0, 1, 2\)"):
        gj.compensate(warmup_table, method="composite", train_runs=[0, 7])
    with pytest.raises(ValueError, match="method must be one of polynomial, composite, model .* got 'spline'"):
        gj.compensate(warmup_table, method="spline")
    with pytest.raises(ValueError, match=r"train_runs must be a non-empty list of run ids \(integers\), got \[\]"):
        gj.compensate(warmup_table, train_runs=[])
    cols = warmup_table.columns
    cols["drive_freq_hz"] = cols["drive_freq_hz"].copy()
    cols["drive_freq_hz"][30] = np.nan
    holed = gj.Table(cols, source="holed.csv")
    with pytest.raises(gj.DataError, match=r"holed.csv: data row 31, column 'drive_freq_hz': model compensation "
                                           r"needs drive_freq_hz on every rate_table point; device 'paper-qmg.*', "
                                           r"run 1 lacks it"):
        gj.compensate(holed, method="model")
    # the polynomial method needs no side information
    assert len(gj.compensate(holed, method="polynomial").runs) == 3


# ---------------------------------------------------------------------------------------------------------------
# command line


@pytest.mark.slow
def test_cli_compensate_json(warmup_table, tmp_path, capsys):
    data, out = tmp_path / "runs.csv", tmp_path / "comp.json"
    gj.write_table(warmup_table, data)
    assert main(["compensate", str(data), "--method", "composite", "--train-runs", "0,1", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["method"] == "composite"
    run_keys = {"device", "run", "used_for_training", "nonlinearity_max_ppm_before", "nonlinearity_max_ppm_after"}
    assert all(run_keys <= set(r) for r in report["runs"])
    assert [r["used_for_training"] for r in report["runs"]] == [True, True, False]
    dev = report["devices"][0]
    assert {"repeatability_ppm_before", "repeatability_ppm_after"} <= set(dev)
    assert dev["repeatability_ppm_after"] < dev["repeatability_ppm_before"]
    assert "held-out" in capsys.readouterr().out


@pytest.mark.parametrize("argv,message", [
    (["--train-runs", "0,9"], "train_runs names run 9"),
    (["--method", "polynomial", "--train-runs", "2"], None),
])
@pytest.mark.slow
def test_cli_compensate_exit_codes(warmup_table, tmp_path, capsys, argv, message):
    data = tmp_path / "runs.csv"
    gj.write_table(warmup_table, data)
    rc = main(["compensate", str(data), *argv])
    err = capsys.readouterr().err
    assert rc == (2 if message else 0)
    if message:
        assert message in err and "Traceback" not in err


@pytest.mark.parametrize("argv,message", [
    (["--method", "spline"], "invalid choice: 'spline'"),
    (["--train-runs", "a,b"], "--train-runs expects run ids like 0,1, got 'a,b'"),
])
def test_cli_compensate_usage_errors_exit_2(tmp_path, capsys, argv, message):
    try:  # argparse's exit, returned by main() or raised through it
        rc = main(["compensate", str(tmp_path / "x.csv"), *argv])
    except SystemExit as exc:
        rc = exc.code
    assert rc == 2
    assert message in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------------------
# experiments/seed000_table3_compensation.py


@pytest.mark.slow
def test_table3_experiment_reproduces_the_ordering(tmp_path, capsys):
    out = EXPERIMENT.main(["--out", str(tmp_path), "--quick"])
    res = out["results"]
    worst = {m: max(res[m]["runs_ppm"]) for m in EXPERIMENT.METHODS}
    assert worst["uncompensated"] > worst["polynomial"] > worst["composite"] > worst["model"]
    assert out["ordering_reproduced"]
    assert out["model_over_composite_worst_nonlinearity"] > 2.0
    # both calibrate the thermal state out of the scale factor; what is left is the noise's
    assert max(res["model"]["repeatability_ppm"], res["composite"]["repeatability_ppm"]) < 5.0
    assert res["uncompensated"]["repeatability_ppm"] > 50.0
    for name in ("table3.json", "table3.md", "fig10.png", "data.csv"):
        assert (tmp_path / name).stat().st_size > 0
    assert "REPRODUCED" in capsys.readouterr().out


def test_a_run_whose_outputs_do_not_change_is_refused_by_name():
    """A disconnected or saturated output gives the same value at every rate: no scale factor to compensate,
    so no 'after' figure may be computed from round-off (it was 3.5 ppm from a 1e-11 slope)."""
    rates = np.asarray(gj.sweeps.DING_ZHOU_2025_RATES_DPS)
    records = [{"device": "d", "run": r, "sweep": "rate_table", "input": x,
                "output": 13709.8 * x if r == 0 else 5.0, "drive_freq_hz": 4634.0 + 1e-3 * i}
               for r in (0, 1) for i, x in enumerate(rates)]
    table = gj.Table.from_records(records, source="constant.csv")
    with pytest.raises(gj.DataError, match=r"constant.csv: data row 23.*device 'd', run 1: the rate_table outputs "
                                           r"are all 5.0, the same at every rate"):
        gj.compensate(table, method="composite")
