"""Small-signal frequency response of the averaged model around its equilibrium."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Complex, Float

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._numerics.linsolve import solve
from .._physics.stimulus import Stimulus
from ._model import averaged_field, slow_scales
from .tiers import Steady


_INPUTS = ("rate", "vcf")


class StateSpace(eqx.Module):
    """The averaged model linearised at an equilibrium: z' = A z + B u, y = C z + D u (scaled states,
    output in LSB per unit input)."""

    a: Float[Array, "state state"]
    b: Float[Array, " state"]
    c: Float[Array, " state"]
    d: Float[Array, ""]

    def response(self, frequencies: Float[ArrayLike, "*shape"]) -> Complex[Array, "*shape"]:
        """H(j w) = C (j w I - A)^{-1} B + D at angular frequencies `frequencies` (rad/s)."""
        return _response(self, jnp.asarray(frequencies, dtype=float))

    def bandwidth(self, f_max_hz: float = 5000.0) -> float:
        """-3 dB bandwidth (Hz) relative to the DC response.

        Scans a log grid from 0.1 Hz to `f_max_hz` for the first crossing below 1/sqrt(2) of the DC gain and
        refines it by bisection. Raises if the response never falls that far.
        """
        f = np.geomspace(0.1, f_max_hz, 4000)
        h = np.asarray(_gain_hz(self, jnp.asarray(f)))
        level = float(_gain_hz(self, jnp.zeros(1))[0]) / np.sqrt(2.0)
        below = np.nonzero(h < level)[0]
        if below.size == 0:
            raise ValueError(f"bandwidth: the response never falls 3 dB below DC up to {f_max_hz} Hz; "
                             "raise f_max_hz.")
        lo, hi = (f[below[0] - 1], f[below[0]]) if below[0] > 0 else (0.0, f[0])
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if float(_gain_hz(self, jnp.full((1,), mid))[0]) >= level else (lo, mid)
        return float(0.5 * (lo + hi))


def linearise(gyro: Gyroscope, stimulus: Stimulus = Stimulus(), *, input: str = "rate") -> StateSpace:
    """Linearise the averaged model at the steady state under `stimulus` (see `frequency_response`)."""
    if input not in _INPUTS:
        raise ValueError(f"input must be one of {_INPUTS}, got {input!r}.")
    return _linearise(gyro, stimulus, input)


@jit
def _linearise(gyro, stimulus, input):
    """Linearise the averaged model at the steady state under `stimulus`, with respect to a small extra
    table rate (`input="rate"`, per rad/s) or virtual-Coriolis drive (`input="vcf"`, per V^2 of
    V_ac V_fc), with the rate output in LSB."""
    settled = Steady().settle(gyro, stimulus)
    scales = slow_scales(gyro)
    z0, unravel = ravel_pytree(jax.tree.map(lambda s, x: s / x, settled.state, scales))

    def field(z, u):
        if input == "rate":
            stim = eqx.tree_at(lambda s: s.rate, stimulus, stimulus.rate + u)
        else:
            product = stimulus.vcf_ac * stimulus.vcf_fc + u
            stim = eqx.tree_at(lambda s: (s.vcf_ac, s.vcf_fc), stimulus, (product, jnp.ones(())))
        state = jax.tree.map(lambda p, q: p * q, unravel(z), scales)
        d, out = averaged_field(0.0, state, gyro, stim)
        dz, _ = ravel_pytree(jax.tree.map(lambda p, q: p / q, d, scales))
        return dz, out.rate

    (a, b), (c, d) = jax.jacfwd(field, argnums=(0, 1))(z0, jnp.zeros(()))
    return StateSpace(a, b, c, d)


def frequency_response(gyro: Gyroscope, frequencies: Float[ArrayLike, "*shape"], stimulus: Stimulus = Stimulus(), *,
                       input: str = "rate") -> Complex[Array, "*shape"]:
    r"""Complex response of the rate output to a sinusoidal input, from the averaged model linearised at
    the equilibrium under `stimulus`:  H(j w) = C (j w I - A)^{-1} B + D.

    **Arguments:**

    - `gyro`: the device.
    - `frequencies`: modulation angular frequencies, rad/s (array).
    - `stimulus`: the operating point (default: at rest).
    - `input`: `"rate"` (LSB per rad/s of table rate) or `"vcf"` (LSB per V^2 of V_ac V_fc, seed 003's
      dynamic virtual-Coriolis test).

    **Returns:** complex array of the shape of `frequencies`.
    """
    return linearise(gyro, stimulus, input=input).response(frequencies)


def bandwidth(gyro: Gyroscope, stimulus: Stimulus = Stimulus(), *, input: str = "rate",
              f_max_hz: float = 5000.0) -> float:
    """-3 dB bandwidth (Hz) of the rate output relative to its DC response (see `StateSpace.bandwidth`)."""
    return linearise(gyro, stimulus, input=input).bandwidth(f_max_hz)


@jit  # one program, not one per operation of the solves, when called outside a traced one
def _response(ss: StateSpace, w):
    eye = jnp.eye(ss.a.shape[0])

    def one(wi):
        lhs = jax.lax.complex(-ss.a, wi * eye)
        rhs = ss.b.astype(jnp.complex128)
        return ss.c.astype(jnp.complex128) @ solve(lhs, rhs) + ss.d.astype(jnp.complex128)

    return jax.vmap(one)(jnp.ravel(w)).reshape(w.shape)


@jit
def _gain_hz(ss: StateSpace, f_hz):
    return jnp.abs(ss.response(2 * jnp.pi * f_hz))
