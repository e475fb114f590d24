"""The drive-frequency sweep: the PLL frequency read against the AGC set-point. Reveals `duffing_drive`.

The baseline's frequency is w_x at the die temperature, the same at every set-point; a cubic drive spring
bends it along the backbone w = w_x (1 + 3/8 kappa a^2) (the closed form of the AGC set-point sweeps). A free
`omega_x` takes the mean and the rho^2 shape is left: at typical size 38 ppm x (rho^2 - 1) on paper-qmg,
500 ppm x (rho^2 - 1) on vcf-2018. At the nominal set-point alone it is an `omega_x` shift.
"""

from typing import ClassVar

import numpy as np
from jaxtyping import Array, Float

from .base import timing_field
from .lot_campaign import LotCampaign
from .protocol import Protocol
from .setpoint import DRIVE_REGISTER_DWELL_S, AbstractSetpointSweep, SetpointReading


FREQUENCY_SIGMA_PPM = 1.0
"""Relative standard uncertainty of an averaged drive-frequency reading, ASSUMPTION: set by the die temperature
during the sweep, not by the PLL: silicon's -30 ppm/K times a chamber holding the die within ~0.03 K over
the sweep (4.6 mHz on paper-qmg, 1.8 mHz on vcf-2018)."""


class DriveFrequency(AbstractSetpointSweep):
    """The PLL (drive) frequency read at each AGC set-point, zero table rate. Inputs `setpoint_ratios`
    times the device's nominal set-point (LSB); dwell `register_dwell_s`; noise `FREQUENCY_SIGMA_PPM`
    of the reading, independent per point."""

    register_dwell_s: float = timing_field(DRIVE_REGISTER_DWELL_S)

    name = "drive_frequency"
    stream: ClassVar[int] = 6
    title = "drive-frequency"
    output_unit = "Hz"
    input_meaning = "the AGC set-point, drive ADC LSB, at zero table rate (as for `drive_amplitude`)"
    output_meaning = "the PLL's drive frequency, Hz (a register of the drive loop)"
    biased = False
    sign_definite = False  # a cubic drive spring of either sign bends the frequency up or down
    # The PLL's reading gives the drive resonance to ~1 ppm, far inside a lot's spread of omega_x, which the
    # rate table, VCF and DAC sweeps do not see; held, the spread would be taken for duffing_drive's pull.
    reads = ("omega_x",)

    def applicable_metrics(self) -> tuple[str, ...]:
        return ()

    def metric_not_applicable(self, metric: str) -> str:
        return ("not a measurement on a drive_frequency sweep: the frequency changes with the set-point only by a "
                "cubic drive spring's bend (duffing_drive, fitted by identify and diagnose)")

    def dwell_s(self, protocol: Protocol) -> float:
        return self.register_dwell_s

    def reading(self, points: SetpointReading) -> Float[Array, " point"]:
        return points.frequency_hz

    def relative_sigma(self, protocol: Protocol) -> float:
        return float(FREQUENCY_SIGMA_PPM * 1e-6)

    def add_noise(self, out: np.ndarray, campaign: LotCampaign) -> tuple[np.ndarray, np.ndarray]:
        sigma = FREQUENCY_SIGMA_PPM * 1e-6 * np.abs(out)
        return out + sigma * campaign.rng(self).standard_normal(out.shape), sigma
