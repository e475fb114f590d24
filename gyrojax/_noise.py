"""Measurement noise of a settled point and of a run."""

import equinox as eqx

from ._checks import check_nonnegative, check_positive


class RateNoise(eqx.Module):
    """Noise of rate-table points (seed 000 §5: 1 min warm-up, 2 min per rate at 100 Hz).

    - `arw_dps_per_sqrt_h`: angle random walk, deg/sqrt(h); a point's mean over `dwell_s` then has a
      standard uncertainty ARW / sqrt(dwell) (white rate noise).
    - `turn_on_bias_dps`: 1-sigma bias change from run to run (turn-on repeatability).
    - `warmup_s`, `dwell_s`: the protocol's timing, s; point i is centred at warmup + (i + 1/2) dwell.

    Defaults are ASSUMPTIONS for a tactical-grade QMG (seed 000 gives no noise figures): 0.05 deg/sqrt(h)
    and 0.01 deg/s.
    """

    arw_dps_per_sqrt_h: float = 0.05
    turn_on_bias_dps: float = 0.01
    warmup_s: float = 60.0
    dwell_s: float = 120.0

    def __check_init__(self):
        check_nonnegative("RateNoise", "arw_dps_per_sqrt_h", self.arw_dps_per_sqrt_h)
        check_nonnegative("RateNoise", "turn_on_bias_dps", self.turn_on_bias_dps)
        check_nonnegative("RateNoise", "warmup_s", self.warmup_s)
        check_positive("RateNoise", "dwell_s", self.dwell_s)

    def point_sigma_dps(self):
        """Standard uncertainty of one point's mean, deg/s."""
        return self.arw_dps_per_sqrt_h / 60.0 / self.dwell_s**0.5
