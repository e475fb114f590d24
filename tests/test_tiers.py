"""The three tiers against Eq. (2) and against each other, and the loops doing their jobs."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj


DEG = gj.units.DEG


RATES = gj.ding_zhou_2025_rates()
X = np.asarray(RATES)


def _fit(y):
    a = np.stack([X, np.ones_like(X)], 1)
    coef = np.linalg.lstsq(a, np.asarray(y), rcond=None)[0]
    res = np.asarray(y) - a @ coef
    return coef[0], np.max(np.abs(res)) / (abs(coef[0]) * np.max(np.abs(X))) * 1e6


@pytest.fixture(scope="module")
def devices():
    # Same array shapes for both devices, so each tier compiles once for the whole module.
    ideal = gj.add_effect(gj.paper_qmg(), gj.effects.DacInl.typical(0.0))
    inl = gj.add_effect(gj.paper_qmg(), gj.effects.DacInl.typical(1.0))
    return ideal, inl


TIERS = {"steady": gj.Steady(), "averaged": gj.Averaged(), "full": gj.FullWaveform()}


@pytest.fixture(scope="module")
def sweeps(devices):
    out = {}
    for name, tier in TIERS.items():
        for label, dev in zip(("ideal", "inl"), devices):
            s = gj.rate_sweep(dev, RATES, tier=tier)
            assert np.all(np.asarray(s.result == gj.RESULTS.successful)), (name, label)
            out[name, label] = s
    return out


def test_preset_scale_factor_is_seed000(devices):
    ideal, _ = devices
    # Eq. (2) in LSB/(deg/s) reproduces the measured 13,709.853 of seed 000 §5 by construction of K_vf.
    assert float(ideal.ideal_scale_factor()) * DEG == pytest.approx(13709.853, rel=1e-12)


@pytest.mark.parametrize("tier", list(TIERS))
@pytest.mark.slow
def test_ideal_scale_factor_matches_eq2(devices, sweeps, tier):
    ideal, _ = devices
    sf, _ = _fit(sweeps[tier, "ideal"].rate)
    assert abs(sf / float(ideal.ideal_scale_factor()) - 1) < 1e-6


@pytest.mark.slow
def test_chord_and_newton_steady_agree(devices, sweeps):
    """The default chord root find (one Jacobian) and Newton's method (a Jacobian per step) reach the same
    equilibrium: the sweeps agree far inside a ppm, and the chord takes at most a few more steps."""
    _, inl = devices
    newton = gj.rate_sweep(inl, RATES, tier=gj.Steady(jacobian="every_step"))
    chord = sweeps["steady", "inl"]
    full_scale = float(np.max(np.abs(np.asarray(newton.rate))))
    assert np.max(np.abs(np.asarray(chord.rate) - np.asarray(newton.rate))) / full_scale < 1e-9
    assert np.max(np.abs(np.asarray(chord.quadrature) - np.asarray(newton.quadrature))) / full_scale < 1e-9
    assert int(np.max(np.asarray(newton.num_steps))) >= 2  # the INL needs more than the operating point
    assert int(np.max(np.asarray(chord.num_steps))) <= int(np.max(np.asarray(newton.num_steps))) + 3


@pytest.mark.slow
def test_sweep_chord_matches_point_by_point_values_and_derivatives(devices):
    """`Steady.settle_points` (one chord Jacobian for the whole sweep, at its centre) against `settle` vmapped
    point by point (a chord Jacobian per point): the same rates far inside a ppm, and the same derivatives with
    respect to a feedback factor and an INL coefficient (each point's is implicit at its own root)."""
    _, inl = devices
    rates = jnp.asarray(RATES)

    def device(p):
        return eqx.tree_at(lambda g: (g.feedback_electrode.k_vf, g.excitation.dac.inl), inl,
                           (p[0], inl.excitation.dac.inl.at[1].set(p[1])))

    @jax.jit
    def by_sweep(p):
        return gj.rate_sweep(device(p), rates).rate

    @jax.jit
    def by_point(p):
        return jax.vmap(lambda r: gj.settle(device(p), gj.physics.Stimulus(rate=r)))(rates).rate

    p = jnp.array([float(inl.feedback_electrode.k_vf), float(inl.excitation.dac.inl[1])])
    a, b = np.asarray(by_sweep(p)), np.asarray(by_point(p))
    assert np.max(np.abs(a - b)) / np.max(np.abs(b)) < 1e-9
    ja, jb = np.asarray(jax.jit(jax.jacfwd(by_sweep))(p)), np.asarray(jax.jit(jax.jacfwd(by_point))(p))
    assert np.all(np.abs(jb) > 0)
    assert np.max(np.abs(ja - jb) / np.max(np.abs(jb), axis=0)) < 1e-7


@pytest.mark.parametrize("tier", ["averaged", "full"])
@pytest.mark.slow
def test_tiers_agree_with_inl(sweeps, tier):
    sf_s, nl_s = _fit(sweeps["steady", "inl"].rate)
    sf_t, nl_t = _fit(sweeps[tier, "inl"].rate)
    assert nl_s > 400  # the INL is really on: ~460 ppm of nonlinearity
    assert abs(sf_t / sf_s - 1) < 1e-6
    assert abs(nl_t - nl_s) < 1.0
    # point by point, relative to full scale
    fs = abs(sf_s) * np.max(np.abs(X))
    assert np.max(np.abs(np.asarray(sweeps[tier, "inl"].rate) - np.asarray(sweeps["steady", "inl"].rate))) / fs < 1e-6


@pytest.mark.slow
def test_loops_hold_their_set_points(devices, sweeps):
    ideal, _ = devices
    s = sweeps["full", "ideal"]
    w = np.asarray(s.frequency)
    omega_x = float(ideal.resonator.omega_x)
    # PLL locked to the drive resonance
    assert np.max(np.abs(w / omega_x - 1)) < 1e-6
    x, v = np.asarray(s.state.drive[:, 0]), np.asarray(s.state.drive[:, 1])
    a = float(ideal.drive_amplitude(omega_x))
    # AGC holds the drive amplitude
    assert np.max(np.abs(np.hypot(x, v / w) / a - 1)) < 1e-6
    # FTR holds the sense mass: residual motion < 1e-9 of what the open-loop sense would do at 200 deg/s
    r = ideal.resonator
    gy = float(r.omega_y / (2 * r.q_y))
    dy = float((r.omega_y**2 - r.omega_x**2) / (2 * r.omega_x))
    open_loop = 200 * DEG * a / np.hypot(gy, dy)
    y, vy = np.asarray(s.state.sense[:, 0]), np.asarray(s.state.sense[:, 1])
    assert np.max(np.hypot(y, vy / w)) < 1e-9 * open_loop


@pytest.mark.slow
def test_quadrature_loop_nulls_quadrature(devices):
    ideal, _ = devices
    kap = 2000.0  # rad^2/s^2 of stiffness coupling
    dev = eqx.tree_at(lambda g: g.resonator.stiffness_coupling, ideal, jnp.asarray(kap))
    r = dev.resonator
    a = dev.drive_amplitude(r.omega_x)
    expected = -float(r.mass * a * kap / dev.rebalance_gain(r.omega_x))
    for tier in (gj.Steady(), gj.Averaged()):
        s = gj.rate_sweep(dev, RATES, tier=tier)
        assert np.allclose(np.asarray(s.quadrature), expected, rtol=1e-7)
        assert np.max(np.abs(np.asarray(s.state.sense))) < 1e-15
    # the rate output does not see it (quadrature and rate are orthogonal with an exact carrier phase)
    base = gj.rate_sweep(ideal, RATES)
    quad = gj.rate_sweep(dev, RATES)
    assert np.max(np.abs(np.asarray(quad.rate) - np.asarray(base.rate))) < 1e-6


@pytest.mark.slow
def test_carrier_phase_error_mixes_quadrature_into_rate(devices):
    ideal, _ = devices
    kap, phi = 2000.0, 0.01
    dev = eqx.tree_at(lambda g: (g.resonator.stiffness_coupling, g.rebalance_loop.carrier_phase), ideal,
                      (jnp.asarray(kap), ideal.rebalance_loop.carrier_phase + phi))
    s0 = gj.settle(eqx.tree_at(lambda g: g.resonator.stiffness_coupling, ideal, jnp.asarray(kap)),
                   gj.physics.Stimulus())
    s = gj.settle(dev, gj.physics.Stimulus())
    q = float(s0.quadrature)
    # output = SF Om cos(phi) + Q sin(phi): at zero rate the bias is the quadrature word times sin(phi)
    assert float(s.rate) == pytest.approx(q * np.sin(phi), rel=1e-6)
