"""The timing of a measurement run: order of the points, warm-up, dwell, chamber plateaus (seed 000 §5, seed 003 §3).

A `Protocol` holds what every sweep kind of a campaign shares: the timing of a run (warm-up, dwell per settled
point, sampling rate), the order its points are applied in, the die's warm-up after power-on (`RunWarmup`) and
a temperature chamber's plateaus. What a sweep applies (the table rates, the VCF voltages, the set-points ...)
is the sweep kind's own (its fields, `gyrojax.AbstractSweep`); a kind says which of the protocol's timings it
reads (`AbstractSweep.dwell_s`, `sample_rate_hz`). `gyrojax.simulate_table` runs them.
"""

import math
from typing import ClassVar, Protocol as _Structural

import equinox as eqx
import numpy as np

from .._checks import check_nonnegative, check_positive
from .._gyroscope import Gyroscope
from .._physics.thermal import AbstractTemperature, PlateauTemperature, WarmupTemperature


RATE_TABLE_WARMUP_S = 60.0
"""s, seed 000 §5: "after powering the gyroscope and allowing a 1 min warm-up"."""

RATE_TABLE_DWELL_S = 120.0
"""s, seed 000 §5: "data were collected continuously for 2 min" per rate."""

RATE_TABLE_SAMPLE_RATE_HZ = 100.0
"""Hz, seed 000 §5: "at a sampling rate of 100 Hz"."""


class Scheduled(_Structural):
    """What the protocol reads of a sweep kind to schedule its points (every `gyrojax.AbstractSweep` has it)."""

    timed: ClassVar[bool]
    stream: ClassVar[int]

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray: ...

    def n_points(self) -> int: ...

    def dwell_s(self, protocol: "Protocol") -> float: ...

    def sample_rate_hz(self, protocol: "Protocol") -> float: ...


ORDERS = ("listed", "reversed", "alternating", "shuffled")
"""The orders a sweep's points can be applied in (`Protocol.order`)."""

ORDER_STREAM = 7919  # a random stream of its own for shuffled orders, apart from the noise streams

WARMUP_RISE_K = 2.0
"""K, ASSUMPTION: die self-heating after power-on ("a couple of kelvin"; neither seed gives a figure)."""

WARMUP_TIME_CONSTANT_S = 120.0
"""s, ASSUMPTION: self-heating time constant of a run that starts with the fixture already warm (settled
within the first few points)."""

FIRST_RUN_TIME_CONSTANT_S = 600.0
"""s, ASSUMPTION: the first run of a session stabilises slower (fixture and table warm from cold too):
seed 000 §5, "due to the longer time required for temperature stabilization during the first set of
repeated experiments ... discrepancies were observed between the first set and the subsequent second and
third sets"."""


CHAMBER_PLATEAUS_C = (10.0, 25.0, 40.0)
"""deg C, ASSUMPTION: a plateau run's chamber temperatures (`Protocol.chamber_plateaus_c`), three plateaus 15 K
apart around room temperature. Three (not two) so that a linear temperature coefficient is checked on a third
point; a +/-15 K span keeps inside the range where the library's linear coefficients hold (silicon's TCF is
linear to a few percent over +/-15 K) and gives the effects' typical sizes 300 ppm (`vref_drift`), 45 ppm
(`thermal_drift`) and 0.015 deg/s (`zro_tempco`) of swing."""

PACKAGE_TIME_CONSTANT_S = 300.0
"""s, ASSUMPTION: die-to-chamber thermal time constant of a ceramic LCC-packaged MEMS gyroscope on a fixture
(minutes: the fixture's and package's heat capacity through convection in the chamber)."""

PLATEAU_SOAK_S = 1800.0
"""s, ASSUMPTION: soak per chamber plateau, six package time constants: the die within 0.25 % of the step
(0.04 K of 15 K) before the plateau's first point."""


def _optional_float_tuple(values):
    return None if values is None else tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


class RunWarmup(eqx.Module):
    """The die temperature of each run after power-on: a first-order warm-up from the device's own
    temperature at power-on,

        T_r(t) = T_device(0) + rise_r (1 - exp(-t / tau_r)),

    with the first run (run index 0) slower than the others (seed 000 §5).

    **Arguments:**

    - `rise_k`, `time_constant_s`: rise (K) and time constant (s) of runs 1, 2, ...
    - `first_rise_k`, `first_time_constant_s`: the same for run 0.
    """

    rise_k: float = WARMUP_RISE_K
    time_constant_s: float = WARMUP_TIME_CONSTANT_S
    first_rise_k: float = WARMUP_RISE_K
    first_time_constant_s: float = FIRST_RUN_TIME_CONSTANT_S

    def __check_init__(self):
        for name in ("rise_k", "first_rise_k"):
            value = getattr(self, name)
            if not math.isfinite(float(value)):
                raise ValueError(f"RunWarmup.{name} must be finite, got {value!r}.")
        check_positive("RunWarmup", "time_constant_s", self.time_constant_s)
        check_positive("RunWarmup", "first_time_constant_s", self.first_time_constant_s)

    def history(self, gyro: Gyroscope, run: int) -> WarmupTemperature:
        """Temperature history (deg C vs s since power-on) of run `run` of `gyro` (a single device)."""
        first = run == 0
        return WarmupTemperature(
            ambient=float(np.asarray(gyro.temperature(0.0))),
            rise=float(self.first_rise_k if first else self.rise_k),
            time_constant=float(self.first_time_constant_s if first else self.time_constant_s))


class Protocol(eqx.Module):
    """The timing of each run of a campaign: warm-up, dwell, order of the points, the die's warm-up and a
    chamber's plateaus. What each sweep applies is the sweep kind's own (its fields: `RateTable.rates_dps`,
    `VcfStatic.virtual_rates_dps`, ...).

    Every (run, sweep) is its own power-on session (seed 003 Fig. 3 uses separate set-ups for the rate table
    and the virtual rate table): a warm-up of `warmup_s`, then the points back to back, each averaged over
    its dwell. A point's `temperature_c` is the die temperature at the middle of its dwell.

    **Arguments:**

    - `warmup_s`: time from power-on to the first point, s.
    - `dwell_s`, `sample_rate_hz`: averaging time and sampling rate of a settled point (the rate table, the
      static VCF sweep and every kind that reads the rate output's dwell; a kind with its own, such as the
      dynamic VCF test's lock-in, says so in its fields).
    - `warmup`: the die's warm-up per run (`RunWarmup`), or None to use the device's own `temperature`
      history for every run.
    - `chamber_plateaus_c`: a plateau run, or None (default). Given (deg C, e.g. `CHAMBER_PLATEAUS_C`), each
      run of a timed sweep kind takes its listed points once per chamber plateau within the one power-on
      (one turn-on bias): the chamber steps to plateau k, the die soaks for `plateau_soak_s`, then the
      points follow back to back. The die temperature is `PlateauTemperature`: the chamber through a
      first-order lag of `package_time_constant_s`, starting soaked at the first plateau, plus the run's
      self-heating (`warmup`; none when it is None). A bench measurement without a time axis (the DAC sweep)
      is unaffected.
    - `plateau_soak_s`, `package_time_constant_s`: see `PLATEAU_SOAK_S`, `PACKAGE_TIME_CONSTANT_S`.
    - `order`: the order the points of a timed sweep are applied in, per run (`ORDERS`): `"listed"`
      (default: as the kind lists them, ascending for the default lists), `"reversed"`, `"alternating"`
      (listed in even runs, reversed in odd ones: up-down) or `"shuffled"` (a random order per run, drawn
      from the campaign's seed and the kind's `stream`). A sweep applied in one direction only ties its input
      to time and temperature within a run: drift then looks like a shape in the input. A sweep without a
      time axis is always applied as listed.

    Defaults: seed 000 §5 (1 min warm-up, 2 min per point at 100 Hz). See the module's constants for each
    number's source.
    """

    warmup_s: float = RATE_TABLE_WARMUP_S
    dwell_s: float = RATE_TABLE_DWELL_S
    sample_rate_hz: float = RATE_TABLE_SAMPLE_RATE_HZ
    warmup: RunWarmup | None = RunWarmup()
    chamber_plateaus_c: tuple | None = eqx.field(converter=_optional_float_tuple, default=None)
    plateau_soak_s: float = PLATEAU_SOAK_S
    package_time_constant_s: float = PACKAGE_TIME_CONSTANT_S
    order: str = eqx.field(static=True, default="listed")

    def __check_init__(self):
        check_nonnegative("Protocol", "warmup_s", self.warmup_s)
        for name in ("dwell_s", "sample_rate_hz"):
            check_positive("Protocol", name, getattr(self, name))
        if round(self.dwell_s * self.sample_rate_hz) < 1:
            raise ValueError(f"Protocol: dwell_s x sample_rate_hz = {self.dwell_s * self.sample_rate_hz:g} gives no "
                             "sample per point.")
        if self.chamber_plateaus_c is not None:
            plateaus = np.asarray(self.chamber_plateaus_c)
            if plateaus.size < 2 or not np.all(np.isfinite(plateaus)):
                raise ValueError("Protocol.chamber_plateaus_c must hold at least 2 finite chamber temperatures "
                                 f"(deg C), got {plateaus.tolist()}.")
        check_positive("Protocol", "plateau_soak_s", self.plateau_soak_s)
        check_positive("Protocol", "package_time_constant_s", self.package_time_constant_s)
        if self.order not in ORDERS:
            raise ValueError(f"Protocol.order must be one of {', '.join(ORDERS)}, got {self.order!r}.")
        if self.warmup is not None and not isinstance(self.warmup, RunWarmup):
            raise ValueError(f"Protocol.warmup must be a RunWarmup or None, got {self.warmup!r}.")

    def plateaus(self, sweep: Scheduled) -> int:
        """How many times `sweep`'s listed points are applied per run: the number of chamber plateaus for a
        timed kind in a plateau run, else 1."""
        return len(self.chamber_plateaus_c) if self.chamber_plateaus_c and sweep.timed else 1

    def inputs(self, sweep: Scheduled, gyro: Gyroscope | None = None) -> np.ndarray:
        """The `input` column of a sweep kind, listed (`AbstractSweep.inputs`; in a plateau run, the listed points
        once per plateau); the nominal single device `gyro` where the kind sets its inputs from design values."""
        return np.tile(sweep.inputs(gyro), self.plateaus(sweep))

    def n_points(self, sweep: Scheduled) -> int:
        """Number of points of a sweep kind per run (all plateaus of a plateau run)."""
        return sweep.n_points() * self.plateaus(sweep)

    def dwell(self, sweep: Scheduled) -> float:
        """Averaging time of one point of `sweep`, s."""
        return sweep.dwell_s(self)

    def n_samples(self, sweep: Scheduled) -> int:
        """Samples averaged per point of `sweep`."""
        return int(round(sweep.dwell_s(self) * sweep.sample_rate_hz(self)))

    def point_order(self, sweep: Scheduled, runs: int, seed: int = 0) -> np.ndarray:
        """Indices into `inputs(sweep)` of the points in the order applied, shape (runs, points); `seed` draws
        the `"shuffled"` orders (each run and sweep kind its own). A sweep without a time axis (`timed`
        false: the DAC sweep) is always applied as listed; in a plateau run the order applies within each
        plateau."""
        kind = sweep
        n = kind.n_points()
        listed = np.arange(n)
        rows = []
        for r in range(runs):
            if self.order == "listed" or not kind.timed:
                row = [listed] * self.plateaus(kind)
            elif self.order == "reversed" or (self.order == "alternating" and r % 2 == 1):
                row = [listed[::-1]] * self.plateaus(kind)
            elif self.order == "alternating":
                row = [listed] * self.plateaus(kind)
            else:
                rng = np.random.default_rng([int(seed) % 2**63, ORDER_STREAM, kind.stream, r])
                row = [rng.permutation(n) for _ in range(self.plateaus(kind))]
            rows.append(np.concatenate([k * n + block for k, block in enumerate(row)]))
        return np.stack(rows)

    def plateau_starts(self, sweep: Scheduled) -> np.ndarray:
        """Time since power-on at which the chamber steps to each plateau, s (a plateau run): plateau k
        starts at warmup + k (soak + points x dwell), its soak first."""
        block = self.plateau_soak_s + sweep.n_points() * self.dwell(sweep)
        return self.warmup_s + np.arange(self.plateaus(sweep)) * block

    def point_times(self, sweep: Scheduled) -> np.ndarray:
        """Time since power-on of the middle of each point's dwell, s: warmup + (i + 1/2) dwell, or in a
        plateau run the plateau's start + soak + (i + 1/2) dwell."""
        if self.plateaus(sweep) == 1:
            n = self.n_points(sweep)
            return self.warmup_s + (np.arange(n) + 0.5) * self.dwell(sweep)
        n = sweep.n_points()
        within = self.plateau_soak_s + (np.arange(n) + 0.5) * self.dwell(sweep)
        return np.ravel(self.plateau_starts(sweep)[:, None] + within[None, :])

    def run_history(self, gyro: Gyroscope, run: int, sweep: Scheduled | None = None) -> AbstractTemperature:
        """The die-temperature history of run `run` (the device's own when `warmup` is None; in a plateau run,
        the chamber's `PlateauTemperature` for `sweep`'s schedule)."""
        plateaus = self.chamber_plateaus_c
        if sweep is not None and plateaus is not None and self.plateaus(sweep) > 1:
            heating = (WarmupTemperature(rise=0.0) if self.warmup is None
                       else self.warmup.history(gyro, run))
            return PlateauTemperature(
                plateaus_c=plateaus, starts_s=self.plateau_starts(sweep),
                initial_c=plateaus[0], package_time_constant_s=self.package_time_constant_s,
                rise_k=heating.rise, heating_time_constant_s=heating.time_constant)
        return gyro.temperature if self.warmup is None else self.warmup.history(gyro, run)

    def temperatures(self, gyro: Gyroscope, runs: int, sweep: Scheduled) -> np.ndarray:
        """Die temperature (deg C) at the middle of each point's dwell, shape (runs, points)."""
        t = self.point_times(sweep)
        return np.stack([np.broadcast_to(np.asarray(self.run_history(gyro, r, sweep)(t), dtype=float), t.shape)
                         for r in range(runs)])
