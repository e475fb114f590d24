"""`quadrature_phase`: a phase error of the rate channel, which mixes quadrature into the rate output."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope, open_loop_readout
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: 5 mrad (0.29 deg), the size of a mis-compensated DAC hold delay or analog-filter phase at a few
# kHz. With paper-qmg's residual quadrature (10 deg/s equivalent) it is a 0.05 deg/s bias (five times the
# turn-on bias repeatability) and a 12.5 ppm gain loss (1 - cos phi).
_TYPICAL_PHASE = 5e-3


class QuadraturePhase(AbstractEffect):
    r"""Phase error phi (rad) of the rate channel: added to `RebalanceLoop.carrier_phase` in closed loop (the
    rebalance force is rotated by phi) or to `OpenLoopReadout.phase_error` in open loop (the demodulation
    reference is rotated by phi).

    Either way the rate output reads SF Om cos(phi) + Q sin(phi), Q the quadrature in output units: a bias
    proportional to the quadrature (first order; absorbed by a free per-run bias) and a gain loss 1 - cos(phi)
    (second order). On a device without quadrature (vcf-2018) only the gain loss is left. Any device.
    """

    phase: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "quadrature_phase"
    description = "phase error of the rate channel: quadrature leaks into the rate output as a bias"
    plugs_into = "rebalance_loop.carrier_phase (closed loop), readout.phase_error (open loop)"
    revealed_by = ("a quadrature_injection sweep (a virtual-Coriolis drive in phase with the displacement): the "
                   "rate channel reads sin(phi) of it; otherwise it is a bias and a second-order gain loss")

    def __check_init__(self):
        check_finite("QuadraturePhase", "phase", self.phase)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        if gyro.rebalance_loop is not None:  # closed loop
            return eqx.tree_at(lambda g: g.rebalance_loop.carrier_phase, gyro,
                               gyro.rebalance_loop.carrier_phase + self.phase)
        readout = open_loop_readout(gyro, self.name)
        return eqx.tree_at(lambda g: g.readout.phase_error, gyro, readout.phase_error + self.phase)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "QuadraturePhase":
        return cls(scale * jnp.asarray(_TYPICAL_PHASE))
