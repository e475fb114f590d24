"""The revealing experiments' measurement models (gyrojax/_revealing): closed forms, zero effect -> zero change,
the fingerprint's size in noise sigmas after the baseline absorbs what it can, the tiers, gradients."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj
from gyrojax._revealing import (
    amplitude_rate_table as art,
    branch_voltages as bv,
    drive_amplitude as da,
    quadrature_injection as qi,
    temperature_plateaus as tp,
)
from gyrojax._revealing._absorb import absorption


DEG = gj.units.DEG
SIGMA_DPS = gj.RateNoise().point_sigma_dps(120.0)


@pytest.fixture(scope="module")
def qmg():
    return gj.paper_qmg()


def _sf(gyro):
    return float(gyro.ideal_scale_factor()) * DEG


def test_drive_amplitude_backbone_and_sag(qmg):
    """The PLL frequency follows the Duffing backbone w_x sqrt(1 + 3/4 duffing_x a^2) and the AGC's standing
    error is the same fraction of every set-point, beta = 2 w m g_x leak / (K_dx |G_d| (kp leak + ki)); with
    both effects at zero the readings are exactly the nominal frequency and the set-points."""
    s = da.DriveAmplitudeSettings()
    ratio = np.asarray(s.setpoint_ratio)
    zero = da.predict(gj.add_effect(qmg, gj.DuffingDrive.typical(0.0)), s)
    assert np.array_equal(np.asarray(zero.frequency_hz), np.full(ratio.shape, 4634.0))
    assert np.array_equal(np.asarray(zero.amplitude_lsb), np.asarray(da.setpoint_lsb(qmg, s)))

    duff = gj.add_effect(qmg, gj.DuffingDrive.typical(1.0))
    got = np.asarray(da.predict(duff, s).frequency_hz)
    r = duff.resonator
    a = ratio * float(qmg.drive_amplitude(r.omega_x))
    expected = float(r.omega_x) * np.sqrt(1.0 + 0.75 * float(r.duffing_x) * a**2 / float(r.omega_x) ** 2) / (2 * np.pi)
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    assert (got[-1] / got[0] - 1) * 1e6 == pytest.approx(49.2, abs=0.5)  # 0.5x -> 1.25x at the typical kappa

    leaky = gj.add_effect(qmg, gj.AgcFiniteGain.typical(1.0))
    sag = np.asarray(da.predict(leaky, s).amplitude_lsb / da.setpoint_lsb(qmg, s)) - 1.0
    dl, rr = leaky.drive_loop, leaky.resonator
    w = float(rr.omega_x)
    beta = (2 * w * float(rr.mass) * w / (2 * float(rr.q_x)) * float(dl.agc_leak)
            / (float(leaky.drive_electrode.force_per_volt) * abs(complex(leaky.drive_frontend.phasor_gain(w)))
               * (float(dl.agc_kp) * float(dl.agc_leak) + float(dl.agc_ki))))
    np.testing.assert_allclose(sag, -beta / (1 + beta), rtol=1e-6)
    assert sag[0] * 1e6 == pytest.approx(-13.7, abs=0.1)
    # The sag alone, in sigmas of the amplitude reading, with nothing in the baseline to take it.
    assert np.linalg.norm(sag / (da.AMPLITUDE_SIGMA_PPM * 1e-6)) > 30


def test_quadrature_injection_reads_tan_phi(qmg):
    """Closed loop, the rate output moves with the injected quadrature by tan(phi) of the quadrature word's
    change; at phi = 0 it does not move (to round-off), so a run bias cannot take the slope."""
    s = qi.QuadratureInjectionSettings.from_rates(qmg)
    sf = _sf(qmg)
    zero = qi.predict(gj.add_effect(qmg, gj.QuadraturePhase.typical(0.0)), s)
    assert np.max(np.abs(np.asarray(zero.rate_lsb))) < 1e-9 * sf
    np.testing.assert_allclose(np.asarray(zero.quadrature_lsb) / sf, [-110, -60, -10, 40, 90], atol=1e-6)

    phi = float(gj.QuadraturePhase.typical(1.0).phase)
    out = qi.predict(gj.add_effect(qmg, gj.QuadraturePhase.typical(1.0)), s)
    slope_rate = np.polyfit(np.asarray(s.amplitude_v), np.asarray(out.rate_lsb), 1)[0]
    slope_quad = np.polyfit(np.asarray(s.amplitude_v), np.asarray(out.quadrature_lsb), 1)[0]
    assert slope_rate / slope_quad == pytest.approx(np.tan(phi), rel=1e-6)
    # +/-100 deg/s of injected quadrature: the rate moves by ~+/-0.5 deg/s, thousands of point sigmas even
    # after a run bias takes the mean.
    change = np.asarray(out.rate_lsb - zero.rate_lsb) / sf
    assert np.linalg.norm((change - change.mean()) / SIGMA_DPS) > 3000


def test_branch_voltages_ratio(qmg):
    """V+ / V- = (1 + e+) / (1 + e-) at every rate; exactly 1 with matched branches."""
    s = bv.BranchVoltageSettings()
    zero = bv.predict(gj.add_effect(qmg, gj.PushPullMismatch.typical(0.0)), s)
    np.testing.assert_array_equal(np.asarray(zero.v_plus), np.asarray(zero.v_minus))
    # 200 deg/s is seed 000 Table 2's 1.637 V at the DAC (K_a = 1), less the quadrature's share.
    assert float(zero.v_plus[-1]) == pytest.approx(1.637, rel=2e-3)
    eff = gj.PushPullMismatch.typical(1.0)
    out = bv.predict(gj.add_effect(qmg, eff), s)
    np.testing.assert_allclose(np.asarray(out.v_plus / out.v_minus), (1 + float(eff.plus)) / (1 + float(eff.minus)),
                               rtol=1e-12)
    with pytest.raises(ValueError, match="closed-loop device"):
        bv.predict(gj.vcf_2018(), s)


def test_two_amplitude_intercepts(qmg):
    """The damping coupling's zero-rate output scales with the drive amplitude: the intercepts at set-point 1 and
    0.5 differ by (SF(1) - SF(0.5)) c / (2 Ag), which one run bias cannot take."""
    s = art.AmplitudeRateTableSettings.default()
    sf = _sf(qmg)
    base = art.predict(gj.add_effect(qmg, gj.DampingCoupling.typical(0.0)), s).rate_lsb
    eff = gj.DampingCoupling.typical(1.0)
    out = art.predict(gj.add_effect(qmg, eff), s).rate_lsb
    change = np.asarray(out - base) / sf
    zro = float(eff.c) / (2 * float(qmg.resonator.angular_gain)) / DEG
    np.testing.assert_allclose(change[:7], zro, rtol=1e-6)
    np.testing.assert_allclose(change[7:], 0.5 * zro, rtol=1e-6)
    # Slopes halve with the set-point (the AGC holds the ratio).
    slope = [np.polyfit(np.asarray(s.rates_dps[k:k + 7]), np.asarray(base[k:k + 7]), 1)[0] for k in (0, 7)]
    assert slope[1] / slope[0] == pytest.approx(0.5, rel=1e-9)


def test_plateau_history_and_vref(qmg):
    """The die reaches each plateau (plus its self-heating) within the soak, and vref_drift scales the static
    VCF output by 1 / (1 + tc dT) between plateaus (the rate table also by the drive frequency's TCF)."""
    s = tp.PlateauSettings.for_device(qmg)
    history = s.history()
    t_rate, t_vcf = s.point_times()
    temps = np.asarray(history(t_rate[:, 0]))
    np.testing.assert_allclose(temps, np.asarray(s.plateaus_c) + tp.WARMUP_RISE_K, atol=0.05)
    base = tp.predict(gj.add_effect(qmg, gj.VrefDrift.typical(0.0)), s)
    eff = gj.VrefDrift.typical(1.0)
    out = tp.predict(gj.add_effect(qmg, eff), s)
    ratio = np.asarray(out.vcf_lsb / base.vcf_lsb)
    dt = np.asarray(out.vcf_temperature_c) - float(qmg.resonator.t_ref)
    np.testing.assert_allclose(ratio, 1.0 / (1.0 + float(eff.tc) * dt), rtol=1e-9)
    with pytest.raises(ValueError, match="at least 2 plateaus"):
        tp.PlateauSettings(vcf_amplitudes_v=(1.0,), plateaus_c=(25.0,), rates_dps=(10.0,))
    with pytest.raises(ValueError, match="one voltage per rate"):
        tp.PlateauSettings(vcf_amplitudes_v=(1.0,))


def test_settings_errors(qmg):
    with pytest.raises(ValueError, match="setpoint_ratio must be a 1-d array of positive"):
        da.DriveAmplitudeSettings(setpoint_ratio=[1.0, -0.5])
    with pytest.raises(ValueError, match="virtual-Coriolis electrode"):
        qi.QuadratureInjectionSettings.from_rates(eqx.tree_at(lambda g: g.vcf_electrode.force_per_volt2, qmg, 0.0))
    with pytest.raises(ValueError, match="starts_s must be >= 0 and increasing"):
        tp.PlateauTemperature((10.0, 20.0), (100.0, 50.0))


@pytest.mark.slow
def test_full_waveform_agrees(qmg):
    """The full-waveform tier (carrier, 3w harmonic of the cubic spring, demodulator ripple) against the steady
    tier: the Duffing shift between set-points 0.5 and 1.25 and the quadrature injection's rate change (the
    tiers' common 0.24 ppm frequency offset cancels). The AGC sag is not compared: on paper-qmg the full
    waveform's demodulator ripple, through the AGC's proportional gain, supplies most of the drive force, so its
    integrator (and the leak's sag) sit elsewhere than the averaged tiers'."""
    full = gj.FullWaveform(settle_time=0.05, average_periods=20)
    s = da.DriveAmplitudeSettings(setpoint_ratio=[0.5, 1.25])
    duff = gj.add_effect(qmg, gj.DuffingDrive.typical(1.0))
    rs, rf = da.predict(duff, s), da.predict(duff, s, tier=full)
    shift_s = float(rs.frequency_hz[1] / rs.frequency_hz[0] - 1)
    shift_f = float(rf.frequency_hz[1] / rf.frequency_hz[0] - 1)
    assert abs(shift_f - shift_s) < 0.3e-6  # of a 49 ppm shift

    q = qi.QuadratureInjectionSettings.from_rates(qmg, (-100.0, 100.0))
    phase = gj.add_effect(qmg, gj.QuadraturePhase.typical(1.0))
    qs, qf = qi.predict(phase, q), qi.predict(phase, q, tier=full)
    sf = _sf(qmg)
    step_s = float(qs.rate_lsb[1] - qs.rate_lsb[0]) / sf
    step_f = float(qf.rate_lsb[1] - qf.rate_lsb[0]) / sf
    assert step_f == pytest.approx(step_s, rel=0.01)  # a 1.0 deg/s step


@pytest.mark.slow
def test_baseline_leaves_the_fingerprints(qmg):
    """After the baseline's free parameters (and run biases, a meter gain) absorb what they can, each effect's
    fingerprint stays many sigmas; a zero effect leaves nothing."""
    free = gj._parameters.DEFAULT_FREE
    s = da.DriveAmplitudeSettings()

    def drive(d):
        r = da.predict(d, s)
        return jnp.concatenate([r.frequency_hz / (da.FREQUENCY_SIGMA_PPM * 1e-6 * 4634.0),
                                r.amplitude_lsb / (da.AMPLITUDE_SIGMA_PPM * 1e-6 * da.setpoint_lsb(qmg, s))])

    base = gj.add_effect(qmg, gj.DuffingDrive.typical(0.0))
    duff = absorption(drive, base, gj.add_effect(qmg, gj.DuffingDrive.typical(1.0)), 1.0, free=free + ("omega_x",))
    assert duff.signature_sigmas > 80 and duff.residual_sigmas > 40
    assert absorption(drive, base, base, 1.0, free=free + ("omega_x",)).residual_sigmas == 0.0

    q = qi.QuadratureInjectionSettings.from_rates(qmg)
    sf = _sf(qmg)
    phase = absorption(lambda d: qi.predict(d, q).rate_lsb, gj.add_effect(qmg, gj.QuadraturePhase.typical(0.0)),
                       gj.add_effect(qmg, gj.QuadraturePhase.typical(1.0)), SIGMA_DPS * sf, free=free,
                       offsets=np.ones((5, 1)))
    assert phase.residual_sigmas > 4000


@pytest.mark.slow
def test_gradient_matches_finite_differences(qmg):
    """d(drive frequency at set-point 1.25)/d(duffing_x) through the steady tier's implicit derivative, against a
    central difference."""
    s = da.DriveAmplitudeSettings(setpoint_ratio=[1.25])
    gyro = gj.add_effect(qmg, gj.DuffingDrive.typical(1.0))

    def f(k):
        g = eqx.tree_at(lambda d: d.resonator.duffing_x, gyro, k)
        return da.predict(g, s).frequency_hz[0]

    k0 = gyro.resonator.duffing_x
    grad = float(jax.jit(jax.grad(f))(k0))
    h = 1e-3 * float(k0)
    fd = (float(f(k0 + h)) - float(f(k0 - h))) / (2 * h)
    assert grad == pytest.approx(fd, rel=1e-5)
    # The backbone's own derivative: w_x 3/8 a^2 / w_x^2 (1 + ...)^(-1/2) / (2 pi).
    assert grad > 0
