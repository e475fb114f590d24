r"""AGC set-point sweeps: the drive amplitude stepped at zero table rate, the drive loop's registers and the
rate output read at each set-point.

**Protocol.** At zero table rate the AGC set-point is stepped to s_k = rho_k s_0 (s_0 the device's nominal
set-point, `DriveLoop.amplitude_setpoint`; the ratios are the kind's `setpoint_ratios`); after the loops settle,
a reading is averaged over the point's dwell. Three readings are taken per set-point, each its own sweep kind
so that a row of the data format is one settled reading with one unit: the PLL frequency (`drive_frequency`,
Hz), the AGC's demodulated pick-off amplitude |e_d| (`drive_amplitude`, drive ADC LSB) and the rate output
(`setpoint_zero_rate`, LSB). The first two are registers of a digital drive loop (seed 000 Fig. 8 runs PLL and
AGC in the FPGA); no extra instrument is needed.

**Model.** The slow flow of the drive mode with a cubic stiffness (`Resonator.duffing_x`, per unit mass) and
the PLL holding the drive in phase with its velocity gives the backbone

    w^2 = w_x^2 + (3/4) duffing_x a^2,   i.e.   w = w_x (1 + (3/8) kappa a^2),   kappa = duffing_x / w_x^2,

and the AGC (V_d = kp err + z, z' = ki err - leak z, err = s - |e_d|) settles with err = V_d leak / (kp leak +
ki). The drive voltage the resonator needs is V_d = 2 w m g_x a / K_dx, proportional to a = |e_d| / |G_d|, so
the standing error is a fixed fraction of the set-point:

    |e_d| = s / (1 + beta),   beta = 2 w m g_x leak / (K_dx |G_d| (kp leak + ki)).

The steady tier solves the full slow flow (both loops, the sense and the demodulators), not these closed forms;
the full-waveform tier keeps the carrier (the cubic spring's 3w harmonic, the demodulators' 2w ripple).
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._gyroscope import Gyroscope
from .._physics.stimulus import Stimulus
from .._simulate._model import SlowState, WaveState
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._solution import RESULTS
from .base import AbstractSweep, points_field
from .lot_campaign import LotCampaign
from .steady import AbstractSettledSweep, lot_steady, raise_unsettled, read_out, settled_points


SETPOINT_RATIOS = (0.5, 0.625, 0.75, 0.875, 1.0, 1.125, 1.25)
"""AGC set-points relative to the nominal, ASSUMPTION: down to half the nominal amplitude (the scale factor and
the pick-off's signal halve; below that the drive-frequency reading loses its margin over the pick-off noise)
and up to 1.25x (comb-drive fingers keep a constant force per volt only while the stroke stays well inside
their overlap, typically designed with ~2x margin over the nominal stroke; the drive voltage rises in
proportion: 3 V on paper-qmg, within a 5 V DAC)."""

DRIVE_REGISTER_DWELL_S = 10.0
"""s, ASSUMPTION: averaging per set-point of the drive loop's registers (frequency, pick-off amplitude); 10 s
averages the loops' noise far below their reading uncertainties (`FREQUENCY_SIGMA_PPM`,
`AMPLITUDE_SIGMA_PPM`). The loops settle within 1 s of a step (20 time constants of the presets' 20 Hz AGC
and PLL), inside the first tenth of the dwell."""


class SetpointReading(eqx.Module):
    """What one settled set-point gives: `frequency_hz` (PLL frequency, Hz), `amplitude_lsb` (the AGC's
    demodulated pick-off amplitude, drive ADC LSB), `rate_lsb` (the rate output through the device's readout
    terms, LSB) and `settled` (the tier's solution)."""

    frequency_hz: jax.Array
    amplitude_lsb: jax.Array
    rate_lsb: jax.Array
    settled: Settled

    @property
    def result(self) -> RESULTS:
        """The tier's result per point (`settled.result`)."""
        return self.settled.result


def with_setpoint(gyro: Gyroscope, setpoint_lsb) -> Gyroscope:
    """`gyro` with its AGC set-point at `setpoint_lsb` (drive ADC LSB; the drive amplitude follows)."""
    return eqx.tree_at(lambda g: g.drive_loop.amplitude_setpoint, gyro, jnp.asarray(setpoint_lsb, dtype=float))


def displacement_amplitude(state, frequency):
    """Drive displacement amplitude |X| (m) of a settled state of any tier (for the full waveform, from the
    displacement and velocity at the end of the window; `frequency` in rad/s)."""
    if isinstance(state, WaveState):
        return jnp.hypot(state.drive[..., 0], state.drive[..., 1] / frequency)
    if isinstance(state, SlowState):
        return jnp.hypot(state.drive[..., 0], state.drive[..., 1])
    raise ValueError(f"displacement_amplitude: expected a SlowState or WaveState, got {type(state).__name__}.")


def setpoint_points(gyro: Gyroscope, sweep: AbstractSweep, setpoints_lsb: Float[ArrayLike, " point"],
                    temperatures: Float[ArrayLike, " point"], times: Float[ArrayLike, " point"] | None = None,
                    tier: AbstractTier = Steady()) -> SetpointReading:
    """The settled set-points of one device at zero table rate (`steady_points` settles them with other
    sweeps' points in one call).

    **Arguments:**

    - `gyro`: the device (a single one; vmap for a lot).
    - `sweep`: the set-point sweep kind read (an `AbstractSetpointSweep`; its name reaches the device's readout
      terms).
    - `setpoints_lsb`: the AGC set-point of each point, drive ADC LSB (1-d).
    - `temperatures`: die temperature of each point, deg C (NaN: the device's own at power-on).
    - `times`: time since power-on of each point, s (None or NaN: 0).
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.

    **Returns:** a `SetpointReading`.
    """
    if not isinstance(sweep, AbstractSetpointSweep):
        raise ValueError(f"setpoint_points: {sweep!r} is not a set-point sweep (an AbstractSetpointSweep).")
    return settled_points(gyro, [(sweep, setpoints_lsb, temperatures, times)], tier)[0]


class AbstractSetpointSweep(AbstractSettledSweep):
    """A sweep of the AGC set-point at zero table rate, one reading of the settled loops per point (see the
    module's docstring). Inputs: the set-point in drive ADC LSB, `setpoint_ratios` times the nominal device's
    set-point. A kind says which reading it takes (`reading`), its dwell and its noise. Its points settle in
    one call with the device's other settled sweeps (`steady_points`), from a chord Jacobian of their own.

    **Arguments:**

    - `setpoint_ratios`: the AGC set-points relative to the nominal device's, in order (> 0).
    """

    setpoint_ratios: tuple = points_field(SETPOINT_RATIOS, "set-point ratios")

    input_quantity = "AGC set-point"
    input_unit = "LSB"
    straight_line = True

    @abc.abstractmethod
    def reading(self, points: SetpointReading) -> Float[Array, " point"]:
        """The reading this kind takes from the settled points."""

    @abc.abstractmethod
    def add_noise(self, out: np.ndarray, campaign: LotCampaign) -> tuple[np.ndarray, np.ndarray]:
        """The noisy readings and their standard uncertainties, both shaped like `out` (device, run, point)."""

    def __check_init__(self):
        if not all(r > 0 for r in self.setpoint_ratios):
            raise ValueError(f"{type(self).__name__}.setpoint_ratios must be > 0, got {list(self.setpoint_ratios)}.")

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        if gyro is None:
            raise ValueError(f"{type(self).__name__}.inputs needs the device to turn setpoint_ratios into LSB; "
                             "pass gyro=.")
        nominal = float(np.asarray(gyro.drive_loop.amplitude_setpoint))
        return np.asarray([float(f"{r * nominal:.12g}") for r in self.setpoint_ratios])

    def n_points(self) -> int:
        return len(self.setpoint_ratios)

    def check_device(self, gyro: Gyroscope) -> None:
        if not float(np.asarray(gyro.drive_loop.amplitude_setpoint)) > 0:
            raise ValueError(f"a {self.name} sweep needs a positive AGC set-point; {gyro.name!r} has "
                             f"drive_loop.amplitude_setpoint = {gyro.drive_loop.amplitude_setpoint!r}.")

    def point(self, gyro: Gyroscope, value: Float[Array, " point"], time: Float[Array, " point"]
              ) -> tuple[Gyroscope, Stimulus]:
        return with_setpoint(gyro, value), Stimulus(rate=0.0 * value, time=time)

    def finish(self, gyro: Gyroscope, gyros: Gyroscope, settled: Settled, inputs: Float[Array, " point"],
               temperatures: Float[Array, " point"], times: Float[Array, " point"]) -> SetpointReading:
        a = displacement_amplitude(settled.state, settled.frequency)
        gain = jnp.abs(jax.vmap(lambda g, w: g.drive_frontend.phasor_gain(w))(gyros, settled.frequency))
        rate = read_out(gyro, settled, self, inputs, temperatures, times).rate
        return SetpointReading(settled.frequency / (2.0 * jnp.pi), gain * a, rate, settled)

    def read(self, points: SetpointReading) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        out = self.reading(points)
        return out, (points.settled.result != RESULTS.successful) | ~jnp.isfinite(out)

    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        inputs = campaign.applied(self, campaign.protocol.inputs(self, campaign.gyro))
        temps, times, full = campaign.temperatures(self), campaign.times(self), campaign.shape(self)
        points = campaign.settled.get(self.name)
        if points is None:
            points = lot_steady(lot, ((self, jnp.asarray(inputs), jnp.asarray(temps), jnp.asarray(times)),),
                                campaign.tier)[0]
            raise_unsettled(points.result, self.title)
        out = np.asarray(self.reading(points), dtype=float)
        if campaign.noise_free:
            sigma = np.zeros(full)
        else:
            out, sigma = self.add_noise(out, campaign)
        return {"input": np.broadcast_to(inputs, full), "output": out, "output_sigma": sigma,
                "n_samples": np.full(full, float(campaign.protocol.n_samples(self))), "temperature_c": temps,
                "drive_freq_hz": np.asarray(points.frequency_hz, dtype=float),
                "time_s": np.broadcast_to(times, full)}

