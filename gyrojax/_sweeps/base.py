"""The sweep interface: one kind of experiment, from its protocol to its measurement model and its metrics."""

import abc
import dataclasses
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._gyroscope import Gyroscope
from .._lots.noise import RateNoise
from .._physics.thermal import ConstantTemperature
from .._simulate.tiers import AbstractTier
from .lot_campaign import LotCampaign
from .protocol import Protocol


LINE_METRICS = ("scale_factor", "bias", "nonlinearity", "asymmetry", "repeatability")
"""The metrics of a straight-line fit, as `AbstractSweep.applicable_metrics` names them."""


def float_tuple(values) -> tuple:
    """`values` (a number or a sequence) as a flat tuple of floats: a kind's listed points, hashable."""
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


def _optional_float_tuple(values):
    return None if values is None else float_tuple(values)


def points_field(default: tuple | None, what: str, *, optional: bool = False) -> Any:
    """A field of a sweep kind that lists its points (`what`: their quantity and unit, for messages), a tuple of
    floats; None allowed where `optional`. `AbstractSweep` checks that it holds at least 2 finite distinct
    values, and `run_settings` leaves it out (a run lists its inputs)."""
    return eqx.field(default=default, converter=_optional_float_tuple if optional else float_tuple,
                     metadata={"points": what, "run_setting": False})


def timing_field(default: float) -> Any:
    """A field of a sweep kind's own timing (a dwell, a sampling rate), > 0; reported by `run_settings` through
    `dwell_s`, not as itself."""
    return eqx.field(default=default, metadata={"timing": True, "run_setting": False})


class AbstractSweep(eqx.Module):
    """One kind of experiment: the `sweep` value of the tidy data format (docs/data_format.md).

    A sweep kind owns what the data format, the simulator, identification, the metrics, the planner and the
    plots need to know about it, so that a new experiment is one file (a final subclass) plus
    `gyrojax.sweeps.register_sweep`. Its fields are its settings: the points it applies (`points_field`: the table
    rates, the VCF voltages, the set-points ...), its own timing where it has one (`timing_field`) and the
    settings of its measurement model (the carrier of a virtual-Coriolis sweep), each with a default;
    `gyrojax.sweeps.sweep_kind(name)` gives the instance with the defaults. The run timing every kind shares (warm-up,
    dwell, order, chamber plateaus) is the `Protocol`'s.

    **Class attributes:**

    - `name`: the `sweep` value in files (the registry key).
    - `stream`: the number of the kind's random streams in `gyrojax.simulate_table` (its noise and a shuffled
      order), unique among the registered kinds: a kind's draws do not depend on which other kinds exist or
      are simulated with it.
    - `reads`: physical parameters (names of `gyrojax.PARAMETERS`) this kind determines that a baseline of the
      standard sweeps holds; a fit of data with runs of the kind frees them (`reads_on(gyro)`: those it
      determines on that device).
    - `title`: the kind in words, for messages ("rate-table").
    - `input_quantity`, `input_unit`: what the `input` column holds, e.g. "table rate", "deg/s" (plot labels
      and the scale factor's unit).
    - `output_unit`: the unit of the `output` column.
    - `input_meaning`, `output_meaning`: the data format's description of `input` and `output`.
    - `biased`: the output carries the run's turn-on bias (a free bias per run in a fit, noise that is
      constant over a run in the simulator).
    - `straight_line`: the metrics of a straight-line fit apply (scale factor, bias, nonlinearity, asymmetry,
      repeatability); otherwise the sweep gives a rate bandwidth.
    - `word_input`: `input` is a DAC word (a signed integer, or hex; written back as an integer).
    - `rate_input`: `input` is a rate in deg/s, so a run that looks converted to rad/s is refused.
    - `timed`: points follow one another in a power-on run (a time axis, a point order, a die temperature
      per point); False for a bench measurement.
    - `rate_output`: `output` is the gyro's rate channel (LSB): it scales with the gain of the rate path, and
      the diagnosis's generic gain shapes act on it.
    - `rate_noise`: the simulator's noise is rate noise (deg/s) converted to LSB with each device's
      rate-table scale factor.
    - `fit_against_rate`: the metrics also fit `output` against the `rate_dps` column when it is given.
    - `sign_definite`: the output's slope against the input has a sign that a convention sets (the rate
      table's direction, the output's polarity), not the device's small effects: identification refuses data
      whose slope runs clearly against the model's, and `metrics` and `compensate` refuse a run whose outputs
      do not change with the input (a dead output). False for a kind whose slope is an effect's to set (the
      drive frequency against the set-point: a cubic spring of either sign).

    **Metrics.** `applicable_metrics()` names the metrics of `gyrojax.metrics.metrics_report` that measure something on
    this kind, `metric_not_applicable(name)` says why another does not.
    """

    name: ClassVar[str]
    stream: ClassVar[int]
    title: ClassVar[str]
    input_quantity: ClassVar[str]
    input_unit: ClassVar[str]
    output_unit: ClassVar[str]
    input_meaning: ClassVar[str]
    output_meaning: ClassVar[str]
    biased: ClassVar[bool]
    straight_line: ClassVar[bool]
    word_input: ClassVar[bool] = False
    rate_input: ClassVar[bool] = False
    timed: ClassVar[bool] = True
    rate_output: ClassVar[bool] = False
    rate_noise: ClassVar[bool] = False
    fit_against_rate: ClassVar[bool] = False
    sign_definite: ClassVar[bool] = True
    reads: ClassVar[tuple[str, ...]] = ()

    def __check_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if "points" in f.metadata:
                if value is None:  # an optional list left out
                    continue
                values = np.asarray(value)
                if values.size < 2 or not np.all(np.isfinite(values)):
                    raise ValueError(f"{type(self).__name__}.{f.name} must hold at least 2 finite "
                                     f"{f.metadata['points']}, got {values.tolist()}.")
                if np.unique(values).size != values.size:
                    dup = sorted({v for v in values.tolist() if values.tolist().count(v) > 1})
                    raise ValueError(f"{type(self).__name__}.{f.name} repeats {dup}; each point is applied once "
                                     "(give repeats as more runs).")
            elif "timing" in f.metadata and not (float(value) > 0 and np.isfinite(float(value))):
                raise ValueError(f"{type(self).__name__}.{f.name} must be finite and > 0, got {value!r}.")

    @property
    def input_label(self) -> str:
        """Axis label of the input: quantity and unit."""
        return f"{self.input_quantity} ({self.input_unit})"

    @property
    def scale_factor_unit(self) -> str | None:
        """Output unit per input unit (None when the sweep has no straight-line fit)."""
        if not self.straight_line:
            return None
        unit = f"({self.input_unit})" if "/" in self.input_unit else self.input_unit
        out = f"({self.output_unit})" if "/" in self.output_unit else self.output_unit
        return f"{out}/{unit}"

    def applicable_metrics(self) -> tuple[str, ...]:
        """The metrics of `gyrojax.metrics.metrics_report` that are measurements on this kind, from `LINE_METRICS` and
        "bandwidth". Default: every straight-line metric for a straight-line kind, else the bandwidth."""
        return LINE_METRICS if self.straight_line else ("bandwidth",)

    def metric_not_applicable(self, metric: str) -> str:
        """Why `metric` (not in `applicable_metrics()`) is not a measurement on this kind, in words."""
        if not self.straight_line:
            return f"a {self.name} sweep gives a bandwidth, not a straight-line fit"
        if metric == "bandwidth":
            return f"a {self.name} sweep gives a straight-line fit, not a bandwidth"
        return (f"not a measurement on a {self.name} sweep: its output is not proportional to its input by design "
                "(the slope is a small effect, not a gain), so figures relative to the slope are noise")

    def reads_on(self, gyro: Gyroscope) -> tuple[str, ...]:
        """What of `reads` this kind determines on `gyro` (all of it, unless the kind says otherwise)."""
        return tuple(self.reads)

    # -- protocol ------------------------------------------------------------------------------------------------

    @abc.abstractmethod
    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        """The listed inputs of this sweep (its settings), in the data unit, in the order listed (the nominal
        single device `gyro` where the inputs are set from its design values)."""

    @abc.abstractmethod
    def n_points(self) -> int:
        """Number of listed points of this sweep (without a device)."""

    def dwell_s(self, protocol: Protocol) -> float:
        """Averaging time of one point, s. Default: the protocol's `dwell_s`."""
        return protocol.dwell_s

    def sample_rate_hz(self, protocol: Protocol) -> float:
        """Output sampling rate of one point, Hz. Default: the protocol's `sample_rate_hz`."""
        return protocol.sample_rate_hz

    @abc.abstractmethod
    def check_device(self, gyro: Gyroscope) -> None:
        """Raise a `ValueError` naming the device when this sweep cannot be measured on `gyro` (a single
        nominal device), before anything is simulated."""

    # -- measurement model ---------------------------------------------------------------------------------------

    @abc.abstractmethod
    def predict(self, gyro: Gyroscope, inputs: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                times: Float[ArrayLike, " point"] | None, tier: AbstractTier
                ) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        """The noise-free, bias-free outputs of one device at the points, and a flag of points the model could
        not evaluate (not settled, not finite).

        **Arguments:**

        - `gyro`: one device.
        - `inputs`, `temperatures`, `times`: 1-d arrays, one value per point: the `input` column, the die
          temperature (deg C; NaN: the device's own at power-on) and the time since power-on (s; NaN: 0).
        - `tier`: the simulation tier of settled points.

        **Returns:** `(outputs, bad)`, 1-d arrays like `inputs`.
        """

    # -- simulation ----------------------------------------------------------------------------------------------

    @abc.abstractmethod
    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        """This sweep of every device and run of `lot` (leaves with a leading device axis), with its noise.

        **Returns:** columns of shape (device, run, point): `input`, `output`, `output_sigma`, `n_samples`,
        `temperature_c` and `drive_freq_hz` (NaN where not given), and any other optional column the sweep
        records (`time_s`, `phase_deg`, `rate_dps`).
        """

    # -- planning ------------------------------------------------------------------------------------------------
    # What a measurement planner needs to propose one run of this kind; the defaults fit a timed sweep of rate
    # noise, and a kind overrides what differs.

    def run_inputs(self, gyro: Gyroscope) -> np.ndarray:
        """The `input` column of one run on the nominal single device `gyro`, as listed (what `predict`
        takes). Default: `inputs`."""
        return np.asarray(self.inputs(gyro), dtype=float)

    def run_minutes(self, protocol: Protocol) -> float:
        """Test time of one run under `protocol`, minutes. Default: the warm-up of a timed sweep plus one
        dwell per point."""
        warmup = protocol.warmup_s if self.timed else 0.0
        return (warmup + self.n_points() * self.dwell_s(protocol)) / 60.0

    def run_settings(self, protocol: Protocol) -> dict:
        """What one run applies besides its inputs, for people and JSON: the kind's own settings (its fields)
        and its timing. Default: every field but the listed points and the kind's own timing (`points_field`,
        `timing_field`), the dwell and, for a timed sweep, the warm-up."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.metadata.get("run_setting", True)}
        out["dwell_s"] = float(self.dwell_s(protocol))
        if self.timed:
            out["warmup_s"] = float(protocol.warmup_s)
        return out

    def point_sigmas(self, inputs: Float[ArrayLike, " point"], protocol: Protocol, noise: RateNoise, lsb_per_dps: float,
                     voltmeter_sigma_v: float) -> np.ndarray | None:
        """Standard uncertainty of each point of one run, in the output unit, as the simulator draws it.

        **Arguments:**

        - `inputs`: the run's `input` column (`run_inputs`).
        - `protocol`: timing.
        - `noise`: the rate output's noise model.
        - `lsb_per_dps`: the device's rate-table scale factor, LSB per deg/s.
        - `voltmeter_sigma_v`: the bench voltmeter's noise, V.

        **Returns:** a 1-d array like `inputs`, or None when this kind's noise is not rate noise and the kind
        does not say (a planner then takes the sigmas of this kind in the data, if any). Default: rate noise
        averaged over the dwell, for a kind with `rate_noise`.
        """
        if not self.rate_noise:
            return None
        sigma = noise.point_sigma_dps(self.dwell_s(protocol)) * abs(float(lsb_per_dps))
        return np.full(np.shape(inputs), sigma)

    def relative_sigma(self, protocol: Protocol) -> float | None:
        """Standard uncertainty of each point relative to its reading (a ratio, e.g. 1e-6 for 1 ppm), for a kind
        whose noise is a fraction of what it reads (`point_sigmas` gives None for it): a planner multiplies it
        by the predicted reading. Default None (not relative)."""
        return None


def at_temperature(gyro: Gyroscope, temperature: Float[ArrayLike, ""]) -> Gyroscope:
    """`gyro` held at `temperature` (deg C); NaN keeps the device's own temperature at power-on."""
    t = jnp.asarray(temperature, dtype=float)
    t = jnp.where(jnp.isnan(t), gyro.temperature(0.0), t)
    return eqx.tree_at(lambda g: g.temperature, gyro, ConstantTemperature(t))
