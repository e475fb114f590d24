r"""The balance of the model compensator (`model.py`): D(W), the carrier fundamental of the FTR DAC's output for
a word W with the DAC's INL (describing-function weights of its powers), and the word that balances a given
fundamental, by Newton steps that pass derivatives by the implicit function theorem."""

import math

import jax
import jax.numpy as jnp


def describing_weight(n: int) -> float:
    r"""Carrier-fundamental weight of $u^n$ for a sine: $\sin^n\theta = \rho_n \sin\theta + \ldots$."""
    return 0.0 if n % 2 == 0 else math.comb(n, (n - 1) // 2) / 2.0 ** (n - 1)


def fundamental(word, inl, spec):
    """D(W): the in-phase carrier fundamental of the DAC output, in word LSB, for a carrier of in-phase amplitude
    `word` (LSB) and quadrature amplitude `spec.quadrature_lsb`; `spec` carries `inl_orders`, `word_bits`,
    `dac_bits`. The sample is W sin + Q cos = A sin(. + phi) with A^2 = W^2 + Q^2, so the in-phase fundamental
    of u^n is rho_n A^(n-1) W / H^n."""
    return word + inl_term(word, inl, spec)


def inl_term(word, inl, spec):
    """D(W) - W, computed on its own (it is thousands of LSB where W is millions)."""
    lsb = 2.0 ** (spec.word_bits - spec.dac_bits)
    h = 2.0 ** (spec.word_bits - 1)
    a2 = word**2 + float(spec.quadrature_lsb) ** 2
    acc = jnp.zeros_like(word)
    for i, n in enumerate(spec.inl_orders):
        rho = describing_weight(n)
        if rho:
            acc = acc + lsb * rho * inl[i] * word * a2 ** ((n - 1) // 2) / h**n
    return acc


def newton(g, z0, steps):
    """`steps` Newton steps on the elementwise equation g(z) = 0 (derivative by forward mode)."""
    def step(_, z):
        value, slope = jax.jvp(g, (z,), (jnp.ones_like(z),))
        return z - value / slope

    return jax.lax.fori_loop(0, steps, step, z0)


def balance_offset(v, inl, spec, steps):
    """W - v for the word W with D(W) = v, i.e. the root d of d + (D - 1)(v + d) = 0, as a number of its own
    size (so it rounds relative to the INL's thousands of LSB, not the word's millions): Newton steps on
    constants, then one more step that carries the derivatives (the implicit function theorem,
    dW = (dv - dD/dc dc) / D'(W)), so no derivative passes through the loop."""
    sg = jax.lax.stop_gradient
    c, target = sg(inl), sg(v)
    d = newton(lambda d: d + inl_term(target + d, c, spec), jnp.zeros_like(target), steps)
    value, slope = jax.jvp(lambda d: d + inl_term(v + d, inl, spec), (d,), (jnp.ones_like(d),))
    return d - value / sg(slope)


def balance_word(v, inl, spec, steps):
    """The word W with D(W) = v (see `balance_offset`)."""
    return v + balance_offset(v, inl, spec, steps)
