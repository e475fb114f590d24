"""Simulated measurement campaigns: a lot, repeated runs, several sweeps -> a tidy `Table`.

Every output is computed by a sweep kind's measurement model (`gyrojax.AbstractSweep.simulate`, built on the
`predict` that identification fits), vmapped over the devices of the lot, the runs and the points, one compiled
call per sweep kind (the steady sweeps settle together with the rate table). The campaign adds what belongs to
a run rather than to a device: its temperature history (`Protocol.warmup`), its turn-on bias and its noise
(`RateNoise`).
"""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._data.cells import OPTIONAL_COLUMNS
from .._data.table import Table
from .._gyroscope import Gyroscope
from .._runtime.progress import ProgressArg, as_progress
from .._simulate.tiers import AbstractTier, Steady
from .._sweeps.base import AbstractSweep, float_tuple
from .._sweeps.dac import Dac
from .._sweeps.lot_campaign import LotCampaign
from .._sweeps.protocol import Protocol
from .._sweeps.rate_table import RateTable
from .._sweeps.registry import SWEEP_KINDS, sweep_kind
from .._sweeps.steady import AbstractSettledSweep, lot_steady, raise_unsettled
from .noise import DAC_VOLTMETER_SIGMA_V, RateNoise
from .process import WaferProcess
from .stack import ProcessSpread, as_arrays, make_lot


CAMPAIGN_TIER = Steady(rtol=1e-10, atol=1e-10)
"""The default tier of `simulate_table`: `Steady` at 1e-10 (1e-4 ppm of the O(1)-scaled states). Measured:
`Steady()`'s 1e-11 sits at round-off for open-loop points at high rates - Newton stops shrinking its steps and
runs out of its 40 - on 20 of the 858 rate-table points (and 9 of 858 static-VCF points) of a 13-device
vcf-2018 lot with seed 003's spread; at 1e-10 every point converges in 2 Newton steps."""

DAC_VOLTMETER_SIGMA = DAC_VOLTMETER_SIGMA_V  # V, the default of simulate_table(voltmeter_sigma_v=...)


def _slope(x, y):
    """Least-squares slope of y (..., point) against x (point)."""
    xc = x - x.mean()
    return np.sum((y - y.mean(axis=-1, keepdims=True)) * xc, axis=-1) / np.sum(xc**2)


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


def simulate_table(gyro: Gyroscope, *, devices: int = 1, runs: int = 1,
                   sweeps: str | Sequence[str | AbstractSweep] = ("rate_table",),
                   tier: AbstractTier = CAMPAIGN_TIER, rates_dps: Float[ArrayLike, " point"] | None = None,
                   noise: RateNoise = RateNoise(), noise_free: bool = False, seed: int = 0,
                   spread: ProcessSpread | WaferProcess = ProcessSpread(),
                   device_prefix: str | None = None, protocol: Protocol = Protocol(),
                   voltmeter_sigma_v: float = DAC_VOLTMETER_SIGMA_V, progress: ProgressArg = True) -> Table:
    """Simulate a measurement campaign and return it in the tidy data format (docs/data_format.md).

    **Arguments:**

    - `gyro`: the nominal device (with any effects already added).
    - `devices`: lot size; with more than one, devices are drawn around `gyro` with `spread`.
    - `runs`: repeated runs per device; each (run, sweep) is a power-on session with its own warm-up,
      turn-on bias and noise.
    - `sweeps`: the sweep kinds, in the order the table lists them: `gyrojax.AbstractSweep`s with their
      settings (`gyrojax.sweeps.RateTable(rates_dps=...)`), or names of `gyrojax.sweeps.SWEEP_KINDS` for a kind with its
      default settings (a sequence, or one comma-separated string of names).
    - `tier`: simulation tier of the settled sweeps (`rate_table`, `vcf_static`), default `CAMPAIGN_TIER`
      (`Steady` at 1e-10); the dynamic sweep is the averaged model linearised at rest, the DAC sweep the
      DAC's describing function.
    - `rates_dps`: table rates, deg/s; shorthand for these `rates_dps` in the rate table and the DAC sweep
      (the rates its words stand for).
    - `noise`: the rate-output noise (`RateNoise`, in deg/s); each device's share in LSB is its noise-free
      rate-table scale factor (least-squares slope of run 0) times the noise in deg/s.
    - `noise_free`: no noise, no turn-on bias (then `output_sigma` is 0).
    - `seed`: the PRNG seed (the lot and the noise both derive from it; each sweep kind draws its own
      stream).
    - `spread`: process spread of the lot: a `ProcessSpread` (independent leaves) or a `WaferProcess`
      (thickness, etch and mismatch generate the leaves together).
    - `device_prefix`: device ids are `{prefix}-{i:03d}` (default the device's name).
    - `protocol`: the timing of the runs: warm-up, dwell, order, chamber plateaus (`gyrojax.Protocol`).
    - `voltmeter_sigma_v`: reading noise of the DAC sweep's AC voltmeter, V.
    - `progress`: `True` (default) reports each sweep on standard error, `False` is silent, a callable gets
      the messages (see `gyrojax.identify`).

    **Returns:** a `gyrojax.Table` with `output_sigma` (the standard uncertainty of each point about its
    run's constant bias), `n_samples`, `temperature_c` (die temperature at the middle of the dwell), `time_s`
    (seconds since the run's power-on at the middle of the dwell; not for dac rows; rows in time order),
    `drive_freq_hz` (settled PLL frequency; not given for vcf_dynamic and dac rows), `phase_deg`
    (vcf_dynamic sweeps) and `rate_dps` (dac sweeps: the rate the word stands for, seed 000 Table 2).
    """
    kinds = _sweep_kinds(sweeps, rates_dps)
    _check_lot_arguments(devices, runs, protocol, noise, voltmeter_sigma_v)
    for kind in kinds:
        kind.check_device(gyro)

    say = as_progress(progress, "gyrojax.simulate_table")
    lot = campaign_lot(gyro, devices=devices, seed=seed, spread=spread)
    structure = jax.tree.structure(eqx.filter(lot, eqx.is_array))
    campaign = LotCampaign(gyro=gyro, protocol=protocol, devices=devices, runs=runs, seed=seed, noise=noise,
                           noise_free=noise_free, tier=tier, voltmeter_sigma_v=voltmeter_sigma_v,
                           lsb_per_dps=np.zeros(devices), settled={})

    def announce(kind, k, compiles=True):
        say(f"sweep {k}/{len(kinds)}: {kind.name}, {devices} device(s) x {runs} run(s) x "
            f"{protocol.n_points(kind)} points" + ("" if compiles else " (settled with the other settled sweeps)"))
        if compiles:
            say.compiling(("simulate", kind, structure, devices, runs, protocol.n_points(kind), tier),
                          f"the {kind.name} measurement model")

    # The rate table of the campaign (a noise-free one for the scale factor when the table is not simulated).
    rate = next((k for k in kinds if isinstance(k, RateTable)),
                RateTable() if rates_dps is None else RateTable(rates_dps=float_tuple(rates_dps)))
    if rate in kinds or (not noise_free and any(k.rate_noise for k in kinds)):
        announce(rate, kinds.index(rate) + 1 if rate in kinds else 0)
        campaign = _settle_with_rate_table(lot, campaign, kinds, rate, tier)
    campaign = _settle_the_rest(lot, campaign, kinds, structure, say)

    columns = []
    for k, kind in enumerate(kinds, 1):
        if kind != rate:
            announce(kind, k, compiles=kind.name not in campaign.settled)
        columns.append(_sweep_columns(kind, lot, campaign, device_prefix or gyro.name))
    return _table_of(columns)


def _sweep_columns(kind, lot, campaign: LotCampaign, prefix: str) -> dict:
    """One sweep kind simulated on the lot, with its device names (`prefix`-000 ...), runs and kind, each
    (device, run, point)."""
    device_ids = np.asarray([f"{prefix}-{i:03d}" for i in range(campaign.devices)])
    cols = kind.simulate(lot, campaign)
    full = cols["output"].shape
    return {
        "device": np.broadcast_to(device_ids[:, None, None], full),
        "run": np.broadcast_to(np.arange(campaign.runs)[None, :, None], full),
        "sweep": np.full(full, kind.name),
        **cols,
    }


def _sweep_kinds(sweeps, rates_dps) -> list:
    """The sweep kinds of `sweeps` (names, a comma-separated string, or kinds), each once, with `rates_dps`
    (the shorthand) as the rate table's rates and the DAC sweep's words."""
    sweeps = tuple(x.strip() for x in sweeps.split(",")) if isinstance(sweeps, str) else tuple(sweeps)
    kinds = []
    for s in sweeps:
        try:
            kinds.append(sweep_kind(s))
        except ValueError:
            raise ValueError(f"cannot simulate sweep {s!r}; choose from {', '.join(SWEEP_KINDS)}.") from None
    if rates_dps is not None:  # the shorthand: these table rates for the rate table and the DAC sweep's words
        kinds = [dataclasses.replace(k, rates_dps=rates_dps) if isinstance(k, (RateTable, Dac)) else k for k in kinds]
    names = [k.name for k in kinds]
    repeated = sorted({s for s in names if names.count(s) > 1})
    if repeated:
        raise ValueError(f"sweeps lists {', '.join(map(repr, repeated))} more than once; give each sweep once "
                         "(repeats are runs).")
    if not sweeps:
        raise ValueError(f"sweeps is empty; choose from {', '.join(SWEEP_KINDS)}.")
    return kinds


def _check_lot_arguments(devices, runs, protocol, noise, voltmeter_sigma_v) -> None:
    """`simulate_table`'s lot size, runs, protocol and noise, each with what is expected."""
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


def _settle_with_rate_table(lot, campaign: LotCampaign, kinds, rate: RateTable, tier) -> LotCampaign:
    """The rate-table sweep settled: an output, and each device's scale factor for the noise in LSB. The other
    settled sweeps (steady and set-point kinds) settle in the same call (one compiled program) when they use
    the same tier. Returns the campaign with the scale factors and the settled sweeps."""
    protocol, gyro = campaign.protocol, campaign.gyro
    rate_tier = tier if rate in kinds else CAMPAIGN_TIER
    shared = [rate] + [k for k in kinds if isinstance(k, AbstractSettledSweep) and k != rate
                       and rate_tier is tier]
    requests = tuple((k, jnp.asarray(campaign.applied(k, protocol.inputs(k, gyro))),
                      jnp.asarray(campaign.temperatures(k)), jnp.asarray(campaign.times(k))) for k in shared)
    steady = lot_steady(lot, requests, rate_tier)
    raise_unsettled(steady[0].result, rate.title if rate in kinds
                    else "rate-table (the noise-free sweep whose scale factor converts the noise to LSB)")
    for k, settled in zip(shared[1:], steady[1:]):
        raise_unsettled(settled.result, k.title)
    rates_run = np.asarray(requests[0][1])
    lsb_per_dps = np.abs(_slope(rates_run[0], np.asarray(steady[0].rate[:, 0], dtype=float)))
    return dataclasses.replace(campaign, lsb_per_dps=lsb_per_dps,
                               settled={k.name: s for k, s in zip(shared, steady) if k in kinds})


def _settle_the_rest(lot, campaign: LotCampaign, kinds, structure, say) -> LotCampaign:
    """The settled sweeps not settled with the rate table, in one call of the campaign's tier (where there are
    several)."""
    rest = [k for k in kinds if isinstance(k, AbstractSettledSweep) and k.name not in campaign.settled]
    if len(rest) > 1:
        protocol, gyro, tier = campaign.protocol, campaign.gyro, campaign.tier
        requests = tuple((k, jnp.asarray(campaign.applied(k, protocol.inputs(k, gyro))),
                          jnp.asarray(campaign.temperatures(k)), jnp.asarray(campaign.times(k))) for k in rest)
        say.compiling(("simulate", tuple(rest), structure, campaign.devices, campaign.runs, tier),
                      "the measurement model of " + ", ".join(k.name for k in rest))
        for k, settled in zip(rest, lot_steady(lot, requests, tier)):
            raise_unsettled(settled.result, k.title)
            campaign = dataclasses.replace(campaign, settled={**campaign.settled, k.name: settled})
    return campaign


def _table_of(columns) -> Table:
    """The simulated sweeps' columns as one table, in the data format's column order (NaN where a sweep lacks
    a column)."""
    order = ["device", "run", "sweep", "input", "output", "output_sigma", "n_samples", "phase_deg",
             "temperature_c", "time_s", "drive_freq_hz", "rate_dps"]
    order += [c for c in OPTIONAL_COLUMNS if c not in order]
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
