"""Force-to-rebalance loop: a complex PI that nulls both the rate and the quadrature sense motion."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Complex

from .._checks import check_finite, check_nonnegative, check_positive


class RebalanceLoop(eqx.Module):
    r"""Rate (in-phase) and quadrature-suppression loops of a digital FTR gyroscope (seed 000 Fig. 8).

    The sense pick-off is demodulated with the PLL carrier (`demod_order` first-order stages at `demod_cutoff`) and
    rotated by `reference_phase` into e_s, whose real part is the rate channel and imaginary part the
    quadrature channel. One PI per channel (equal gains) gives the complex word

        W = -(kp e_s + z),   z' = ki e_s - leak z

    whose real part (rate word, the gyro's output in LSB) is modulated on the carrier in phase with the
    drive velocity and whose imaginary part (quadrature word) on the carrier in phase with the drive
    displacement; both go through the same DAC (seed 000 Fig. 5). `carrier_phase` advances the carrier to
    cancel the DAC's hold delay at the design frequency; any residual error phi rotates the rebalance
    force, so the rate word reads SF Om cos(phi) + Q sin(phi) (the `quadrature_phase` effect).
    `leak` > 0 gives a finite DC loop gain ki / leak and a residual sense motion proportional to the rate.
    """

    kp: float | Array
    ki: float | Array
    demod_cutoff: float | Array
    reference_phase: float | Array = 0.0
    carrier_phase: float | Array = 0.0
    leak: float | Array = 0.0

    demod_order: int = eqx.field(static=True, default=4)

    def __check_init__(self):
        if not isinstance(self.demod_order, int) or self.demod_order < 1:
            raise ValueError(f"RebalanceLoop.demod_order must be an integer >= 1, got {self.demod_order!r}.")
        for name in ("kp", "ki", "demod_cutoff"):
            check_positive("RebalanceLoop", name, getattr(self, name))
        check_finite("RebalanceLoop", "reference_phase", self.reference_phase)
        check_finite("RebalanceLoop", "carrier_phase", self.carrier_phase)
        check_nonnegative("RebalanceLoop", "leak", self.leak)

    def control(self, e_s: Complex[Array, ""], z: Complex[Array, ""]) -> tuple[Complex[Array, ""], Complex[Array, ""]]:
        """`(word, dz)` from the sense phasor and the (complex) integrator state."""
        kp, ki, leak = (jnp.asarray(v).astype(e_s.dtype) for v in (self.kp, self.ki, self.leak))
        return -(kp * e_s + z), ki * e_s - leak * z
