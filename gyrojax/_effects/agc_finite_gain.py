"""`agc_finite_gain`: a leaky AGC integrator, so the drive amplitude sags with the load on the drive."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_nonnegative
from .._gyroscope import Gyroscope
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: a leaky AGC integrator with a 50 ms time constant (leak 20/s, slower than the 8 ms of the
# presets' 20 Hz AGC), the kind of leak an anti-windup or an analog integrator's finite gain gives. On
# vcf-2018 (Q = 9824) the amplitude sags by ~550 ppm (a gain change), and with the presets' TCQ a 10 K
# warm-up moves it by ~17 ppm. On paper-qmg (Q = 1e6, the drive needs almost no voltage) everything is
# ~40x smaller (14 ppm of sag, 0.4 ppm per 10 K). The sag saturates at the proportional-only value (leak -> inf: 2300
# ppm on vcf-2018), so the effect is linear in `leak` only for leak << 60/s.
_TYPICAL_LEAK = 20.0


class AgcFiniteGain(AbstractEffect):
    r"""Leak of the AGC integrator (1/s), added to `DriveLoop.agc_leak`: z' = ki err - leak z, a finite DC
    loop gain, so the drive amplitude sags in proportion to the drive voltage the AGC must supply:

        err = V_d / (kp + ki / leak),   a = (setpoint - err) / |front-end gain|.

    The scale factor follows a (closed loop SF = 2 Ag m a w / K_vf; open loop SF ~ a). Its fingerprints:

    - a gain change of rate-table sweeps (first order in `leak`); closed-loop VCF and DAC sweeps do not
      move (the virtual and the feedback forces do not scale with a);
    - with a temperature-dependent drive Q (`Resonator.tcq`), a drift of the rate-table scale factor with
      die temperature that does not track the drive frequency (unlike `thermal_drift`);
    - open loop, the Coriolis back-action (the sense motion damps the drive by (Ag Om)^2 g_y / d_y^2) adds
      an odd cubic, ~Om^2 relative, but only ~1e-4 of the sag at 200 deg/s on vcf-2018. In closed loop the
      sense mass is held at rest and there is no back-action.

    Any device.
    """

    leak: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "agc_finite_gain"
    description = "leaky (finite DC gain) AGC integrator: the drive amplitude sags with the drive load"
    plugs_into = "drive_loop.agc_leak"
    revealed_by = ("a drive_amplitude sweep: the drive pick-off's amplitude read against the AGC set-point (the "
                   "sag is the AGC's standing error; the baseline reads the set-point exactly), or rate tables at "
                   "two die temperatures: the sag follows the drive Q, where a resonator TCF follows the drive "
                   "frequency")

    def __check_init__(self):
        check_nonnegative("AgcFiniteGain", "leak", self.leak)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        return eqx.tree_at(lambda g: g.drive_loop.agc_leak, gyro, gyro.drive_loop.agc_leak + self.leak)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "AgcFiniteGain":
        return cls(scale * jnp.asarray(_TYPICAL_LEAK))
