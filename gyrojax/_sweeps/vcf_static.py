"""The static virtual-Coriolis sweep (seed 003 Eq. 7): a virtual rate from the VCF electrode, no rotation."""

from typing import ClassVar

import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._gyroscope import Gyroscope
from .._physics.stimulus import Stimulus
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._units import DEG
from .base import points_field
from .rate_table import DING_ZHOU_2025_RATES_DPS
from .steady import AbstractSteadySweep, settled_points


VCF_STATIC_RATES_DPS = DING_ZHOU_2025_RATES_DPS
"""deg/s, the static virtual-Coriolis sweep as a "virtual rate table" (seed 003 Fig. 4b): V_ac is set so that
seed 003 Eq. (7), Om = K_svf V_fc V_ac / (2 m Ag a w_d), with the device's design values gives these rates
(seed 000's 22). Seed 003 prints no static voltages. With Table 1's values (vcf-2018) 200 deg/s is
V_ac = 6.546 mV at V_fc = 1 V; on paper-qmg's electrode (`gyrojax/_presets.py`) it is 2 V."""

VCF_CARRIER_V = 1.0
"""V, seed 003 §3: "Vfc = 1 V", the fixed carrier of the virtual-Coriolis multiplier."""


def virtual_rate_volts(gyro: Gyroscope, rates_dps, carrier_v: float = VCF_CARRIER_V) -> np.ndarray:
    """The V_ac whose virtual-Coriolis force equals the Coriolis force of `rates_dps` (deg/s) on `gyro`'s
    nominal values (a single device), by seed 003 Eq. (7) inverted: V_ac = Om 2 m Ag a w_d / (K_svf V_fc),
    a the AGC's amplitude and w_d the drive resonance at t_ref, rounded to 12 significant digits. Raises a
    `ValueError` for a device without a virtual-Coriolis electrode."""
    r = gyro.resonator
    k_svf = float(np.asarray(gyro.vcf_electrode.force_per_volt2))
    if k_svf == 0.0:
        raise ValueError(f"a vcf sweep needs a virtual-Coriolis electrode; {gyro.name!r} has "
                         "vcf_electrode.force_per_volt2 = 0.")
    coriolis = 2.0 * r.mass * r.angular_gain * gyro.drive_amplitude(r.omega_x) * r.omega_x
    volts_per_rad_s = float(np.asarray(coriolis)) / (k_svf * float(carrier_v))
    volts = np.asarray(rates_dps, dtype=float) * DEG * volts_per_rad_s
    return np.asarray([float(f"{v:.12g}") for v in volts])  # a generator's setting; clean numbers in files


class VcfStatic(AbstractSteadySweep):
    """A static virtual-Coriolis sweep: the virtual-rate voltage V_ac times the fixed carrier V_fc on the
    VCF electrode, the settled rate output read (seed 003 Eq. 7). The rate table's timing (ASSUMPTION: seed 003
    prints none).

    **Arguments:**

    - `virtual_rates_dps`: the sweep as virtual rates, deg/s, in order: V_ac is set from them with seed 003
      Eq. (7) and the nominal device's own m, Ag, a, w_d and K_svf at `carrier_v` (what a test engineer does
      with the design values; `virtual_rate_volts`).
    - `amplitudes_v`: explicit voltages V_ac, V, in order; when given they replace `virtual_rates_dps`.
    - `carrier_v`: the fixed carrier V_fc, V.
    """

    virtual_rates_dps: tuple = points_field(VCF_STATIC_RATES_DPS, "virtual rates (deg/s)")
    amplitudes_v: tuple | None = points_field(None, "voltages (V)", optional=True)
    carrier_v: float = VCF_CARRIER_V

    name = "vcf_static"
    stream: ClassVar[int] = 1
    title = "static-VCF"
    input_quantity = "virtual-rate voltage V_ac"
    input_unit = "V"
    output_unit = "LSB"
    input_meaning = ("the virtual-rate voltage V_ac on the virtual-Coriolis electrode, V, signed (at the fixed "
                     "carrier V_fc = 1 V; seed 003 Eq. (7))")
    output_meaning = "the gyro's rate output, LSB"
    rate_output = True

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        if self.amplitudes_v is not None:
            return np.asarray(self.amplitudes_v)
        if gyro is None:
            raise ValueError("VcfStatic.inputs needs the device to turn virtual_rates_dps into volts; pass gyro=.")
        return virtual_rate_volts(gyro, self.virtual_rates_dps, self.carrier_v)

    def n_points(self) -> int:
        return len(self.amplitudes_v if self.amplitudes_v is not None else self.virtual_rates_dps)

    def check_device(self, gyro: Gyroscope) -> None:
        # Voltages set from the electrode's design values need an electrode (`virtual_rate_volts` raises);
        # explicit voltages on a device without one read zero, as measured.
        self.inputs(gyro)

    def stimulus(self, value: Float[Array, " point"], time: Float[Array, " point"]) -> Stimulus:
        return Stimulus(rate=0.0 * value, vcf_ac=value, vcf_fc=self.carrier_v, time=time)


def vcf_static_points(gyro: Gyroscope, amplitudes_v: Float[ArrayLike, " point"],
                      temperatures: Float[ArrayLike, " point"], tier: AbstractTier = Steady(),
                      carrier_v: float = VCF_CARRIER_V,
                      *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled static virtual-Coriolis points (seed 003 Eq. 7): the virtual-rate voltage V_ac (V, signed)
    times the fixed carrier V_fc, one die temperature and optionally one time since power-on per point."""
    return settled_points(gyro, [(VcfStatic(carrier_v=carrier_v), amplitudes_v, temperatures, times)], tier)[0]
