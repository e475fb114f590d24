"""gyrojax's compile options (`gyrojax._compile.jit`): set on its top-level programs on the CPU, never on a program
called inside another trace (JAX refuses that), and never over an option the user's XLA_FLAGS names."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from gyrojax._compile import jit as _compile


def test_options_on_cpu_and_the_users_flag_wins(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    assert _compile.compiler_options() == {"xla_cpu_use_fusion_emitters": False}
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_fusion_emitters=true")
    assert _compile.compiler_options() is None


def test_top_level_calls_get_the_options_nested_calls_do_not(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    seen, filter_jit = [], eqx.filter_jit

    def recording_jit(fn, **kwargs):
        seen.append(kwargs.get("compiler_options"))
        return filter_jit(fn, **kwargs)

    monkeypatch.setattr(_compile.eqx, "filter_jit", recording_jit)

    @_compile.jit
    def square_sum(x):
        return jnp.sum(x**2)

    x = jnp.arange(3.0)
    assert float(square_sum(x)) == 5.0
    assert seen == [{"xla_cpu_use_fusion_emitters": False}]
    # Inside another jit (JAX raises for compiler options on a nested jit) and under grad: no options.
    assert float(jax.jit(lambda y: square_sum(y) + 1.0)(x)) == 6.0
    np.testing.assert_allclose(jax.grad(square_sum)(x), 2 * np.arange(3.0))
    assert seen[1:] == [None]  # one plain program, compiled once for both traced callers
    assert float(square_sum(x + 1.0)) == 14.0 and len(seen) == 2  # the top-level program is reused


def test_a_gyrojax_program_inside_a_users_jit():
    """A regression: `rate_sweep`'s program called inside a user's jit raised JAX's nested-options error."""
    import gyrojax as gj

    gyro = gj.paper_qmg()
    rates = jnp.array([-10.0, 10.0])
    direct = gj.rate_sweep(gyro, rates).rate
    inside = jax.jit(lambda r: gj.rate_sweep(gyro, r).rate)(rates)
    np.testing.assert_allclose(inside, direct, rtol=1e-12)
