"""What the gyroscope is subjected to during one settled point or one transient."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._checks import check_finite, check_nonnegative


# A field is one number, or an array of one per point when the points of a sweep settle together.
_Value = float | Float[Array, "*point"]


class Stimulus(eqx.Module):
    """Inputs of one measurement point.

    **Arguments:**

    - `rate`: input angular rate (amplitude when modulated), rad/s.
    - `rate_frequency`: angular frequency of a sinusoidal rate, rad/s; 0 for a constant rate.
    - `vcf_ac`, `vcf_fc`: virtual-Coriolis voltages (seed 003): the carrier amplitude V_ac and V_fc, V.
    - `vcf_frequency`: angular frequency of V_fc, rad/s; 0 for a static (DC) virtual rate.
    - `vcf_phase`: phase of the virtual-Coriolis force's carrier, rad: 0 puts the force in phase with the
      drive velocity (a virtual rate, seed 003), pi/2 in phase with the drive displacement (a virtual
      quadrature: the quadrature injection).
    - `time`: time since power-on at the start of the point, s (sets the temperature).
    """

    rate: _Value = 0.0
    rate_frequency: _Value = 0.0
    vcf_ac: _Value = 0.0
    vcf_fc: _Value = 0.0
    vcf_frequency: _Value = 0.0
    vcf_phase: _Value = 0.0
    time: _Value = 0.0

    def __check_init__(self):
        for name in ("rate", "vcf_ac", "vcf_fc", "vcf_phase"):
            check_finite("Stimulus", name, getattr(self, name))
        for name in ("rate_frequency", "vcf_frequency", "time"):
            check_nonnegative("Stimulus", name, getattr(self, name))

    def rate_at(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        return self.rate * jnp.cos(self.rate_frequency * t)

    def vcf_at(self, t: Float[ArrayLike, "*t"]) -> Float[Array, "*t"]:
        """V_ac V_fc(t), V^2."""
        return self.vcf_ac * self.vcf_fc * jnp.cos(self.vcf_frequency * t)
