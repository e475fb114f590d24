"""The DAC sweep (seed 000 Table 2): the FTR DAC alone, fed with carrier sines of given word amplitudes."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Real

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._lots.noise import RateNoise
from .._simulate.tiers import AbstractTier
from .._units import DEG
from .base import AbstractSweep, points_field
from .lot_campaign import LotCampaign
from .protocol import Protocol
from .rate_table import DING_ZHOU_2025_RATES_DPS


DAC_READING_S = 10.0
"""s, ASSUMPTION: one AC-voltmeter reading of a DAC word (settling and a 1 s integration, several times over;
seed 000 Table 2 prints the readings, not the time they took): the test time of a DAC point."""


class Dac(AbstractSweep):
    """The DAC sweep: the FTR DAC fed with carrier sines of given word amplitudes, the signed carrier
    fundamental read at its output by an AC voltmeter (seed 000 Table 2). A bench measurement of the DAC
    alone: no time axis, no die temperature, no turn-on bias; the noise is the voltmeter's.

    **Arguments:**

    - `rates_dps`: the rates the words stand for, deg/s, in order (word = -SF x rate with each device's ideal
      scale factor, seed 000 Table 2; default seed 000's 22, as the rate table's).
    """

    rates_dps: tuple = points_field(DING_ZHOU_2025_RATES_DPS, "rates (deg/s)")

    name = "dac"
    stream: ClassVar[int] = 3
    title = "DAC"
    input_quantity = "DAC word"
    input_unit = "LSB"
    output_unit = "V"
    input_meaning = "the FTR DAC word, 24-bit two's complement (seed 000 Table 2)"
    output_meaning = "the signed carrier-fundamental AC amplitude at the excitation circuit, V"
    biased = False
    straight_line = True
    word_input = True
    timed: ClassVar[bool] = False
    fit_against_rate = True

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        # The rates the words stand for, deg/s: the words themselves depend on each device's scale factor.
        return np.asarray(self.rates_dps)

    def n_points(self) -> int:
        return len(self.rates_dps)

    def check_device(self, gyro: Gyroscope) -> None:
        if not gyro.closed_loop:
            raise ValueError(f"a dac sweep needs a closed-loop device; {gyro.name!r} is open loop.")

    def run_inputs(self, gyro: Gyroscope) -> np.ndarray:
        # The words for the listed rates with the device's ideal scale factor (seed 000 Table 2).
        sf_ideal = float(np.asarray(gyro.ideal_scale_factor()))
        return np.round(-np.asarray(self.rates_dps, dtype=float) * DEG * sf_ideal)

    def run_minutes(self, protocol: Protocol) -> float:
        return self.n_points() * DAC_READING_S / 60.0

    def run_settings(self, protocol: Protocol) -> dict:
        return {"reading_s": DAC_READING_S}

    def point_sigmas(self, inputs: Float[ArrayLike, " point"], protocol: Protocol, noise: RateNoise, lsb_per_dps: float,
                     voltmeter_sigma_v: float) -> np.ndarray:
        return np.full(np.shape(inputs), float(voltmeter_sigma_v))

    def predict(self, gyro: Gyroscope, inputs: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                times: Float[ArrayLike, " point"] | None, tier: AbstractTier | None = None
                ) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        pred = dac_points(gyro, inputs)
        return pred, ~jnp.isfinite(pred)

    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        full = campaign.shape(self)
        rates = self.inputs()
        sf_ideal = np.asarray(_lot_ideal_sf(lot), dtype=float)  # LSB per rad/s
        words = np.round(-rates[None, :] * DEG * sf_ideal[:, None])  # seed 000 Table 2: word = -SF x rate
        volts = np.asarray(_lot_dac(lot, jnp.asarray(words)), dtype=float)
        out = np.broadcast_to(volts[:, None, :], full)
        sigma = np.full(full, 0.0 if campaign.noise_free else float(campaign.voltmeter_sigma_v))
        if not campaign.noise_free:
            out = out + sigma * campaign.rng(self).standard_normal(full)
        return {"input": np.broadcast_to(words[:, None, :], full), "output": out, "output_sigma": sigma,
                "n_samples": np.full(full, np.nan), "temperature_c": np.full(full, np.nan),  # the DAC alone
                "drive_freq_hz": np.full(full, np.nan), "rate_dps": np.broadcast_to(rates, full)}


def _dac_fundamental(gyro, word):
    """Signed carrier-fundamental amplitude (V) of the DAC output for a sine of amplitude `word` LSB."""
    dac = gyro.excitation.dac
    n = max(gyro.phase_points, 256)
    theta = 2.0 * jnp.pi * jnp.arange(n, dtype=float) / n
    hold_gain, _ = dac.hold(gyro.resonator.omega_x)
    v = dac(word * jnp.sin(theta)) * hold_gain
    return 2.0 * jnp.mean(v * jnp.sin(theta))


def dac_sweep(gyro: Gyroscope, words: Real[ArrayLike, " word"]) -> Float[Array, " word"]:
    """Seed 000 Table 2's experiment: the FTR DAC fed with carrier sines of the given word amplitudes
    (LSB of the 24-bit word, signed), returning the measured AC amplitude (V) at the DAC output: the
    signed fundamental, including the hold's gain. Closed-loop devices only."""
    if not gyro.closed_loop:
        raise ValueError(f"dac_sweep needs a closed-loop device with an FTR DAC; {gyro.name!r} is open loop.")
    return jax.vmap(lambda w: _dac_fundamental(gyro, w))(jnp.asarray(words, dtype=float))


def dac_points(gyro: Gyroscope, words: Real[ArrayLike, " word"]) -> Float[Array, " word"]:
    """Seed 000 Table 2's DAC sweep: signed carrier-fundamental amplitude (V) for each word (LSB)."""
    return dac_sweep(gyro, words)


@jit
def _lot_dac(lot, words):
    return eqx.filter_vmap(dac_points)(lot, words)


@jit
def _lot_ideal_sf(lot):
    return eqx.filter_vmap(lambda g: g.ideal_scale_factor())(lot)
