"""Experiment protocols: what is applied to a device, in which order, for how long (seed 000 §5, seed 003 §3).

A `Protocol` holds the inputs of each sweep kind (table rates, virtual-Coriolis voltages and modulation
frequencies), the timing of a run (warm-up, dwell per point, sampling rate) and the die's warm-up after
power-on (`RunWarmup`); each sweep kind says which of them it reads (`AbstractSweep.inputs`, `dwell_s`,
`sample_rate_hz`). `gyrojax.simulate_table` runs it.
"""

import math

import equinox as eqx
import numpy as np

from .._checks import check_nonnegative, check_positive
from .._gyroscope import Gyroscope
from .._physics.thermal import AbstractTemperature, PlateauTemperature, WarmupTemperature
from .._units import DEG
from .base import AbstractSweep
from .branch_voltages import BRANCH_RATES_DPS
from .quadrature_injection import INJECTED_QUADRATURE_DPS
from .rate_table import DING_ZHOU_2025_RATES_DPS, RATE_TABLE_DWELL_S, RATE_TABLE_SAMPLE_RATE_HZ, RATE_TABLE_WARMUP_S
from .registry import stream_index, sweep_kind
from .setpoint import DRIVE_REGISTER_DWELL_S, SETPOINT_RATIOS
from .vcf_dynamic import (
    VCF_DYNAMIC_AMPLITUDE_V,
    VCF_DYNAMIC_DWELL_S,
    VCF_DYNAMIC_FREQUENCIES_HZ,
    VCF_DYNAMIC_SAMPLE_RATE_HZ,
)
from .vcf_static import VCF_CARRIER_V, VCF_STATIC_RATES_DPS


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


def _float_tuple(values):
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


def _optional_float_tuple(values):
    return None if values is None else _float_tuple(values)


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

    def history(self, gyro: Gyroscope, run: int) -> AbstractTemperature:
        """Temperature history (deg C vs s since power-on) of run `run` of `gyro` (a single device)."""
        first = run == 0
        return WarmupTemperature(
            ambient=float(np.asarray(gyro.temperature(0.0))),
            rise=float(self.first_rise_k if first else self.rise_k),
            time_constant=float(self.first_time_constant_s if first else self.time_constant_s))


class Protocol(eqx.Module):
    """How each sweep kind is measured: its inputs, the timing of a run and the die's warm-up.

    Every (run, sweep) is its own power-on session (seed 003 Fig. 3 uses separate set-ups for the rate table
    and the virtual rate table): a warm-up of `warmup_s`, then the points back to back, each averaged over
    its dwell. A point's `temperature_c` is the die temperature at the middle of its dwell.

    **Arguments:**

    - `rates_dps`: rate-table rates, deg/s, in the order applied (default seed 000's 22); the `dac` sweep
      uses the words that stand for these rates (seed 000 Table 2).
    - `vcf_rates_dps`: the static virtual-Coriolis sweep as virtual rates, deg/s, in order: V_ac is set from
      them with seed 003 Eq. (7) and the nominal device's own m, Ag, a, w_d and K_svf at V_fc = 1 V (what a
      test engineer does with the design values; see `vcf_static_amplitudes`).
    - `vcf_amplitudes_v`: explicit static voltages V_ac, V, in order; when given they replace
      `vcf_rates_dps`.
    - `vcf_frequencies_hz`: modulation frequencies of the dynamic test, Hz, in order.
    - `vcf_dynamic_amplitude_v`: V_ac of the dynamic test, V (seed 003: 20 mV).
    - `quadrature_rates_dps`: the quadrature injection's virtual quadrature, deg/s of equivalent rate, in
      order: V_ac is set from them as for `vcf_rates_dps` (`virtual_rate_volts`).
    - `quadrature_amplitudes_v`: explicit injection voltages V_ac, V, in order; when given they replace
      `quadrature_rates_dps`.
    - `setpoint_ratios`: the AGC set-points of the set-point sweeps (`drive_amplitude`, `drive_frequency`,
      `setpoint_zero_rate`) relative to the nominal device's, in order.
    - `drive_dwell_s`: averaging time of a drive-loop register reading (`drive_amplitude`,
      `drive_frequency`), s.
    - `branch_rates_dps`: table rates of the branch-voltage ratio (`branch_ratio`), deg/s, in order.
    - `warmup_s`: time from power-on to the first point, s.
    - `dwell_s`, `sample_rate_hz`: averaging time and sampling rate of a settled point (rate_table,
      vcf_static).
    - `dynamic_dwell_s`, `dynamic_sample_rate_hz`: the same for a dynamic (lock-in) point.
    - `warmup`: the die's warm-up per run (`RunWarmup`), or None to use the device's own `temperature`
      history for every run.
    - `chamber_plateaus_c`: a plateau run, or None (default). Given (deg C, e.g. `CHAMBER_PLATEAUS_C`), each
      run of a timed sweep kind takes its listed points once per chamber plateau within the one power-on
      (one turn-on bias): the chamber steps to plateau k, the die soaks for `plateau_soak_s`, then the
      points follow back to back. The die temperature is `PlateauTemperature`: the chamber through a
      first-order lag of `package_time_constant_s`, starting soaked at the first plateau, plus the run's
      self-heating (`warmup`; none when it is None). The DAC sweep (a bench measurement) is unaffected.
    - `plateau_soak_s`, `package_time_constant_s`: see `PLATEAU_SOAK_S`, `PACKAGE_TIME_CONSTANT_S`.
    - `order`: the order the points of a settled or dynamic sweep are applied in, per run (`ORDERS`):
      `"listed"` (default: as listed above, ascending for the default lists), `"reversed"`, `"alternating"`
      (listed in even runs, reversed in odd ones: up-down) or `"shuffled"` (a random order per run, drawn
      from the campaign's seed). A sweep applied in one direction only ties its input to time and
      temperature within a run: drift then looks like a shape in the input. The DAC sweep is a bench
      measurement without a time axis.

    Defaults: seed 000 §5 for the rate table (1 min warm-up, 2 min per rate at 100 Hz); seed 003 §3 for the
    virtual-Coriolis tests; the static VCF sweep reuses the rate table's timing (ASSUMPTION: seed 003 prints
    none). See the module's constants for each number's source.
    """

    rates_dps: tuple = eqx.field(converter=_float_tuple, default=DING_ZHOU_2025_RATES_DPS)
    vcf_rates_dps: tuple = eqx.field(converter=_float_tuple, default=VCF_STATIC_RATES_DPS)
    vcf_amplitudes_v: tuple | None = eqx.field(converter=_optional_float_tuple, default=None)
    vcf_frequencies_hz: tuple = eqx.field(converter=_float_tuple, default=VCF_DYNAMIC_FREQUENCIES_HZ)
    vcf_dynamic_amplitude_v: float = VCF_DYNAMIC_AMPLITUDE_V
    quadrature_rates_dps: tuple = eqx.field(converter=_float_tuple, default=INJECTED_QUADRATURE_DPS)
    quadrature_amplitudes_v: tuple | None = eqx.field(converter=_optional_float_tuple, default=None)
    setpoint_ratios: tuple = eqx.field(converter=_float_tuple, default=SETPOINT_RATIOS)
    drive_dwell_s: float = DRIVE_REGISTER_DWELL_S
    branch_rates_dps: tuple = eqx.field(converter=_float_tuple, default=BRANCH_RATES_DPS)
    warmup_s: float = RATE_TABLE_WARMUP_S
    dwell_s: float = RATE_TABLE_DWELL_S
    sample_rate_hz: float = RATE_TABLE_SAMPLE_RATE_HZ
    dynamic_dwell_s: float = VCF_DYNAMIC_DWELL_S
    dynamic_sample_rate_hz: float = VCF_DYNAMIC_SAMPLE_RATE_HZ
    warmup: RunWarmup | None = RunWarmup()
    chamber_plateaus_c: tuple | None = eqx.field(converter=_optional_float_tuple, default=None)
    plateau_soak_s: float = PLATEAU_SOAK_S
    package_time_constant_s: float = PACKAGE_TIME_CONSTANT_S
    order: str = eqx.field(static=True, default="listed")

    def __check_init__(self):
        for name, what in (("rates_dps", "table rates (deg/s)"), ("vcf_rates_dps", "virtual rates (deg/s)"),
                           ("vcf_amplitudes_v", "voltages (V)"), ("vcf_frequencies_hz", "frequencies (Hz)"),
                           ("quadrature_rates_dps", "virtual quadratures (deg/s)"),
                           ("quadrature_amplitudes_v", "voltages (V)"), ("setpoint_ratios", "set-point ratios"),
                           ("branch_rates_dps", "table rates (deg/s)")):
            if getattr(self, name) is None:
                continue
            values = np.asarray(getattr(self, name))
            if values.size < 2 or not np.all(np.isfinite(values)):
                raise ValueError(f"Protocol.{name} must hold at least 2 finite {what}, got {values.tolist()}.")
            if np.unique(values).size != values.size:
                dup = sorted({v for v in values.tolist() if values.tolist().count(v) > 1})
                raise ValueError(f"Protocol.{name} repeats {dup}; each point is applied once (give repeats as "
                                 "more runs).")
        f = np.asarray(self.vcf_frequencies_hz)
        if np.any(f <= 0):
            raise ValueError(f"Protocol.vcf_frequencies_hz must be > 0 Hz, got {f.tolist()}.")
        if self.vcf_dynamic_amplitude_v == 0 or not math.isfinite(self.vcf_dynamic_amplitude_v):
            raise ValueError("Protocol.vcf_dynamic_amplitude_v must be finite and non-zero, got "
                             f"{self.vcf_dynamic_amplitude_v!r}.")
        if not all(r > 0 for r in self.setpoint_ratios):
            raise ValueError(f"Protocol.setpoint_ratios must be > 0, got {list(self.setpoint_ratios)}.")
        check_nonnegative("Protocol", "warmup_s", self.warmup_s)
        for name in ("dwell_s", "sample_rate_hz", "dynamic_dwell_s", "dynamic_sample_rate_hz", "drive_dwell_s"):
            check_positive("Protocol", name, getattr(self, name))
        if f.max() >= self.dynamic_sample_rate_hz / 2:
            raise ValueError(f"Protocol.dynamic_sample_rate_hz = {self.dynamic_sample_rate_hz} Hz does not sample "
                             f"the highest modulation frequency {f.max()} Hz (Nyquist: more than 2x).")
        for dwell, rate, name in ((self.dwell_s, self.sample_rate_hz, "dwell_s x sample_rate_hz"),
                                  (self.dynamic_dwell_s, self.dynamic_sample_rate_hz,
                                   "dynamic_dwell_s x dynamic_sample_rate_hz")):
            if round(dwell * rate) < 1:
                raise ValueError(f"Protocol: {name} = {dwell * rate:g} gives no sample per point.")
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

    def vcf_static_amplitudes(self, gyro: Gyroscope) -> np.ndarray:
        """V_ac of each static virtual-Coriolis point, V: `vcf_amplitudes_v` if given, else `vcf_rates_dps`
        through `virtual_rate_volts`."""
        if self.vcf_amplitudes_v is not None:
            return np.asarray(self.vcf_amplitudes_v)
        return self.virtual_rate_volts(gyro, self.vcf_rates_dps)

    @staticmethod
    def virtual_rate_volts(gyro: Gyroscope, rates_dps, carrier_v: float = VCF_CARRIER_V) -> np.ndarray:
        """The V_ac whose virtual-Coriolis force equals the Coriolis force of `rates_dps` (deg/s) on `gyro`'s
        nominal values (a single device), by seed 003 Eq. (7) inverted: V_ac = Om 2 m Ag a w_d / (K_svf V_fc),
        a the AGC's amplitude and w_d the drive resonance at t_ref, rounded to 12 significant digits. Raises a
        `ValueError` for a device without a virtual-Coriolis electrode."""
        r = gyro.resonator
        k_svf = float(np.asarray(gyro.vcf_electrode.force_per_volt2))
        if k_svf == 0.0:
            raise ValueError(f"a vcf sweep needs a virtual-Coriolis electrode; {gyro.name!r} has "
                             "vcf_electrode.force_per_volt2 = 0.")
        coriolis = 2.0 * r.mass * r.angular_gain * gyro.drive_amplitude(r.omega_x) * r.omega_x
        volts_per_rad_s = float(np.asarray(coriolis)) / (k_svf * float(carrier_v))
        volts = np.asarray(rates_dps, dtype=float) * DEG * volts_per_rad_s
        return np.asarray([float(f"{v:.12g}") for v in volts])  # a generator's setting; clean numbers in files

    def plateaus(self, sweep: str | AbstractSweep) -> int:
        """How many times `sweep`'s listed points are applied per run: the number of chamber plateaus for a
        timed kind in a plateau run, else 1."""
        return len(self.chamber_plateaus_c) if self.chamber_plateaus_c and sweep_kind(sweep).timed else 1

    def inputs(self, sweep: str | AbstractSweep, gyro: Gyroscope | None = None) -> np.ndarray:
        """The `input` column of a sweep kind, listed (for `dac`: the rates the words stand for, deg/s; in a
        plateau run, the listed points once per plateau); `vcf_static`, `quadrature_injection` and the
        set-point sweeps need the nominal device (see `virtual_rate_volts`)."""
        return np.tile(sweep_kind(sweep).inputs(self, gyro), self.plateaus(sweep))

    def n_points(self, sweep: str | AbstractSweep) -> int:
        """Number of points of a sweep kind per run (all plateaus of a plateau run)."""
        return sweep_kind(sweep).n_points(self) * self.plateaus(sweep)

    def dwell(self, sweep: str | AbstractSweep) -> float:
        """Averaging time of one point of `sweep`, s."""
        return sweep_kind(sweep).dwell_s(self)

    def n_samples(self, sweep: str | AbstractSweep) -> int:
        """Samples averaged per point of `sweep`."""
        kind = sweep_kind(sweep)
        return int(round(kind.dwell_s(self) * kind.sample_rate_hz(self)))

    def point_order(self, sweep: str | AbstractSweep, runs: int, seed: int = 0) -> np.ndarray:
        """Indices into `inputs(sweep)` of the points in the order applied, shape (runs, points); `seed` draws
        the `"shuffled"` orders (each run and sweep kind its own). A sweep without a time axis (`timed`
        false: the DAC sweep) is always applied as listed; in a plateau run the order applies within each
        plateau."""
        kind = sweep_kind(sweep)
        n = kind.n_points(self)
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
                rng = np.random.default_rng([int(seed) % 2**63, ORDER_STREAM, stream_index(kind), r])
                row = [rng.permutation(n) for _ in range(self.plateaus(kind))]
            rows.append(np.concatenate([k * n + block for k, block in enumerate(row)]))
        return np.stack(rows)

    def plateau_starts(self, sweep: str | AbstractSweep) -> np.ndarray:
        """Time since power-on at which the chamber steps to each plateau, s (a plateau run): plateau k
        starts at warmup + k (soak + points x dwell), its soak first."""
        block = self.plateau_soak_s + sweep_kind(sweep).n_points(self) * self.dwell(sweep)
        return self.warmup_s + np.arange(self.plateaus(sweep)) * block

    def point_times(self, sweep: str | AbstractSweep) -> np.ndarray:
        """Time since power-on of the middle of each point's dwell, s: warmup + (i + 1/2) dwell, or in a
        plateau run the plateau's start + soak + (i + 1/2) dwell."""
        if self.plateaus(sweep) == 1:
            n = self.n_points(sweep)
            return self.warmup_s + (np.arange(n) + 0.5) * self.dwell(sweep)
        n = sweep_kind(sweep).n_points(self)
        within = self.plateau_soak_s + (np.arange(n) + 0.5) * self.dwell(sweep)
        return np.ravel(self.plateau_starts(sweep)[:, None] + within[None, :])

    def run_history(self, gyro: Gyroscope, run: int, sweep: str | AbstractSweep | None = None) -> AbstractTemperature:
        """The die-temperature history of run `run` (the device's own when `warmup` is None; in a plateau run,
        the chamber's `PlateauTemperature` for `sweep`'s schedule)."""
        if sweep is not None and self.plateaus(sweep) > 1:
            heating = (WarmupTemperature(rise=0.0) if self.warmup is None
                       else self.warmup.history(gyro, run))
            return PlateauTemperature(
                plateaus_c=self.chamber_plateaus_c, starts_s=self.plateau_starts(sweep),
                initial_c=self.chamber_plateaus_c[0], package_time_constant_s=self.package_time_constant_s,
                rise_k=heating.rise, heating_time_constant_s=heating.time_constant)
        return gyro.temperature if self.warmup is None else self.warmup.history(gyro, run)

    def temperatures(self, gyro: Gyroscope, runs: int, sweep: str | AbstractSweep) -> np.ndarray:
        """Die temperature (deg C) at the middle of each point's dwell, shape (runs, points)."""
        t = self.point_times(sweep)
        return np.stack([np.broadcast_to(np.asarray(self.run_history(gyro, r, sweep)(t), dtype=float), t.shape)
                         for r in range(runs)])
