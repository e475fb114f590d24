"""jax.grad, jax.jacfwd and jax.vmap through every tier, checked against finite differences."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gyrojax as gj


DEG = gj.units.DEG


RATE = 100 * DEG


@pytest.fixture(scope="module")
def device():
    return gj.add_effect(gj.paper_qmg(), gj.effects.DacInl.typical(1.0))


def _with(dev, k_vf, inl3):
    return eqx.tree_at(lambda g: (g.feedback_electrode.k_vf, g.excitation.dac.inl), dev,
                       (k_vf, dev.excitation.dac.inl.at[1].set(inl3)))


def _output(tier):
    @jax.jit
    def f(params, dev):
        return gj.settle(_with(dev, params[0], params[1]), gj.physics.Stimulus(rate=RATE), tier).rate

    return f


def _central_difference(f, p, dev, rel):
    grads = []
    for i in range(p.shape[0]):
        h = rel * abs(float(p[i]))
        e = jnp.zeros_like(p).at[i].set(h)
        grads.append((float(f(p + e, dev)) - float(f(p - e, dev))) / (2 * h))
    return np.array(grads)


CASES = {
    "steady": (gj.Steady(), 1e-4, 1e-6),
    # FD step 1e-3: with the preset's residual quadrature the adaptive steps of the short averaged settle
    # make a 1e-4 central difference noisy at 1e-5 (1e-3 agrees with the gradient to 4e-7)
    "averaged": (gj.Averaged(settle_time=0.06, adjoint=diffrax.RecursiveCheckpointAdjoint()), 1e-3, 1e-5),
    "full": (gj.FullWaveform(settle_time=0.04, average_periods=20), 1e-4, 1e-4),
}


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.slow
def test_grad_matches_finite_differences(device, name):
    tier, rel, tol = CASES[name]
    f = _output(tier)
    p = jnp.array([device.feedback_electrode.k_vf, device.excitation.dac.inl[1]])
    g = np.asarray(jax.jit(jax.grad(f))(p, device))
    fd = _central_difference(f, p, device, rel)
    assert np.allclose(g, fd, rtol=tol, atol=0)
    # and physics: the word scales as 1/K_vf, up to the INL's local slope (~1 % at 100 deg/s)
    assert g[0] * float(p[0]) / float(f(p, device)) == pytest.approx(-1.0, rel=2e-2)


@pytest.mark.slow
def test_jacfwd_through_averaged_with_forward_mode(device):
    tier = gj.Averaged(settle_time=0.06, adjoint=diffrax.ForwardMode())
    f = _output(tier)
    p = jnp.array([device.feedback_electrode.k_vf, device.excitation.dac.inl[1]])
    jf = np.asarray(jax.jit(jax.jacfwd(f))(p, device))
    jr = np.asarray(jax.jit(jax.grad(_output(gj.Averaged(settle_time=0.06))))(p, device))
    assert np.allclose(jf, jr, rtol=1e-7)


@pytest.mark.slow
def test_jacfwd_through_steady_matches_grad(device):
    f = _output(gj.Steady())
    p = jnp.array([device.feedback_electrode.k_vf, device.excitation.dac.inl[1]])
    assert np.allclose(np.asarray(jax.jacfwd(f)(p, device)), np.asarray(jax.grad(f)(p, device)), rtol=1e-9)


@pytest.mark.slow
def test_vmap_over_devices_equals_loop(device):
    lot = gj.make_lot(device, 3, jax.random.PRNGKey(3))
    rates = jnp.array([-50.0, 10.0, 200.0]) * DEG
    batched = eqx.filter_vmap(lambda g: gj.rate_sweep(g, rates).rate)(lot)
    for i in range(3):
        one = jax.tree.map(lambda x: x[i], lot)
        assert np.allclose(np.asarray(batched[i]), np.asarray(gj.rate_sweep(one, rates).rate), rtol=1e-12)


@pytest.mark.slow
def test_steady_derivative_of_a_point_without_steady_state_is_nan_not_an_error(device):
    """A fit's trial step can reach parameters where a point has no steady state. Its value and derivative
    must come back NaN (the fit's trust region rejects the step), not raise inside the compiled fit (as
    optimistix's implicit adjoint did: its tangent solve is a throwing lineax solve)."""
    f = _output(gj.Steady())
    p = jnp.array([float(device.feedback_electrode.k_vf), 1e-5])
    broken = eqx.tree_at(lambda g: g.resonator.q_y, device, jnp.asarray(jnp.nan))
    assert np.isnan(float(f(p, broken)))
    jac = np.asarray(jax.jit(jax.jacfwd(f))(p, broken))
    assert jac.shape == (2,) and np.all(np.isnan(jac))
    # the same compiled derivative is finite and right on a device that settles
    assert np.all(np.isfinite(np.asarray(jax.jit(jax.jacfwd(f))(p, device))))


def test_implicit_root_derivative_matches_the_closed_form():
    """The implicit-function derivative of the root of z^2 - a (z = sqrt a): dz/da = 1 / (2 sqrt a), forward
    and reverse."""
    from gyrojax._simulate._implicit import implicit_root

    def find(a):
        return jnp.sqrt(a), jnp.zeros((), dtype=int)

    def residual(z, a):
        return z**2 - a

    def root(a):
        return implicit_root(a, find=find, residual=residual)[0]

    a = jnp.asarray(2.0)
    expected = 1.0 / (2.0 * np.sqrt(2.0))
    assert np.isclose(float(jax.jacfwd(root)(a)), expected, rtol=1e-14)
    assert np.isclose(float(jax.grad(root)(a)), expected, rtol=1e-14)
