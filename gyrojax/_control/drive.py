"""Drive loop: a PLL locked to the drive resonance and an AGC holding the drive amplitude."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Complex, Float

from .._checks import check_finite, check_nonnegative, check_positive


class DriveLoop(eqx.Module):
    r"""PLL + AGC on the demodulated drive pick-off (seed 000 §5, Fig. 8).

    The pick-off is demodulated against the PLL's own carrier and low-pass filtered (`demod_order` first-order
    stages at `demod_cutoff`), then rotated by `reference_phase` (the designer's compensation of the front end's
    phase), giving the drive phasor e_d in LSB. The PLL drives the phase of e_d to zero:

        w = center_frequency + pll_kp * arg(e_d) + z_pll,   z_pll' = pll_ki * arg(e_d)

    and the AGC drives |e_d| to `amplitude_setpoint` (LSB):

        V_d = agc_kp * err + z_agc,   z_agc' = agc_ki * err - agc_leak * z_agc,   err = setpoint - |e_d|

    `agc_leak` > 0 makes the integrator leaky: a finite DC loop gain agc_ki / agc_leak, so the amplitude
    sags under load (the `agc_finite_gain` effect); zero is an ideal integrator. The drive force is
    V_d times the drive electrode's N/V, in phase with the drive velocity.
    """

    amplitude_setpoint: float | Array
    center_frequency: float | Array
    pll_kp: float | Array
    pll_ki: float | Array
    agc_kp: float | Array
    agc_ki: float | Array
    demod_cutoff: float | Array
    reference_phase: float | Array = 0.0
    agc_leak: float | Array = 0.0

    demod_order: int = eqx.field(static=True, default=4)

    def __check_init__(self):
        if not isinstance(self.demod_order, int) or self.demod_order < 1:
            raise ValueError(f"DriveLoop.demod_order must be an integer >= 1, got {self.demod_order!r}.")
        for name in ("amplitude_setpoint", "center_frequency", "pll_kp", "pll_ki", "agc_kp", "agc_ki",
                     "demod_cutoff"):
            check_positive("DriveLoop", name, getattr(self, name))
        check_finite("DriveLoop", "reference_phase", self.reference_phase)
        check_nonnegative("DriveLoop", "agc_leak", self.agc_leak)

    def control(self, e_d: Complex[Array, ""], z_pll: Float[Array, ""], z_agc: Float[Array, ""]
                ) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
        """`(omega, drive_voltage, dz_pll, dz_agc)` from the drive phasor and the integrator states."""
        phase = jnp.angle(e_d)
        err = self.amplitude_setpoint - jnp.abs(e_d)
        omega = self.center_frequency + self.pll_kp * phase + z_pll
        v_d = self.agc_kp * err + z_agc
        return omega, v_d, self.pll_ki * phase, self.agc_ki * err - self.agc_leak * z_agc
