"""A user's own effect in one file, loaded with `gyrojax diagnose DATA --effects-module experiments/user_effects.py`
(or `gyrojax.load_effects_module`): the example of docs/adding_an_effect.md, used by experiments/open_world.py
and the suite's open-world tests.

A zero-rate output that keeps growing after power-on (dielectric charging of the electrodes) acts like a rate:
the rebalance loop balances it. So it is a rate term (`gyrojax.AbstractRateTerm`), the device's slot for a
rate-equivalent sense force, and the effect is this one class.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

import gyrojax as gj


# ASSUMPTION: 0.02 (deg/s)/h: dielectric charging settles over hours, and a few hundredths of a deg/s per hour
# is the order of the drifts reported for unshielded combs; in rad/s per hour.
_TYPICAL_PER_HOUR = 0.02 * gj.units.DEG


class ZroTimeDrift(gj.AbstractEffect, gj.AbstractRateTerm):
    """A zero-rate output linear in the time since power-on, `per_hour` in rad/s per hour."""

    per_hour: jax.Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))

    name = "zro_time_drift"
    description = "zero-rate output linear in the time since power-on, (rad/s)/h"
    plugs_into = "terms (a rate-equivalent sense force)"
    revealed_by = "a long run at a constant chamber temperature: the bias keeps moving after the die settles"

    @classmethod
    def supports(cls, gyro):
        return True

    def apply(self, gyro):
        return gyro.with_term(self)

    def rate(self, gyro, temperature, time, rate):
        return self.per_hour * time / 3600.0

    @classmethod
    def typical(cls, scale=1.0):
        return cls(scale * _TYPICAL_PER_HOUR)
