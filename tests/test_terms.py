"""The device's slots for new physics (`gyrojax.AbstractRateTerm`, `AbstractFeedbackTerm`,
`AbstractOutputTerm`, `TemperatureCoefficient`): each acts where its physics sits, and nowhere else.

The expected numbers are derived by hand from the loop physics, not from the model: a rate term is a rate the
loop balances (SF x Om_eq), a cubic after the DAC compresses the carrier fundamental by 3c/4 (w/W)^2, a
temperature coefficient on the drive pick-off makes the AGC hold an amplitude (and a scale factor) smaller
by 1 / (1 + tc dT)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj


QMG = gj.paper_qmg()
RATES = np.array([-200.0, -50.0, 0.0, 50.0, 200.0])  # deg/s
AT_25 = np.full(RATES.size, 25.0)


class _OffsetPerHour(gj.AbstractOutputTerm):
    """A readout offset drifting with time, in LSB per hour (test-only)."""

    per_hour: jax.Array

    def __call__(self, gyro, output, conditions):
        return output + self.per_hour * conditions.time / 3600.0


class _RateBias(gj.AbstractRateTerm):
    """A constant rate-equivalent force (test-only): must read exactly like a rate."""

    bias: jax.Array

    def rate(self, gyro, temperature, time, rate):
        return self.bias


def _rate_out(gyro, rates=RATES, temps=AT_25, times=None):
    return np.asarray(gj.rate_table_points(gyro, rates, temps, times=times).rate)


def test_with_term_checks_what_it_is_given():
    with pytest.raises(ValueError, match="Gyroscope.with_term expects a gyrojax term"):
        QMG.with_term(gj.effects.DacInl.typical())
    with pytest.raises(ValueError, match=r"TemperatureCoefficient.path 'drive_frontend.gian' is not a leaf"):
        QMG.with_term(gj.TemperatureCoefficient("drive_frontend.gian", 1e-5))
    with pytest.raises(ValueError, match=r"'drive_frontend.kind' of device 'paper-qmg' is a str, not a number"):
        QMG.with_term(gj.TemperatureCoefficient("drive_frontend.kind", 1e-5))


@pytest.mark.slow
def test_a_rate_term_reads_exactly_like_a_rate():
    """Om_eq enters the sense equation beside Ag Om: a constant term of 1 deg/s gives the outputs of the table
    rates shifted by 1 deg/s, in every settled tier."""
    shifted = _rate_out(QMG, RATES + 1.0)
    with_term = _rate_out(QMG.with_term(_RateBias(jnp.asarray(1.0 * gj.units.DEG))))
    np.testing.assert_allclose(with_term, shifted, rtol=1e-11, atol=1e-6)
    averaged = gj.rate_sweep(QMG.with_term(_RateBias(jnp.asarray(1.0 * gj.units.DEG))), RATES * gj.units.DEG,
                             tier=gj.Averaged())
    np.testing.assert_allclose(np.asarray(averaged.rate), shifted, rtol=1e-7)


@pytest.mark.slow  # 33-44 s cold (fast tier, 2026-11-26)
def test_an_output_term_reaches_the_rate_outputs_only():
    """A readout offset of 100 LSB/h, one hour after power-on: +100 LSB on rate-table and static-VCF points;
    the DAC sweep (read at the DAC) does not see it."""
    g = QMG.with_term(_OffsetPerHour(jnp.asarray(100.0)))
    hour = np.full(RATES.size, 3600.0)
    np.testing.assert_allclose(_rate_out(g, times=hour) - _rate_out(QMG, times=hour), 100.0, rtol=1e-12)
    np.testing.assert_allclose(_rate_out(g) - _rate_out(QMG), 0.0, atol=1e-9)  # time not recorded: 0
    volts = np.array([-1.0, 1.0])
    vcf = np.asarray(gj.sweeps.vcf_static_points(g, volts, AT_25[:2], times=hour[:2]).rate)
    vcf0 = np.asarray(gj.sweeps.vcf_static_points(QMG, volts, AT_25[:2], times=hour[:2]).rate)
    np.testing.assert_allclose(vcf - vcf0, 100.0, rtol=1e-12)
    words = jnp.array([-2.0e6, 2.0e6])
    np.testing.assert_array_equal(np.asarray(gj.sweeps.dac_points(g, words)),
                                  np.asarray(gj.sweeps.dac_points(QMG, words)))


@pytest.mark.slow
def test_an_output_term_does_not_reach_the_dynamic_vcf_lock_in():
    """The dynamic VCF's lock-in reads the output at the modulation frequency: a readout offset does not reach
    it. (Slow: linearising the averaged model compiles for about a minute.)"""
    g = QMG.with_term(_OffsetPerHour(jnp.asarray(100.0)))
    amp, _ = gj.sweeps.vcf_dynamic_points(g, jnp.array([10.0, 100.0]), 25.0)
    amp0, _ = gj.sweeps.vcf_dynamic_points(QMG, jnp.array([10.0, 100.0]), 25.0)
    np.testing.assert_array_equal(np.asarray(amp), np.asarray(amp0))


@pytest.mark.slow
def test_a_temperature_coefficient_scales_its_leaf_at_the_die_temperature():
    """On the drive pick-off gain: the AGC holds the measured amplitude, so at dT = +10 K the real amplitude and
    the closed-loop scale factor fall by 1 / (1 + tc dT); at t_ref nothing moves. The rate-table output of a
    closed loop is linear in the word, so the ratio is the same at every rate."""
    tc = 50e-6
    g = QMG.with_term(gj.TemperatureCoefficient("drive_frontend.gain", tc))
    hot = np.full(RATES.size, 35.0)
    ratio = _rate_out(g, temps=hot)[[0, 1, 3, 4]] / _rate_out(QMG, temps=hot)[[0, 1, 3, 4]]
    np.testing.assert_allclose(ratio, 1.0 / (1.0 + tc * 10.0), rtol=1e-9)
    np.testing.assert_allclose(_rate_out(g), _rate_out(QMG), rtol=1e-12, atol=1e-9)
    # the coefficient acts inside the tiers at each instant's temperature, so the averaged tier agrees
    warm = eqx.tree_at(lambda d: d.temperature, g, gj.temperature.ConstantTemperature(jnp.asarray(35.0)))
    averaged = gj.rate_sweep(warm, RATES * gj.units.DEG, tier=gj.Averaged())
    np.testing.assert_allclose(np.asarray(averaged.rate), _rate_out(g, temps=hot), rtol=1e-7, atol=1e-3)


def test_feedback_compression_compresses_the_carrier_and_leaves_the_dac_sweep():
    """V -> V (1 - c (V/V_fs)^2) on the carrier samples: the fundamental of a sine of amplitude A falls by
    3c/4 (A/V_fs)^2, so the loop raises the word by that much at |word|/W = A/V_fs. The carrier carries the rate
    word and the quadrature word (paper-qmg's 10 deg/s of quadrature): both set the amplitude, so even the
    zero-rate gain moves, by 3c/4 (Q/W)^2 = 2e-7 here. The DAC's zero-order hold scales the carrier amplitude by
    sinc(w T / 2) (1 - 3.5e-5 at 1 MHz). The DAC sweep reads before the amplifier."""
    c = 1e-3
    g = gj.effects.FeedbackCompression(c).apply(QMG)
    settled = gj.rate_table_points(QMG, RATES, AT_25)
    base, quad = np.asarray(settled.rate), np.asarray(settled.quadrature)
    hold = float(QMG.excitation.dac.hold(QMG.resonator.omega_x)[0])
    k = 0.75 * c * hold**2 * (base**2 + quad**2) / 2.0**46
    expected = base * (1.0 + k + 3.0 * k**2)  # w' (1 - k w'^2/w^2) = w, inverted to second order
    np.testing.assert_allclose(_rate_out(g), expected, rtol=1e-10, atol=1e-6)
    assert 1.9e-7 < 0.75 * c * quad[2] ** 2 / 2.0**46 < 2.1e-7
    words = jnp.array([-2.7e6, 1.0e6, 2.7e6])
    np.testing.assert_array_equal(np.asarray(gj.sweeps.dac_points(g, words)),
                                  np.asarray(gj.sweeps.dac_points(QMG, words)))


@pytest.mark.slow
def test_zro_tempco_is_a_bias_that_follows_the_die_temperature():
    """SF x b_T (T - t_ref) at every rate: 13709.8 LSB/(deg/s) x 1e-3 (deg/s)/K x 10 K = 137 LSB (a constant
    shift of the whole sweep), and nothing at t_ref; the gradient at zero matches a central difference."""
    hot = np.full(RATES.size, 35.0)
    g = gj.add_effect(QMG, "zro_tempco")
    sf = np.polyfit(RATES, _rate_out(QMG, temps=hot), 1)[0]
    np.testing.assert_allclose(_rate_out(g, temps=hot) - _rate_out(QMG, temps=hot), sf * 1e-3 * 10.0, rtol=1e-6)
    np.testing.assert_allclose(_rate_out(g), _rate_out(QMG), atol=1e-6)

    def out(b):
        return gj.rate_table_points(gj.effects.ZroTempco(b).apply(QMG), RATES, hot).rate

    slope = np.asarray(jax.jacfwd(out)(0.0))
    h = 1e-6
    fd = (np.asarray(out(h)) - np.asarray(out(-h))) / (2 * h)
    np.testing.assert_allclose(slope, fd, rtol=1e-6)
