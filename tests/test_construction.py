"""Bad parameters are refused at construction, naming the parameter and the value; the DAC model's
describing function is right; the effect nests at zero."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj


def _resonator(**kw):
    base = dict(mass=1e-6, omega_x=3e4, omega_y=3e4, q_x=1e5, q_y=1e5)
    base.update(kw)
    return gj.physics.Resonator(**base)


@pytest.mark.parametrize("name,value", [("mass", -1e-6), ("mass", 0.0), ("q_x", 0.0), ("q_y", -5.0),
                                        ("omega_x", 0.0), ("omega_y", float("nan")), ("angular_gain", 0.0)])
def test_resonator_refuses_nonphysical(name, value):
    with pytest.raises(ValueError, match=rf"Resonator\.{name} must be positive.*{value!r}"):
        _resonator(**{name: value})


def test_electrode_gap_and_fraction():
    with pytest.raises(ValueError, match=r"FeedbackElectrode\.gap must be positive.*0\.0"):
        gj.physics.FeedbackElectrode(k_vf=1e-6, v_dc=10.0, gap=0.0)
    with pytest.raises(ValueError, match=r"FeedbackElectrode\.gap_fraction must lie in \[0\.0, 1\.0\).*1\.5"):
        gj.physics.FeedbackElectrode(k_vf=1e-6, v_dc=10.0, gap=2e-6, gap_fraction=1.5)
    with pytest.raises(ValueError, match=r"from_geometry\.thickness must be positive"):
        gj.physics.FeedbackElectrode.from_geometry(fingers=100, thickness=-1, gap=2e-6, tip_width=4e-6, v_dc=10)


@pytest.mark.parametrize("bits", [0, -3, 2.5])
def test_dac_bits(bits):
    with pytest.raises(ValueError, match=rf"DAC\.bits must be an integer >= 1, got {bits!r}"):
        gj.physics.DAC(bits=bits)


def test_dac_other_fields():
    with pytest.raises(ValueError, match=r"DAC\.word_bits must be an integer >= bits \(16\)"):
        gj.physics.DAC(bits=16, word_bits=12)
    with pytest.raises(ValueError, match=r"DAC\.update_rate must be positive.*-1"):
        gj.physics.DAC(update_rate=-1.0)
    with pytest.raises(ValueError, match=r"DAC\.full_scale must be positive"):
        gj.physics.DAC(full_scale=0.0)


def test_unknown_names():
    with pytest.raises(ValueError, match=r"unknown preset 'qmg'; expected one of \['paper-qmg', 'vcf-2018'\]"):
        gj.preset("qmg")
    with pytest.raises(ValueError, match=r"unknown effect 'dac_inl2'; expected one of "
                                         r"\[.*'dac_inl', .*'vref_drift', 'zro_tempco'\]"):
        gj.effect("dac_inl2")
    with pytest.raises(ValueError, match=r"FrontEnd\.kind must be one of"):
        gj.physics.FrontEnd(1e-6, 1e11, 1e-7, kind="capacitive")


def test_loops_and_tiers_refuse_bad_settings():
    with pytest.raises(ValueError, match=r"DriveLoop\.pll_kp must be positive"):
        gj.physics.DriveLoop(1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"RebalanceLoop\.leak must be non-negative"):
        gj.physics.RebalanceLoop(1.0, 1.0, 1.0, leak=-1.0)
    with pytest.raises(ValueError, match=r"Averaged\.settle_time must be positive"):
        gj.Averaged(settle_time=0.0)
    with pytest.raises(ValueError, match=r"Steady\.jacobian must be 'once' \(chord\) or 'every_step'"):
        gj.Steady(jacobian="broyden")
    with pytest.raises(ValueError, match=r"Steady tier: stimulus\.rate_frequency must be 0"):
        gj.settle(gj.paper_qmg(), gj.physics.Stimulus(rate=1.0, rate_frequency=10.0), gj.Steady())
    with pytest.raises(ValueError, match=r"Stimulus\.time must be non-negative"):
        gj.physics.Stimulus(time=-1.0)
    with pytest.raises(ValueError, match=r"give exactly one of rebalance_loop"):
        g = gj.paper_qmg()
        gj.Gyroscope(g.resonator, g.drive_electrode, g.drive_frontend, g.sense_frontend, g.drive_loop)


def test_dac_describing_function_of_quantiser_against_fft():
    """The DAC is memoryless on the carrier; its fundamental by phase quadrature must equal the FFT of a
    densely sampled, quantised sine."""
    dac = gj.physics.DAC(quantize=True, inl=jnp.array([0.0, 3.0]), update_rate=math.inf)
    word = 5.3 * 256.0  # a 5.3-code sine: quantisation matters at the percent level
    n = 1 << 16
    theta = 2 * np.pi * np.arange(n) / n
    v = np.asarray(dac(jnp.asarray(word * np.sin(theta))))
    fft_fundamental = 2 * np.fft.rfft(v)[1] / n  # phasor of the cos component; sine -> -imag
    quadrature = 2 * np.mean(v * np.sin(theta))
    assert quadrature == pytest.approx(-fft_fundamental.imag, rel=1e-9)
    # and it differs from the ideal linear amplitude by more than 0.1 %: quantisation is really on
    ideal = word * dac.volts_per_word_lsb
    assert abs(quadrature / ideal - 1) > 1e-3


def test_dac_hold_is_sinc_and_half_sample_delay():
    dac = gj.physics.DAC(update_rate=1e6)
    gain, delay = dac.hold(2 * np.pi * 5e3)
    x = np.pi * 5e3 / 1e6
    assert float(gain) == pytest.approx(np.sin(x) / x, rel=1e-14)
    assert float(delay) == pytest.approx(x, rel=1e-14)


def test_dac_sweep_reproduces_table2_scale():
    """16-bit DAC, +/-5 V, 24-bit word: seed 000 Table 2's 0x29E345 = 2,745,157 gives about 1.637 V."""
    volts = float(gj.sweeps.dac_sweep(gj.paper_qmg(), np.array([2745157.0]))[0])
    assert volts == pytest.approx(1.637, rel=2e-3)


def test_effect_nests_at_zero():
    g = gj.paper_qmg()
    s0 = gj.rate_sweep(g, gj.ding_zhou_2025_rates())
    s1 = gj.rate_sweep(gj.add_effect(g, gj.effects.DacInl.typical(0.0)), gj.ding_zhou_2025_rates())
    assert np.array_equal(np.asarray(s0.rate), np.asarray(s1.rate))


def test_feedback_force_is_linear_at_rest_and_geometry_consistent():
    e = gj.physics.FeedbackElectrode.from_geometry(fingers=200, thickness=60e-6, gap=2e-6, tip_width=4e-6, v_dc=10.0)
    v = jnp.linspace(-2, 2, 9)
    assert np.allclose(np.asarray(e.force(0.0, v, v)), np.asarray(e.k_vf * v), rtol=1e-12, atol=0)
    # at v = 0 the electrostatic spring is removed (it is inside the operated w_y): what is left of the
    # finger-tip term is odd and cubic, 1/2 a V_dc^2 rho 8 (y/d0)^3 with a = K_vf / (2 V_dc)
    y = 1e-8
    assert float(e.force(y, 0.0, 0.0)) == pytest.approx(-float(e.force(-y, 0.0, 0.0)), rel=1e-9)
    cubic = 0.5 * float(e.k_vf) / 20.0 * 100.0 * float(e.gap_fraction) * 8 * (y / 2e-6) ** 3
    assert float(e.force(y, 0.0, 0.0)) == pytest.approx(cubic, rel=1e-3)
    mismatched = eqx.tree_at(lambda x: x.gap_fraction, e, 0.0)
    # unequal branches leave a DC force K_vf (v+^2 - v-^2) / (4 V_dc)
    f = float(mismatched.force(0.0, 1.1, 1.0))
    assert f == pytest.approx(float(e.k_vf) * (1.05 + (1.1**2 - 1.0) / (4 * 10.0)), rel=1e-12)
