"""Experiment protocols as functions of a device: rate-table sweeps (seed 000 §5)."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._gyroscope import Gyroscope
from ._simulate.tiers import AbstractTier, Settled, Steady
from ._stimulus import Stimulus
from ._units import DEG


SEED000_RATES_DPS = (-200.0, -100.0, -50.0, -20.0, -10.0, -5.0, -2.0, -1.0, -0.5, -0.2, -0.1,
                     0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
"""Seed 000 §5: the 22 table rates, deg/s."""


@eqx.filter_jit
def _rate_sweep(gyro, rates, times, tier):
    def one(rate, time):
        return tier.settle(gyro, Stimulus(rate=rate, time=time))

    return jax.vmap(one)(rates, times)


def rate_sweep(gyro: Gyroscope, rates, *, tier: AbstractTier = Steady(), times=None) -> Settled:
    """Settle `gyro` at each table rate (rad/s), vmapped, with one compiled call per shape and tier.

    **Arguments:**

    - `gyro`: the device.
    - `rates`: table rates, rad/s (1-d array).
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.
    - `times`: time since power-on of each point, s (sets the temperature); default all zero.

    **Returns:** a `Settled` whose fields have a leading axis over the rates.
    """
    rates = jnp.asarray(rates, dtype=float)
    if rates.ndim != 1 or rates.shape[0] < 1:
        raise ValueError(f"rates must be a non-empty 1-d array of rad/s, got shape {rates.shape}.")
    times = jnp.zeros_like(rates) if times is None else jnp.broadcast_to(jnp.asarray(times, dtype=float),
                                                                          rates.shape)
    return _rate_sweep(gyro, rates, times, tier)


def seed000_rates():
    """Seed 000's 22 table rates in rad/s."""
    return jnp.asarray(SEED000_RATES_DPS) * DEG


def _dac_fundamental(gyro, word):
    """Signed carrier-fundamental amplitude (V) of the DAC output for a sine of amplitude `word` LSB."""
    dac = gyro.excitation.dac
    n = max(gyro.phase_points, 256)
    theta = 2.0 * jnp.pi * jnp.arange(n, dtype=float) / n
    hold_gain, _ = dac.hold(gyro.resonator.omega_x)
    v = dac(word * jnp.sin(theta)) * hold_gain
    return 2.0 * jnp.mean(v * jnp.sin(theta))


def dac_sweep(gyro: Gyroscope, words):
    """Seed 000 Table 2's experiment: the FTR DAC fed with carrier sines of the given word amplitudes
    (LSB of the 24-bit word, signed), returning the measured AC amplitude (V) at the DAC output: the
    signed fundamental, including the hold's gain. Closed-loop devices only."""
    if not gyro.closed_loop:
        raise ValueError(f"dac_sweep needs a closed-loop device with an FTR DAC; {gyro.name!r} is open loop.")
    return jax.vmap(lambda w: _dac_fundamental(gyro, w))(jnp.asarray(words, dtype=float))
