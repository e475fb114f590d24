"""The drive-amplitude sweep: the AGC's pick-off amplitude read against its set-point. Reveals
`agc_finite_gain`.

The baseline (ideal AGC integrator) reads |e_d| = set-point exactly, whatever the device's gains: the AGC
regulates the digital reading itself, so no front-end or electrode gain can make a standing error. A leaky
integrator is the only source of one, a fixed fraction beta / (1 + beta) of every set-point
(the closed form of the AGC set-point sweeps); at the one nominal set-point of the standard sweeps it is only a
gain change.
"""

from typing import ClassVar

import numpy as np
from jaxtyping import Array, Float

from .base import timing_field
from .lot_campaign import LotCampaign
from .protocol import Protocol
from .setpoint import DRIVE_REGISTER_DWELL_S, AbstractSetpointSweep, SetpointReading


AMPLITUDE_SIGMA_PPM = 1.0
"""Relative standard uncertainty of an averaged pick-off amplitude |e_d|, ASSUMPTION: the AGC regulates this
digital reading itself, so references and front-end gains drop out; what is left is the loop's own noise,
averaged over the dwell (a 24-bit ADC at ~4e6 LSB of signal)."""


class DriveAmplitude(AbstractSetpointSweep):
    """The AGC's demodulated pick-off amplitude |e_d| read at each AGC set-point, zero table rate. Inputs
    `setpoint_ratios` times the device's nominal set-point (LSB); dwell `register_dwell_s`
    (default `DRIVE_REGISTER_DWELL_S`); noise `AMPLITUDE_SIGMA_PPM` of the reading, independent per point."""

    register_dwell_s: float = timing_field(DRIVE_REGISTER_DWELL_S)

    name = "drive_amplitude"
    stream: ClassVar[int] = 5
    title = "drive-amplitude"
    output_unit = "LSB"
    input_meaning = ("the AGC set-point, drive ADC LSB (the amplitude the AGC regulates the demodulated drive "
                     "pick-off to), at zero table rate")
    output_meaning = ("the amplitude of the AGC's demodulated drive pick-off e_d, drive ADC LSB (a register of "
                      "the drive loop; equal to the set-point for an ideal AGC)")
    biased = False

    def dwell_s(self, protocol: Protocol) -> float:
        return self.register_dwell_s

    def reading(self, points: SetpointReading) -> Float[Array, " point"]:
        return points.amplitude_lsb

    def relative_sigma(self, protocol: Protocol) -> float:
        return float(AMPLITUDE_SIGMA_PPM * 1e-6)

    def add_noise(self, out: np.ndarray, campaign: LotCampaign) -> tuple[np.ndarray, np.ndarray]:
        sigma = AMPLITUDE_SIGMA_PPM * 1e-6 * np.abs(out)
        return out + sigma * campaign.rng(self).standard_normal(out.shape), sigma


