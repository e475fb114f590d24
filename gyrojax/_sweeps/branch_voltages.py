r"""The two push-pull feedback branches' AC voltages compared during a rate table. Reveals `pushpull_mismatch`.

**Protocol.** During rate-table points (closed loop), a two-channel lock-in referenced to the drive carrier
reads the carrier-fundamental amplitude of each feedback branch's AC voltage, V_f+ and V_f- (seed 000 Fig. 5:
the amplifier output V_fa and its inverted copy, each AC-coupled onto V_dc), through one instrument and the
same cable length, in ratio mode: the reading is V_f+ / V_f-.

**Why one reading, the ratio.** The two amplitudes share the instrument's absolute gain (0.1 %-class), which
would otherwise be a free nuisance gain common to two rows; the ratio cancels it in the instrument, so a row is
one settled reading and the baseline predicts it with no free parameter of its own.

**Model.** The rebalance word W (complex: rate and quadrature) is modulated on the carrier, converted by the
DAC (hold gain, INL) and amplified (K_a, then the device's feedback terms); the branches are

    v+ = v (1 + e+),   v- = v (1 + e-),   v = K_a DAC(W),

(`FTRExcitation.branch_voltages`), each read as its fundamental over the carrier phase. The word is the settled
word of the rate point, so every rate-path effect reaches the amplitudes, and cancels in the ratio unless it
acts on one branch.

**Why it sees the effect apart from the baseline.** On rate-table, VCF and DAC sweeps only the common part
(e+ + e-)/2 acts (a K_vf change) and the differential part is second order. The ratio (1 + e+) / (1 + e-) is
1 in the baseline whatever K_vf, the DAC gain or the word. At the typical e+ = +2e-3, e- = -1e-3 it is 3000
ppm off, ~200 sigma of a 14 ppm ratio per point. A share of a branch's gain error sitting in its comb (finger
area) rather than its amplifier acts on the force, not on the voltage: a voltmeter cannot see it.
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._simulate._model import SlowState, controls, dac_voltage, expj, phase_grid
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._solution import RESULTS
from .base import AbstractSweep, at_temperature, points_field
from .lot_campaign import LotCampaign
from .protocol import Protocol
from .rate_table import RateTable
from .steady import per_run, raise_unsettled, settled_points


BRANCH_RATES_DPS = (-200.0, -100.0, -50.0, 50.0, 100.0, 200.0)
"""deg/s, rate-table points read by the lock-in, ASSUMPTION: seed 000's rates from 50 deg/s up, where the
feedback voltage (0.4-1.6 V at 13,710 LSB/(deg/s)) is far above the quadrature's share (10 deg/s)."""

BRANCH_SIGMA_PPM = 10.0
"""Relative standard uncertainty of each branch amplitude, ASSUMPTION: a lock-in's two channels at a few kHz,
averaged over the rate table's 2-min dwell: the gain ratio of the two inputs is stable to ~10 ppm. The ratio
of two such readings carries sqrt(2) x 10 ppm."""


def branch_amplitudes(gyro: Gyroscope, loops, temperature):
    """Carrier-fundamental amplitudes (V) of the two feedback branches, `(v_plus, v_minus)`, of one settled
    closed-loop state (`loops`: `SlowState.loops`) at die temperature `temperature` (deg C)."""
    gyro = gyro.at_die_temperature(temperature)
    ctl = controls(gyro, loops)
    theta = phase_grid(max(gyro.phase_points, 64))
    v_plus, v_minus = gyro.feedback_voltages(dac_voltage(gyro, ctl.word, theta, ctl.omega))

    def fundamental(v):
        return jnp.abs(2.0 * jnp.mean(v.astype(complex) * expj(-theta)))

    return fundamental(v_plus), fundamental(v_minus)


def branch_ratio_points(gyro: Gyroscope, rates_dps: Float[ArrayLike, " point"],
                        temperatures: Float[ArrayLike, "*#point"],
                        times: Float[ArrayLike, " point"] | None = None, tier: AbstractTier = Steady()
                        ) -> tuple[Float[Array, " point"], Settled]:
    """V_f+ / V_f- at each rate-table point of one closed-loop device (rates in deg/s, die temperatures in
    deg C, times since power-on in s), and the `Settled` points of the tier (steady or averaged: the full
    waveform's loop states carry a 2w ripple)."""
    if not gyro.closed_loop:
        raise ValueError(f"branch voltages need a closed-loop device (push-pull feedback combs); {gyro.name!r} "
                         "is open loop.")
    rates = jnp.atleast_1d(jnp.asarray(rates_dps, dtype=float))
    temps = jnp.broadcast_to(jnp.asarray(temperatures, dtype=float), rates.shape)
    (settled,) = settled_points(gyro, [(RateTable(), rates, temps, times)], tier)
    if not isinstance(settled.state, SlowState):
        raise ValueError(f"branch voltages need the steady or averaged tier, got {type(tier).__name__}.")

    return _ratio(gyro, settled.state.loops, temps), settled


@jit  # one program, not one per operation, when called outside a traced one
def _ratio(gyro, loops, temps):
    def one(loops_i, temp):
        g = at_temperature(gyro, temp)
        return branch_amplitudes(g, loops_i, g.temperature(0.0))

    v_plus, v_minus = jax.vmap(one)(loops, temps)
    return v_plus / v_minus


@jit
def _lot_branch_ratio(lot, rates, temperatures, times, tier):
    r, t = per_run(rates, temperatures), per_run(times, temperatures)

    def device(g, temps):
        return jax.vmap(lambda x, tt, tm: branch_ratio_points(g, x, tt, tm, tier))(r, temps, t)

    return eqx.filter_vmap(device)(lot, temperatures)


class BranchRatio(AbstractSweep):
    """The ratio V_f+ / V_f- of the push-pull feedback branches' carrier amplitudes at rate-table points
    (closed loop). The rate table's timing; no turn-on bias reaches a lock-in ratio; noise sqrt(2)
    `BRANCH_SIGMA_PPM` of the ratio, independent per point.

    **Arguments:**

    - `rates_dps`: the table rates read by the lock-in, deg/s, in order.
    """

    rates_dps: tuple = points_field(BRANCH_RATES_DPS, "table rates (deg/s)")

    name = "branch_ratio"
    stream: ClassVar[int] = 8
    title = "branch-ratio"
    input_quantity = "table rate"
    input_unit = "deg/s"
    output_unit = "V/V"
    input_meaning = "the table rate, deg/s (a rate-table point of a closed-loop device)"
    output_meaning = ("the ratio V_f+ / V_f- of the two push-pull feedback branches' AC amplitudes at the drive "
                      "carrier, V/V (a two-channel lock-in in ratio mode; 1 for matched branches)")
    biased = False
    straight_line = True
    rate_input = True
    sign_definite = False  # the ratio's change with the rate is a small effect of either sign

    def applicable_metrics(self) -> tuple[str, ...]:
        return ("bias",)  # the ratio at zero rate: the branches' mismatch

    def metric_not_applicable(self, metric: str) -> str:
        return ("not a measurement on a branch_ratio sweep: the ratio is 1 at every rate for matched branches and "
                "changes with the rate only by small effects (fitted by identify and diagnose); its bias, the "
                "ratio at zero rate, is the branches' mismatch")

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        return np.asarray(self.rates_dps)

    def n_points(self) -> int:
        return len(self.rates_dps)

    def check_device(self, gyro: Gyroscope) -> None:
        if not gyro.closed_loop:
            raise ValueError(f"a branch_ratio sweep needs a closed-loop device (push-pull feedback combs); "
                             f"{gyro.name!r} is open loop.")

    def predict(self, gyro: Gyroscope, inputs: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                times: Float[ArrayLike, " point"] | None, tier: AbstractTier = Steady()
                ) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        ratio, settled = branch_ratio_points(gyro, inputs, temperatures, times, tier)
        return ratio, (settled.result != RESULTS.successful) | ~jnp.isfinite(ratio)

    def relative_sigma(self, protocol: Protocol) -> float:
        return float(np.sqrt(2.0) * BRANCH_SIGMA_PPM * 1e-6)

    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        inputs = campaign.applied(self, campaign.protocol.inputs(self))
        temps, times, full = campaign.temperatures(self), campaign.times(self), campaign.shape(self)
        ratio, settled = _lot_branch_ratio(lot, jnp.asarray(inputs), jnp.asarray(temps), jnp.asarray(times),
                                           campaign.tier)
        raise_unsettled(settled.result, self.title)
        out = np.asarray(ratio, dtype=float)
        if campaign.noise_free:
            sigma = np.zeros(full)
        else:
            sigma = np.sqrt(2.0) * BRANCH_SIGMA_PPM * 1e-6 * np.abs(out)
            out = out + sigma * campaign.rng(self).standard_normal(full)
        return {"input": np.broadcast_to(inputs, full), "output": out, "output_sigma": sigma,
                "n_samples": np.full(full, float(campaign.protocol.n_samples(self))), "temperature_c": temps,
                "drive_freq_hz": np.asarray(settled.frequency, dtype=float) / (2.0 * np.pi),
                "time_s": np.broadcast_to(times, full)}
