r"""The two push-pull feedback branches' AC voltages read apart during a rate table. Reveals
`pushpull_mismatch`.

**Protocol.** During rate-table points (closed loop), a two-channel lock-in referenced to the drive carrier
reads the carrier-fundamental amplitude of each feedback branch's AC voltage, V_f+ and V_f- (seed 000 Fig. 5:
the amplifier output V_fa and its inverted copy, each AC-coupled onto V_dc), through one instrument and the
same cable length.

**Model.** The rebalance word W (complex: rate and quadrature) is modulated on the carrier, converted by the
DAC (hold gain, INL) and amplified (K_a, then the device's feedback terms); the branches are

    v+ = v (1 + e+),   v- = v (1 + e-),   v = K_a DAC(W),

(`FTRExcitation.branch_voltages`). The reading is |V+-|, the fundamental of each over the carrier phase, in V.
The word itself is the settled word of the rate point, so every rate-path effect reaches the reading too.

**Why it sees the effect apart from the baseline.** On rate-table, VCF and DAC sweeps only the common part
(e+ + e-)/2 acts (a K_vf change) and the differential part is second order. The ratio V+ / V- =
(1 + e+) / (1 + e-) is 1 in the baseline whatever K_vf, the DAC gain or the word: neither a free `k_vf`, a free
`dac_gain_error` nor a free gain of the voltmeter (common to both channels) makes the branches differ. At the
typical e+ = +2e-3, e- = -1e-3 the ratio is 3000 ppm off, ~300 sigma of a 10 ppm ratio per point. The common
part is seen only as well as the instrument's absolute gain and K_a are known (0.1 %-class): it stays a K_vf
change, as on the standard sweeps.

What the voltmeter cannot see: the share of a branch's gain error that sits in its comb (finger area) rather
than in its amplifier acts on the force, not on the voltage. The model (like the effect) places the whole
error in the voltage; a comb-area mismatch would need the branch forces apart (e.g. driving one branch at a
time against a rate, a sweep the presets' single rebalance DAC cannot make).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._gyroscope import Gyroscope
from .._simulate._model import SlowState, controls, dac_voltage, expj, phase_grid
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._stimulus import Stimulus
from .._sweeps.base import at_temperature
from .._units import DEG


RATES_DPS = (-200.0, -100.0, -50.0, 50.0, 100.0, 200.0)
"""deg/s, rate-table points read by the lock-in, ASSUMPTION: seed 000's rates from 50 deg/s up, where the
feedback voltage (0.4-1.6 V at 13,710 LSB/(deg/s)) is far above the quadrature's share (10 deg/s)."""

BRANCH_SIGMA_PPM = 10.0
"""Relative standard uncertainty of each branch amplitude, ASSUMPTION: a lock-in's two channels (or one
channel switched between the branches) at a few kHz, averaged over the rate table's 2-min dwell: the gain
ratio of the two inputs is stable to ~10 ppm; the common gain (absolute accuracy ~0.1 %) is left free."""


class BranchVoltageSettings(eqx.Module):
    """The points of a branch-voltage reading: `rates_dps` (table rate of each point, deg/s) and `temperature_c`
    (die temperature of each point, deg C; NaN: the device's own at power-on)."""

    rates_dps: Float[Array, " point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                  default=RATES_DPS)
    temperature_c: Float[Array, "*#point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                       default=np.nan)


class BranchVoltageReading(eqx.Module):
    """What a branch-voltage reading gives per point: `v_plus`, `v_minus` (carrier-fundamental amplitude of
    each branch's AC voltage, V) and `rate_lsb` (the rate output); `settled`: the tier's solution."""

    v_plus: Float[Array, " point"]
    v_minus: Float[Array, " point"]
    rate_lsb: Float[Array, " point"]
    settled: Settled


def _branch_amplitudes(gyro: Gyroscope, loops, temperature):
    gyro = gyro.at_die_temperature(temperature)
    ctl = controls(gyro, loops)
    theta = phase_grid(max(gyro.phase_points, 64))
    v_plus, v_minus = gyro.feedback_voltages(dac_voltage(gyro, ctl.word, theta, ctl.omega))

    def fundamental(v):
        return jnp.abs(2.0 * jnp.mean(v.astype(complex) * expj(-theta)))

    return fundamental(v_plus), fundamental(v_minus)


def predict(gyro: Gyroscope, settings: BranchVoltageSettings = BranchVoltageSettings(), *,
            tier: AbstractTier = Steady()) -> BranchVoltageReading:
    """The branch voltages of one closed-loop device at the settings' rate-table points.

    **Arguments:**

    - `gyro`: a closed-loop device (a single one; vmap for a lot).
    - `settings`: a `BranchVoltageSettings`.
    - `tier`: `Steady()` (default) or `Averaged()` (the loop states are read at the end of the window;
      the full waveform's carry a 2w ripple and are refused).

    **Returns:** a `BranchVoltageReading`.
    """
    if not gyro.closed_loop:
        raise ValueError(f"branch voltages need a closed-loop device (push-pull feedback combs); {gyro.name!r} "
                         "is open loop.")
    rates = settings.rates_dps
    temps = jnp.broadcast_to(settings.temperature_c, rates.shape)

    def one(rate, temp):
        return at_temperature(gyro, temp), Stimulus(rate=rate * DEG)

    gyros, stimuli = jax.vmap(one)(rates, temps)
    settled = tier.settle_points(gyros, stimuli)
    if not isinstance(settled.state, SlowState):
        raise ValueError(f"branch voltages need the steady or averaged tier, got {type(tier).__name__}.")
    die = jax.vmap(lambda g: g.temperature(0.0))(gyros)
    v_plus, v_minus = jax.vmap(lambda g, loops, t: _branch_amplitudes(g, loops, t))(gyros, settled.state.loops, die)
    return BranchVoltageReading(v_plus, v_minus, settled.rate, settled)
