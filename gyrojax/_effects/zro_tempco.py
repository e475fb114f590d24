"""`zro_tempco`: a zero-rate output that follows the die temperature."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._checks import check_finite
from .._gyroscope import Gyroscope
from .._terms import AbstractRateTerm
from .._units import DEG
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: 1e-3 (deg/s)/K = 3.6 (deg/h)/K of zero-rate output drift: uncompensated tactical-grade MEMS
# gyroscopes quote bias temperature coefficients of one to a few tens of (deg/h)/K; over a 2 K warm-up this is
# 2e-3 deg/s, twenty times a settled point's noise on the presets (0.1 deg/s per 10 K of chamber step).
_TYPICAL_DPS_PER_K = 1e-3


class ZroTempco(AbstractEffect, AbstractRateTerm):
    r"""A zero-rate output (ZRO) linear in the die temperature: the sense mode feels the Coriolis force of
    Om + b_T (T - t_ref), b_T in rad/s per K (`coefficient`).

    Physically, the couplings that make a zero-rate output (anisodamping, electrical crosstalk of the drive
    into the sense pick-off) change with temperature; this is the linear part. The loop balances it like a
    rate, so the rate-table and static-VCF outputs of a closed-loop device, and the rate output of an
    open-loop one, move by SF b_T dT; a lock-in reading (dynamic VCF) and the DAC sweep do not see it. A
    turn-on bias per run takes its mean: what is left is its change within each run (a warm-up), and the
    difference between runs at different temperatures. Any device.
    """

    coefficient: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "zro_tempco"
    description = "zero-rate output linear in the die temperature, (rad/s)/K"
    plugs_into = "terms (a rate-equivalent sense force)"
    revealed_by = ("rate-table or static-VCF runs at two or more chamber temperatures (plateaus): a bias that "
                   "follows the die temperature in every rate-output sweep alike; within one warm-up it is "
                   "confounded with a drift in time since power-on")

    def __check_init__(self):
        check_finite("ZroTempco", "coefficient", self.coefficient)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        return gyro.with_term(self)

    def rate(self, gyro: Gyroscope, temperature: Float[Array, ""], time: Float[Array, ""], rate: Float[Array, ""]
             ) -> Float[Array, ""]:
        return self.coefficient * (temperature - gyro.resonator.t_ref)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "ZroTempco":
        return cls(scale * jnp.asarray(_TYPICAL_DPS_PER_K * DEG))
