"""Simulated measurement campaigns: a lot, repeated runs, several sweeps -> a tidy `Table`.

Every output is computed by the measurement model of `gyrojax/_observe.py` (`rate_table_points`,
`vcf_static_points`, `vcf_dynamic_points`, `dac_points`) - the functions identification fits - vmapped over
the devices of the lot, the runs and the points, one compiled call per sweep kind. The campaign adds what
belongs to a run rather than to a device: its temperature history (`Protocol.warmup`), its turn-on bias and
its noise (`RateNoise`).
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from ._data.table import Table
from ._gyroscope import Gyroscope
from ._lot import ProcessSpread, as_arrays, make_lot
from ._noise import DAC_VOLTMETER_SIGMA_V, RateNoise
from ._observe import dac_points, steady_points, vcf_dynamic_points
from ._process import WaferProcess
from ._progress import as_progress
from ._simulate.tiers import AbstractTier, Steady
from ._solution import RESULTS, result_code
from ._sweeps import Protocol
from ._units import DEG


SIMULATED_SWEEPS = ("rate_table", "vcf_static", "vcf_dynamic", "dac")
"""Sweeps `simulate_table` can produce (the data format, docs/data_format.md)."""

CAMPAIGN_TIER = Steady(rtol=1e-10, atol=1e-10)
"""The default tier of `simulate_table`: `Steady` at 1e-10 (1e-4 ppm of the O(1)-scaled states). Measured:
`Steady()`'s 1e-11 sits at round-off for open-loop points at high rates - Newton stops shrinking its steps and
runs out of its 40 - on 20 of the 858 rate-table points (and 9 of 858 static-VCF points) of a 13-device
vcf-2018 lot with seed 003's spread; at 1e-10 every point converges in 2 Newton steps."""

DAC_VOLTMETER_SIGMA = DAC_VOLTMETER_SIGMA_V  # V, the default of simulate_table(voltmeter_sigma_v=...)


def _per_run(x, temperatures):
    """Inputs or times, (point,) or (run, point), as (run, point) like the temperatures' last two axes."""
    return jnp.broadcast_to(jnp.asarray(x, dtype=float), temperatures.shape[1:])


@eqx.filter_jit
def _lot_steady(lot, requests, tier):
    """`steady_points` for every device (axis 0) and run (axis 1), several steady sweeps in one call (one
    compiled settle): `requests` is a tuple of `(sweep, inputs, temperatures, times)` with temperatures
    (device, run, point) and inputs and times (point,) or (run, point) (times NaN: not recorded). Returns a
    `Settled` per request, (device, run, point)."""
    temps = tuple(r[2] for r in requests)
    inputs = tuple(_per_run(r[1], t) for r, t in zip(requests, temps))
    times = tuple(_per_run(r[3], t) for r, t in zip(requests, temps))
    sweeps = tuple(r[0] for r in requests)

    def device(g, dev_temps):
        def run(xs, ts, tms):
            return steady_points(g, tuple(zip(sweeps, xs, ts, tms)), tier)

        return jax.vmap(run)(inputs, dev_temps, times)

    return eqx.filter_vmap(device)(lot, temps)


def _lot_rate_table(lot, rates_dps, temperatures, tier, times=None):
    """`rate_table_points` for every device (axis 0) and run (axis 1); temperatures (device, run, point);
    rates and times since power-on (point,) or (run, point) (default: times not recorded)."""
    return _lot_steady(lot, (("rate_table", rates_dps, temperatures, jnp.nan if times is None else times),),
                       tier)[0]


def _lot_vcf_static(lot, amplitudes_v, temperatures, tier, times=None):
    """`vcf_static_points` for every device and run (shapes as `_lot_rate_table`)."""
    return _lot_steady(lot, (("vcf_static", amplitudes_v, temperatures, jnp.nan if times is None else times),),
                       tier)[0]


@eqx.filter_jit
def _lot_vcf_dynamic(lot, frequencies_hz, temperatures, amplitude_v):
    """`vcf_dynamic_points` for every device, run and point, each point at its own temperature; frequencies
    (point,) or (run, point)."""
    freqs = _per_run(frequencies_hz, temperatures)

    def device(g, temps):
        return jax.vmap(lambda f, t_run: vcf_dynamic_points(g, f, t_run, amplitude_v))(freqs, temps)

    return eqx.filter_vmap(device)(lot, temperatures)


@eqx.filter_jit
def _lot_dac(lot, words):
    return eqx.filter_vmap(dac_points)(lot, words)


@eqx.filter_jit
def _lot_ideal_sf(lot):
    return eqx.filter_vmap(lambda g: g.ideal_scale_factor())(lot)


def _raise_unsettled(result, what):
    codes = np.asarray(result_code(result))
    bad = codes != result_code(RESULTS.successful)
    if bad.any():
        codes = codes[bad]
        raise RuntimeError(
            f"{int(bad.sum())} of {bad.size} {what} points did not settle (result code "
            f"{sorted(set(codes.tolist()))}). Steady() at rtol = atol = 1e-11 can stall at round-off (use "
            "gyrojax.CAMPAIGN_TIER, Steady at 1e-10); otherwise try the averaged tier to see the transient, "
            "smaller inputs, or check the device's loop gains.")


def _slope(x, y):
    """Least-squares slope of y (..., point) against x (point)."""
    xc = x - x.mean()
    return np.sum((y - y.mean(axis=-1, keepdims=True)) * xc, axis=-1) / np.sum(xc**2)


def _rng(seed, sweep):
    """An independent NumPy generator per sweep kind: adding a sweep leaves the others' noise unchanged."""
    return np.random.default_rng([int(seed) % 2**63, SIMULATED_SWEEPS.index(sweep)])


def campaign_lot(gyro: Gyroscope, *, devices: int = 1, seed: int = 0,
                 spread: ProcessSpread | WaferProcess = ProcessSpread()) -> Gyroscope:
    """The devices that `simulate_table` simulates for these arguments: one Gyroscope whose array leaves
    have a leading device axis (device i is the table's `{prefix}-{i:03d}`). With `devices=1` it is `gyro`
    itself; otherwise `make_lot(gyro, devices, key, spread)` (a `ProcessSpread`: independent leaves) or
    `spread.draw(gyro, devices, key)` (a `WaferProcess`: leaves generated together by the process), with the
    key derived from `seed`."""
    if not isinstance(devices, int) or isinstance(devices, bool) or devices < 1:
        raise ValueError(f"devices must be an integer >= 1, got {devices!r}.")
    if devices == 1:
        return jax.tree.map(lambda x: x[None], as_arrays(gyro))
    key_lot, _ = jax.random.split(jax.random.PRNGKey(seed))
    if isinstance(spread, WaferProcess):
        return spread.draw(gyro, devices, key_lot)
    if not isinstance(spread, ProcessSpread):
        raise ValueError(f"spread must be a gyrojax.ProcessSpread or gyrojax.WaferProcess, got {spread!r}.")
    return make_lot(gyro, devices, key_lot, spread)


def simulate_table(gyro: Gyroscope, *, devices: int = 1, runs: int = 1, sweeps=("rate_table",),
                   tier: AbstractTier = CAMPAIGN_TIER, rates_dps: Float[ArrayLike, " point"] | None = None,
                   noise: RateNoise = RateNoise(), noise_free: bool = False, seed: int = 0,
                   spread: ProcessSpread | WaferProcess = ProcessSpread(),
                   device_prefix: str | None = None, protocol: Protocol = Protocol(),
                   voltmeter_sigma_v: float = DAC_VOLTMETER_SIGMA_V, progress=True) -> Table:
    """Simulate a measurement campaign and return it in the tidy data format (docs/data_format.md).

    **Arguments:**

    - `gyro`: the nominal device (with any effects already added).
    - `devices`: lot size; with more than one, devices are drawn around `gyro` with `spread`.
    - `runs`: repeated runs per device; each (run, sweep) is a power-on session with its own warm-up,
      turn-on bias and noise.
    - `sweeps`: any of `SIMULATED_SWEEPS` (a sequence, or one comma-separated string), in the order the
      table lists them.
    - `tier`: simulation tier of the settled sweeps (`rate_table`, `vcf_static`), default `CAMPAIGN_TIER`
      (`Steady` at 1e-10); the dynamic sweep is the averaged model linearised at rest, the DAC sweep the
      DAC's describing function.
    - `rates_dps`: table rates, deg/s; shorthand for `protocol` with these `rates_dps`.
    - `noise`: the rate-output noise (`RateNoise`, in deg/s); each device's share in LSB is its noise-free
      rate-table scale factor (least-squares slope of run 0) times the noise in deg/s.
    - `noise_free`: no noise, no turn-on bias (then `output_sigma` is 0).
    - `seed`: the PRNG seed (the lot and the noise both derive from it; each sweep kind draws its own
      stream).
    - `spread`: process spread of the lot: a `ProcessSpread` (independent leaves) or a `WaferProcess`
      (thickness, etch and mismatch generate the leaves together).
    - `device_prefix`: device ids are `{prefix}-{i:03d}` (default the device's name).
    - `protocol`: inputs, timing and warm-up of each sweep kind (`gyrojax.Protocol`).
    - `voltmeter_sigma_v`: reading noise of the DAC sweep's AC voltmeter, V.
    - `progress`: `True` (default) reports each sweep on standard error, `False` is silent, a callable gets
      the messages (see `gyrojax.identify`).

    **Returns:** a `gyrojax.Table` with `output_sigma` (the standard uncertainty of each point about its
    run's constant bias), `n_samples`, `temperature_c` (die temperature at the middle of the dwell), `time_s`
    (seconds since the run's power-on at the middle of the dwell; not for dac rows; rows in time order),
    `drive_freq_hz` (settled PLL frequency; not given for vcf_dynamic and dac rows), `phase_deg`
    (vcf_dynamic sweeps) and `rate_dps` (dac sweeps: the rate the word stands for, seed 000 Table 2).
    """
    sweeps = tuple(x.strip() for x in sweeps.split(",")) if isinstance(sweeps, str) else tuple(sweeps)
    for s in sweeps:
        if s not in SIMULATED_SWEEPS:
            raise ValueError(f"cannot simulate sweep {s!r}; choose from {', '.join(SIMULATED_SWEEPS)}.")
    repeated = sorted({s for s in sweeps if sweeps.count(s) > 1})
    if repeated:
        raise ValueError(f"sweeps lists {', '.join(map(repr, repeated))} more than once; give each sweep once "
                         "(repeats are runs).")
    if not sweeps:
        raise ValueError(f"sweeps is empty; choose from {', '.join(SIMULATED_SWEEPS)}.")
    if not isinstance(devices, int) or isinstance(devices, bool) or devices < 1:
        raise ValueError(f"devices must be an integer >= 1, got {devices!r}.")
    if not isinstance(runs, int) or isinstance(runs, bool) or runs < 1:
        raise ValueError(f"runs must be an integer >= 1, got {runs!r}.")
    if not isinstance(protocol, Protocol):
        raise ValueError(f"protocol must be a gyrojax.Protocol, got {protocol!r}.")
    if not isinstance(noise, RateNoise):
        raise ValueError(f"noise must be a gyrojax.RateNoise, got {noise!r}.")
    if not voltmeter_sigma_v >= 0:
        raise ValueError(f"voltmeter_sigma_v must be >= 0 V, got {voltmeter_sigma_v!r}.")
    if rates_dps is not None:
        protocol = dataclasses.replace(protocol, rates_dps=rates_dps)
    if "dac" in sweeps and not gyro.closed_loop:
        raise ValueError(f"a dac sweep needs a closed-loop device; {gyro.name!r} is open loop.")
    vcf_amplitudes = protocol.inputs("vcf_static", gyro) if "vcf_static" in sweeps else None
    if "vcf_dynamic" in sweeps and float(np.asarray(gyro.vcf_electrode.force_per_volt2)) == 0.0:
        raise ValueError(f"a vcf_dynamic sweep needs a virtual-Coriolis electrode; {gyro.name!r} has "
                         "vcf_electrode.force_per_volt2 = 0.")

    say = as_progress(progress, "gyrojax.simulate_table")
    lot = campaign_lot(gyro, devices=devices, seed=seed, spread=spread)
    structure = jax.tree.structure(eqx.filter(lot, eqx.is_array))

    def announce(sweep, k, compiles=True):
        say(f"sweep {k}/{len(sweeps)}: {sweep}, {devices} device(s) x {runs} run(s) x "
            f"{protocol.n_points(sweep)} points" + ("" if compiles else " (settled with the rate table)"))
        if compiles:
            say.compiling(("simulate", sweep, structure, devices, runs, protocol.n_points(sweep), tier),
                          f"the {sweep} measurement model")
    prefix = device_prefix or gyro.name
    names = np.asarray([f"{prefix}-{i:03d}" for i in range(devices)])
    shape_runs = (devices, runs)

    def temperatures(sweep):
        return np.broadcast_to(protocol.temperatures(gyro, runs, sweep), shape_runs + (protocol.n_points(sweep),))

    def applied(sweep, listed):
        """The inputs of each run in the order applied, (run, point): rows of the table in time order."""
        return np.asarray(listed)[protocol.point_order(sweep, runs, seed)]

    def times(sweep):
        return np.broadcast_to(protocol.point_times(sweep), (runs, protocol.n_points(sweep)))

    rates = np.asarray(protocol.rates_dps)
    rates_run = applied("rate_table", rates)
    rate_settled = vcf_settled = None
    if "rate_table" in sweeps or (not noise_free and {"vcf_static", "vcf_dynamic"} & set(sweeps)):
        # The rate-table sweep: an output, and each device's scale factor for the noise in LSB. A static VCF
        # sweep settles in the same call (one compiled program) when both use the same tier.
        rate_tier = tier if "rate_table" in sweeps else CAMPAIGN_TIER
        announce("rate_table", sweeps.index("rate_table") + 1 if "rate_table" in sweeps else 0)
        requests = (("rate_table", jnp.asarray(rates_run), jnp.asarray(temperatures("rate_table")),
                     jnp.asarray(times("rate_table"))),)
        with_vcf = "vcf_static" in sweeps and rate_tier is tier
        if with_vcf:
            requests += (("vcf_static", jnp.asarray(applied("vcf_static", vcf_amplitudes)),
                          jnp.asarray(temperatures("vcf_static")), jnp.asarray(times("vcf_static"))),)
        steady = _lot_steady(lot, requests, rate_tier)
        rate_settled = steady[0]
        vcf_settled = steady[1] if with_vcf else None
        _raise_unsettled(rate_settled.result, "rate-table" if "rate_table" in sweeps
                         else "rate-table (the noise-free sweep whose scale factor converts the noise to LSB)")
    lsb_per_dps = (np.zeros(devices) if rate_settled is None
                   else np.abs(_slope(rates_run[0], np.asarray(rate_settled.rate[:, 0], dtype=float))))

    columns = []
    for k, sweep in enumerate(sweeps, 1):
        if sweep != "rate_table":
            announce(sweep, k, compiles=not (sweep == "vcf_static" and vcf_settled is not None))
        temps = temperatures(sweep)
        rng = _rng(seed, sweep)
        n = protocol.n_points(sweep)
        full = shape_runs + (n,)
        extra = {}
        if sweep in ("rate_table", "vcf_static"):
            if sweep == "rate_table":
                inputs, settled = rates_run, rate_settled
            else:
                inputs = applied(sweep, vcf_amplitudes)
                settled = vcf_settled if vcf_settled is not None else _lot_vcf_static(
                    lot, jnp.asarray(inputs), jnp.asarray(temps), tier, jnp.asarray(times(sweep)))
                _raise_unsettled(settled.result, "vcf-static")
            out = np.asarray(settled.rate, dtype=float)
            dwell = protocol.dwell(sweep)
            if noise_free:
                sigma = np.zeros(full)
            else:
                bias, wobble = noise.sample_point_means(rng, shape_runs, n, dwell)
                out = out + (bias[..., None] + wobble) * lsb_per_dps[:, None, None]
                sigma = np.broadcast_to((noise.point_sigma_dps(dwell) * lsb_per_dps)[:, None, None], full)
            freq = np.asarray(settled.frequency, dtype=float) / (2.0 * np.pi)
            n_samples = np.full(full, float(protocol.n_samples(sweep)))
            extra["time_s"] = np.broadcast_to(times(sweep), full)
        elif sweep == "vcf_dynamic":
            inputs = applied(sweep, protocol.vcf_frequencies_hz)
            amp, phase = _lot_vcf_dynamic(lot, jnp.asarray(inputs), jnp.asarray(temps),
                                          float(protocol.vcf_dynamic_amplitude_v))
            amp, phase = np.asarray(amp, dtype=float), np.asarray(phase, dtype=float)
            if not (np.all(np.isfinite(amp)) and np.all(np.isfinite(phase))):
                raise RuntimeError("the vcf-dynamic response is not finite for some points; the device has no "
                                   "stable equilibrium at rest (check its loop gains).")
            out = amp
            if noise_free:
                sigma = np.zeros(full)
            else:
                # Lock-in over whole cycles: each quadrature component carries sqrt(G(f) / T) (see RateNoise).
                sigma = (noise.amplitude_sigma_dps(inputs, protocol.dynamic_dwell_s)[None, :, :]
                         * lsb_per_dps[:, None, None]) * np.ones(full)
                z = rng.standard_normal(full + (2,))
                reading = 1.0 + sigma * (z[..., 0] + 1j * z[..., 1]) / amp
                out = amp * np.abs(reading)
                phase = phase + np.rad2deg(np.angle(reading))
            extra["phase_deg"] = phase
            extra["time_s"] = np.broadcast_to(times(sweep), full)
            freq = np.full(full, np.nan)
            n_samples = np.full(full, float(protocol.n_samples(sweep)))
        else:  # dac
            sf_ideal = np.asarray(_lot_ideal_sf(lot), dtype=float)  # LSB per rad/s
            words = np.round(-rates[None, :] * DEG * sf_ideal[:, None])  # seed 000 Table 2: word = -SF x rate
            volts = np.asarray(_lot_dac(lot, jnp.asarray(words)), dtype=float)
            inputs = np.broadcast_to(words[:, None, :], full)
            out = np.broadcast_to(volts[:, None, :], full)
            sigma = np.full(full, 0.0 if noise_free else float(voltmeter_sigma_v))
            if not noise_free:
                out = out + sigma * rng.standard_normal(full)
            extra["rate_dps"] = np.broadcast_to(rates, full)
            temps = np.full(full, np.nan)  # a bench measurement of the DAC alone
            freq = np.full(full, np.nan)
            n_samples = np.full(full, np.nan)
        columns.append({
            "device": np.broadcast_to(names[:, None, None], full),
            "run": np.broadcast_to(np.arange(runs)[None, :, None], full),
            "sweep": np.full(full, sweep),
            "input": np.broadcast_to(inputs, full),
            "output": out,
            "output_sigma": sigma,
            "n_samples": n_samples,
            "temperature_c": temps,
            "drive_freq_hz": freq,
            **extra,
        })

    order = ["device", "run", "sweep", "input", "output", "output_sigma", "n_samples", "phase_deg",
             "temperature_c", "time_s", "drive_freq_hz", "rate_dps"]
    present = [c for c in order if any(c in cols for cols in columns)]
    table = {}
    for c in present:
        parts = []
        for cols in columns:
            if c in cols:
                parts.append(np.ravel(cols[c]))
            else:
                parts.append(np.full(cols["output"].size, np.nan))
        table[c] = np.concatenate(parts)
    table["run"] = table["run"].astype(np.int64)
    return Table.from_columns(table, source="<simulated>")
