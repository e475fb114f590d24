"""The candidate-effects library: every effect nested at zero, structure-preserving, with a first-order
fingerprint (jacfwd against finite differences), the same in every tier, and with the fingerprint shape that
docs/physics.md states.

Compile budget: one values-and-Jacobian program per device structure (closed loop, open loop) serves the
nested-at-zero, fingerprint, finite-difference and shape tests; the tier checks reuse `gj.rate_sweep`'s
compiled programs at the shapes `test_tiers.py` and `test_open_loop.py` use; the full waveform is one
vmapped call at two rates over a stack of closed-loop devices.
"""

import dataclasses
import pathlib
import re

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import gyrojax as gj


DEG = gj.units.DEG


# --- devices -------------------------------------------------------------------------------------------
# A proportional-only-like rebalance loop (leak 1e4/s >> ki/kp): the residual sense motion that comb_gap and a
# closed-loop duffing_sense need (19 nm at 200 deg/s). Same structure as paper-qmg: one compile for both.
LEAKY_LEAK = 1e4


def _leaky(g):
    return eqx.tree_at(lambda d: d.rebalance_loop.leak, g, jnp.asarray(LEAKY_LEAK, dtype=float))


def _at(g, temperature):
    return eqx.tree_at(lambda d: d.temperature, g,
                       gj.temperature.ConstantTemperature(jnp.asarray(temperature, dtype=float)))


QMG = gj.paper_qmg()
LEAKY = _leaky(QMG)
VCF = gj.vcf_2018()
BASES = {"paper-qmg": QMG, "qmg-leaky": LEAKY, "vcf-2018": VCF}

# Where each effect's fingerprint is checked (its strongest supported device).
HOME = {
    "dac_inl": "paper-qmg", "pushpull_mismatch": "paper-qmg", "comb_gap": "qmg-leaky",
    "thermal_drift": "vcf-2018", "agc_finite_gain": "vcf-2018", "duffing_drive": "paper-qmg",
    "duffing_sense": "vcf-2018", "quadrature_phase": "paper-qmg", "damping_coupling": "paper-qmg",
    "vref_drift": "paper-qmg", "zro_tempco": "paper-qmg", "feedback_compression": "paper-qmg",
}

T_HOT = 35.0  # deg C: 10 K above the resonators' t_ref
RATES_DPS = np.array([-200.0, -100.0, -50.0, 50.0, 100.0, 200.0])
# Points (rate deg/s, VCF V_ac with V_fc = 1 V, die temperature): the six rates at t_ref, 200 deg/s hot, and
# closed loop a static VCF point (a 100 deg/s virtual rate on paper-qmg) cold and hot.
CLOSED_POINTS = (np.r_[RATES_DPS, 200.0, 0.0, 0.0], np.r_[np.zeros(7), 1.0, 1.0],
                 np.r_[np.full(6, 25.0), T_HOT, 25.0, T_HOT])
OPEN_POINTS = (np.r_[RATES_DPS, 200.0], np.zeros(7), np.r_[np.full(6, 25.0), T_HOT])
I_COLD, I_HOT, I_VCF, I_VCF_HOT = 5, 6, 7, 8  # 200 deg/s cold and hot, VCF cold and hot


def _outputs(gyro, points):
    """Steady (rate, quadrature, frequency) at each point, shape (point, 3)."""
    rates, vcf, temps = points

    def one(rate, v, temp):
        s = gj.Steady().settle(_at(gyro, temp), gj.physics.Stimulus(rate=rate * DEG, vcf_ac=v, vcf_fc=1.0))
        return jnp.stack([s.rate, s.quadrature, s.frequency])

    return jax.vmap(one)(*(jnp.asarray(p, dtype=float) for p in points))


class _Family:
    """Every effect supported on one device structure, as one flat parameter vector theta."""

    def __init__(self, names):
        self.names = tuple(names)
        zeros = tuple(jax.tree.map(jnp.zeros_like, gj.EFFECTS[n].typical(1.0)) for n in names)
        _, self.unravel = ravel_pytree(zeros)
        self.typical = np.asarray(ravel_pytree(tuple(gj.EFFECTS[n].typical(1.0) for n in names))[0])
        self.blocks, start = {}, 0
        for n, z in zip(names, zeros):
            size = ravel_pytree(z)[0].size
            self.blocks[n] = slice(start, start + size)
            start += size

    def device(self, theta, base):
        g = base
        for e in self.unravel(theta):
            g = e.apply(g)
        return g

    def theta(self, **scales):
        """theta with the named effects at `scale` x typical (name=scale)."""
        t = np.zeros_like(self.typical)
        for name, scale in scales.items():
            t[self.blocks[name]] = scale * self.typical[self.blocks[name]]
        return jnp.asarray(t)


CLOSED_FAMILY = _Family([n for n, c in gj.EFFECTS.items() if c.supports(LEAKY)])
OPEN_FAMILY = _Family([n for n, c in gj.EFFECTS.items() if c.supports(VCF)])


# These programs run in milliseconds; XLA's backend optimisation would cost more compile time than it saves.
_QUICK_COMPILE = {"xla_backend_optimization_level": 0}


def _jacobian_program(family):
    def f(theta, base, points):
        out = _outputs(family.device(theta, base), points)
        return out, out

    return jax.jit(jax.jacfwd(f, has_aux=True), compiler_options=_QUICK_COMPILE)


_PROGRAMS = {"closed": _jacobian_program(CLOSED_FAMILY), "open": _jacobian_program(OPEN_FAMILY)}


def _kind(base_name):
    return "open" if base_name == "vcf-2018" else "closed"


def _family_of(base_name):
    return OPEN_FAMILY if _kind(base_name) == "open" else CLOSED_FAMILY


def evaluate(base_name, theta=None, base=None):
    """`(values, jacobian)`: values (point, 3), jacobian (point, 3, theta) of the base device with `theta`."""
    kind = _kind(base_name)
    family = _family_of(base_name)
    points = OPEN_POINTS if kind == "open" else CLOSED_POINTS
    theta = jnp.zeros(family.typical.shape) if theta is None else theta
    jac, val = _PROGRAMS[kind](theta, BASES[base_name] if base is None else base, points)
    return np.asarray(val), np.asarray(jac)


def values(base_name, **effects):
    return evaluate(base_name, _family_of(base_name).theta(**effects))[0]


def _fit_line(x, y):
    a = np.stack([x, np.ones_like(x)], 1)
    coef = np.linalg.lstsq(a, y, rcond=None)[0]
    return coef, y - a @ coef


# --- the registry and the interface --------------------------------------------------------------------

def test_registry_names_every_effect_of_design_table():
    assert list(gj.EFFECTS) == ["dac_inl", "pushpull_mismatch", "comb_gap", "thermal_drift", "agc_finite_gain",
                                "duffing_drive", "duffing_sense", "quadrature_phase", "damping_coupling",
                                "vref_drift", "zro_tempco", "feedback_compression"]
    for name, cls in gj.EFFECTS.items():
        assert cls.name == name
        assert cls.description and "\n" not in cls.description and len(cls.description) < 110
        assert issubclass(cls, gj.AbstractEffect)
        assert getattr(gj.effects, cls.__name__) is cls
        # typical(0) is all zeros, typical(1) nonzero (dac_inl's u^4 term is zero by design)
        assert all(np.all(np.asarray(x) == 0) for x in jax.tree.leaves(cls.typical(0.0)))
        leaves = np.concatenate([np.ravel(x) for x in jax.tree.leaves(cls.typical(1.0))])
        assert np.count_nonzero(leaves) >= (leaves.size - 1 if name == "dac_inl" else leaves.size)
        assert all(jax.typeof(x).dtype == jnp.float64 and not jax.typeof(x).weak_type
                   for x in jax.tree.leaves(cls.typical(1.0)))


def test_supported_effects_per_device():
    assert gj.supported_effects(QMG) == ("dac_inl", "pushpull_mismatch", "thermal_drift", "agc_finite_gain",
                                         "duffing_drive", "quadrature_phase", "damping_coupling", "vref_drift",
                                         "zro_tempco", "feedback_compression")
    assert gj.supported_effects(LEAKY) == tuple(gj.EFFECTS)
    assert gj.supported_effects(VCF) == ("thermal_drift", "agc_finite_gain", "duffing_drive", "duffing_sense",
                                         "quadrature_phase", "damping_coupling", "zro_tempco")


@pytest.mark.parametrize("name, device, needs", [
    ("dac_inl", "vcf-2018", "a closed-loop device"),
    ("pushpull_mismatch", "vcf-2018", "a closed-loop device"),
    ("vref_drift", "vcf-2018", "a closed-loop device"),
    ("comb_gap", "vcf-2018", "a closed-loop device whose rebalance loop has a finite DC gain"),
    ("comb_gap", "paper-qmg", r"a closed-loop device whose rebalance loop has a finite DC gain \(RebalanceLoop\.leak"),
    ("duffing_sense", "paper-qmg", "a moving sense mass"),
    ("feedback_compression", "vcf-2018", "a closed-loop device"),
])
def test_unsupported_device_is_refused(name, device, needs):
    with pytest.raises(ValueError, match=rf"effect '{name}' cannot act on device '{device}': it needs {needs}"):
        gj.EFFECTS[name].typical().apply(BASES[device])
    with pytest.raises(ValueError, match=rf"effect '{name}' cannot act on device '{device}'"):
        gj.add_effect(BASES[device], name, 0.5)


def _leaf_paths(tree):
    return {jax.tree_util.keystr(p): x for p, x in jax.tree_util.tree_flatten_with_path(tree)[0]}


def _supported_pairs():
    return [(n, b) for n, c in gj.EFFECTS.items() for b, g in BASES.items() if c.supports(g)]


def _is_term(cls):
    return issubclass(cls, gj.AbstractTerm)


@pytest.mark.parametrize("name, base_name", [p for p in _supported_pairs() if _is_term(gj.EFFECTS[p[0]])])
def test_term_effects_add_one_term_of_the_same_structure_at_any_size(name, base_name):
    """An effect that needs a new term adds itself to the device's `terms` slot: the same structure at zero
    and at typical size (so the diagnosis compiles one model), and its only change is that term."""
    base = BASES[base_name]
    cls = gj.EFFECTS[name]
    zero, typ = cls.typical(0.0).apply(base), cls.typical(1.0).apply(base)
    assert zero.terms[:-1] == base.terms and isinstance(zero.terms[-1], cls)
    assert jax.tree.structure(zero) == jax.tree.structure(typ)
    assert [jax.typeof(x) for x in jax.tree.leaves(zero)] == [jax.typeof(x) for x in jax.tree.leaves(typ)]
    assert eqx.tree_equal(eqx.tree_at(lambda g: g.terms, zero, ()), base)
    assert len(cls.typical(1.0).apply(typ).terms) == len(base.terms) + 2


@pytest.mark.parametrize("name, base_name", [p for p in _supported_pairs() if not _is_term(gj.EFFECTS[p[0]])])
def test_nested_at_zero_and_structure_kept(name, base_name):
    base = BASES[base_name]
    cls = gj.EFFECTS[name]
    zero = cls.typical(0.0).apply(base)
    typ = cls.typical(1.0).apply(base)
    # nested at zero: the same tree, every leaf bit-identical
    assert jax.tree.structure(zero) == jax.tree.structure(base)
    for a, b in zip(jax.tree.leaves(zero), jax.tree.leaves(base)):
        assert jax.typeof(a) == jax.typeof(b) and np.array_equal(np.asarray(a), np.asarray(b))
    # at typical size: the structure, shapes and dtypes (weak types included) are kept: no retracing
    assert jax.tree.structure(typ) == jax.tree.structure(base)
    assert [jax.typeof(x) for x in jax.tree.leaves(typ)] == [jax.typeof(x) for x in jax.tree.leaves(base)]
    # and exactly the leaves named by plugs_into move
    before, after = _leaf_paths(base), _leaf_paths(typ)
    moved = {p for p in before if not np.array_equal(np.asarray(before[p]), np.asarray(after[p]))}
    declared = set(re.findall(r"[a-z_]+(?:\.[a-z_]+)+", cls.plugs_into))
    assert moved and {p.lstrip(".") for p in moved} <= declared
    # adds to what the device has: applying twice is the effect at twice the size
    twice = cls.typical(1.0).apply(typ)
    double = cls.typical(2.0).apply(base)
    for a, b in zip(jax.tree.leaves(twice), jax.tree.leaves(double)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-15, atol=0)


@pytest.mark.parametrize("base_name", list(BASES))
@pytest.mark.slow
def test_nested_at_zero_steady_outputs_are_identical(base_name):
    base = BASES[base_name]
    ref, _ = evaluate(base_name)
    for name, cls in gj.EFFECTS.items():
        if cls.supports(base):
            out, _ = evaluate(base_name, base=cls.typical(0.0).apply(base))
            assert np.array_equal(out, ref), name


def test_a_lot_as_large_as_an_effects_coefficients_gets_them_per_device():
    """A DAC INL has 4 coefficients: on a lot of 4 devices (as of 3 or 5) every device starts from all four,
    not device k from the k-th (a leading axis of the lot's size is not the device axis unless the leaf has one
    dimension more than one device's); an effect already per device is kept, and one of another lot refused."""
    from gyrojax._model.parameters import Model, batched

    inl = gj.effects.DacInl.typical(1.0)
    for n in (3, 4, 5):
        lot = batched(Model(gj.paper_qmg(), (inl, gj.effects.ThermalDrift.typical(1.0))), n)
        coefficients = np.asarray(lot.effects[0].coefficients)
        assert coefficients.shape == (n, 4)
        np.testing.assert_array_equal(coefficients, np.broadcast_to(np.asarray(inl.coefficients), (n, 4)))
        assert np.shape(lot.effects[1].tcf) == (n,)
        again = batched(lot, n)
        np.testing.assert_array_equal(np.asarray(again.effects[0].coefficients), coefficients)
    per_device = gj.effects.DacInl(jnp.arange(12.0).reshape(3, 4))
    with pytest.raises(ValueError, match=r"effect 'dac_inl': a parameter of shape \(3, 4\) has a device axis of 3, "
                                         r"the lot has 4 device"):
        batched(Model(gj.paper_qmg(), (per_device,)), 4)


# --- first-order fingerprints --------------------------------------------------------------------------

@pytest.mark.parametrize("name", list(gj.EFFECTS))
def test_first_order_fingerprint_matches_finite_differences(name):
    base_name = HOME[name]
    family = _family_of(base_name)
    block = family.blocks[name]
    val0, jac = evaluate(base_name)
    full_scale = np.max(np.abs(val0[:, 0]))
    for i in range(block.start, block.stop):
        typical = family.typical[i]
        if typical == 0.0:
            continue
        col = jac[:, 0, i]
        # size of the first-order fingerprint at typical size, in ppm of the full-scale output
        size_ppm = np.max(np.abs(col * typical)) / full_scale * 1e6
        if name == "dac_inl" and (i - block.start) % 2 == 0:
            # even INL terms (u^2, u^4) never reach the carrier fundamental
            assert size_ppm < 1e-6, (name, i, size_ppm)
            continue
        assert size_ppm > 5.0, (name, i, size_ppm)
        h = 1e-2 * abs(typical)
        e = np.zeros_like(family.typical)
        e[i] = h
        plus, _ = evaluate(base_name, jnp.asarray(e))
        minus, _ = evaluate(base_name, jnp.asarray(-e))
        fd = (plus[:, 0] - minus[:, 0]) / (2 * h)
        np.testing.assert_allclose(col, fd, rtol=2e-4, atol=2e-4 * np.max(np.abs(col)))


# --- fingerprint shapes (docs/physics.md) --------------------------------------------------------------

def test_damping_coupling_is_a_pure_bias():
    bias = float(gj.effects.DampingCoupling.typical().c / 2)  # rad/s of equivalent rate (Ag = 1 on both presets)
    for base_name in ("paper-qmg", "vcf-2018"):
        v0, v = values(base_name), values(base_name, damping_coupling=1.0)
        delta = v[:6, 0] - v0[:6, 0]
        assert float(BASES[base_name].resonator.angular_gain) == 1.0
        # the output of a rate Om + c / (2 Ag): the local scale factor times the equivalent-rate offset
        np.testing.assert_allclose(delta, v0[:6, 0] / (RATES_DPS * DEG) * bias, rtol=1e-6)
    # closed loop the scale factor is flat, so the offset is the same number of LSB at every rate
    delta = values("paper-qmg", damping_coupling=1.0)[:6, 0] - values("paper-qmg")[:6, 0]
    assert np.ptp(delta) < 1e-9 * np.max(np.abs(values("paper-qmg")[:6, 0]))


def test_quadrature_phase_mixes_quadrature_into_rate():
    phi = float(gj.effects.QuadraturePhase.typical().phase)
    v0, v = values("paper-qmg"), values("paper-qmg", quadrature_phase=1.0)
    assert np.min(np.abs(v0[:, 1])) > 1e5  # the preset's residual quadrature (10 deg/s) in word LSB
    # output = SF Om cos(phi) + Q sin(phi), at every rate, temperature and in the closed-loop VCF points
    np.testing.assert_allclose(v[:, 0], v0[:, 0] * np.cos(phi) + v0[:, 1] * np.sin(phi), rtol=1e-9,
                               atol=1e-9 * np.max(np.abs(v0[:, 0])))
    bias = np.mean(v[:6, 0] - v0[:6, 0] * np.cos(phi))
    assert bias == pytest.approx(v0[0, 1] * np.sin(phi), rel=1e-6)
    # open loop without quadrature: only the cos(phi) gain loss is left (second order)
    o0, o = values("vcf-2018"), values("vcf-2018", quadrature_phase=1.0)
    assert np.max(np.abs(o0[:, 1])) < 1e-3 * np.max(np.abs(o0[:, 0]))
    np.testing.assert_allclose(o[:, 0], o0[:, 0] * np.cos(phi) + o0[:, 1] * np.sin(phi), rtol=1e-9)
    np.testing.assert_allclose(o[:, 0] / o0[:, 0], np.cos(phi), rtol=2e-6)


def test_thermal_drift_tracks_the_drive_frequency_and_not_closed_loop_vcf():
    v0, v = values("paper-qmg"), values("paper-qmg", thermal_drift=1.0)
    for vals in (v0, v):
        # closed loop: SF(T)/SF(t_ref) = w(T)/w(t_ref), to 0.3 ppm: the hot carrier is 300 ppm slower, the
        # DAC hold delay compensated at 25 deg C is then 4 urad off and mixes 0.2 ppm of quadrature in
        np.testing.assert_allclose(vals[I_HOT, 0] / vals[I_COLD, 0], vals[I_HOT, 2] / vals[I_COLD, 2], rtol=3e-7)
    tcf = float(gj.effects.ThermalDrift.typical().tcf)
    gain = (v[I_HOT, 0] / v[I_COLD, 0]) / (v0[I_HOT, 0] / v0[I_COLD, 0]) - 1
    tracking = (v[I_HOT, 2] / v[I_COLD, 2]) / (v0[I_HOT, 2] / v0[I_COLD, 2]) - 1
    assert gain == pytest.approx(tracking, rel=1e-3)
    assert gain == pytest.approx(tcf * (T_HOT - 25.0), rel=2e-3)  # +30 ppm over 10 K
    # the closed-loop VCF output does not follow: the virtual force does not scale with w
    vcf_change = (v[I_VCF_HOT, 0] / v[I_VCF, 0]) / (v0[I_VCF_HOT, 0] / v0[I_VCF, 0]) - 1
    assert abs(vcf_change) < 1e-7
    # open loop: SF ~ 1/d_y, with the split drift amplified by w/dw
    o0, o = values("vcf-2018"), values("vcf-2018", thermal_drift=1.0)
    r = VCF.resonator
    eff = gj.effects.ThermalDrift.typical()

    def inverse_split(tcf, tcf_split):
        dt = T_HOT - 25.0
        w, wy = r.omega_x * (1 + tcf * dt), r.omega_y * (1 + (tcf + tcf_split) * dt)
        return float(2 * w / (wy**2 - w**2))

    expected = inverse_split(r.tcf + eff.tcf, eff.tcf_split) / inverse_split(r.tcf, 0.0) - 1
    measured = (o[I_HOT, 0] / o[I_COLD, 0]) / (o0[I_HOT, 0] / o0[I_COLD, 0]) - 1
    assert measured == pytest.approx(expected, rel=2e-2)
    assert measured < -100e-6  # ~ -185 ppm over 10 K


def test_vref_drift_moves_rate_and_closed_loop_vcf_alike():
    tc = float(gj.effects.VrefDrift.typical().tc)
    expected = 1.0 / (1.0 + tc * (T_HOT - 25.0)) - 1.0  # -200 ppm over 10 K
    v0, v = values("paper-qmg"), values("paper-qmg", vref_drift=1.0)
    for cold, hot in ((I_COLD, I_HOT), (I_VCF, I_VCF_HOT)):
        change = (v[hot, 0] / v0[hot, 0]) - 1
        assert change == pytest.approx(expected, rel=1e-5)
        assert v[cold, 0] == v0[cold, 0]  # nothing at the reference temperature


def test_pushpull_mismatch_is_a_gain_change_the_dac_sweep_does_not_see():
    eff = gj.effects.PushPullMismatch.typical()
    v0, v = values("paper-qmg"), values("paper-qmg", pushpull_mismatch=1.0)
    expected = 1.0 / (1.0 + 0.5 * float(eff.plus + eff.minus)) - 1.0  # -500 ppm
    np.testing.assert_allclose(v[:, 0] / v0[:, 0] - 1, expected, rtol=1e-6, atol=0)
    words = jnp.array([-2.7e6, 1e5, 2.7e6])
    dac = eqx.filter_jit(gj.sweeps.dac_sweep)
    assert np.array_equal(np.asarray(dac(eff.apply(QMG), words)), np.asarray(dac(QMG, words)))


def test_duffing_drive_shifts_the_drive_frequency_and_the_gain():
    kappa = float(gj.effects.DuffingDrive.typical().kappa)
    a = float(QMG.drive_amplitude(QMG.resonator.omega_x))
    shift = 3.0 / 8.0 * kappa * a**2  # relative backbone shift, 37.5 ppm
    v0, v = values("paper-qmg"), values("paper-qmg", duffing_drive=1.0)
    np.testing.assert_allclose(v[:6, 2] / v0[:6, 2] - 1, shift, rtol=1e-3)
    # closed loop: SF ~ w, a gain change (plus a 0.03 ppm bias: the DAC hold delay is compensated at the
    # unshifted carrier, and the 0.5 urad left mixes in the preset's quadrature)
    (sf0, _), _ = _fit_line(RATES_DPS, v0[:6, 0])
    (sf, _), _ = _fit_line(RATES_DPS, v[:6, 0])
    assert sf / sf0 - 1 == pytest.approx(shift, rel=1e-3)


def _odd_cubic(delta, rates):
    """`(g0, g2, misfit)` of delta = g0 Om + g2 Om^3 on symmetric rates, with the even part checked zero."""
    n = len(rates) // 2
    odd = 0.5 * (delta[n:] - delta[:n][::-1])
    even = 0.5 * (delta[n:] + delta[:n][::-1])
    om = rates[n:]
    a = np.stack([om, om**3], 1)
    coef = np.linalg.lstsq(a, odd, rcond=None)[0]
    return coef[0], coef[1], np.max(np.abs(odd - a @ coef)), np.max(np.abs(even))


def test_duffing_sense_is_an_odd_cubic_amplified_by_the_split():
    o0, o = values("vcf-2018"), values("vcf-2018", duffing_sense=1.0)
    rel = o[:6, 0] / o0[:6, 0] - 1
    om = RATES_DPS * DEG
    r = VCF.resonator
    w = o0[:6, 2]
    gy = float(r.omega_y / (2 * r.q_y))
    dy = (float(r.omega_y) ** 2 - w**2) / (2 * w)
    a = float(VCF.drive_amplitude(r.omega_x))
    amplitude = r.angular_gain * np.abs(om) * a / np.hypot(gy, dy)
    kappa = float(gj.effects.DuffingSense.typical().kappa)
    expected = -3.0 / 8.0 * kappa * float(r.omega_y) ** 2 * amplitude**2 / (w * dy)
    np.testing.assert_allclose(rel, expected, rtol=2e-2)
    assert np.max(rel) > 200e-6  # softening narrows the split: +250 ppm at 200 deg/s
    g0, g2, misfit, even = _odd_cubic(o[:6, 0] - o0[:6, 0], om)
    assert misfit < 1e-3 * abs(g2) * np.max(om) ** 3 and even < 1e-9 * np.max(np.abs(o0[:6, 0]))


def test_agc_finite_gain_open_loop_is_a_sag_and_an_odd_cubic():
    o0, o = values("vcf-2018"), values("vcf-2018", agc_finite_gain=1.0)
    om = RATES_DPS * DEG
    # the scale factor sags by s0 (1 + b Om^2): an even relative change, an odd cubic in the output
    rel = o[:6, 0] / o0[:6, 0] - 1
    np.testing.assert_allclose(rel[:3], rel[3:][::-1], rtol=1e-6)
    (c2, c0), misfit = _fit_line(om[3:] ** 2, rel[3:])
    assert -1e-3 < c0 < -3e-4  # ~550 ppm of amplitude sag
    assert np.max(np.abs(misfit)) < 1e-3 * abs(c2) * np.max(om) ** 2
    # b: the sense motion damps the drive by (Ag Om)^2 g_y / (g_y^2 + d_y^2); the AGC must push harder and,
    # with a finite gain, sags further
    r = VCF.resonator
    gx, gy = float(r.omega_x / (2 * r.q_x)), float(r.omega_y / (2 * r.q_y))
    dy = float((r.omega_y**2 - r.omega_x**2) / (2 * r.omega_x))
    assert c2 / c0 == pytest.approx(float(r.angular_gain) ** 2 * gy / ((gy**2 + dy**2) * gx), rel=0.05)
    # closed loop there is no back-action: a pure gain change
    v0, v = values("paper-qmg"), values("paper-qmg", agc_finite_gain=1.0)
    rel = v[:6, 0] / v0[:6, 0] - 1
    assert np.ptp(rel) < 1e-3 * np.max(np.abs(rel)) and np.max(np.abs(rel)) > 5e-6


def test_comb_gap_needs_residual_motion_and_is_an_odd_cubic():
    v0, v = values("qmg-leaky"), values("qmg-leaky", comb_gap=1.0)
    om = RATES_DPS * DEG
    g0, g2, misfit, even = _odd_cubic(v[:6, 0] - v0[:6, 0], om)
    full_scale = np.max(np.abs(v0[:6, 0]))
    cubic_ppm = abs(g2) * np.max(om) ** 3 / full_scale * 1e6
    assert 2.0 < cubic_ppm < 50.0  # a few ppm at 200 deg/s
    assert misfit < 0.02 * abs(g2) * np.max(om) ** 3
    # The leaky quadrature loop leaves a residual quadrature motion too; its cross term with the rate
    # motion adds an even (asymmetric) term of a few ppm, which vanishes without quadrature.
    assert 1e-6 < even / full_scale < 2e-5
    no_quad = eqx.tree_at(lambda g: g.resonator.stiffness_coupling, LEAKY, jnp.zeros(()))
    family = CLOSED_FAMILY
    w0 = evaluate("qmg-leaky", base=no_quad)[0]
    w = evaluate("qmg-leaky", family.theta(comb_gap=1.0), base=no_quad)[0]
    g0q, g2q, _, even_q = _odd_cubic(w[:6, 0] - w0[:6, 0], om)
    assert even_q < 1e-9 * full_scale
    assert g2q == pytest.approx(g2, rel=0.05)


# --- tiers ---------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_steady_and_averaged_agree_closed_loop():
    rates = gj.ding_zhou_2025_rates()  # the shape test_tiers.py compiles for: shared programs
    for name, cls in gj.EFFECTS.items():
        base = LEAKY if name in ("comb_gap", "duffing_sense") else QMG
        dev = _at(cls.typical().apply(base), T_HOT)
        s = gj.rate_sweep(dev, rates)
        a = gj.rate_sweep(dev, rates, tier=gj.Averaged())
        assert np.all(np.asarray(a.result == gj.RESULTS.successful)), name
        # every steady point settles (agc_finite_gain did not, at the AGC residual's round-off)
        assert np.all(np.asarray(s.result == gj.RESULTS.successful)), name
        full_scale = np.max(np.abs(np.asarray(s.rate)))
        assert np.max(np.abs(np.asarray(a.rate) - np.asarray(s.rate))) / full_scale < 1e-6, name


@pytest.mark.slow
def test_steady_and_averaged_agree_open_loop():
    rates = np.array([1.0, 50.0, 100.0, 200.0]) * DEG  # the shape test_open_loop.py compiles for
    tier = gj.Averaged(settle_time=0.1)
    for name, cls in gj.EFFECTS.items():
        if not cls.supports(VCF):
            continue
        dev = _at(cls.typical().apply(VCF), T_HOT)
        s = gj.rate_sweep(dev, rates)
        a = gj.rate_sweep(dev, rates, tier=tier)
        full_scale = np.max(np.abs(np.asarray(s.rate)))
        assert np.max(np.abs(np.asarray(a.rate) - np.asarray(s.rate))) / full_scale < 1e-6, name


# The effects with carrier-level physics (harmonics, DC and 2w forces that averaging drops), and the two
# bases they sit on.
CARRIER_LEVEL = (("dac_inl", "paper-qmg"), ("pushpull_mismatch", "paper-qmg"), ("comb_gap", "qmg-leaky"),
                 ("duffing_drive", "paper-qmg"), ("duffing_sense", "qmg-leaky"), ("feedback_compression", "paper-qmg"),
                 (None, "paper-qmg"), (None, "qmg-leaky"))
FULL_RATES_DPS = (-50.0, 200.0)


def _small_full_tier():
    """Tsit5 with its stages in diffrax's own loop: the smallest full-waveform program to compile (a tier with
    unrolled stages runs faster per step but takes several times longer to compile)."""
    unrolled = {f.name for f in dataclasses.fields(gj.FullWaveform)} & {"unroll_stages"}
    return gj.FullWaveform(solver=diffrax.Tsit5(), **{name: False for name in unrolled})


@eqx.filter_jit
def _full_stack(devices, rates):
    tier = _small_full_tier()
    return eqx.filter_vmap(
        lambda g: jax.vmap(lambda r: tier.settle(g, gj.physics.Stimulus(rate=r)).rate)(rates))(devices)


@pytest.mark.slow
def test_full_waveform_agrees_with_steady_for_carrier_level_effects():
    # every device carries the feedback term (at zero where it is not the effect): one structure to stack
    with_term = {b: gj.effects.FeedbackCompression.typical(0.0).apply(BASES[b]) for b in ("paper-qmg", "qmg-leaky")}
    devices = [gj.effects.FeedbackCompression.typical().apply(BASES[b]) if n == "feedback_compression" else
               gj.EFFECTS[n].typical().apply(with_term[b]) if n else with_term[b] for n, b in CARRIER_LEVEL]
    stack = jax.tree.map(lambda *x: jnp.stack(x), *devices)
    full = dict(zip(CARRIER_LEVEL, np.asarray(_full_stack(stack, jnp.asarray(FULL_RATES_DPS) * DEG))))
    index = [list(RATES_DPS).index(r) for r in FULL_RATES_DPS]
    steady = {(n, b): values(b, **({n: 1.0} if n else {}))[index, 0] for n, b in CARRIER_LEVEL}
    full_scale = abs(values("paper-qmg")[I_COLD, 0])
    # paper-qmg: the full waveform and the steady state agree point by point (0.23 ppm of demodulator
    # ripple through the AGC, `gyrojax/_presets.py`)
    for key in CARRIER_LEVEL:
        if key[1] == "paper-qmg":
            assert np.max(np.abs(full[key] - steady[key])) / full_scale < 1e-6, key
    # the leaky (proportional-only) rebalance loop passes the demodulator's 2w ripple (four 1 kHz stages
    # at 9.3 kHz) straight into the word, which the averaged tiers drop: ~1e-4 of full scale. The effects
    # themselves are the same in both tiers.
    base = (None, "qmg-leaky")
    assert 2e-5 < np.max(np.abs(full[base] - steady[base])) / full_scale < 1e-3
    for key in CARRIER_LEVEL:
        reference = (None, key[1])
        fingerprint_full = full[key] - full[reference]
        fingerprint_steady = steady[key] - steady[reference]
        assert np.max(np.abs(fingerprint_full - fingerprint_steady)) / full_scale < 1e-7, key


# --- the guide -----------------------------------------------------------------------------------------

GUIDE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "adding_an_effect.md"


@pytest.mark.slow
def test_guide_code_runs():
    blocks = re.findall(r"```python\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    assert len(blocks) >= 4
    namespace = {"__name__": "adding_an_effect"}
    try:
        for block in blocks:
            exec(compile(block, str(GUIDE), "exec"), namespace)
        assert gj.EFFECTS["dac_gain"] is namespace["DacGain"]
        assert "dac_gain" in gj.supported_effects(QMG) and "dac_gain" not in gj.supported_effects(VCF)
    finally:
        gj.EFFECTS.pop("dac_gain", None)
    assert "dac_gain" not in gj.EFFECTS


def test_register_effect_checks_the_interface():
    with pytest.raises(ValueError, match=r"register_effect expects a subclass of gyrojax\.AbstractEffect"):
        gj.effects.register_effect(int)
    with pytest.raises(ValueError, match=r"effect name 'comb_gap' is already registered by CombGap"):

        class Clash(gj.AbstractEffect):
            name = "comb_gap"
            description = "a clash"
            plugs_into = "resonator.q_x"

            def apply(self, gyro):
                return gyro

            @classmethod
            def typical(cls, scale=1.0):
                return cls()

            @classmethod
            def supports(cls, gyro):
                return True

        gj.effects.register_effect(Clash)
    assert gj.effects.register_effect(gj.effects.CombGap) is gj.effects.CombGap  # registering a class again is harmless
