"""`damping_coupling`: anisodamping c_xy between the drive and sense modes."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: a damping coupling of 2e-3 1/s, a zero-rate output of c / (2 Ag) = 1e-3 rad/s = 0.057 deg/s
# (six times the turn-on bias repeatability). Passive damping needs c^2 <= 4 g_x g_y: this is 4 % of that
# bound on paper-qmg (g ~ 0.014 and 0.043 1/s) and 0.2 % on vcf-2018.
_TYPICAL_C = 2e-3


class DampingCoupling(AbstractEffect):
    r"""Damping coupling c (1/s, per unit mass), added to `Resonator.damping_coupling`.

    In the sense equation c x' sits beside the Coriolis term 2 Ag Om x', in phase with it: the force to
    rebalance (closed loop) or the sense motion (open loop) is that of a rate Om + c / (2 Ag). The
    fingerprint is a pure bias, the same at every rate (exactly, to the steady tier's precision), so a free
    per-run bias absorbs it. Any device.
    """

    c: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "damping_coupling"
    description = "damping coupling c_xy between drive and sense: a zero-rate output in phase with rate"
    plugs_into = "resonator.damping_coupling"
    revealed_by = ("a setpoint_zero_rate sweep (the zero-rate output at several AGC set-points in one run: c's "
                   "output scales with the drive amplitude, the turn-on bias does not; a quadrature_phase scales "
                   "alike) or a mode-reversal test (swapping the drive and sense roles flips the Coriolis term's "
                   "sign, not c's): at one configuration it is a constant c / (2 Ag) that a turn-on bias takes up")

    def __check_init__(self):
        check_finite("DampingCoupling", "c", self.c)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        return eqx.tree_at(lambda g: g.resonator.damping_coupling, gyro, gyro.resonator.damping_coupling + self.c)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "DampingCoupling":
        return cls(scale * jnp.asarray(_TYPICAL_C))
