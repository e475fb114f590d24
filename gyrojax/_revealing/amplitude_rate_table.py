r"""A rate table at two drive amplitudes within one run: the stand-in for a mode reversal. Reveals
`damping_coupling` (with `quadrature_phase` confounded; the quadrature injection splits them).

**Why not a mode reversal.** Swapping the drive and sense roles flips the sign of the Coriolis term but not
that of the damping coupling c, so the two zero-rate outputs differ by c / Ag. Neither preset can do it:
paper-qmg (seed 000) has drive combs and an AGC/PLL on x only and the push-pull feedback combs, their DAC and
the sense tuning on y only, and its modes are 77 Hz apart as built (tuned to ~1 Hz from the y side); vcf-2018
(seed 003) is open loop with drive combs on x and a 62 Hz split. A reversal needs both loops' electrodes and
electronics on both axes and a tuning that can move either mode; `gyrojax.Gyroscope` has fixed roles (drive
on x, sense on y).

**Protocol instead.** Within one power-on run, a rate table at the nominal AGC set-point, then the same rates
at a second set-point (rho = 0.5): the drive amplitude halves, and so does the scale factor.

**Model.** The closed-loop output at table rate Om and set-point ratio rho is

    R = SF(rho) [Om + c / (2 Ag) + Om_q] + b_run,      SF(rho) = 2 Ag m (rho a) w / K_vf,

with Om_q = Q_0 sin(phi) / SF the rate-equivalent bias of a rate-channel phase error on the quadrature
(Q_0 / SF is set by the stiffness coupling, kap / (2 Ag w): it does not depend on a either) and b_run the
run's turn-on bias in LSB: an offset of the electronics, the same at both amplitudes within the run
(ASSUMPTION: it is an electronic offset, not a force that scales with the drive). Open loop the same holds
with SF ~ Ag a / |g_y - j d_y|. Reading, per point: `rate_lsb`.

**Why it sees the effect apart from the baseline.** A zero-rate output that is a force proportional to the
drive motion (c x', or quadrature read through phi) scales with a, like the scale factor, while b_run does
not: the intercepts at the two amplitudes differ by (SF(1) - SF(rho)) (c / (2 Ag) + Om_q). The baseline has
no such output (its zero-rate output is 0 at every amplitude); `k_vf` scales both slopes together and one
run bias takes one intercept. At the typical c = 2e-3 1/s (0.057 deg/s) and rho = 0.5 the intercepts differ
by 0.029 deg/s of the nominal scale factor, ~180 sigma of a 2-min point. c and phi leave the same fingerprint
here (both are a rate-equivalent bias that scales with the drive); the quadrature injection sees phi alone.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._gyroscope import Gyroscope
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._stimulus import Stimulus
from .._sweeps.base import at_temperature
from .._units import DEG
from .drive_amplitude import with_setpoint


RATES_DPS = (-200.0, -100.0, -20.0, 0.0, 20.0, 100.0, 200.0)
"""deg/s, ASSUMPTION: seven of seed 000's rates (and zero), the ends and the middle, at each amplitude."""

SECOND_SETPOINT_RATIO = 0.5
"""The second AGC set-point relative to the nominal, ASSUMPTION: the lowest of the drive-amplitude sweep
(`drive_amplitude.SETPOINT_RATIOS`); the intercept difference grows as 1 - rho."""

DWELL_S = 120.0
"""s, seed 000 §5: 2 min per rate."""


class AmplitudeRateTableSettings(eqx.Module):
    """The points of a two-amplitude rate table: `rates_dps` (deg/s), `setpoint_ratio` (AGC set-point relative
    to the nominal) and `temperature_c` (deg C; NaN: the device's own), one value per point (or broadcast).
    `default()` gives `RATES_DPS` at ratio 1 then at `SECOND_SETPOINT_RATIO`."""

    rates_dps: Float[Array, " point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    setpoint_ratio: Float[Array, " point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    temperature_c: Float[Array, "*#point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                       default=np.nan)

    @classmethod
    def default(cls, rates_dps=RATES_DPS, ratios=(1.0, SECOND_SETPOINT_RATIO)) -> "AmplitudeRateTableSettings":
        rates = np.tile(np.asarray(rates_dps, dtype=float), len(ratios))
        rho = np.repeat(np.asarray(ratios, dtype=float), len(rates_dps))
        return cls(rates, rho)


class AmplitudeRateTableReading(eqx.Module):
    """The rate output of each point, LSB (`rate_lsb`); `settled`: the tier's solution."""

    rate_lsb: Float[Array, " point"]
    settled: Settled


def predict(gyro: Gyroscope, settings: AmplitudeRateTableSettings, *,
            tier: AbstractTier = Steady()) -> AmplitudeRateTableReading:
    """The two-amplitude rate table of one device (noise-free, without the run's bias).

    **Arguments:**

    - `gyro`: the device (a single one; vmap for a lot).
    - `settings`: an `AmplitudeRateTableSettings`.
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.

    **Returns:** an `AmplitudeRateTableReading`.
    """
    rates = settings.rates_dps
    rho = jnp.broadcast_to(settings.setpoint_ratio, rates.shape)
    temps = jnp.broadcast_to(settings.temperature_c, rates.shape)

    def one(rate, r, temp):
        return with_setpoint(at_temperature(gyro, temp), r), Stimulus(rate=rate * DEG)

    settled = tier.settle_points(*jax.vmap(one)(rates, rho, temps))
    return AmplitudeRateTableReading(settled.rate, settled)
