"""Simulated measurement campaigns: a lot, repeated runs, several sweeps -> a tidy `Table`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._dataset import Table
from ._gyroscope import Gyroscope
from ._lot import ProcessSpread, as_arrays, make_lot
from ._noise import RateNoise
from ._simulate.tiers import AbstractTier, Steady
from ._solution import RESULTS
from ._sweeps import SEED000_RATES_DPS, _rate_sweep, dac_sweep
from ._units import DEG


SIMULATED_SWEEPS = ("rate_table", "dac")
"""Sweeps `simulate_table` can produce so far."""

DAC_VOLTMETER_SIGMA = 2e-5  # V, ASSUMPTION: 1-sigma reading noise of the AC amplitude in a DAC sweep


@eqx.filter_jit
def _lot_rate_sweep(lot, rates, times, tier):
    return eqx.filter_vmap(lambda g: _rate_sweep(g, rates, times, tier))(lot)


@eqx.filter_jit
def _lot_dac_sweep(lot, words):
    return eqx.filter_vmap(lambda g, w: dac_sweep(g, w))(lot, words)


@eqx.filter_jit
def _lot_ideal_sf(lot):
    return eqx.filter_vmap(lambda g: g.ideal_scale_factor())(lot)


def _raise_unsettled(result, what):
    bad = np.asarray(result._value) != RESULTS.successful._value
    if bad.any():
        codes = np.asarray(result._value)[bad]
        raise RuntimeError(
            f"{int(bad.sum())} of {bad.size} {what} points did not settle (result code "
            f"{sorted(set(codes.tolist()))}). Try another tier (averaged/full show the transient), longer "
            "settle_time, or check the device's loop gains.")


def simulate_table(gyro: Gyroscope, *, devices: int = 1, runs: int = 1, sweeps=("rate_table",),
                   tier: AbstractTier = Steady(), rates_dps=SEED000_RATES_DPS, noise: RateNoise = RateNoise(),
                   noise_free: bool = False, seed: int = 0, spread: ProcessSpread = ProcessSpread(),
                   device_prefix: str | None = None) -> Table:
    """Simulate a measurement campaign and return it in the tidy format of DESIGN.md §6.

    **Arguments:**

    - `gyro`: the nominal device (with any effects already added).
    - `devices`: lot size; with more than one, devices are drawn around `gyro` with `spread`.
    - `runs`: repeated runs per device (each with its own turn-on bias and noise).
    - `sweeps`: any of `SIMULATED_SWEEPS`.
    - `tier`: simulation tier for rate-table points.
    - `rates_dps`: table rates, deg/s (default seed 000's 22 rates).
    - `noise`, `noise_free`: the noise model, or none at all.
    - `seed`: the PRNG seed (the lot and the noise both derive from it).

    **Returns:** a `gyrojax.Table` with `output_sigma`, `temperature_c`, `drive_freq_hz` and, for `dac`
    sweeps, `rate_dps`.
    """
    unknown = [s for s in sweeps if s not in SIMULATED_SWEEPS]
    if unknown:
        raise ValueError(f"cannot simulate sweep(s) {unknown}; available: {list(SIMULATED_SWEEPS)}.")
    if not isinstance(devices, int) or devices < 1:
        raise ValueError(f"devices must be an integer >= 1, got {devices!r}.")
    if not isinstance(runs, int) or runs < 1:
        raise ValueError(f"runs must be an integer >= 1, got {runs!r}.")
    key_lot, key_noise = jax.random.split(jax.random.PRNGKey(seed))
    if devices == 1:
        lot = jax.tree.map(lambda x: x[None], as_arrays(gyro))
    else:
        lot = make_lot(gyro, devices, key_lot, spread)
    prefix = device_prefix or gyro.name
    names = [f"{prefix}-{i:03d}" for i in range(devices)]
    rates_dps = np.asarray(rates_dps, dtype=float)
    rates = jnp.asarray(rates_dps * DEG)
    times = noise.warmup_s + (np.arange(rates_dps.size) + 0.5) * noise.dwell_s
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key_noise)).ravel()[-1].item())
    cols = {k: [] for k in ("device", "run", "sweep", "input", "output", "output_sigma", "temperature_c",
                            "drive_freq_hz", "rate_dps")}

    def add(dev, run, sweep, x, y, sig, temp, freq, rate):
        n = len(x)
        cols["device"] += [dev] * n
        cols["run"] += [run] * n
        cols["sweep"] += [sweep] * n
        for k, v in (("input", x), ("output", y), ("output_sigma", sig), ("temperature_c", temp),
                     ("drive_freq_hz", freq), ("rate_dps", rate)):
            cols[k] += list(np.broadcast_to(np.asarray(v, dtype=float), (n,)))

    if "rate_table" in sweeps:
        settled = _lot_rate_sweep(lot, rates, jnp.asarray(times), tier)
        _raise_unsettled(settled.result, "rate-table")
        sf = np.abs(np.asarray(settled.rate[:, -1] - settled.rate[:, 0])) / (rates_dps[-1] - rates_dps[0])
        temps = np.asarray(gyro.temperature(jnp.asarray(times)))
        for d, name in enumerate(names):
            sigma = 0.0 if noise_free else noise.point_sigma_dps() * sf[d]
            for r in range(runs):
                out = np.asarray(settled.rate[d], dtype=float).copy()
                if not noise_free:
                    out += rng.normal() * noise.turn_on_bias_dps * sf[d]
                    out += rng.normal(size=out.shape) * sigma
                add(name, r, "rate_table", rates_dps, out, sigma, temps,
                    np.asarray(settled.frequency[d]) / (2 * np.pi), np.nan)
    if "dac" in sweeps:
        if not gyro.closed_loop:
            raise ValueError(f"a dac sweep needs a closed-loop device; {gyro.name!r} is open loop.")
        sf_ideal = np.asarray(_lot_ideal_sf(lot))  # LSB per rad/s
        words = np.round(-rates_dps[None, :] * DEG * sf_ideal[:, None])  # seed 000 Table 2: word = -SF x rate
        volts = np.asarray(_lot_dac_sweep(lot, jnp.asarray(words)))
        for d, name in enumerate(names):
            sigma = 0.0 if noise_free else DAC_VOLTMETER_SIGMA
            for r in range(runs):
                out = volts[d] + (0.0 if noise_free else rng.normal(size=volts[d].shape) * sigma)
                add(name, r, "dac", words[d], out, sigma, np.nan, np.nan, rates_dps)
    return Table.from_columns({k: np.asarray(v) for k, v in cols.items()}, source="<simulated>")
