"""The force-to-rebalance DAC of seed 000 Fig. 5: resolution, INL, DNL, gain, offset and update rate."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._checks import check_finite, check_nonnegative, check_positive, check_positive_or_inf


class DAC(eqx.Module):
    r"""A `bits`-wide DAC fed with the top bits of a `word_bits`-wide controller word.

    The instantaneous carrier sample s (in word LSB) becomes the code c = s / 2^(word_bits - bits) and the
    output voltage

        v = full_scale (1 + gain_error) [q(c) + INL(u) + DNL(c)] / 2^(bits-1) + offset,  u = c / 2^(bits-1)

    with q the rounding quantiser (only when `quantize`), INL(u) = sum_k inl[k] u^(k+2) in DAC LSB (the
    constant and linear parts are the offset and gain error), and DNL(c) a segment error repeating every
    `dnl_period` codes (a sawtooth of `dnl_amplitude` LSB, the shape of a mismatched segment at each major
    carry).

    The update rate acts through the zero-order hold. For the carrier fundamental a ZOH is exactly a gain
    sinc(w T / 2) and a delay of T/2 (T = 1 / update_rate); the images at f_s +/- f_d lie far above the
    mechanical band and are dropped in every tier.

    Seed 000 §5: 16-bit DAC; Table 2 gives 1.637 V for the word 0x29E345 = 2,745,157, i.e. 5.963e-7 V per
    24-bit LSB = 5.0 V / 2^23: a +/-5 V full scale fed from a 24-bit word.
    """

    full_scale: float = 5.0
    gain_error: float = 0.0
    offset: float = 0.0
    inl: jnp.ndarray = eqx.field(default_factory=lambda: jnp.zeros(0))
    dnl_amplitude: float = 0.0
    update_rate: float = math.inf
    bits: int = eqx.field(static=True, default=16)
    word_bits: int = eqx.field(static=True, default=24)
    dnl_period: int = eqx.field(static=True, default=4096)
    quantize: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if not isinstance(self.bits, (int, np.integer)) or self.bits < 1:
            raise ValueError(f"DAC.bits must be an integer >= 1, got {self.bits!r}.")
        if not isinstance(self.word_bits, (int, np.integer)) or self.word_bits < self.bits:
            raise ValueError(f"DAC.word_bits must be an integer >= bits ({self.bits}), got {self.word_bits!r}.")
        if not isinstance(self.dnl_period, (int, np.integer)) or self.dnl_period < 2:
            raise ValueError(f"DAC.dnl_period must be an integer >= 2 codes, got {self.dnl_period!r}.")
        check_positive("DAC", "full_scale", self.full_scale)
        check_positive_or_inf("DAC", "update_rate", self.update_rate)
        check_finite("DAC", "gain_error", self.gain_error)
        check_finite("DAC", "offset", self.offset)
        check_finite("DAC", "inl", self.inl)
        check_nonnegative("DAC", "dnl_amplitude", self.dnl_amplitude)

    @property
    def code_scale(self) -> float:
        """Codes per word LSB."""
        return 2.0 ** (self.bits - self.word_bits)

    @property
    def volts_per_word_lsb(self) -> float | Float[Array, ""]:
        """Ideal output volts per word LSB (the linear DAC gain)."""
        return self.full_scale * self.code_scale / 2.0 ** (self.bits - 1)

    def inl_lsb(self, u: Float[ArrayLike, "*s"]) -> Float[Array, "*s"]:
        """INL in DAC LSB at normalised code u = c / 2^(bits-1)."""
        powers = jnp.arange(self.inl.shape[0], dtype=float) + 2.0
        return jnp.sum(self.inl * jnp.asarray(u)[..., None] ** powers, axis=-1)

    def _dnl_lsb(self, code):
        phase = code / self.dnl_period
        return self.dnl_amplitude * (2.0 * (phase - jnp.floor(phase)) - 1.0)

    def __call__(self, word_sample: Float[Array, "*s"]) -> Float[Array, "*s"]:
        """Output voltage (V) for an instantaneous carrier sample in word LSB (memoryless part)."""
        code = word_sample * self.code_scale
        half = 2.0 ** (self.bits - 1)
        q = jnp.round(code) if self.quantize else code
        err = self.inl_lsb(code / half) + self._dnl_lsb(code)
        return self.full_scale * (1.0 + self.gain_error) * (q + err) / half + self.offset

    def hold(self, omega: float | Float[Array, "*s"]) -> tuple[Float[Array, "*s"], float | Float[Array, "*s"]]:
        """ZOH at the carrier: `(gain, delay_phase)` with gain sinc(wT/2) and phase lag wT/2 (rad)."""
        half_angle = 0.5 * omega / self.update_rate
        gain = jnp.where(half_angle > 0, jnp.sin(half_angle) / jnp.where(half_angle > 0, half_angle, 1.0), 1.0)
        return gain, half_angle
