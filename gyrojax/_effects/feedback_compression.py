"""`feedback_compression`: odd (cubic) compression of the feedback amplifier after the DAC."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._checks import check_finite
from .._gyroscope import Gyroscope, closed_loop_parts
from .._terms import AbstractFeedbackTerm
from ._support import as_parameter, require
from .base import AbstractEffect


# ASSUMPTION: a third-harmonic distortion of about -90 dBc at full swing (a general-purpose op-amp driving the
# combs' capacitance at the 4.6 kHz carrier): HD3 = c / 4 = 3e-5, so c = 1.2e-4, a fundamental compressed by
# 3c/4 = 90 ppm at full scale and ~10 ppm at 200 deg/s on paper-qmg (a third of full scale).
_TYPICAL_CUBIC = 1.2e-4


class FeedbackCompression(AbstractEffect, AbstractFeedbackTerm):
    r"""Cubic compression of the feedback amplifier (or of the electrodes' drive) after the DAC:

        V_fa -> V_fa (1 - c (V_fa / V_fs)^2),   V_fs = K_a x DAC full scale,

    on the instantaneous carrier samples. The fundamental is compressed by 3c/4 (w/W)^2 at word amplitude w
    (W the full-scale word), so the loop raises the word: the rate-table and closed-loop VCF outputs gain an
    odd cubic +3c/4 (w/W)^2 w. The DAC sweep, read at the DAC's output before the amplifier, does not move:
    that, with the shared cubic, is what places it after the DAC (a DAC INL moves the DAC sweep too).
    Closed loop only.
    """

    cubic: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "feedback_compression"
    description = "cubic compression of the feedback amplifier after the DAC (relative, at full scale)"
    plugs_into = "terms (a feedback-path nonlinearity after the DAC)"
    revealed_by = ("a DAC sweep beside the rate table: the same odd cubic in the rate-table and closed-loop VCF "
                   "outputs while the DAC's own output stays linear; or each feedback branch's AC voltage "
                   "measured after the amplifier")

    def __check_init__(self):
        check_finite("FeedbackCompression", "cubic", self.cubic)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return gyro.closed_loop

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro), "a closed-loop device (a feedback amplifier); it is open loop")
        return gyro.with_term(self)

    def __call__(self, gyro: Gyroscope, voltage: Float[Array, "*sample"]) -> Float[Array, "*sample"]:
        excitation = closed_loop_parts(gyro, self.name).excitation
        full = excitation.amplifier_gain * excitation.dac.full_scale
        return voltage * (1.0 - self.cubic * (voltage / full) ** 2)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "FeedbackCompression":
        return cls(scale * jnp.asarray(_TYPICAL_CUBIC))
