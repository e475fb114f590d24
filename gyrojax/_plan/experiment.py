"""Candidate experiments: what the planner may add to a campaign, and how each one's points are predicted.

Everything the planner knows about an experiment is here: its name, its sweep kind, its minutes of test time,
the noise-free outputs of its points for a device (the kind's own measurement model, `AbstractSweep.predict`,
shared with simulation and fitting; the steady kinds settled in one call) and the standard uncertainty of each
point (`AbstractSweep.point_sigmas`, or `AbstractSweep.relative_sigma` times the predicted reading). The
default candidates are the registered sweep kinds, so a kind added
with `gyrojax.sweeps.register_sweep` is a candidate without changing the planner.
"""

import math
from collections.abc import Iterable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._lots.noise import DAC_VOLTMETER_SIGMA_V, RateNoise
from .._model.parameters import apply_u, read_values
from .._model.residuals import settle_with_scale_factor
from .._simulate.tiers import Steady
from .._sweeps.base import AbstractSweep
from .._sweeps.protocol import Protocol
from .._sweeps.registry import SWEEP_KINDS, sweep_kind
from .._sweeps.steady import AbstractSettledSweep, AbstractSteadySweep


CHAMBER_STEP_K = 20.0
"""K, ASSUMPTION: the second chamber plateau of a sweep "at another temperature" lies this far above the
ambient of the data given. Seeds 000 and 003 test at room temperature only; a 20 K step is one plateau of the
usual -40 to 85 deg C qualification range and moves the die well beyond its ~2 K self-heating."""

CHAMBER_SOAK_S = 1800.0
"""s, ASSUMPTION: soak of a temperature chamber at a new plateau before power-on (a packaged die on a rate
table's fixture settles within tens of minutes; not printed by the seeds)."""


def _floats(values):
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


class CandidateExperiment(eqx.Module):
    """One run of a measurement the planner may add: which sweep kind, what is applied, for how long, and at
    which die temperature.

    **Arguments:**

    - `name`: what the plan calls it, e.g. `"rate_table"` or `"rate_table_hot"`.
    - `sweep`: the sweep kind (a registered `gyrojax.AbstractSweep`, with its settings), or its name.
    - `inputs`: each point's `input`, in the sweep's unit (deg/s, V of V_ac, Hz, DAC word).
    - `temperatures_c`: die temperature of each point, deg C (NaN: the device's own at power-on).
    - `times_s`: time since power-on of each point, s (NaN: not recorded).
    - `minutes`: test time of one run, warm-up and soak included.
    - `protocol`: the timing the kind reads its dwell from (sets each point's noise).
    - `settings`: `(key, value)` pairs describing the run for people and JSON.

    Every run of a biased sweep kind (`AbstractSweep.biased`) carries its own turn-on bias: a nuisance
    parameter of the run that the planner projects out, as identification does.
    """

    name: str = eqx.field(static=True)
    sweep: AbstractSweep = eqx.field(static=True)
    inputs: tuple[float, ...] = eqx.field(static=True, converter=_floats)
    temperatures_c: tuple[float, ...] = eqx.field(static=True, converter=_floats)
    times_s: tuple[float, ...] = eqx.field(static=True, converter=_floats)
    minutes: float = eqx.field(static=True)
    protocol: Protocol = eqx.field(static=True, default=Protocol())
    settings: tuple[tuple[str, object], ...] = eqx.field(static=True, default=())

    def __init__(self, name: str, sweep: AbstractSweep | str, inputs: Float[ArrayLike, " point"] | Sequence[float],
                 temperatures_c: Float[ArrayLike, " point"] | Sequence[float],
                 times_s: Float[ArrayLike, " point"] | Sequence[float], minutes: float,
                 protocol: Protocol = Protocol(), settings: Iterable[tuple[str, object]] = ()):
        if isinstance(sweep, str):
            if sweep not in SWEEP_KINDS:
                raise ValueError(f"CandidateExperiment {name!r}: sweep must be a registered sweep kind "
                                 f"({', '.join(SWEEP_KINDS)}) or an AbstractSweep, got {sweep!r}.")
            sweep = sweep_kind(sweep)
        if not isinstance(sweep, AbstractSweep):
            raise ValueError(f"CandidateExperiment {name!r}: sweep must be an AbstractSweep or a registered name, "
                             f"got {sweep!r}.")
        if not isinstance(protocol, Protocol):
            raise ValueError(f"CandidateExperiment {name!r}: protocol must be a gyrojax.Protocol, got {protocol!r}.")
        self.name, self.sweep, self.protocol = name, sweep, protocol
        self.inputs, self.temperatures_c, self.times_s = _floats(inputs), _floats(temperatures_c), _floats(times_s)
        self.minutes, self.settings = minutes, tuple(settings)

    def __check_init__(self):
        n = len(self.inputs)
        if n < 1 or len(self.temperatures_c) != n or len(self.times_s) != n:
            raise ValueError(f"CandidateExperiment {self.name!r}: inputs, temperatures_c and times_s must have one "
                             f"value per point, got {n}, {len(self.temperatures_c)} and {len(self.times_s)}.")
        if not (isinstance(self.minutes, (int, float)) and self.minutes > 0 and math.isfinite(self.minutes)):
            raise ValueError(f"CandidateExperiment {self.name!r}: minutes must be > 0, got {self.minutes!r}.")

    @property
    def kind(self) -> str:
        """The `sweep` value its rows would have."""
        return self.sweep.name

    @property
    def biased(self) -> bool:
        """Whether each run carries a turn-on bias (a nuisance per run)."""
        return self.sweep.biased

    @property
    def points(self) -> int:
        return len(self.inputs)

    @property
    def reads(self) -> tuple:
        """Physical parameters (names of `gyrojax.PARAMETERS`) its runs determine that a baseline of the
        standard sweeps holds (the kind's `AbstractSweep.reads`): a fit of data with these runs frees them."""
        return tuple(self.sweep.reads)

    def to_json(self) -> dict:
        return {"sweep": self.name, "kind": self.kind, "settings": dict(self.settings), "minutes": self.minutes,
                "points": self.points}

    def sigmas(self, noise: "NoiseLevel", outputs: Float[ArrayLike, " point"] | None = None) -> np.ndarray:
        """Standard uncertainty of each point for one device whose noise is `noise`: the kind's own noise
        model (`AbstractSweep.point_sigmas`), rate noise scaled to the data's level; else, for a kind whose
        noise is relative to its reading (`AbstractSweep.relative_sigma`), that fraction of the predicted
        `outputs` (one per point); else the median sigma of this kind's points in the data. Raises a
        `ValueError` when none gives one."""
        sigma = self.sweep.point_sigmas(np.asarray(self.inputs), self.protocol, noise.rate_noise,
                                        noise.lsb_per_dps, noise.voltmeter_sigma_v)
        relative = self.sweep.relative_sigma(self.protocol)
        if sigma is not None:
            sigma = np.asarray(sigma, dtype=float) * (noise.scale if self.sweep.rate_noise else 1.0)
        elif relative is not None and outputs is not None:
            sigma = float(relative) * np.abs(np.asarray(outputs, dtype=float))
        elif self.kind in noise.measured:
            sigma = np.full(self.points, noise.measured[self.kind])
        else:
            raise ValueError(f"experiment {self.name!r}: the sweep kind {self.kind!r} has no noise model "
                             "(AbstractSweep.point_sigmas, or relative_sigma with predicted outputs) and the data "
                             "have no points of it to take one from.")
        if sigma.shape != (self.points,) or not np.all(sigma > 0):
            raise ValueError(f"experiment {self.name!r}: point sigmas must be > 0, one per point; got {sigma!r}.")
        return sigma


class NoiseLevel(eqx.Module):
    """The noise of one device, read from its data: the rate output's noise model (`RateNoise`) times
    `scale`, in LSB through `lsb_per_dps`; the DAC sweep's voltmeter; and the median `output_sigma` of each
    sweep kind in the data (`measured`, by name), for kinds without a noise model of their own."""

    lsb_per_dps: float
    scale: float
    voltmeter_sigma_v: float
    rate_noise: RateNoise = RateNoise()
    measured: dict = eqx.field(default_factory=dict)


def predict(gyro: Gyroscope, experiments, sf_temperature=None, tier=Steady()):
    """Noise-free outputs of every point of `experiments` (one device) through each kind's measurement model,
    the settled kinds' points (steady and set-point) in one call of the tier (one compiled settle); with
    `sf_temperature` (deg C) also the zero-rate scale factor there (LSB per deg/s, the central difference identification
    reports).

    **Returns:** `(outputs per experiment, scale factor or None)`.
    """
    return _predict_points(gyro, tuple(e.sweep for e in experiments), _points(experiments), sf_temperature, tier)


def _points(experiments) -> tuple:
    """Each experiment's `(inputs, temperatures_c, times_s)` as arrays: the numbers a compiled prediction takes
    as arguments, so that experiments of the same kinds and point counts share one program."""
    return tuple((jnp.asarray(e.inputs), jnp.asarray(e.temperatures_c), jnp.asarray(e.times_s))
                 for e in experiments)


def _predict_points(gyro, sweeps, points, sf_temperature, tier):
    """`predict` on the sweep kinds `sweeps` and their points `points` (one `(inputs, temperatures_c,
    times_s)` per kind, as `_points` gives)."""
    steady = [i for i, s in enumerate(sweeps) if isinstance(s, AbstractSettledSweep)]
    requests = [(sweeps[i],) + tuple(points[i]) for i in steady]
    settled, sf = (settle_with_scale_factor(gyro, requests, tier, sf_temperature)
                   if requests or sf_temperature is not None else ((), None))
    by_index = {i: sweeps[i].read(s)[0] for i, s in zip(steady, settled)}
    out = []
    for i, (sweep, p) in enumerate(zip(sweeps, points)):
        out.append(by_index[i] if i in by_index else sweep.predict(gyro, *p, tier)[0])
    return tuple(out), sf


@jit
def _jacobians(model, entries, sweeps, points, sf_temperature, tier):
    def one(model_d, t_sf):
        start = read_values(model_d, entries)
        n = sum(e.size for e in entries)

        def outputs(u):
            gyro = apply_u(model_d, entries, start, u, jnp.zeros(0)).gyroscope()
            preds, sf = _predict_points(gyro, sweeps, points, t_sf, tier)
            return (preds, sf), (preds, sf)

        return jax.jacfwd(outputs, has_aux=True)(jnp.zeros(n))

    return eqx.filter_vmap(one)(model, sf_temperature)


def jacobians(model, entries, experiments, sf_temperature, tier=Steady()):
    """Derivatives of every point of `experiments`, and of the zero-rate scale factor at `sf_temperature`,
    with respect to the internal coordinates of `entries` at the model's values (one compiled call for the
    lot: a `Model` whose leaves have a leading device axis). The program depends on the experiments' sweep
    kinds and point counts only, not on their inputs, temperatures and times (the DAC words and VCF
    voltages of the default experiments follow each lot's fitted device), so plans on lots of the same shapes
    share it.

    **Returns:** `((jacobian per experiment (device, point, param), scale-factor gradient (device, param)),
    (outputs per experiment (device, point), scale factor (device,)))`.
    """
    (jac, g), (pred, sf) = _jacobians(model, tuple(entries), tuple(e.sweep for e in experiments),
                                      _points(experiments), jnp.asarray(sf_temperature, dtype=float), tier)
    return ((tuple(np.asarray(j) for j in jac), np.asarray(g)),
            (tuple(np.asarray(p) for p in pred), np.asarray(sf)))


def window_correlation(noise: RateNoise, n: int, dwell_s: float) -> np.ndarray:
    """Correlation matrix (n, n) of the noise of `n` settled points averaged over back-to-back windows of
    `dwell_s`, about the run's turn-on bias, as the simulator draws it (`RateNoise.sample_point_means`): the
    white part is independent, the Gauss-Markov wander's window means of points k apart share
    q^2 (tau / T)^2 (1 - exp(-T / tau))^2 exp(-(k - 1) T / tau)."""
    q, tau = noise.wander_sigma_dps, noise.bias_correlation_s
    x = dwell_s / tau
    var = noise.point_sigma_dps(dwell_s) ** 2
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    cov = q**2 * (tau / dwell_s) ** 2 * math.expm1(-x) ** 2 * np.exp(-x * np.maximum(lag - 1, 0))
    return np.where(lag == 0, 1.0, cov / var)


def weighted_rows(experiment: CandidateExperiment, jac: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """One run's rows of the standardised residuals' Jacobian (point, param) for one device: each point
    over its sigma, with the run's turn-on bias projected out (the weighted mean of the run removed, as
    `gyrojax/_model/residuals.py` does) when the sweep is biased."""
    jac = np.asarray(jac, dtype=float)
    if experiment.biased:
        w = 1.0 / sigmas**2
        jac = jac - (w @ jac) / np.sum(w)
    return jac / sigmas[:, None]


def default_experiments(gyro: Gyroscope, protocol: Protocol = Protocol(), ambient_c: float | None = None,
                        chamber_kinds: Sequence[str] = ("rate_table",), kinds: Iterable[AbstractSweep] = ()) -> tuple:
    """One run of every registered sweep kind that `gyrojax.sweeps.SWEEP_KINDS` holds, each with its default settings
    unless `kinds` gives it others (a kind whose `check_device` refuses `gyro` is left out), timed by
    `protocol`, plus each kind of `chamber_kinds` again at a chamber `CHAMBER_STEP_K` warmer after a
    `CHAMBER_SOAK_S` soak (named `<kind>_hot`). A run's inputs, minutes, settings and noise are the kind's own
    (`AbstractSweep.run_inputs`, `run_minutes`, `run_settings`, `point_sigmas`); a timed run is not the
    session's first (its die warms up as runs 1, 2, ... of `protocol`).

    **Arguments:**

    - `gyro`: the nominal device (a single one): its design values set inputs such as VCF voltages and DAC
      words.
    - `protocol`: the timing (`gyrojax.Protocol`, default seed 000's).
    - `ambient_c`: the chamber temperature at power-on, deg C (default the device's own at power-on).
    - `chamber_kinds`: sweep names also proposed at the warmer plateau.
    - `kinds`: sweep kinds with their own settings (`gyrojax.sweeps.RateTable(rates_dps=...)`), each replacing the
      registered kind of its name.

    **Returns:** a tuple of `CandidateExperiment`, in registry order.
    """
    if not isinstance(protocol, Protocol):
        raise ValueError(f"protocol must be a gyrojax.Protocol, got {protocol!r}.")
    for k in chamber_kinds:
        if k not in SWEEP_KINDS:
            raise ValueError(f"chamber_kinds: unknown sweep {k!r}; expected names of {', '.join(SWEEP_KINDS)}.")
    given = {}
    for k in kinds:
        if not isinstance(k, AbstractSweep) or k.name not in SWEEP_KINDS:
            raise ValueError(f"kinds: expected sweep kinds registered in gyrojax.sweeps.SWEEP_KINDS "
                             f"({', '.join(SWEEP_KINDS)}), got {k!r}.")
        given[k.name] = k
    own = float(np.asarray(gyro.temperature(0.0)))
    ambient = own if ambient_c is None else float(ambient_c)
    out = []
    for name, cls in SWEEP_KINDS.items():
        kind = given.get(name) or cls()
        try:
            kind.check_device(gyro)
        except ValueError:
            continue
        inputs = kind.run_inputs(gyro)
        n = inputs.size
        if kind.timed:
            times = np.asarray(protocol.point_times(kind), dtype=float)
            # a run after the first (runs 1, 2, ... share one warm-up), shifted to the chamber's ambient
            temps = np.asarray(protocol.temperatures(gyro, 2, kind)[1], dtype=float) + (ambient - own)
        else:
            times, temps = np.full(n, np.nan), np.full(n, np.nan)
        minutes = kind.run_minutes(protocol)
        settings = tuple(sorted(kind.run_settings(protocol).items()))
        out.append(CandidateExperiment(name=name, sweep=kind, inputs=inputs, temperatures_c=temps, times_s=times,
                                       minutes=minutes, protocol=protocol,
                                       settings=(("inputs", list(_floats(inputs))),) + settings
                                       + ((("chamber_c", ambient),) if kind.timed else ())))
        if name in chamber_kinds and kind.timed:
            hot = ambient + CHAMBER_STEP_K
            out.append(CandidateExperiment(name=f"{name}_hot", sweep=kind, inputs=inputs,
                                           temperatures_c=temps + CHAMBER_STEP_K, times_s=times,
                                           minutes=minutes + CHAMBER_SOAK_S / 60.0, protocol=protocol,
                                           settings=(("inputs", list(_floats(inputs))),) + settings
                                           + (("chamber_c", hot), ("soak_s", CHAMBER_SOAK_S))))
    return tuple(out)


def noise_levels(data, lsb_per_dps: np.ndarray, protocol: Protocol = Protocol(),
                 rate_noise: RateNoise = RateNoise()) -> tuple:
    """Each device's `NoiseLevel` from its data (`FitData`, whose sigmas are the given `output_sigma` or the
    noise a fit estimated): the rate output's noise is `rate_noise` scaled to the median sigma of the first
    steady rate-noise kind in the data (rate table, else static VCF), assumed taken at that kind's dwell under
    `protocol`; the voltmeter's is the DAC points' median sigma (else `DAC_VOLTMETER_SIGMA_V`). A device
    without either keeps `rate_noise` as it is.

    The planner's point noise is independent from point to point at these levels: noise that wanders slowly
    within a run is partly absorbed by the run's bias, so a planned standard error can be pessimistic for it.
    """
    out = []
    for d in range(len(data.devices)):
        lsb = abs(float(lsb_per_dps[d]))
        scale, measured = 1.0, {}
        for sweep, b in data.blocks.items():
            real = np.asarray(b.mask[d])
            if real.any():
                measured[sweep] = float(np.median(np.asarray(b.sigmas[d])[real]))
        for sweep, b in data.blocks.items():
            if isinstance(b.kind, AbstractSteadySweep) and sweep in measured:
                dwell = b.kind.dwell_s(protocol)
                scale = measured[sweep] / (rate_noise.point_sigma_dps(dwell) * lsb)
                break
        volt = measured.get("dac", DAC_VOLTMETER_SIGMA_V)
        out.append(NoiseLevel(lsb, scale, volt, rate_noise, measured))
    return tuple(out)
