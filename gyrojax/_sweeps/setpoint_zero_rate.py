r"""The zero-rate output against the AGC set-point within one run: the stand-in for a mode reversal. Reveals
`damping_coupling` (with `quadrature_phase` confounded; the quadrature injection splits them).

**Why not a mode reversal.** Swapping the drive and sense roles flips the sign of the Coriolis term but not
that of the damping coupling c, so the two zero-rate outputs differ by c / Ag. Neither preset can do it:
paper-qmg (seed 000) has drive combs and an AGC/PLL on x only and the push-pull feedback combs, their DAC and
the sense tuning on y only, and its modes are 77 Hz apart as built (tuned to ~1 Hz from the y side); vcf-2018
(seed 003) is open loop with drive combs on x and a 62 Hz split. `gyrojax.Gyroscope` has fixed roles (drive
on x, sense on y).

**Model.** At zero table rate and set-point ratio rho the closed-loop output is

    R = SF(rho) [c / (2 Ag) + Om_q] + b_run,      SF(rho) = 2 Ag m (rho a) w / K_vf,

with Om_q = Q_0 sin(phi) / SF the rate-equivalent bias of a rate-channel phase error on the quadrature
(Q_0 / SF is set by the stiffness coupling: it does not depend on a either) and b_run the run's turn-on bias
in LSB, the same at every set-point within the run (ASSUMPTION: it is an offset of the electronics, not a
force that scales with the drive). Open loop the same holds with SF ~ Ag a / |g_y - j d_y|.

**Why it sees the effect apart from the baseline.** A zero-rate output that is a force proportional to the
drive motion (c x', or quadrature read through phi) scales with a, while b_run does not. The baseline's
zero-rate output is 0 at every amplitude, and one run bias takes only the mean: at the typical c = 2e-3 1/s
(0.057 deg/s) the output moves by 0.029 deg/s of the nominal scale factor between rho = 0.5 and 1. c and phi
leave the same fingerprint here; the quadrature injection sees phi alone.
"""

from typing import ClassVar

import numpy as np
from jaxtyping import Array, Float

from .lot_campaign import LotCampaign
from .setpoint import AbstractSetpointSweep, SetpointReading


class SetpointZeroRate(AbstractSetpointSweep):
    """The rate output at zero table rate read at each AGC set-point, within one power-on run. Inputs
    `setpoint_ratios` times the device's nominal set-point (LSB); the rate table's dwell and sampling
    (`Protocol.dwell_s`, `sample_rate_hz`); the output carries the run's turn-on bias and rate noise, as a
    rate-table point."""

    name = "setpoint_zero_rate"
    stream: ClassVar[int] = 7
    title = "set-point zero-rate"
    output_unit = "LSB"
    input_meaning = "the AGC set-point, drive ADC LSB, at zero table rate (as for `drive_amplitude`)"
    output_meaning = "the gyro's rate output, LSB (as for `rate_table`)"
    biased = True
    rate_noise = True
    sign_definite = False  # the slope is a damping coupling's or a phase error's, of either sign

    def applicable_metrics(self) -> tuple[str, ...]:
        return ("scale_factor", "bias")  # the zero-rate output per set-point LSB, and the run's turn-on bias
    # dwell_s: the protocol's rate-output dwell (AbstractSweep's default), not the drive registers' register_dwell_s

    def reading(self, points: SetpointReading) -> Float[Array, " point"]:
        return points.rate_lsb

    def add_noise(self, out: np.ndarray, campaign: LotCampaign) -> tuple[np.ndarray, np.ndarray]:
        full, dwell, lsb = out.shape, self.dwell_s(campaign.protocol), campaign.lsb_per_dps
        bias, wobble = campaign.noise.sample_point_means(campaign.rng(self), full[:2], full[2], dwell)
        sigma = np.broadcast_to((campaign.noise.point_sigma_dps(dwell) * lsb)[:, None, None], full)
        return out + (bias[..., None] + wobble) * lsb[:, None, None], sigma
