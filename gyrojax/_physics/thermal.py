"""Temperature histories: what the die temperature does during a run."""

import abc

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite, check_positive


class AbstractTemperature(eqx.Module):
    """A die-temperature history T(t) in degrees Celsius, t in seconds since power-on."""

    @abc.abstractmethod
    def __call__(self, t):
        """Temperature in deg C at time `t` (s)."""


class ConstantTemperature(AbstractTemperature):
    """A die held at one temperature (a settled, thermostatted device)."""

    value: float = 25.0

    def __check_init__(self):
        check_finite("ConstantTemperature", "value", self.value)

    def __call__(self, t):
        return jnp.asarray(self.value, dtype=float) + 0.0 * jnp.asarray(t, dtype=float)


class WarmupTemperature(AbstractTemperature):
    """Self-heating after power-on: T(t) = ambient + rise (1 - exp(-t / time_constant)).

    Seed 000 §5 reports a first run that needed longer to stabilise thermally than the next two;
    a first-order warm-up is the simplest history with that signature.
    """

    ambient: float = 25.0
    rise: float = 0.0
    time_constant: float = 120.0

    def __check_init__(self):
        check_finite("WarmupTemperature", "ambient", self.ambient)
        check_finite("WarmupTemperature", "rise", self.rise)
        check_positive("WarmupTemperature", "time_constant", self.time_constant)

    def __call__(self, t):
        t = jnp.asarray(t, dtype=float)
        return self.ambient + self.rise * (1.0 - jnp.exp(-t / self.time_constant))
