"""Temperature histories: what the die temperature does during a run."""

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._checks import check_finite, check_positive


class AbstractTemperature(eqx.Module):
    """A die-temperature history T(t) in degrees Celsius, t in seconds since power-on."""

    @abc.abstractmethod
    def __call__(self, t: Float[ArrayLike, "*time"]) -> Float[Array, "*time"]:
        """Temperature in deg C at time `t` (s)."""


class ConstantTemperature(AbstractTemperature):
    """A die held at one temperature (a settled, thermostatted device)."""

    value: float | Float[Array, ""] = 25.0

    def __check_init__(self):
        check_finite("ConstantTemperature", "value", self.value)

    def __call__(self, t: Float[ArrayLike, "*time"]) -> Float[Array, "*time"]:
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

    def __call__(self, t: Float[ArrayLike, "*time"]) -> Float[Array, "*time"]:
        t = jnp.asarray(t, dtype=float)
        return self.ambient + self.rise * (1.0 - jnp.exp(-t / self.time_constant))


def _floats(values):
    return tuple(float(v) for v in values)


class PlateauTemperature(AbstractTemperature):
    r"""Die temperature in a thermal chamber that steps through plateaus, with self-heating after power-on:

        T(t) = T_0 + sum_k (T_k - T_{k-1}) (1 - exp(-(t - t_k) / tau_p)) H(t - t_k) + rise (1 - exp(-t / tau_w)),

    t_k the time the chamber steps to plateau k (T_{-1} = T_0, the chamber at power-on), tau_p the die's
    first-order lag behind the chamber (package and fixture), tau_w the self-heating's time constant.

    **Arguments:**

    - `plateaus_c`: chamber temperature of each plateau, deg C.
    - `starts_s`: time since power-on at which the chamber steps to each plateau, s (>= 0, increasing).
    - `initial_c`: chamber (and die) temperature at power-on, deg C.
    - `package_time_constant_s`: the die's lag behind the chamber, s.
    - `rise_k`, `heating_time_constant_s`: self-heating after power-on, K and s.
    """

    plateaus_c: tuple = eqx.field(converter=_floats)
    starts_s: tuple = eqx.field(converter=_floats)
    initial_c: float
    package_time_constant_s: float
    rise_k: float
    heating_time_constant_s: float

    def __check_init__(self):
        if len(self.plateaus_c) != len(self.starts_s) or not self.plateaus_c:
            raise ValueError(f"PlateauTemperature: plateaus_c and starts_s need one entry per plateau, got "
                             f"{len(self.plateaus_c)} and {len(self.starts_s)}.")
        if any(b <= a for a, b in zip(self.starts_s, self.starts_s[1:])) or self.starts_s[0] < 0:
            raise ValueError(f"PlateauTemperature.starts_s must be >= 0 and increasing, got {list(self.starts_s)}.")
        check_finite("PlateauTemperature", "initial_c", self.initial_c)
        check_finite("PlateauTemperature", "rise_k", self.rise_k)
        check_positive("PlateauTemperature", "package_time_constant_s", self.package_time_constant_s)
        check_positive("PlateauTemperature", "heating_time_constant_s", self.heating_time_constant_s)

    def __call__(self, t: Float[ArrayLike, "*time"]) -> Float[Array, "*time"]:
        t = jnp.asarray(t, dtype=float)
        temp = self.initial_c + self.rise_k * (1.0 - jnp.exp(-t / self.heating_time_constant_s))
        previous = self.initial_c
        for start, plateau in zip(self.starts_s, self.plateaus_c):
            since = jnp.maximum(t - start, 0.0)
            temp = temp + (plateau - previous) * (-jnp.expm1(-since / self.package_time_constant_s))
            previous = plateau
        return temp
