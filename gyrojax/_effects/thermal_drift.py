"""`thermal_drift`: extra temperature coefficients of the resonances, seen through the die temperature."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: the TCF of silicon resonators spreads by a few ppm/K around the nominal -30 ppm/K with doping
# and packaging stress: an extra +3e-6/K, i.e. 30 ppm of closed-loop scale factor over a 10 K warm-up.
_TYPICAL_TCF = 3e-6
# ASSUMPTION: the two modes' TCFs differ (different stress sensitivity, electrostatic tuning of the sense
# mode) by about 0.5 ppm/K: on vcf-2018 (1.8 kHz, 62 Hz split) the split drifts by 0.9 mHz/K, which the
# open-loop scale factor amplifies by w/dw = 29 to ~15 ppm/K (150 ppm over 10 K).
_TYPICAL_TCF_SPLIT = 0.5e-6


class ThermalDrift(AbstractEffect):
    r"""Extra temperature coefficients of the resonant frequencies, added to `Resonator.tcf` (both modes) and
    `Resonator.tcf_split` (the sense mode only), 1/K.

    They act through `Resonator.at_temperature`, i.e. through the die temperature of each point (the
    `temperature_c` column; a warm-up history in simulation). Fingerprints, for a die dT above `t_ref`:

    - closed loop: SF = 2 Ag m a w / K_vf tracks the drive frequency, SF(T)/SF(t_ref) = w(T)/w(t_ref), a
      relative change `tcf` dT; the split does not matter (the sense mass is held at rest), and neither
      does anything in a closed-loop VCF sweep (the virtual force does not scale with w);
    - open loop: SF ~ Ag a / d_y with d_y = (w_y^2 - w^2) / (2 w): -`tcf` dT from the common part and
      -`tcf_split` dT w_y^2 / (w d_y) from the split (amplified by w/dw).

    A run at one temperature shows a gain change (run-to-run repeatability); a drift within a run, with the
    points in sweep order, looks even-order. Any device.
    """

    tcf: jnp.ndarray = eqx.field(converter=as_parameter)
    tcf_split: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "thermal_drift"
    description = "extra temperature coefficient of both resonances and of the mode split, 1/K"
    plugs_into = "resonator.tcf, resonator.tcf_split"
    revealed_by = ("rate tables at two or more die temperatures with the drive frequency read (drive_freq_hz): "
                   "the scale factor tracks the drive frequency")

    def __check_init__(self):
        check_finite("ThermalDrift", "tcf", self.tcf)
        check_finite("ThermalDrift", "tcf_split", self.tcf_split)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        r = gyro.resonator
        return eqx.tree_at(lambda g: (g.resonator.tcf, g.resonator.tcf_split), gyro,
                           (r.tcf + self.tcf, r.tcf_split + self.tcf_split))

    @classmethod
    def typical(cls, scale: float = 1.0) -> "ThermalDrift":
        return cls(scale * jnp.asarray(_TYPICAL_TCF), scale * jnp.asarray(_TYPICAL_TCF_SPLIT))
