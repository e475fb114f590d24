"""`duffing_drive`: cubic stiffness of the drive mode."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_finite
from .._gyroscope import Gyroscope
from ._support import as_parameter
from .base import AbstractEffect


# ASSUMPTION: folded-beam drive springs are nearly linear; a relative cubic stiffness k3/k1 of 4e6 1/m^2 moves
# the drive resonance by 3/8 k3/k1 a^2: 38 ppm (0.17 Hz) at paper-qmg's 5 um, 500 ppm (0.9 Hz) at vcf-2018's
# 18 um, the size of the backbone shifts reported for comb-driven gyros.
_TYPICAL_KAPPA = 4e6


class DuffingDrive(AbstractEffect):
    r"""Relative cubic stiffness k3/k1 of the drive mode (1/m^2), added to the resonator as
    `duffing_x += kappa w_x^2` (per unit mass, x'' + ... + w_x^2 x + duffing_x x^3).

    The PLL locks to the amplitude-dependent resonance w = w_x (1 + 3/8 kappa a^2) and the AGC holds a, so the
    fingerprint is a constant frequency shift: a gain change (closed loop SF ~ w: +3/8 kappa a^2; open loop SF
    ~ 1/d_y: amplified by w/dw) and a shifted drive-frequency reading, nearly collinear with a change of
    `omega_x`. The carrier-level x^3 also makes a 3w harmonic that averaging drops (the full-waveform tier
    keeps it). Any device.
    """

    kappa: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "duffing_drive"
    description = "cubic (Duffing) stiffness of the drive mode: amplitude-dependent drive frequency"
    plugs_into = "resonator.duffing_x"
    revealed_by = ("a drive_frequency sweep (the PLL frequency read against the AGC set-point): w = w_x (1 + 3/8 "
                   "kappa a^2); at one amplitude it is an omega_x shift")

    def __check_init__(self):
        check_finite("DuffingDrive", "kappa", self.kappa)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return True

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        r = gyro.resonator
        return eqx.tree_at(lambda g: g.resonator.duffing_x, gyro, r.duffing_x + self.kappa * r.omega_x**2)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "DuffingDrive":
        return cls(scale * jnp.asarray(_TYPICAL_KAPPA))
