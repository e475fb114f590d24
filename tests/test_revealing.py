"""The revealing experiments' sweep kinds (quadrature_injection, drive_amplitude, drive_frequency,
setpoint_zero_rate, branch_ratio) and the plateau run: closed forms, zero effect -> zero change, the
fingerprint's size in noise sigmas after the baseline absorbs what it can, simulation and the CSV, the tiers,
gradients."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._model.parameters import DEFAULT_FREE
from gyrojax._plan.absorb import absorption
from gyrojax._sweeps.drive_amplitude import AMPLITUDE_SIGMA_PPM
from gyrojax._sweeps.drive_frequency import FREQUENCY_SIGMA_PPM
from gyrojax._sweeps.steady import settled_points


DEG = gj.units.DEG
SIGMA_DPS = gj.RateNoise().point_sigma_dps(120.0)
NAN = float("nan")


@pytest.fixture(scope="module")
def qmg():
    return gj.paper_qmg()


def _sf(gyro):
    return float(gyro.ideal_scale_factor()) * DEG


def _setpoints(gyro, ratios=gj.sweeps.SETPOINT_RATIOS):
    return gj.sweeps.DriveAmplitude(setpoint_ratios=ratios).inputs(gyro)


def _points(gyro, setpoints, tier=gj.Steady()):
    return gj.sweeps.setpoint_points(gyro, gj.sweeps.DriveAmplitude(), setpoints, NAN, None, tier)


@pytest.mark.slow  # 33-44 s cold (fast tier, 2026-11-26)
def test_drive_amplitude_backbone_and_sag(qmg):
    """The PLL frequency follows the Duffing backbone w_x sqrt(1 + 3/4 duffing_x a^2) and the AGC's standing
    error is the same fraction of every set-point, beta = 2 w m g_x leak / (K_dx |G_d| (kp leak + ki)); with
    both effects at zero the readings are exactly the nominal frequency and the set-points. The kinds'
    `predict` reads the same points."""
    setpoints = _setpoints(qmg)
    ratio = np.asarray(gj.sweeps.SETPOINT_RATIOS)
    zero = _points(gj.add_effect(qmg, gj.effects.DuffingDrive.typical(0.0)), setpoints)
    assert np.array_equal(np.asarray(zero.frequency_hz), np.full(ratio.shape, 4634.0))
    np.testing.assert_allclose(np.asarray(zero.amplitude_lsb), setpoints, rtol=1e-13)

    duff = gj.add_effect(qmg, gj.effects.DuffingDrive.typical(1.0))
    got, bad = gj.sweeps.DriveFrequency().predict(duff, setpoints, NAN, None)
    got = np.asarray(got)
    assert not np.any(np.asarray(bad))
    r = duff.resonator
    a = ratio * float(qmg.drive_amplitude(r.omega_x))
    expected = float(r.omega_x) * np.sqrt(1.0 + 0.75 * float(r.duffing_x) * a**2 / float(r.omega_x) ** 2) / (2 * np.pi)
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    assert (got[-1] / got[0] - 1) * 1e6 == pytest.approx(49.2, abs=0.5)  # 0.5x -> 1.25x at the typical kappa

    leaky = gj.add_effect(qmg, gj.effects.AgcFiniteGain.typical(1.0))
    sag = np.asarray(gj.sweeps.DriveAmplitude().predict(leaky, setpoints, NAN, None)[0]) / setpoints - 1.0
    dl, rr = leaky.drive_loop, leaky.resonator
    w = float(rr.omega_x)
    beta = (2 * w * float(rr.mass) * w / (2 * float(rr.q_x)) * float(dl.agc_leak)
            / (float(leaky.drive_electrode.force_per_volt) * abs(complex(leaky.drive_frontend.phasor_gain(w)))
               * (float(dl.agc_kp) * float(dl.agc_leak) + float(dl.agc_ki))))
    np.testing.assert_allclose(sag, -beta / (1 + beta), rtol=1e-6)
    assert sag[0] * 1e6 == pytest.approx(-13.7, abs=0.1)
    # The sag alone, in sigmas of the amplitude reading, with nothing in the baseline to take it.
    assert np.linalg.norm(sag / (AMPLITUDE_SIGMA_PPM * 1e-6)) > 30


def test_quadrature_injection_reads_tan_phi(qmg):
    """Closed loop, the rate output moves with the injected quadrature by tan(phi) of the quadrature word's
    change; at phi = 0 it does not move (to round-off), so a run bias cannot take the slope."""
    kind = gj.sweeps.QuadratureInjection()
    volts = kind.inputs(qmg)
    sf = _sf(qmg)

    def settle(gyro):
        return settled_points(gyro, [(kind, volts, NAN, None)])[0]

    zero = settle(gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(0.0)))
    assert np.max(np.abs(np.asarray(zero.rate))) < 1e-9 * sf
    np.testing.assert_allclose(np.asarray(zero.quadrature) / sf, [-110, -60, -10, 40, 90], atol=1e-6)

    phi = float(gj.effects.QuadraturePhase.typical(1.0).phase)
    gyro = gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(1.0))
    out = settle(gyro)
    slope_rate = np.polyfit(volts, np.asarray(out.rate), 1)[0]
    slope_quad = np.polyfit(volts, np.asarray(out.quadrature), 1)[0]
    assert slope_rate / slope_quad == pytest.approx(np.tan(phi), rel=1e-6)
    np.testing.assert_array_equal(np.asarray(kind.predict(gyro, volts, NAN, None)[0]), np.asarray(out.rate))
    # +/-100 deg/s of injected quadrature: the rate moves by ~+/-0.5 deg/s, thousands of point sigmas even
    # after a run bias takes the mean.
    change = np.asarray(out.rate - zero.rate) / sf
    assert np.linalg.norm((change - change.mean()) / SIGMA_DPS) > 3000


def test_branch_ratio(qmg):
    """V+ / V- = (1 + e+) / (1 + e-) at every rate; exactly 1 with matched branches."""
    rates = np.asarray(gj.sweeps.BRANCH_RATES_DPS)
    zero, _ = gj.sweeps.branch_ratio_points(gj.add_effect(qmg, gj.effects.PushPullMismatch.typical(0.0)), rates, NAN)
    np.testing.assert_array_equal(np.asarray(zero), 1.0)
    eff = gj.effects.PushPullMismatch.typical(1.0)
    out, bad = gj.sweeps.BranchRatio().predict(gj.add_effect(qmg, eff), rates, NAN, None)
    assert not np.any(np.asarray(bad))
    np.testing.assert_allclose(np.asarray(out), (1 + float(eff.plus)) / (1 + float(eff.minus)), rtol=1e-12)
    with pytest.raises(ValueError, match="closed-loop device"):
        gj.sweeps.branch_ratio_points(gj.vcf_2018(), rates, NAN)
    with pytest.raises(ValueError, match="needs a closed-loop device"):
        gj.sweeps.BranchRatio().check_device(gj.vcf_2018())


def test_zero_rate_scales_with_the_setpoint(qmg):
    """The damping coupling's zero-rate output scales with the drive amplitude: c / (2 Ag) times the scale factor
    at each set-point, which one run bias cannot take."""
    setpoints = _setpoints(qmg, (0.5, 1.0))
    kind = gj.sweeps.SetpointZeroRate()
    base = np.asarray(kind.predict(gj.add_effect(qmg, gj.effects.DampingCoupling.typical(0.0)), setpoints, NAN,
                                   None)[0])
    eff = gj.effects.DampingCoupling.typical(1.0)
    out = np.asarray(kind.predict(gj.add_effect(qmg, eff), setpoints, NAN, None)[0])
    zro = float(eff.c) / (2 * float(qmg.resonator.angular_gain)) / DEG
    np.testing.assert_allclose((out - base) / _sf(qmg), [0.5 * zro, zro], rtol=1e-6)


@pytest.mark.slow  # 33-44 s cold (fast tier, 2026-11-26)
def test_simulate_and_csv_round_trip(qmg, tmp_path):
    """Every revealing kind through simulate_table (noise-free: the readings are the measurement model's) and the
    CSV; a device without a VCF electrode is refused by name before anything is simulated."""
    names = ("quadrature_injection", "drive_amplitude", "drive_frequency", "setpoint_zero_rate", "branch_ratio")
    two = (-100.0, 100.0)
    kinds = (gj.sweeps.QuadratureInjection(quadrature_rates_dps=two),
             gj.sweeps.DriveAmplitude(setpoint_ratios=(0.5, 1.0)),
             gj.sweeps.DriveFrequency(setpoint_ratios=(0.5, 1.0)),
             gj.sweeps.SetpointZeroRate(setpoint_ratios=(0.5, 1.0)),
             gj.sweeps.BranchRatio(rates_dps=two))
    gyro = gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(1.0))
    table = gj.simulate_table(gyro, sweeps=kinds, rates_dps=two, noise_free=True, progress=False)
    gj.write_table(table, tmp_path / "revealing.csv")
    back = gj.read_table(tmp_path / "revealing.csv")
    assert back.equals(table)
    assert tuple(dict.fromkeys(back["sweep"].tolist())) == names
    rows = np.asarray(back["sweep"]) == "drive_amplitude"
    np.testing.assert_array_equal(back["input"][rows], _setpoints(qmg, (0.5, 1.0)))
    np.testing.assert_allclose(back["output"][rows], back["input"][rows], rtol=1e-12)  # an ideal AGC
    volts = kinds[0].inputs(gyro)
    rows = np.asarray(back["sweep"]) == "quadrature_injection"
    np.testing.assert_array_equal(back["input"][rows], volts)
    pred = gj.sweeps.QuadratureInjection().predict(gyro, volts, back["temperature_c"][rows], back["time_s"][rows])[0]
    np.testing.assert_allclose(back["output"][rows], pred, rtol=1e-6)
    no_vcf = eqx.tree_at(lambda g: g.vcf_electrode.force_per_volt2, qmg, 0.0)
    with pytest.raises(ValueError, match="quadrature_injection sweep needs a virtual-Coriolis electrode"):
        gj.simulate_table(no_vcf, sweeps=kinds[:1], progress=False)


def test_plateau_run_history_and_vref(qmg):
    """A plateau run (`Protocol.chamber_plateaus_c`): every listed point once per plateau within the run, the die
    at each plateau (plus its self-heating) after the soak, and vref_drift scaling the static VCF output by
    1 / (1 + tc dT) between plateaus."""
    protocol = gj.Protocol(chamber_plateaus_c=gj.sweeps.CHAMBER_PLATEAUS_C,
                           warmup=gj.sweeps.RunWarmup(first_time_constant_s=120.0))
    vcf = gj.sweeps.VcfStatic(virtual_rates_dps=(-100.0, 100.0))
    assert protocol.n_points(vcf) == 6 and protocol.n_points(gj.sweeps.Dac()) == len(gj.sweeps.Dac().rates_dps)
    np.testing.assert_array_equal(protocol.inputs(vcf, qmg), np.tile(vcf.inputs(qmg), 3))
    tables = [gj.simulate_table(gj.add_effect(qmg, gj.effects.VrefDrift.typical(k)), sweeps=(vcf,),
                                protocol=protocol, noise_free=True, progress=False) for k in (0.0, 1.0)]
    temps = np.asarray(tables[1]["temperature_c"])
    np.testing.assert_allclose(temps[::2], np.asarray(gj.sweeps.CHAMBER_PLATEAUS_C) + 2.0, atol=0.05)
    assert np.all(np.diff(tables[1]["time_s"]) > 0)
    ratio = np.asarray(tables[1]["output"]) / np.asarray(tables[0]["output"])
    dt = temps - float(qmg.resonator.t_ref)
    np.testing.assert_allclose(ratio, 1.0 / (1.0 + float(gj.effects.VrefDrift.typical(1.0).tc) * dt), rtol=1e-9)


def test_settings_errors(qmg):
    with pytest.raises(ValueError, match="DriveAmplitude.setpoint_ratios must be > 0"):
        gj.sweeps.DriveAmplitude(setpoint_ratios=[1.0, -0.5])
    with pytest.raises(ValueError, match="SetpointZeroRate.setpoint_ratios repeats"):
        gj.sweeps.SetpointZeroRate(setpoint_ratios=[1.0, 1.0])
    with pytest.raises(ValueError, match="chamber_plateaus_c must hold at least 2"):
        gj.Protocol(chamber_plateaus_c=(25.0,))
    no_vcf = eqx.tree_at(lambda g: g.vcf_electrode.force_per_volt2, qmg, 0.0)
    with pytest.raises(ValueError, match="virtual-Coriolis electrode"):
        gj.sweeps.QuadratureInjection().inputs(no_vcf)
    with pytest.raises(ValueError, match="needs the device"):
        gj.sweeps.DriveAmplitude().inputs()
    with pytest.raises(ValueError, match="starts_s must be >= 0 and increasing"):
        gj.temperature.PlateauTemperature((10.0, 20.0), (100.0, 50.0), 25.0, 300.0, 2.0, 120.0)


@pytest.mark.slow
def test_full_waveform_agrees(qmg):
    """The full-waveform tier (carrier, 3w harmonic of the cubic spring, demodulator ripple) against the steady
    tier: the Duffing shift between set-points 0.5 and 1.25 and the quadrature injection's rate change (the
    tiers' common 0.24 ppm frequency offset cancels). The AGC sag is not compared: on paper-qmg the full
    waveform's demodulator ripple, through the AGC's proportional gain, supplies most of the drive force, so its
    integrator (and the leak's sag) sit elsewhere than the averaged tiers'."""
    full = gj.FullWaveform(settle_time=0.05, average_periods=20)
    s = _setpoints(qmg, (0.5, 1.25))
    duff = gj.add_effect(qmg, gj.effects.DuffingDrive.typical(1.0))
    rs, rf = _points(duff, s), _points(duff, s, full)
    shift_s = float(rs.frequency_hz[1] / rs.frequency_hz[0] - 1)
    shift_f = float(rf.frequency_hz[1] / rf.frequency_hz[0] - 1)
    assert abs(shift_f - shift_s) < 0.3e-6  # of a 49 ppm shift

    kind = gj.sweeps.QuadratureInjection()
    q = gj.sweeps.QuadratureInjection(quadrature_rates_dps=(-100.0, 100.0)).inputs(qmg)
    phase = gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(1.0))
    qs, qf = kind.predict(phase, q, NAN, None)[0], kind.predict(phase, q, NAN, None, full)[0]
    sf = _sf(qmg)
    step_s = float(qs[1] - qs[0]) / sf
    step_f = float(qf[1] - qf[0]) / sf
    assert step_f == pytest.approx(step_s, rel=0.01)  # a 1.0 deg/s step


@pytest.mark.slow
def test_baseline_leaves_the_fingerprints(qmg):
    """After the baseline's free parameters (and run biases, a meter gain) absorb what they can, each effect's
    fingerprint stays many sigmas; a zero effect leaves nothing."""
    free = DEFAULT_FREE
    s = _setpoints(qmg)

    def drive(d):
        r = _points(d, s)
        return jnp.concatenate([r.frequency_hz / (FREQUENCY_SIGMA_PPM * 1e-6 * 4634.0),
                                r.amplitude_lsb / (AMPLITUDE_SIGMA_PPM * 1e-6 * s)])

    base = gj.add_effect(qmg, gj.effects.DuffingDrive.typical(0.0))
    duff = absorption(drive, base, gj.add_effect(qmg, gj.effects.DuffingDrive.typical(1.0)), 1.0,
                      free=free + ("omega_x",))
    assert duff.signature_sigmas > 80 and duff.residual_sigmas > 40
    assert absorption(drive, base, base, 1.0, free=free + ("omega_x",)).residual_sigmas == 0.0

    kind = gj.sweeps.QuadratureInjection()
    q = kind.inputs(qmg)
    sf = _sf(qmg)
    phase = absorption(lambda d: kind.predict(d, q, NAN, None)[0],
                       gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(0.0)),
                       gj.add_effect(qmg, gj.effects.QuadraturePhase.typical(1.0)), SIGMA_DPS * sf, free=free,
                       offsets=np.ones((5, 1)))
    assert phase.residual_sigmas > 4000


@pytest.mark.slow
def test_gradient_matches_finite_differences(qmg):
    """d(drive frequency at set-point 1.25)/d(duffing_x) through the steady tier's implicit derivative, against a
    central difference."""
    s = _setpoints(qmg, (1.25, 1.0))
    gyro = gj.add_effect(qmg, gj.effects.DuffingDrive.typical(1.0))

    def f(k):
        g = eqx.tree_at(lambda d: d.resonator.duffing_x, gyro, k)
        return gj.sweeps.DriveFrequency().predict(g, s, NAN, None)[0][0]

    k0 = gyro.resonator.duffing_x
    grad = float(jax.jit(jax.grad(f))(k0))
    h = 1e-3 * float(k0)
    fd = (float(f(k0 + h)) - float(f(k0 - h))) / (2 * h)
    assert grad == pytest.approx(fd, rel=1e-5)
    # The backbone's own derivative: w_x 3/8 a^2 / w_x^2 (1 + ...)^(-1/2) / (2 pi).
    assert grad > 0
