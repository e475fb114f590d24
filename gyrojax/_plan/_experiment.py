"""Candidate experiments: what the planner may add to a campaign, and how each one's points are predicted.

Everything the planner knows about an experiment is here: its name, its settings, its minutes of test time,
the noise-free outputs of its points for a device (the measurement model of `gyrojax/_observe.py`, shared
with simulation and fitting) and the standard uncertainty of each point. A new kind of experiment plugs in
as another `CandidateExperiment` whose `sweep` the measurement model knows.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._fitdata import BIASED_SWEEPS
from .._gyroscope import Gyroscope
from .._noise import DAC_VOLTMETER_SIGMA_V, RateNoise
from .._observe import dac_points, steady_points, vcf_dynamic_points
from .._parameters import apply_u, read_values
from .._residuals import SF_STEP_DPS
from .._simulate.tiers import Steady
from .._sweeps import Protocol
from .._units import DEG


CHAMBER_STEP_K = 20.0
"""K, ASSUMPTION: the second chamber plateau of a "rate table at another temperature" lies this far above the
ambient of the data given. Seeds 000 and 003 test at room temperature only; a 20 K step is one plateau of the
usual -40 to 85 deg C qualification range and moves the die well beyond its ~2 K self-heating."""

CHAMBER_SOAK_S = 1800.0
"""s, ASSUMPTION: soak of a temperature chamber at a new plateau before power-on (a packaged die on a rate
table's fixture settles within tens of minutes; not printed by the seeds)."""

DAC_READING_S = 10.0
"""s, ASSUMPTION: one AC-voltmeter reading of a DAC word (settling and a 1 s integration, several times
over; seed 000 Table 2 prints the readings, not the time they took)."""

STEADY_KINDS = ("rate_table", "vcf_static")
KINDS = STEADY_KINDS + ("vcf_dynamic", "dac")


def _floats(values):
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


class CandidateExperiment(eqx.Module):
    """One run of a measurement the planner may add: what is applied, for how long, and at which die
    temperature.

    **Arguments:**

    - `name`: what the plan calls it, e.g. `"rate_table"` or `"rate_table_hot"`.
    - `sweep`: the data format's sweep kind its rows would have (`rate_table`, `vcf_static`, `vcf_dynamic`,
      `dac`).
    - `inputs`: each point's `input`, in the sweep's unit (deg/s, V of V_ac, Hz, DAC word).
    - `temperatures_c`: die temperature of each point, deg C.
    - `times_s`: time since power-on of each point, s.
    - `minutes`: test time of one run, warm-up and soak included.
    - `dwell_s`: averaging time of one point, s (sets its noise).
    - `settings`: `(key, value)` pairs describing the run for people and JSON.
    - `vcf_dynamic_amplitude_v`: V_ac of a dynamic virtual-Coriolis run, V.

    Every run of a biased sweep (`rate_table`, `vcf_static`) carries its own turn-on bias: a nuisance
    parameter of the run that the planner projects out, as identification does.
    """

    name: str = eqx.field(static=True)
    sweep: str = eqx.field(static=True)
    inputs: tuple = eqx.field(static=True, converter=_floats)
    temperatures_c: tuple = eqx.field(static=True, converter=_floats)
    times_s: tuple = eqx.field(static=True, converter=_floats)
    minutes: float = eqx.field(static=True)
    dwell_s: float = eqx.field(static=True)
    settings: tuple = eqx.field(static=True, default=())
    vcf_dynamic_amplitude_v: float = eqx.field(static=True, default=0.02)

    def __check_init__(self):
        if self.sweep not in KINDS:
            raise ValueError(f"CandidateExperiment {self.name!r}: sweep must be one of {', '.join(KINDS)}, got "
                             f"{self.sweep!r}.")
        n = len(self.inputs)
        if n < 1 or len(self.temperatures_c) != n or len(self.times_s) != n:
            raise ValueError(f"CandidateExperiment {self.name!r}: inputs, temperatures_c and times_s must have one "
                             f"value per point, got {n}, {len(self.temperatures_c)} and {len(self.times_s)}.")
        if not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise ValueError(f"CandidateExperiment {self.name!r}: minutes must be > 0, got {self.minutes!r}.")
        if not self.dwell_s > 0:
            raise ValueError(f"CandidateExperiment {self.name!r}: dwell_s must be > 0, got {self.dwell_s!r}.")

    @property
    def biased(self) -> bool:
        """Whether each run carries a turn-on bias (a nuisance per run)."""
        return self.sweep in BIASED_SWEEPS

    @property
    def points(self) -> int:
        return len(self.inputs)

    def to_json(self) -> dict:
        return {"sweep": self.name, "kind": self.sweep, "settings": dict(self.settings), "minutes": self.minutes,
                "points": self.points}

    def sigmas(self, noise: "NoiseLevel") -> np.ndarray:
        """Standard uncertainty of each point for one device whose noise is `noise`."""
        if self.sweep == "dac":
            return np.full(self.points, noise.voltmeter_sigma_v)
        if self.sweep == "vcf_dynamic":
            dps = noise.rate_noise.amplitude_sigma_dps(np.asarray(self.inputs), self.dwell_s)
        else:
            dps = np.full(self.points, noise.rate_noise.point_sigma_dps(self.dwell_s))
        return noise.scale * dps * noise.lsb_per_dps


class NoiseLevel(eqx.Module):
    """The noise of one device, read from its data: the rate output's noise model (`RateNoise`) times
    `scale`, in LSB through `lsb_per_dps`, and the DAC sweep's voltmeter."""

    lsb_per_dps: float
    scale: float
    voltmeter_sigma_v: float
    rate_noise: RateNoise = RateNoise()


def predict(gyro: Gyroscope, experiments, sf_temperature=None, tier=Steady()):
    """Noise-free outputs of every point of `experiments` (one device), the steady sweeps' points settled in
    one call of the tier (one compiled settle); with `sf_temperature` (deg C) also the zero-rate scale
    factor there (LSB per deg/s, the central difference identification reports).

    **Returns:** `(outputs per experiment, scale factor or None)`.
    """
    steady = [e for e in experiments if e.sweep in STEADY_KINDS]
    requests = [(e.sweep, jnp.asarray(e.inputs), jnp.asarray(e.temperatures_c), jnp.asarray(e.times_s))
                for e in steady]
    if sf_temperature is not None:
        requests.append(("rate_table", jnp.asarray([-SF_STEP_DPS, SF_STEP_DPS]),
                         jnp.broadcast_to(jnp.asarray(sf_temperature, dtype=float), (2,)), None))
    settled = steady_points(gyro, requests, tier) if requests else ()
    by_name = {id(e): s.rate for e, s in zip(steady, settled)}
    out = []
    for e in experiments:
        if e.sweep in STEADY_KINDS:
            out.append(by_name[id(e)])
        elif e.sweep == "vcf_dynamic":
            out.append(vcf_dynamic_points(gyro, jnp.asarray(e.inputs), jnp.asarray(e.temperatures_c),
                                          e.vcf_dynamic_amplitude_v)[0])
        else:
            out.append(dac_points(gyro, jnp.asarray(e.inputs)))
    sf = None
    if sf_temperature is not None:
        step = settled[-1].rate
        sf = (step[1] - step[0]) / (2.0 * SF_STEP_DPS)
    return tuple(out), sf


@eqx.filter_jit
def _jacobians(model, entries, experiments, sf_temperature, tier):
    def one(model_d, t_sf):
        start = read_values(model_d, entries)
        n = sum(e.size for e in entries)

        def outputs(u):
            gyro = apply_u(model_d, entries, start, u, jnp.zeros(0)).gyroscope()
            preds, sf = predict(gyro, experiments, t_sf, tier)
            return (preds, sf), (preds, sf)

        return jax.jacfwd(outputs, has_aux=True)(jnp.zeros(n))

    return eqx.filter_vmap(one)(model, sf_temperature)


def jacobians(model, entries, experiments, sf_temperature, tier=Steady()):
    """Derivatives of every point of `experiments`, and of the zero-rate scale factor at `sf_temperature`,
    with respect to the internal coordinates of `entries` at the model's values (one compiled call for the
    lot: a `Model` whose leaves have a leading device axis).

    **Returns:** `((jacobian per experiment (device, point, param), scale-factor gradient (device, param)),
    (outputs per experiment (device, point), scale factor (device,)))`.
    """
    (jac, g), (pred, sf) = _jacobians(model, tuple(entries), tuple(experiments),
                                      jnp.asarray(sf_temperature, dtype=float), tier)
    return ((tuple(np.asarray(j) for j in jac), np.asarray(g)),
            (tuple(np.asarray(p) for p in pred), np.asarray(sf)))


def weighted_rows(experiment: CandidateExperiment, jac: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """One run's rows of the standardised residuals' Jacobian (point, param) for one device: each point
    over its sigma, with the run's turn-on bias projected out (the weighted mean of the run removed, as
    `gyrojax/_residuals.py` does) when the sweep is biased."""
    jac = np.asarray(jac, dtype=float)
    if experiment.biased:
        w = 1.0 / sigmas**2
        jac = jac - (w @ jac) / np.sum(w)
    return jac / sigmas[:, None]


def _warm(protocol: Protocol, ambient: float, times: np.ndarray) -> np.ndarray:
    """Die temperature at `times` after power-on of a run that is not a session's first (its fixture is warm),
    from `ambient`; constant when the protocol has no warm-up."""
    if protocol.warmup is None:
        return np.full(times.shape, ambient)
    w = protocol.warmup
    return ambient + w.rise_k * -np.expm1(-times / w.time_constant_s)


def default_experiments(gyro: Gyroscope, protocol: Protocol = Protocol(), ambient_c: float | None = None) -> tuple:
    """The experiments the library can simulate and fit, as one run each with `protocol`'s settings:

    - `rate_table`: the table rates, warm-up plus one dwell per rate;
    - `rate_table_hot`: the same with the chamber `CHAMBER_STEP_K` warmer, after a `CHAMBER_SOAK_S` soak;
    - `vcf_static`: the static virtual-Coriolis sweep at the rate table's timing (closed-loop VCF devices);
    - `vcf_dynamic`: the dynamic virtual-Coriolis sweep, warm-up plus one lock-in dwell per frequency;
    - `dac`: the DAC sweep of seed 000 Table 2 at the words for the table rates, `DAC_READING_S` per word
      (closed-loop devices).

    **Arguments:**

    - `gyro`: the nominal device (a single one): its design values set the VCF voltages and DAC words.
    - `protocol`: the inputs and timing (`gyrojax.Protocol`, default seed 000's and seed 003's).
    - `ambient_c`: the chamber temperature at power-on, deg C (default the device's own at power-on).
    """
    ambient = float(np.asarray(gyro.temperature(0.0))) if ambient_c is None else float(ambient_c)
    out = []
    rates = np.asarray(protocol.rates_dps)
    t_rate = protocol.point_times("rate_table")
    run_min = (protocol.warmup_s + rates.size * protocol.dwell_s) / 60.0
    timing = (("warmup_s", protocol.warmup_s), ("dwell_s", protocol.dwell_s))
    for name, temp, soak in (("rate_table", ambient, 0.0),
                             ("rate_table_hot", ambient + CHAMBER_STEP_K, CHAMBER_SOAK_S)):
        settings = (("rates_dps", list(_floats(rates))), ("chamber_c", temp)) + timing + (
            (("soak_s", soak),) if soak else ())
        out.append(CandidateExperiment(name, "rate_table", _floats(rates), _floats(_warm(protocol, temp, t_rate)),
                                       _floats(t_rate),
                                       run_min + soak / 60.0, protocol.dwell_s, settings))
    has_vcf = float(np.asarray(gyro.vcf_electrode.force_per_volt2)) != 0.0
    if has_vcf and gyro.closed_loop:
        volts = protocol.vcf_static_amplitudes(gyro)
        t_vcf = protocol.point_times("vcf_static")
        out.append(CandidateExperiment(
            "vcf_static", "vcf_static", _floats(volts), _floats(_warm(protocol, ambient, t_vcf)), _floats(t_vcf),
            (protocol.warmup_s + volts.size * protocol.dwell_s) / 60.0, protocol.dwell_s,
            (("vcf_ac_v", list(_floats(volts))), ("vcf_fc_v", 1.0), ("chamber_c", ambient)) + timing))
    if has_vcf:
        f = np.asarray(protocol.vcf_frequencies_hz)
        t_dyn = protocol.point_times("vcf_dynamic")
        out.append(CandidateExperiment(
            "vcf_dynamic", "vcf_dynamic", _floats(f), _floats(_warm(protocol, ambient, t_dyn)), _floats(t_dyn),
            (protocol.warmup_s + f.size * protocol.dynamic_dwell_s) / 60.0, protocol.dynamic_dwell_s,
            (("frequencies_hz", list(_floats(f))), ("vcf_ac_v", protocol.vcf_dynamic_amplitude_v),
             ("chamber_c", ambient), ("warmup_s", protocol.warmup_s), ("dwell_s", protocol.dynamic_dwell_s)),
            protocol.vcf_dynamic_amplitude_v))
    if gyro.closed_loop:
        sf_ideal = float(np.asarray(gyro.ideal_scale_factor()))
        words = np.round(-rates * DEG * sf_ideal)  # seed 000 Table 2: word = -SF x rate
        out.append(CandidateExperiment(
            "dac", "dac", _floats(words), (ambient,) * words.size, (0.0,) * words.size,
            words.size * DAC_READING_S / 60.0, DAC_READING_S,
            (("words", list(_floats(words))), ("reading_s", DAC_READING_S))))
    return tuple(out)


def noise_levels(data, lsb_per_dps: np.ndarray, protocol: Protocol = Protocol(),
                 rate_noise: RateNoise = RateNoise()) -> tuple:
    """Each device's `NoiseLevel` from its data (`FitData`, whose sigmas are the given `output_sigma` or the
    noise a fit estimated): the rate output's noise is `rate_noise` scaled to the median sigma of the
    rate-table points (else the static VCF points), assumed taken at `protocol`'s dwell; the voltmeter's is
    the DAC points' median sigma (else `DAC_VOLTMETER_SIGMA_V`). A device without either keeps `rate_noise`
    as it is."""
    out = []
    for d in range(len(data.devices)):
        lsb = abs(float(lsb_per_dps[d]))
        scale = 1.0
        for sweep in ("rate_table", "vcf_static"):
            if sweep in data.blocks:
                b = data.blocks[sweep]
                real = np.asarray(b.mask[d])
                if real.any():
                    measured = float(np.median(np.asarray(b.sigmas[d])[real]))
                    scale = measured / (rate_noise.point_sigma_dps(protocol.dwell_s) * lsb)
                    break
        volt = DAC_VOLTMETER_SIGMA_V
        if "dac" in data.blocks and np.asarray(data.blocks["dac"].mask[d]).any():
            b = data.blocks["dac"]
            volt = float(np.median(np.asarray(b.sigmas[d])[np.asarray(b.mask[d])]))
        out.append(NoiseLevel(lsb, scale, volt, rate_noise))
    return tuple(out)
