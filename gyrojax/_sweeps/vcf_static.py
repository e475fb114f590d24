"""The static virtual-Coriolis sweep (seed 003 Eq. 7): a virtual rate from the VCF electrode, no rotation."""

from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import ArrayLike, Float

from .._gyroscope import Gyroscope
from .._physics.stimulus import Stimulus
from .._simulate.tiers import AbstractTier, Settled, Steady
from .rate_table import DING_ZHOU_2025_RATES_DPS
from .steady import AbstractSteadySweep, settled_points


if TYPE_CHECKING:
    from .protocol import Protocol


VCF_STATIC_RATES_DPS = DING_ZHOU_2025_RATES_DPS
"""deg/s, the static virtual-Coriolis sweep as a "virtual rate table" (seed 003 Fig. 4b): V_ac is set so that
seed 003 Eq. (7), Om = K_svf V_fc V_ac / (2 m Ag a w_d), with the device's design values gives these rates
(seed 000's 22). Seed 003 prints no static voltages. With Table 1's values (vcf-2018) 200 deg/s is
V_ac = 6.546 mV at V_fc = 1 V; on paper-qmg's electrode (`gyrojax/_presets.py`) it is 2 V."""

VCF_CARRIER_V = 1.0
"""V, seed 003 §3: "Vfc = 1 V", the fixed carrier of the virtual-Coriolis multiplier."""


class VcfStatic(AbstractSteadySweep):
    """A static virtual-Coriolis sweep: the virtual-rate voltage V_ac times the fixed carrier V_fc on the
    VCF electrode, the settled rate output read (seed 003 Eq. 7). Inputs `Protocol.vcf_amplitudes_v`, or
    `Protocol.vcf_rates_dps` through the device's design values; the rate table's timing (ASSUMPTION: seed
    003 prints none).

    **Arguments:**

    - `carrier_v`: the fixed carrier V_fc, V.
    """

    carrier_v: float = VCF_CARRIER_V

    name = "vcf_static"
    title = "static-VCF"
    input_quantity = "virtual-rate voltage V_ac"
    input_unit = "V"
    output_unit = "LSB"
    input_meaning = ("the virtual-rate voltage V_ac on the virtual-Coriolis electrode, V, signed (at the fixed "
                     "carrier V_fc = 1 V; seed 003 Eq. (7))")
    output_meaning = "the gyro's rate output, LSB"
    rate_output = True

    def inputs(self, protocol: "Protocol", gyro: Gyroscope | None = None) -> np.ndarray:
        if protocol.vcf_amplitudes_v is not None:
            return np.asarray(protocol.vcf_amplitudes_v)
        if gyro is None:
            raise ValueError("Protocol.inputs('vcf_static') needs the device to turn vcf_rates_dps into "
                             "volts; pass gyro=.")
        return protocol.vcf_static_amplitudes(gyro)

    def n_points(self, protocol: "Protocol") -> int:
        return len(protocol.vcf_amplitudes_v if protocol.vcf_amplitudes_v is not None else protocol.vcf_rates_dps)

    def check_device(self, gyro: Gyroscope, protocol: "Protocol") -> None:
        # Voltages set from the electrode's design values need an electrode (`Protocol.vcf_static_amplitudes`
        # raises); explicit voltages on a device without one read zero, as measured.
        self.inputs(protocol, gyro)

    def stimulus(self, value, time) -> Stimulus:
        return Stimulus(rate=0.0 * value, vcf_ac=value, vcf_fc=self.carrier_v, time=time)


def vcf_static_points(gyro: Gyroscope, amplitudes_v: Float[ArrayLike, " point"],
                      temperatures: Float[ArrayLike, " point"], tier: AbstractTier = Steady(), carrier_v=VCF_CARRIER_V,
                      *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled static virtual-Coriolis points (seed 003 Eq. 7): the virtual-rate voltage V_ac (V, signed)
    times the fixed carrier V_fc, one die temperature and optionally one time since power-on per point."""
    return settled_points(gyro, [(VcfStatic(carrier_v), amplitudes_v, temperatures, times)], tier)[0]
