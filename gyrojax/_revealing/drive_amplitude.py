r"""Drive-amplitude (AGC set-point) sweep: the drive frequency and the drive pick-off amplitude read against
the set-point. Reveals `duffing_drive` and `agc_finite_gain`.

**Protocol.** At zero table rate the AGC set-point is stepped to s_k = rho_k s_0 (s_0 the device's nominal
set-point, `DriveLoop.amplitude_setpoint`); after the loops settle, the PLL frequency and the AGC's
demodulated pick-off amplitude |e_d| are averaged over a dwell. Both are registers of a digital drive loop
(seed 000 Fig. 8 runs PLL and AGC in the FPGA); no extra instrument is needed.

**Model.** The slow flow of the drive mode with a cubic stiffness (`Resonator.duffing_x`, per unit mass) and
the PLL holding the drive in phase with its velocity gives the backbone

    w^2 = w_x^2 + (3/4) duffing_x a^2,   i.e.   w = w_x (1 + (3/8) kappa a^2),   kappa = duffing_x / w_x^2,

and the AGC (V_d = kp err + z, z' = ki err - leak z, err = s - |e_d|) settles with err = V_d leak / (kp leak +
ki). The drive voltage the resonator needs is V_d = 2 w m g_x a / K_dx, proportional to a = |e_d| / |G_d|, so
the standing error is a fixed fraction of the set-point:

    |e_d| = s / (1 + beta),   beta = 2 w m g_x leak / (K_dx |G_d| (kp leak + ki)).

Readings, per point: `frequency_hz` (Hz) and `amplitude_lsb` (drive ADC LSB, |e_d| = |G_d(w)| |X|).

**Why it sees the effects apart from the baseline.** The baseline (linear drive spring, ideal AGC integrator)
predicts |e_d| = s exactly, whatever the device's gains: the AGC regulates the digital reading itself, so no
front-end or electrode gain can make a standing error; `agc_finite_gain` is the only source of one (on
paper-qmg a 14 ppm sag, on vcf-2018 550 ppm, at its typical size). The baseline's frequency is w_x at the die
temperature, the same at every set-point: a free w_x (`omega_x`) takes the mean, and the rho^2 shape of the
backbone is left (at typical size, 38 ppm x (rho^2 - 1) on paper-qmg, 500 ppm x (rho^2 - 1) on vcf-2018). At
the one nominal set-point of the standard sweeps both are a gain change and an `omega_x` shift.

The steady tier solves the full slow flow (both loops, the sense and the demodulators), not the closed forms
above; the full-waveform tier keeps the carrier (the 3w harmonic of the cubic spring, the 2w ripple of the
demodulators).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._gyroscope import Gyroscope
from .._simulate._model import SlowState, WaveState
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._stimulus import Stimulus
from .._sweeps.base import at_temperature


SETPOINT_RATIOS = (0.5, 0.625, 0.75, 0.875, 1.0, 1.125, 1.25)
"""AGC set-points relative to the nominal, ASSUMPTION: down to half the nominal amplitude (the scale factor and
the pick-off's signal halve; below that the drive-frequency reading loses its margin over the pick-off noise)
and up to 1.25x (comb-drive fingers keep a constant force per volt only while the stroke stays well inside
their overlap, typically designed with ~2x margin over the nominal stroke; the drive voltage rises in
proportion: 3 V on paper-qmg, within a 5 V DAC)."""

SETTLE_S = 1.0
"""s, ASSUMPTION: wait after each set-point step: 20 time constants of the presets' 20 Hz AGC and PLL."""

DWELL_S = 10.0
"""s, ASSUMPTION: averaging per set-point (the readings are registers of the drive loop; 10 s averages the
loops' noise far below the sigmas below)."""

FREQUENCY_SIGMA_PPM = 1.0
"""Relative standard uncertainty of an averaged drive-frequency reading, ASSUMPTION: set by the die temperature
during the sweep, not by the PLL: silicon's -30 ppm/K times a chamber holding the die within ~0.03 K over
the sweep's 77 s (4.6 mHz on paper-qmg, 1.8 mHz on vcf-2018)."""

AMPLITUDE_SIGMA_PPM = 1.0
"""Relative standard uncertainty of an averaged pick-off amplitude |e_d|, ASSUMPTION: the AGC regulates this
digital reading itself, so references and front-end gains drop out; what is left is the loop's own noise,
averaged over the dwell (a 24-bit ADC at ~4e6 LSB of signal)."""


class DriveAmplitudeSettings(eqx.Module):
    """The points of a drive-amplitude sweep.

    **Arguments:**

    - `setpoint_ratio`: AGC set-point of each point relative to the device's nominal (default
      `SETPOINT_RATIOS`).
    - `temperature_c`: die temperature of each point, deg C (NaN: the device's own at power-on).
    """

    setpoint_ratio: Float[Array, " point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                        default=SETPOINT_RATIOS)
    temperature_c: Float[Array, "*#point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                       default=np.nan)

    def __check_init__(self):
        r = self.setpoint_ratio
        if not isinstance(r, jax.core.Tracer) and (r.ndim < 1 or not bool(jnp.all(r > 0))):
            raise ValueError(f"DriveAmplitudeSettings.setpoint_ratio must be a 1-d array of positive ratios, got "
                             f"{np.asarray(r).tolist()}.")


class DriveAmplitudeReading(eqx.Module):
    """What a drive-amplitude sweep reads, per point: `frequency_hz` (PLL frequency, Hz) and `amplitude_lsb`
    (the AGC's demodulated pick-off amplitude, drive ADC LSB); `settled`: the tier's solution."""

    frequency_hz: Float[Array, " point"]
    amplitude_lsb: Float[Array, " point"]
    settled: Settled

    def sigma(self):
        """Standard uncertainty of each reading, in its unit: `(frequency_hz, amplitude_lsb)`."""
        return (FREQUENCY_SIGMA_PPM * 1e-6 * jnp.abs(self.frequency_hz),
                AMPLITUDE_SIGMA_PPM * 1e-6 * jnp.abs(self.amplitude_lsb))


def with_setpoint(gyro: Gyroscope, ratio) -> Gyroscope:
    """`gyro` with its AGC set-point scaled by `ratio` (the drive amplitude follows; nothing else moves)."""
    return eqx.tree_at(lambda g: g.drive_loop.amplitude_setpoint, gyro,
                       gyro.drive_loop.amplitude_setpoint * jnp.asarray(ratio, dtype=float))


def drive_amplitude(gyro: Gyroscope, state, frequency):
    """Drive displacement amplitude |X| (m) of a settled state of any tier (for the full waveform, from the
    displacement and velocity at the end of the window)."""
    if isinstance(state, WaveState):
        return jnp.hypot(state.drive[..., 0], state.drive[..., 1] / frequency)
    if isinstance(state, SlowState):
        return jnp.hypot(state.drive[..., 0], state.drive[..., 1])
    raise ValueError(f"drive_amplitude: expected a SlowState or WaveState, got {type(state).__name__}.")


def predict(gyro: Gyroscope, settings: DriveAmplitudeSettings = DriveAmplitudeSettings(), *,
            tier: AbstractTier = Steady()) -> DriveAmplitudeReading:
    """The drive-amplitude sweep of one device at zero rate.

    **Arguments:**

    - `gyro`: the device (a single one; vmap for a lot).
    - `settings`: a `DriveAmplitudeSettings`.
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.

    **Returns:** a `DriveAmplitudeReading`.
    """
    ratio = settings.setpoint_ratio
    temps = jnp.broadcast_to(settings.temperature_c, ratio.shape)

    def one(r, t):
        return with_setpoint(at_temperature(gyro, t), r), Stimulus(rate=0.0 * r)

    settled = tier.settle_points(*jax.vmap(one)(ratio, temps))
    a = drive_amplitude(gyro, settled.state, settled.frequency)
    gain = jnp.abs(gyro.drive_frontend.phasor_gain(settled.frequency))
    return DriveAmplitudeReading(settled.frequency / (2.0 * jnp.pi), gain * a, settled)


def setpoint_lsb(gyro: Gyroscope, settings: DriveAmplitudeSettings = DriveAmplitudeSettings()):
    """The set-point of each point, LSB: what the baseline (ideal AGC) predicts for `amplitude_lsb`."""
    return gyro.drive_loop.amplitude_setpoint * settings.setpoint_ratio
