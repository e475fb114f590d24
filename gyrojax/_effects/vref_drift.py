"""`vref_drift`: temperature drift of the feedback bias V_dc (its voltage reference)."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope, closed_loop_parts
from ._support import as_parameter, require
from .base import AbstractEffect


# ASSUMPTION: the 10 V bias is a reference scaled up by a resistor-gain amplifier; a general-purpose
# reference (~10 ppm/K) and thin-film gain resistors (~10 ppm/K) give 20 ppm/K: 200 ppm of rate-table and
# closed-loop VCF scale factor over a 10 K warm-up.
_TYPICAL_TC = 20e-6


class VrefDrift(AbstractEffect):
    r"""Temperature coefficient (1/K) of the feedback bias, added to `FeedbackElectrode.v_dc_tc`:
    V_dc(T) = V_dc (1 + tc (T - t_ref)), with T the die temperature of the point and t_ref the resonator's.

    K_vf = 4 n eps0 h V_dc / d0 (seed 000 Eq. 2) and the push-pull and gap terms of the feedback force follow
    V_dc(T), so every closed-loop output that the feedback force balances scales by 1 / (1 + tc dT): the
    rate-table sweep and, unlike a resonator TCF (`thermal_drift`), the closed-loop VCF sweep too (the
    virtual force does not scale with the drive frequency). The DAC sweep does not move. Closed loop only.
    """

    tc: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "vref_drift"
    description = "temperature drift of the feedback bias V_dc (the voltage reference), 1/K"
    plugs_into = "feedback_electrode.v_dc_tc"
    revealed_by = ("rate-table and closed-loop VCF sweeps at two or more die temperatures: both scale with V_dc,"
                   " while a resonator TCF moves only the rate table")

    def __check_init__(self):
        check_finite("VrefDrift", "tc", self.tc)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return gyro.closed_loop

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro), "a closed-loop device (biased feedback combs); "
                "it is open loop")
        fb = closed_loop_parts(gyro, self.name).feedback_electrode
        return eqx.tree_at(lambda g: g.feedback_electrode.v_dc_tc, gyro, fb.v_dc_tc + self.tc)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "VrefDrift":
        return cls(scale * jnp.asarray(_TYPICAL_TC))
