"""Protocols and simulated measurements (issue 3): every sweep kind for both presets, the measurement model
they go through, the temperature history, the noise and its honest uncertainty, files, the CLI and the seed 003
batch experiment.

Compile time rules the cost here: every test shares two module-scoped campaigns (one per preset, noisy and
noise-free, same shapes), so each sweep kind is compiled once per preset. The CLI and the experiment run
with the same lot sizes and reuse those compiled functions.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from _experiments import load_experiment

import gyrojax as gj
from gyrojax import RateNoise
from gyrojax._sweeps import dac as sweeps_dac, vcf_dynamic as sweeps_vcf_dynamic
from gyrojax._sweeps.steady import lot_steady
from gyrojax.cli import main as cli


DEG = gj.units.DEG
QMG_DEVICES, QMG_RUNS = 3, 8  # 528 rate-table points: enough for a chi^2 test at +/-0.2
VCF_DEVICES, VCF_RUNS = 3, 1  # the experiment's and the CLI test's sizes too (same compiled functions)
ALL = ("rate_table", "vcf_static", "vcf_dynamic", "dac")
OPEN = ("rate_table", "vcf_static", "vcf_dynamic")


def _campaign_pair(gyro, devices, runs, sweeps, seed):
    kw = dict(devices=devices, runs=runs, sweeps=sweeps, seed=seed)
    return {"noisy": gj.simulate_table(gyro, **kw), "clean": gj.simulate_table(gyro, noise_free=True, **kw),
            "lot": gj.campaign_lot(gyro, devices=devices, seed=seed), "gyro": gyro, "seed": seed}


def _ideal_qmg():
    """paper-qmg without its assumed residual quadrature: an ideal closed-loop device (linear, bias-free)."""
    g = gj.paper_qmg()
    return eqx.tree_at(lambda g: g.resonator.stiffness_coupling, g, jnp.zeros(()))


@pytest.fixture(scope="module")
def qmg():
    return _campaign_pair(_ideal_qmg(), QMG_DEVICES, QMG_RUNS, ALL, seed=11)


@pytest.fixture(scope="module")
def vcf():
    return _campaign_pair(gj.vcf_2018(), VCF_DEVICES, VCF_RUNS, OPEN, seed=5)


def _device(lot, d):
    import jax

    return jax.tree.map(lambda x: x[d], lot)


# --- shapes, inputs and columns ------------------------------------------------------------------------------


@pytest.mark.slow
def test_every_sweep_for_both_presets(qmg, vcf):
    p = gj.Protocol()
    for c, devices, runs, sweeps in ((qmg, QMG_DEVICES, QMG_RUNS, ALL), (vcf, VCF_DEVICES, VCF_RUNS, OPEN)):
        t = c["noisy"]
        n_points = {"rate_table": 22, "vcf_static": 22, "vcf_dynamic": 50, "dac": 22}
        assert len(t) == devices * runs * sum(n_points[s] for s in sweeps)
        for s in sweeps:
            arr = t.to_arrays(s)
            assert arr.mask.shape == (devices, runs, n_points[s]) and bool(arr.mask.all())
            assert np.all(np.asarray(arr.sigmas) > 0)
        rate = t.to_arrays("rate_table")
        np.testing.assert_array_equal(np.asarray(rate.inputs[1, -1]), gj.sweeps.DING_ZHOU_2025_RATES_DPS)
        assert np.all(np.asarray(rate.aux["n_samples"]) == 120 * 100)  # seed 000: 2 min at 100 Hz
        dyn = t.to_arrays("vcf_dynamic")
        np.testing.assert_array_equal(np.asarray(dyn.inputs[0, 0]), np.arange(10.0, 501.0, 10.0))
        assert np.all(np.isfinite(np.asarray(dyn.aux["phase_deg"])))
        assert np.all(np.isnan(np.asarray(dyn.drive_freqs)))
    # the static VCF voltages are the virtual equivalents of seed 000's rates (seed 003 Eq. 7): on vcf-2018
    # with Table 1's design values 200 deg/s is 6.546 mV; on paper-qmg's electrode 2 V
    v_vcf = vcf["noisy"].to_arrays("vcf_static").inputs[0, 0]
    design = 2 * 9.740e-8 * 0.206 / (2.14e-5 * 1.0) * 200 * DEG
    assert float(v_vcf[-1]) == pytest.approx(design, rel=1e-10) == pytest.approx(6.546e-3, abs=1e-6)
    assert float(qmg["noisy"].to_arrays("vcf_static").inputs[0, 0, -1]) == pytest.approx(2.0, rel=1e-12)
    assert p.n_samples(gj.sweeps.VcfDynamic()) == 10 * 10_000


# --- the measurement model ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_noise_free_closed_loop_is_the_physics(qmg):
    """Closed loop, noise-free, each row from its own device at its own temperature, in closed form:
    rate word = SF(T) rate with SF = 2 Ag m a w(T) / G(w) (seed 000 Eq. 2); VCF word = K_svf V_fc V_ac / G(w);
    PLL frequency = w_x(T)."""
    t, lot = qmg["clean"], qmg["lot"]
    rate, vcf_s = t.to_arrays("rate_table"), t.to_arrays("vcf_static")
    for d in range(QMG_DEVICES):
        g = _device(lot, d)
        temp = np.asarray(rate.temperatures[d])
        w = np.asarray(g.resonator.at_temperature(jnp.asarray(temp))[0])
        sf = np.asarray(g.ideal_scale_factor(jnp.asarray(temp)))
        np.testing.assert_allclose(np.asarray(rate.outputs[d]), sf * np.asarray(rate.inputs[d]) * DEG, rtol=1e-8)
        np.testing.assert_allclose(np.asarray(rate.drive_freqs[d]), w / (2 * np.pi), rtol=1e-12)
        gain = np.asarray(g.rebalance_gain(jnp.asarray(w)))
        word = float(g.vcf_electrode.force_per_volt2) * gj.sweeps.VCF_CARRIER_V * np.asarray(vcf_s.inputs[d]) / gain
        np.testing.assert_allclose(np.asarray(vcf_s.outputs[d]), word, rtol=1e-8)
    assert np.all(np.asarray(t["output_sigma"]) == 0.0)


@pytest.mark.parametrize("which", ["qmg", "vcf"])
@pytest.mark.slow
def test_noise_free_outputs_are_the_observe_predictions(which, qmg, vcf):
    """Re-evaluate the measurement model (each sweep kind's vmapped model) on the table's own columns -
    device order, input, temperature_c - and get the table's outputs back bit for bit."""
    c = {"qmg": qmg, "vcf": vcf}[which]
    t, lot = c["clean"], c["lot"]
    for sweep in ("rate_table", "vcf_static"):
        arr = t.to_arrays(sweep)
        inputs = np.asarray(arr.inputs)
        assert np.all(inputs == inputs[:1, :1])  # one input list for the whole lot
        request = (gj.sweeps.sweep_kind(sweep), jnp.asarray(inputs[0, 0]), arr.temperatures, jnp.nan)
        settled = lot_steady(lot, (request,), gj.CAMPAIGN_TIER)[0]
        np.testing.assert_array_equal(np.asarray(settled.rate), np.asarray(arr.outputs))
    arr = t.to_arrays("vcf_dynamic")
    amp, phase = sweeps_vcf_dynamic._lot_vcf_dynamic(lot, arr.inputs[0, 0], arr.temperatures, 0.02,
                                                     gj.sweeps.VCF_CARRIER_V)
    np.testing.assert_array_equal(np.asarray(amp), np.asarray(arr.outputs))
    np.testing.assert_array_equal(np.asarray(phase), np.asarray(arr.aux["phase_deg"]))
    if which == "qmg":
        arr = t.to_arrays("dac")
        volts = sweeps_dac._lot_dac(lot, arr.inputs[:, 0])
        np.testing.assert_array_equal(np.asarray(volts)[:, None, :] * np.ones((1, QMG_RUNS, 1)),
                                      np.asarray(arr.outputs))
        # seed 000 Table 2's convention: word = -SF x rate
        sf = np.asarray(sweeps_dac._lot_ideal_sf(lot))
        np.testing.assert_array_equal(np.asarray(arr.inputs[:, 0]),
                                      np.round(-np.asarray(arr.aux["rate_dps"][:, 0]) * DEG * sf[:, None]))


@pytest.mark.parametrize("which", ["qmg", "vcf"])
@pytest.mark.slow
def test_vcf_to_rate_scale_factor_ratio_is_physical(which, qmg, vcf):
    r"""Point by point (same protocol time, same temperature), the rate-table and static-VCF responses per
    unit input stand in the ratio of the forces per unit input, 2 Ag m a w / (K_svf V_fc) (V per rad/s):

    - closed loop: the word cancels the in-phase sense force, F_rate = 2 m w a Ag Om and F_vcf = K_svf V_fc V,
      through the same gain G(w): the ratio is exact;
    - open loop: both forces drive the same sense envelope, Y = F / (2 j w m (g_y - j d_y)); but the real
      rate also acts on the drive (the Ag Om Y term), pulling the PLL down by (Ag Om)^2 / d_y and the SF by
      (Ag Om / d_y)^2, which the sense-only virtual force does not: ratio = phys x (1 - (Ag Om / d_y)^2).
    """
    c = {"qmg": qmg, "vcf": vcf}[which]
    t, lot = c["clean"], c["lot"]
    rate, vs = t.to_arrays("rate_table"), t.to_arrays("vcf_static")
    for d in range(rate.mask.shape[0]):
        g = _device(lot, d)
        r = g.resonator
        temp = np.asarray(rate.temperatures[d])
        np.testing.assert_array_equal(temp, np.asarray(vs.temperatures[d]))
        w = np.asarray(r.at_temperature(jnp.asarray(temp))[0])
        a = np.asarray(g.drive_amplitude(jnp.asarray(w)))
        phys = 2 * float(r.angular_gain) * float(r.mass) * a * w / (float(g.vcf_electrode.force_per_volt2)
                                                                   * gj.sweeps.VCF_CARRIER_V)
        om = np.asarray(rate.inputs[d]) * DEG
        ratio = (np.asarray(rate.outputs[d]) / om) / (np.asarray(vs.outputs[d]) / np.asarray(vs.inputs[d]))
        if g.closed_loop:
            np.testing.assert_allclose(ratio, phys, rtol=1e-8)
        else:
            wx, wy, _, _ = r.at_temperature(jnp.asarray(temp))
            dy = np.asarray((wy**2 - wx**2) / (2 * wx))
            pulling = (float(r.angular_gain) * om / dy) ** 2  # ~80 ppm at 200 deg/s
            assert pulling.max() > 60e-6
            np.testing.assert_allclose(ratio / phys - 1, -pulling, rtol=0.05, atol=1e-8)


# --- temperature history --------------------------------------------------------------------------------------


@pytest.mark.slow
def test_temperature_follows_the_warm_up(qmg):
    t = qmg["noisy"]
    for sweep, dwell in (("rate_table", 120.0), ("vcf_static", 120.0), ("vcf_dynamic", 10.0)):
        temp = np.asarray(t.to_arrays(sweep).temperatures)
        mid = 60.0 + (np.arange(temp.shape[-1]) + 0.5) * dwell  # 1 min warm-up, middle of each dwell
        np.testing.assert_allclose(temp[:, 0], np.broadcast_to(25.0 + 2.0 * (1 - np.exp(-mid / 600.0)),
                                                               temp[:, 0].shape), rtol=1e-12)
        np.testing.assert_allclose(temp[:, 1:], np.broadcast_to(25.0 + 2.0 * (1 - np.exp(-mid / 120.0)),
                                                                temp[:, 1:].shape), rtol=1e-12)
    rate = t.to_arrays("rate_table")
    temp = np.asarray(rate.temperatures)
    # the first run is still warming at its last point (25 mK short of the plateau), the later ones settled
    assert temp[0, 0, -1] < 27.0 - 0.02 and temp[0, 1, -1] > 27.0 - 1e-6 and np.ptp(temp[0, 0]) > 1.5
    # the DAC bench sweep has no die temperature: not given (NaN)
    assert np.all(np.isnan(t["temperature_c"][t["sweep"] == "dac"]))
    # and the outputs follow the temperature: the closed-loop SF tracks w (TCF -30 ppm/K)
    clean = qmg["clean"].to_arrays("rate_table")
    k = np.asarray(clean.outputs[0]) / np.asarray(clean.inputs[0])
    tcf = float(gj.paper_qmg().resonator.tcf)
    np.testing.assert_allclose(k[0] / k[1] - 1, tcf * (temp[0, 0] - temp[0, 1]), atol=2e-7)


def test_protocol_warmup_none_keeps_the_device_history():
    hot = gj.temperature.ConstantTemperature(31.0)
    g = eqx.tree_at(lambda g: g.temperature, gj.paper_qmg(), hot)
    p = gj.Protocol(warmup=None)
    np.testing.assert_array_equal(p.temperatures(g, 2, gj.sweeps.RateTable()), np.full((2, 22), 31.0))
    g2 = eqx.tree_at(lambda g: g.temperature, g, gj.temperature.WarmupTemperature(20.0, 5.0, 100.0))
    temp = gj.Protocol(warmup=None).temperatures(g2, 1, gj.sweeps.VcfDynamic())[0]
    np.testing.assert_allclose(temp, 20.0 + 5.0 * (1 - np.exp(-(60.0 + (np.arange(50) + 0.5) * 10.0) / 100.0)))
    # the default warm-up starts from the device's own temperature at power-on
    temp = gj.Protocol().temperatures(g2, 2, gj.sweeps.RateTable())
    assert temp[0, 0] == pytest.approx(20.0 + 2.0 * (1 - math.exp(-120.0 / 600.0)), rel=1e-12)


# --- noise: honest uncertainties ------------------------------------------------------------------------------


def _line_plus_run_bias_chi2(x, y, sigma):
    """Weighted least squares of y[run, point] = k x[point] + b[run]; returns (chi2 / dof, biases)."""
    runs, n = y.shape
    a = np.zeros((runs * n, runs + 1))
    a[:, 0] = np.tile(x, runs)
    a[np.arange(runs * n), 1 + np.repeat(np.arange(runs), n)] = 1.0
    w = 1.0 / np.ravel(sigma)
    coef, *_ = np.linalg.lstsq(a * w[:, None], np.ravel(y) * w, rcond=None)
    r = (np.ravel(y) - a @ coef) * w
    return float(r @ r), runs * n - (runs + 1), coef[1:]


@pytest.mark.slow
def test_reduced_chi2_of_noise_only_data_is_one(qmg):
    """Noise-only data of the ideal closed-loop device (noisy minus noise-free, same lot and temperatures):
    a line plus one bias per run, fitted with the table's output_sigma, leaves a reduced chi^2 near 1 -
    on the rate table and the static VCF sweep (turn-on bias, bias wander, angle random walk), on the
    dynamic amplitudes (lock-in noise) and on the DAC sweep (voltmeter)."""
    noisy, clean = qmg["noisy"], qmg["clean"]
    noise = RateNoise()
    for sweep in ("rate_table", "vcf_static"):
        a, b = noisy.to_arrays(sweep), clean.to_arrays(sweep)
        chi2 = dof = 0.0
        chi2_white = 0.0
        biases = []
        for d in range(QMG_DEVICES):
            y = np.asarray(a.outputs[d] - b.outputs[d])
            sig = np.asarray(a.sigmas[d])
            c, k, bias = _line_plus_run_bias_chi2(np.asarray(a.inputs[d, 0]), y, sig)
            chi2, dof = chi2 + c, dof + k
            # without the bias-instability share the same residuals are far outside chi^2 ~ 1
            white = sig * (noise.arw_dps_per_sqrt_s / math.sqrt(120.0)) / noise.point_sigma_dps(120.0)
            chi2_white += _line_plus_run_bias_chi2(np.asarray(a.inputs[d, 0]), y, white)[0]
            lsb_per_dps = sig[0, 0] / noise.point_sigma_dps(120.0)
            biases.append(bias / lsb_per_dps)
        assert dof > 450
        assert 0.8 < chi2 / dof < 1.2, (sweep, chi2 / dof)
        assert chi2_white / dof > 2.5, (sweep, chi2_white / dof)
        # the fitted per-run biases are the turn-on biases: 1-sigma 0.01 deg/s (24 runs: +/-15 %)
        assert 0.65 < np.std(np.concatenate(biases)) / noise.turn_on_bias_dps < 1.35
    for sweep in ("vcf_dynamic", "dac"):
        a, b = noisy.to_arrays(sweep), clean.to_arrays(sweep)
        z = np.asarray((a.outputs - b.outputs) / a.sigmas)
        assert z.size > 500 and 0.8 < np.mean(z**2) < 1.2, (sweep, np.mean(z**2))
    # the dynamic phase carries the same noise, sigma / amplitude in radians
    a, b = noisy.to_arrays("vcf_dynamic"), clean.to_arrays("vcf_dynamic")
    zp = np.deg2rad(np.asarray(a.aux["phase_deg"] - b.aux["phase_deg"])) * np.asarray(b.outputs / a.sigmas)
    assert 0.8 < np.mean(zp**2) < 1.2


def test_rate_noise_figures():
    n = RateNoise()
    # Allan deviation of a Gauss-Markov wander: peak 0.6174 q at 1.893 tau (the bias-instability read-off)
    assert gj.RateNoise().wander_sigma_dps * 0.6174 * 3600 == pytest.approx(0.5, rel=1e-4)
    white = 0.05 / 60 / math.sqrt(120)
    x = 120 / 30
    wander = n.wander_sigma_dps**2 * 2 * (x - 1 + math.exp(-x)) / x**2
    assert n.point_sigma_dps(120.0) == pytest.approx(math.sqrt(white**2 + wander), rel=1e-12)
    assert RateNoise(bias_instability_dph=0.0).point_sigma_dps(120.0) == pytest.approx(white, rel=1e-12)
    # lock-in: white part sqrt(2 N^2 / T) per component; the wander is negligible at 10 Hz and above
    assert n.amplitude_sigma_dps(10.0, 10.0) == pytest.approx(0.05 / 60 * math.sqrt(2 / 10), rel=1e-3)
    with pytest.raises(ValueError, match="RateNoise.bias_correlation_s must be positive"):
        RateNoise(bias_correlation_s=0.0)


# --- files ----------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_round_trip_csv_and_parquet(qmg, tmp_path):
    t = qmg["noisy"]
    for suffix in ("csv", "parquet"):
        path = tmp_path / f"lot.{suffix}"
        gj.write_table(t, path)
        back = gj.read_table(path)
        assert back.column_names == t.column_names
        for sweep in ALL:
            a, b = t.to_arrays(sweep), back.to_arrays(sweep)
            for name in ("inputs", "outputs", "sigmas", "temperatures", "mask", "times", "drive_freqs", "order"):
                np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)))
            assert a.aux.keys() == b.aux.keys() and "n_samples" in a.aux and "temperature_c" not in a.aux
            for k in a.aux:
                np.testing.assert_array_equal(np.asarray(a.aux[k]), np.asarray(b.aux[k]))
            assert (a.devices, a.runs) == (b.devices, b.runs)


# --- protocol and argument errors -----------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs,message", [
    (dict(dwell_s=0.0), r"Protocol.dwell_s must be positive"),
    (dict(sample_rate_hz=0.001, dwell_s=100.0), r"dwell_s x sample_rate_hz = 0.1 gives no sample"),
    (dict(warmup=3.0), r"Protocol.warmup must be a RunWarmup or None"),
])
def test_protocol_refuses_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gj.Protocol(**kwargs)


@pytest.mark.parametrize("kind,kwargs,message", [
    (gj.sweeps.RateTable, dict(rates_dps=(1.0,)), r"RateTable.rates_dps must hold at least 2 finite table rates"),
    (gj.sweeps.RateTable, dict(rates_dps=(1.0, 2.0, 1.0)), r"RateTable.rates_dps repeats \[1.0\]"),
    (gj.sweeps.VcfStatic, dict(amplitudes_v=(0.1, np.nan)),
     r"VcfStatic.amplitudes_v must hold at least 2 finite voltages"),
    (gj.sweeps.VcfDynamic, dict(frequencies_hz=(10.0, -5.0)), r"frequencies_hz must be > 0 Hz"),
    (gj.sweeps.VcfDynamic, dict(frequencies_hz=(10.0, 6000.0)),
     r"does not sample the highest modulation frequency 6000.0"),
    (gj.sweeps.VcfDynamic, dict(amplitude_v=0.0), r"VcfDynamic.amplitude_v must be finite and non-zero"),
    (gj.sweeps.VcfDynamic, dict(lockin_dwell_s=0.0), r"lockin_dwell_s x lockin_sample_rate_hz = 0 gives no sample"),
    (gj.sweeps.DriveFrequency, dict(register_dwell_s=-1.0), r"DriveFrequency.register_dwell_s must be finite and > 0"),
])
def test_a_sweep_kind_refuses_bad_settings(kind, kwargs, message):
    """A kind's settings are its fields, checked where they are given."""
    with pytest.raises(ValueError, match=message):
        kind(**kwargs)


def test_simulate_table_refuses_bad_arguments():
    g = gj.vcf_2018()
    with pytest.raises(ValueError, match=r"cannot simulate sweep 'vcf_teleport'; choose from rate_table, "
                                         r"vcf_static, vcf_dynamic, dac"):
        gj.simulate_table(g, sweeps=("rate_table", "vcf_teleport"))
    with pytest.raises(ValueError, match="'rate_table' more than once"):
        gj.simulate_table(g, sweeps=("rate_table", "rate_table"))
    with pytest.raises(ValueError, match="a dac sweep needs a closed-loop device; 'vcf-2018' is open loop"):
        gj.simulate_table(g, sweeps=("dac",))
    bare = eqx.tree_at(lambda g: g.vcf_electrode, g, gj.physics.VirtualCoriolisElectrode(0.0))
    for sweep in ("vcf_static", "vcf_dynamic"):
        with pytest.raises(ValueError, match="needs a virtual-Coriolis electrode; 'vcf-2018' has"):
            gj.simulate_table(bare, sweeps=(sweep,))
    with pytest.raises(ValueError, match="runs must be an integer >= 1, got 0"):
        gj.simulate_table(g, runs=0)
    # a kind's points are its own: the protocol times them
    assert gj.Protocol().point_times(gj.sweeps.RateTable((-3.0, 3.0))).tolist() == [120.0, 240.0]
    # rates_dps is shorthand for the rate table's and the DAC sweep's rates
    t = gj.simulate_table(gj.paper_qmg(), sweeps=("dac",), rates_dps=(-3.0, 3.0), noise_free=True, progress=False)
    assert np.asarray(t["rate_dps"]).tolist() == [-3.0, 3.0]


# --- command line ---------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_simulates_every_sweep(tmp_path, qmg, vcf):
    import json

    out = tmp_path / "vcf.csv"
    assert cli(["simulate", "--preset", "vcf-2018", "--devices", str(VCF_DEVICES), "--sweeps",
                "rate_table,vcf_static,vcf_dynamic", "--seed", "5", "--out", str(out)]) == 0
    assert gj.read_table(out).equals(gj.read_table(_write(vcf["noisy"], tmp_path / "fixture.csv")))
    js = tmp_path / "m.json"
    assert cli(["metrics", str(out), "--json", str(js)]) == 0
    report = json.loads(js.read_text())
    dyn = [p for p in report["points"] if p["sweep"] == "vcf_dynamic"]
    bw = gj.physics.bandwidth(gj.vcf_2018())
    assert len(dyn) == VCF_DEVICES and all(abs(p["bandwidth_hz"] - bw) < 5.0 for p in dyn)
    out = tmp_path / "qmg.parquet"
    assert cli(["simulate", "--preset", "paper-qmg", "--devices", str(QMG_DEVICES), "--runs", str(QMG_RUNS),
                "--sweeps", ",".join(ALL), "--seed", "11", "--out", str(out)]) == 0
    back = gj.read_table(out)
    assert sorted(set(back["sweep"])) == sorted(ALL) and len(back) == len(qmg["noisy"])
    report = gj.metrics.metrics_report(back)
    sf = {p.sweep: p.scale_factor for p in report.points if p.run == 1}
    assert sf["rate_table"] == pytest.approx(13709.853, rel=0.02)  # seed 000's SF, LSB/(deg/s), lot spread
    assert sf["vcf_static"] * 0.01 == pytest.approx(sf["rate_table"], rel=0.05)  # 2 V <-> 200 deg/s, K_svf spread


def _write(table, path):
    gj.write_table(table, path)
    return path


def test_cli_unknown_sweep_exits_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli(["simulate", "--preset", "paper-qmg", "--sweeps", "rate_table,vcf_magic", "--out", "x.csv"]) == 2
    err = capsys.readouterr().err
    assert "cannot simulate sweep 'vcf_magic'; choose from rate_table, vcf_static, vcf_dynamic, dac" in err
    assert "Traceback" not in err and not (tmp_path / "x.csv").exists()


# --- seed 003 batch experiment --------------------------------------------------------------------------------


def _experiment():
    return load_experiment("seed003_batch_calibration")


@pytest.mark.slow
def test_seed003_batch_experiment_small(tmp_path, vcf, capsys):
    out = _experiment().main(["--devices", str(VCF_DEVICES), "--out", str(tmp_path)])
    assert len(out["devices"]) == VCF_DEVICES
    for d in out["devices"]:
        # the ratio rate SF / virtual SF is the physics (2 Ag m a w_d / K_svf against the design values),
        # up to the Coriolis pulling of the rate SF (-66 ppm over seed 000's grid) and the noise
        assert d["ratio"] == pytest.approx(d["ratio_physical"], rel=2e-4)
        # the dynamic VCF test measures the model's own rate bandwidth (~97 Hz, not seed 003's 354 Hz)
        assert abs(d["bandwidth_vcf_hz"] - d["bandwidth_model_hz"]) < 3.0
        assert 85.0 < d["bandwidth_model_hz"] < 110.0
    s = out["summary"]
    assert s["ratio_spread_pct"] < s["rate_sf_spread_pct"]
    assert s["paper_ratio_spread_pct"] == 0.79
    assert "DOES NOT CLOSE" in capsys.readouterr().out
    for name in ("seed003_batch_calibration.json", "seed003_batch_calibration.png"):
        assert (tmp_path / name).stat().st_size > 0
