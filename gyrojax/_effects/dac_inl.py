"""`dac_inl`: integral nonlinearity of the force-to-rebalance DAC."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope, closed_loop_parts
from ._support import require
from .base import AbstractEffect


# A typical INL bow of a 16-bit R-2R DAC: a few LSB across the range used at +/-200 deg/s (a third of full
# scale), an odd S-curve plus an even bow. Sized so that on paper-qmg at scale 1 the closed-loop
# nonlinearity over +/-200 deg/s is about 460 ppm (max residual / full scale), the DAC share that seed 000
# §3.3 reports; the even term is invisible in AC amplitude sweeps (docs/physics.md).
_TYPICAL_INL = (11.4, -1063.6, 0.0, 3418.6)  # LSB coefficients of u^2, u^3, u^4, u^5


class DacInl(AbstractEffect):
    """INL of the FTR DAC, acting on the instantaneous carrier samples.

    `coefficients[k]` is the INL in DAC LSB of the term u^(k+2), u = code / 2^(bits-1); they add to the
    DAC's own INL. Odd terms bend the scale factor (an S-curve), even terms do not reach the carrier
    fundamental at all (so they have no first-order fingerprint on any sweep: identifiability reports them).

    The device's INL array keeps its shape when it has at least as many terms as `coefficients` (the
    presets carry four zero terms for this); a shorter one is zero-padded, which changes the leaf's shape.
    """

    coefficients: jnp.ndarray

    name = "dac_inl"
    description = "INL profile of the force-to-rebalance DAC (odd S-curve and even bow, in LSB)"
    plugs_into = "excitation.dac.inl"
    revealed_by = ("a DAC sweep (the AC amplitude against the word, seed 000 Table 2), or a rate table: its odd "
                   "part is an S-curve no gain takes up")

    def __check_init__(self):
        check_finite("DacInl", "coefficients", self.coefficients)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return gyro.closed_loop

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro), "a closed-loop device (an FTR DAC); it is open loop")
        inl = closed_loop_parts(gyro, self.name).excitation.dac.inl
        n = max(inl.shape[0], self.coefficients.shape[0])
        total = jnp.pad(inl, (0, n - inl.shape[0])) + jnp.pad(self.coefficients,
                                                                 (0, n - self.coefficients.shape[0]))
        return eqx.tree_at(lambda g: g.excitation.dac.inl, gyro, total)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "DacInl":
        return cls(scale * jnp.asarray(_TYPICAL_INL, dtype=float))
