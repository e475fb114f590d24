"""`duffing_sense`: cubic stiffness of the sense mode."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope
from ._support import as_parameter, require, sense_moves
from .base import AbstractEffect


# ASSUMPTION: the sense mode's cubic stiffness is dominated by the electrostatic softening of its
# parallel-plate electrodes (k3_es / k1 ~ 2 (k_es / k1) / d^2: ~5e10 1/m^2 for a 10 % electrostatic share and a
# 2 um gap); a tenth of that bound, softening: k3/k1 = -1e9 1/m^2. On vcf-2018 (162 nm of sense motion at
# 200 deg/s) this is +250 ppm of scale factor and +/-86 ppm of odd cubic nonlinearity over +/-200 deg/s.
_TYPICAL_KAPPA = -1e9


class DuffingSense(AbstractEffect):
    r"""Relative cubic stiffness k3/k1 of the sense mode (1/m^2), added to the resonator as
    `duffing_y += kappa w_y^2`.

    The sense resonance moves with the sense amplitude, w_y -> w_y (1 + 3/8 kappa |Y|^2). Open loop, |Y| grows
    with the rate (and with the virtual rate of a VCF sweep), and the split d_y with it: SF(Om) ~ 1 / d_y(Om),
    an odd cubic amplified by w/dw, first order in kappa. In closed loop the rebalance loop holds the sense
    mass at rest: with an ideal integrator the effect cannot act (`supports` says no, paper-qmg included);
    with a leaky loop (`RebalanceLoop.leak` > 0) the residual motion lets it act, mostly on the quadrature
    word.
    """

    kappa: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "duffing_sense"
    description = "cubic (Duffing) stiffness of the sense mode: sense resonance moves with sense amplitude"
    plugs_into = "resonator.duffing_y"
    revealed_by = ("an open-loop rate table or a dynamic VCF sweep at two V_ac levels: the sense resonance moves"
                   " with the sense amplitude")

    def __check_init__(self):
        check_finite("DuffingSense", "kappa", self.kappa)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return sense_moves(gyro)

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro),
                "a moving sense mass: an open-loop device, or a rebalance loop with a finite DC gain "
                "(RebalanceLoop.leak > 0)")
        r = gyro.resonator
        return eqx.tree_at(lambda g: g.resonator.duffing_y, gyro, r.duffing_y + self.kappa * r.omega_y**2)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "DuffingSense":
        return cls(scale * jnp.asarray(_TYPICAL_KAPPA))
