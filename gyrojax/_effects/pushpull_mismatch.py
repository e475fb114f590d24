"""`pushpull_mismatch`: gain mismatch of the two push-pull feedback branches (seed 000 Fig. 5)."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope, closed_loop_parts
from ._support import as_parameter, require
from .base import AbstractEffect


# ASSUMPTION: seed 000 prints no branch tolerances. Fig. 5 makes -V_fa with a unity-gain inverter from
# 0.1 %-class resistors (a ratio error up to 0.2 %) and each branch drives its own comb, whose area is matched
# to about 0.1 % by lithography: +2e-3 on the V_f+ branch and -1e-3 on the V_f- branch. On paper-qmg this
# is a -500 ppm scale-factor change (-(plus + minus) / 2); the differential part's DC force moves the sense
# mass by ~1e-13 m at 200 deg/s (a stiff sense mode) and reaches the output only at second order.
_TYPICAL_PLUS = 2e-3
_TYPICAL_MINUS = -1e-3


class PushPullMismatch(AbstractEffect):
    r"""Relative gain errors of the V_f+ and V_f- branches (amplifier and electrode together), added to the
    excitation's `branch_gain_error_plus` / `branch_gain_error_minus`.

    With v+ = v (1 + e+), v- = v (1 + e-) the feedback force (`FeedbackElectrode.force`) is

        F = K_vf v (1 + (e+ + e-)/2)  +  K_vf (v+^2 - v-^2) / (4 V_dc)  +  gap terms,

    so the first-order fingerprint is a gain change: the rate and the closed-loop VCF outputs scale by
    1 / (1 + (e+ + e-)/2), while the DAC sweep (which reads the DAC before the branches) does not move. The
    differential part (e+ - e-) gives only a DC force ~ V_ac^2 and 2w forces (a product of two carrier
    waves has no fundamental): it shifts the sense mass, which changes the feedback gain only through the
    gap-dependent term (`comb_gap`), and only at second order (a symmetric comb pair's gain is even in the
    displacement). Closed loop only.
    """

    plus: jnp.ndarray = eqx.field(converter=as_parameter)
    minus: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "pushpull_mismatch"
    description = "gain mismatch of the V_f+ / V_f- feedback branches (amplifier and comb), relative"
    plugs_into = "excitation.branch_gain_error_plus, excitation.branch_gain_error_minus"
    revealed_by = ("a branch_ratio sweep (the two feedback branches' AC voltages compared, V_f+ / V_f-, at "
                   "rate-table points): on rate-table, VCF and DAC sweeps the common part is a K_vf change and the "
                   "DAC sweep reads the word before the branches")

    def __check_init__(self):
        check_finite("PushPullMismatch", "plus", self.plus)
        check_finite("PushPullMismatch", "minus", self.minus)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return gyro.closed_loop

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro), "a closed-loop device (push-pull feedback combs); "
                "it is open loop")
        ex = closed_loop_parts(gyro, self.name).excitation
        return eqx.tree_at(lambda g: (g.excitation.branch_gain_error_plus, g.excitation.branch_gain_error_minus),
                           gyro, (ex.branch_gain_error_plus + self.plus, ex.branch_gain_error_minus + self.minus))

    @classmethod
    def typical(cls, scale: float = 1.0) -> "PushPullMismatch":
        return cls(scale * jnp.asarray(_TYPICAL_PLUS), scale * jnp.asarray(_TYPICAL_MINUS))
