"""The FTR differential excitation circuit of seed 000 Fig. 5: word -> carrier -> DAC -> K_a -> +/- branches."""

from collections.abc import Callable

import equinox as eqx
from jaxtyping import Array, Float

from .._checks import check_finite, check_positive
from .dac import DAC


class FTRExcitation(eqx.Module):
    """Controller word to the AC voltages of the + and - feedback branches.

    The FPGA modulates the rebalance word onto the PLL carrier, the DAC converts it, a non-inverting
    amplifier of gain `amplifier_gain` (K_a) makes V_fa, and an inverter makes -V_fa; both are AC-coupled
    onto V_dc. `branch_gain_error_plus/minus` are the relative gain errors of the two branches (including
    their electrodes' share); zero for a matched pair.
    """

    dac: DAC
    amplifier_gain: float = 1.0
    branch_gain_error_plus: float = 0.0
    branch_gain_error_minus: float = 0.0

    def __check_init__(self):
        check_positive("FTRExcitation", "amplifier_gain", self.amplifier_gain)
        check_finite("FTRExcitation", "branch_gain_error_plus", self.branch_gain_error_plus)
        check_finite("FTRExcitation", "branch_gain_error_minus", self.branch_gain_error_minus)

    def branch_voltages(self, dac_voltage: Float[Array, "*s"],
                        after_amplifier: Callable[[Float[Array, "*s"]], Float[Array, "*s"]] | None = None
                        ) -> tuple[Float[Array, "*s"], Float[Array, "*s"]]:
        """AC parts of V_f+ and of -(V_f-) for a DAC output voltage: `(v_plus, v_minus)`. `after_amplifier`
        (optional) maps the amplifier output V_fa before the split (the device's feedback terms)."""
        v = self.amplifier_gain * dac_voltage
        if after_amplifier is not None:
            v = after_amplifier(v)
        return v * (1.0 + self.branch_gain_error_plus), v * (1.0 + self.branch_gain_error_minus)
