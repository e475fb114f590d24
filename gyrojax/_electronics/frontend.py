"""Readout front end: motional current -> charge or transimpedance amplifier -> ADC."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from .._checks import check_finite, check_positive


_KINDS = ("charge", "transimpedance")


class FrontEnd(eqx.Module):
    """Pick-off of one mode, in ADC LSB.

    The comb's motional current is i = K_vi x' (seed 000 Table 1: velocity-to-current factors). A charge
    amplifier (`kind="charge"`, `gain` = 1/C_f in V/C) gives v = gain K_vi x, proportional to displacement; a
    resistive transimpedance amplifier (`kind="transimpedance"`, `gain` = R_f in V/A) gives v = gain K_vi x',
    proportional to velocity. The ADC divides by `adc_lsb` (V per LSB).

    Which one matters: an AGC regulating a displacement-proportional signal holds the drive amplitude a,
    and then the closed-loop scale factor tracks the drive frequency (seed 000 Eq. 2, 8); regulating a
    velocity signal holds a w instead.
    """

    current_per_velocity: float
    gain: float
    adc_lsb: float
    kind: str = eqx.field(static=True, default="charge")

    def __check_init__(self):
        if self.kind not in _KINDS:
            raise ValueError(f"FrontEnd.kind must be one of {_KINDS}, got {self.kind!r}.")
        check_positive("FrontEnd", "current_per_velocity", self.current_per_velocity)
        check_finite("FrontEnd", "gain", self.gain)
        check_positive("FrontEnd", "adc_lsb", self.adc_lsb)

    def phasor_gain(self, omega: Float[ArrayLike, "*s"]) -> Complex[Array, "*s"]:
        """Complex LSB per metre of displacement phasor at angular frequency `omega`."""
        g = self.gain * self.current_per_velocity / self.adc_lsb
        if self.kind == "charge":
            return jnp.asarray(g * jnp.ones_like(omega), dtype=complex)
        return jnp.asarray(omega * g, dtype=complex) * 1j

    def sample(self, displacement: Float[Array, "*s"], velocity: Float[Array, "*s"]) -> Float[Array, "*s"]:
        """Instantaneous output, LSB."""
        g = self.gain * self.current_per_velocity / self.adc_lsb
        return g * (displacement if self.kind == "charge" else velocity)
