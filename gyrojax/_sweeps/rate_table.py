"""The rate table (seed 000 §5): the device on a turntable at a constant rate per point."""

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._physics.stimulus import Stimulus
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._units import DEG
from .base import points_field
from .steady import AbstractSteadySweep, settled_points


DING_ZHOU_2025_RATES_DPS = (-200.0, -100.0, -50.0, -20.0, -10.0, -5.0, -2.0, -1.0, -0.5, -0.2, -0.1,
                     0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
"""The 22 table rates of the rate-table protocol of Ding & Zhou 2025 (seed 000 §5), deg/s, in sweep order."""

class RateTable(AbstractSteadySweep):
    """A rate table: the device turned at a constant table rate per point, its settled rate output read
    (seed 000 §5). Timing `Protocol.dwell_s` at `Protocol.sample_rate_hz`.

    **Arguments:**

    - `rates_dps`: the table rates, deg/s, in the order listed (default seed 000's 22).
    """

    rates_dps: tuple = points_field(DING_ZHOU_2025_RATES_DPS, "table rates (deg/s)")

    name = "rate_table"
    stream: ClassVar[int] = 0
    title = "rate-table"
    input_quantity = "table rate"
    input_unit = "deg/s"
    output_unit = "LSB"
    input_meaning = "the table rate, deg/s (a physical rate on a rate table, seed 000 §5)"
    output_meaning = ("the gyro's rate output, LSB: the rebalance word in closed loop, the readout's ADC word in "
                      "open loop")
    rate_output = True
    rate_input = True

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        return np.asarray(self.rates_dps)

    def n_points(self) -> int:
        return len(self.rates_dps)

    def check_device(self, gyro: Gyroscope) -> None:
        pass

    def stimulus(self, value: Float[Array, " point"], time: Float[Array, " point"]) -> Stimulus:
        return Stimulus(rate=value * DEG, vcf_fc=0.0 * value, time=time)


def rate_table_points(gyro: Gyroscope, rates_dps: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                      tier: AbstractTier = Steady(), *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled rate-table points: table rates in deg/s, one die temperature (deg C) and optionally one time
    since power-on (s) per point."""
    return settled_points(gyro, [(RateTable(), rates_dps, temperatures, times)], tier)[0]


@jit
def _rate_sweep(gyro, rates, times, tier):
    def one(rate, time):
        return gyro, Stimulus(rate=rate, time=time)

    return tier.settle_points(*jax.vmap(one)(rates, times))


def rate_sweep(gyro: Gyroscope, rates: Float[ArrayLike, " point"], *, tier: AbstractTier = Steady(),
               times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settle `gyro` at each table rate (rad/s), vmapped, with one compiled call per shape and tier.

    **Arguments:**

    - `gyro`: the device.
    - `rates`: table rates, rad/s (1-d array).
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.
    - `times`: time since power-on of each point, s (sets the temperature); default all zero.

    **Returns:** a `Settled` whose fields have a leading axis over the rates.
    """
    rates = jnp.asarray(rates, dtype=float)
    if rates.ndim != 1 or rates.shape[0] < 1:
        raise ValueError(f"rates must be a non-empty 1-d array of rad/s, got shape {rates.shape}.")
    times = jnp.zeros_like(rates) if times is None else jnp.broadcast_to(jnp.asarray(times, dtype=float),
                                                                          rates.shape)
    return _rate_sweep(gyro, rates, times, tier)


def ding_zhou_2025_rates() -> Float[Array, " 22"]:
    """The 22 table rates of the rate-table protocol of Ding & Zhou 2025 (seed 000 §5: -200 ... 200 deg/s),
    in rad/s (`DING_ZHOU_2025_RATES_DPS` in deg/s)."""
    return jnp.asarray(DING_ZHOU_2025_RATES_DPS) * DEG
