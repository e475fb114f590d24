"""Open-loop physics (seed 003 device): Coriolis frequency pulling and the rate bandwidth."""

import numpy as np
import pytest

import gyrojax as gj


DEG = gj.units.DEG


RATES = np.array([1.0, 50.0, 100.0, 200.0]) * DEG


@pytest.fixture(scope="module")
def device():
    return gj.vcf_2018()


def _split(dev):
    r = dev.resonator
    return float((r.omega_y**2 - r.omega_x**2) / (2 * r.omega_x))


@pytest.mark.parametrize("tier", [gj.Steady(), gj.Averaged(settle_time=0.1)], ids=["steady", "averaged"])
def test_coriolis_frequency_pulling(device, tier):
    """Levels repel: the drive resonance is pulled down by (Ag Om)^2 / dw, the split widens, and the
    open-loop scale factor FALLS as SF0 (1 - Ag^2 Om^2 / dw^2) (docs/physics.md). (Not 1 +: the
    full-waveform tier below settles the sign.)"""
    s = gj.rate_sweep(device, RATES, tier=tier)
    sf = np.asarray(s.rate) / RATES
    law = -(RATES / _split(device)) ** 2  # Ag = 1
    measured = sf / sf[0] - 1 - law[0]
    assert np.allclose(measured[1:], law[1:], rtol=0.05)
    # and the PLL frequency moves by -(Ag Om)^2 / dw
    dw = np.asarray(s.frequency) - float(device.resonator.omega_x)
    assert np.allclose(dw[1:], -(RATES[1:] ** 2) / _split(device), rtol=0.05)


@pytest.mark.slow
def test_pulling_sign_in_full_waveform(device):
    s = gj.rate_sweep(device, RATES[[0, 3]], tier=gj.FullWaveform(settle_time=0.05, average_periods=40))
    sf = np.asarray(s.rate) / RATES[[0, 3]]
    change = sf[1] / sf[0] - 1
    expected = -((RATES[3] / _split(device)) ** 2)
    assert change < 0
    assert change == pytest.approx(expected, rel=0.1)


@pytest.mark.slow
def test_bandwidth_against_seed003(device):
    """The model's rate bandwidth with Table 2's numbers is ~1.55 x the split (~97 Hz), not the paper's
    354.3 Hz (measured) / 349.5 Hz (simulated): seed 003's numbers do not close."""
    bw = gj.physics.bandwidth(device)
    split_hz = _split(device) / (2 * np.pi)
    assert bw == pytest.approx(np.sqrt(1 + np.sqrt(2)) * split_hz, rel=0.02)
    assert bw < 0.3 * 354.3
    # the dynamic virtual-Coriolis test sees the same response
    assert gj.physics.bandwidth(device, input="vcf") == pytest.approx(bw, rel=1e-9)


@pytest.mark.slow
def test_frequency_response_dc_gain_is_the_steady_slope(device):
    h0 = complex(np.asarray(gj.physics.frequency_response(device, np.zeros(1)))[0])
    d = 1e-3
    s = gj.rate_sweep(device, np.array([-d, d]))
    slope = float(s.rate[1] - s.rate[0]) / (2 * d)
    assert h0.real == pytest.approx(slope, rel=1e-7)
    assert abs(h0.imag) < 1e-9 * abs(h0.real)


@pytest.mark.slow
def test_closed_loop_bandwidth_is_set_by_the_rebalance_loop():
    bw = gj.physics.bandwidth(gj.paper_qmg())
    # designed at wn = 100 Hz, zeta = 0.7, with four 1 kHz LPF stages: the rate output's -3 dB point
    assert 150 < bw < 400
