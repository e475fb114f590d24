r"""`plan`: which measurements to add so that each candidate effect becomes testable, and how to spend a time
budget on the scale factor. From the baseline fit's Jacobians and one Jacobian of each candidate experiment's
points; no refit.

**Effects.** Identification's residuals are standardised and linear in the parameters near the fit, so a
candidate effect at its typical size theta (internal units: 1 = typical, `gyrojax/_model/parameters.py`) leaves an
expected chi2 (the noncentrality of its test) of

    lambda = theta^T (I_ee - I_eb I_bb^+ I_be) theta,    I = J_0^T J_0 + sum_k n_k J_k^T (1 - P_k) J_k

per device, with J_0 the standardised Jacobian of the data given, J_k that of one run of experiment k (its
points over their sigma), P_k the projector onto the run's turn-on bias (a nuisance of each new run), n_k
the runs of it, b the nuisance parameters (what the joint fit would free: the baseline's free parameters and
whatever else the joint data determine, by identification's own rule) and e the effect's. lambda is the
Schur complement of the joint Fisher information, computed from stacked triangular factors so that the
condition number is not squared. Summed over the lot's devices, it is the noncentrality of a chi2 test with
df = parameters x devices; the power at level alpha is P(chi2(df, lambda) > chi2_{1-alpha}(df)).

**Scale factor.** Its variance is g^T I_bb^+ g with g its gradient; the design chooses the rates and
static-VCF points of a fresh campaign (runs, points per run, each run with its own bias) within a time
budget greedily (largest variance reduction per minute), for a number of rate-table and VCF runs each, and
keeps the best; seed 000's 22-rate protocol at equal time is the reference.
"""

import dataclasses
import functools
import itertools
import math
from typing import NamedTuple

import equinox as eqx
import jax
import numpy as np

from .._data.table import Table
from .._diagnose.candidates import baseline_fit, baseline_model, candidate_effects
from .._effects.registry import EFFECTS
from .._identify import Fit
from .._identify.fit import p_text
from .._identify.order import DEFAULT_MODEL, model_and_data
from .._identify.problem import sf_temperature
from .._identify.spec import FitSpec, fit_spec
from .._lots.noise import RateNoise
from .._model.fitdata import FitData, fit_data
from .._model.parameters import DEFAULT_FREE, as_model
from .._numerics.testability import MIN_TYPICAL_CHI2, is_testable
from .._progress import as_progress
from .._sweeps.protocol import Protocol
from .._sweeps.rate_table import RateTable
from .._sweeps.registry import SWEEP_KINDS
from .._sweeps.vcf_static import VcfStatic
from .experiment import (
    CandidateExperiment,
    default_experiments,
    jacobians,
    noise_levels,
    weighted_rows,
    window_correlation,
)
from .power import power, required_noncentrality
from .simulate import simulate_runs


_RATE, _VCF = RateTable.name, VcfStatic.name
"""The scale-factor design's kinds (their default experiments' names)."""

SF_HELD_TOL = 0.1
"""A design determines the scale factor when the part of its gradient along directions the design cannot fix
is below this many standard errors (identification's own test). On the data given, whether the scale factor
is determined is identification's own verdict: the baseline fit's status."""

MAX_BUDGET_MIN = 7 * 24 * 60.0
"""min: the longest scale-factor design the planner makes, a week of rate-table time per device. A longer
budget is refused: the design is many short +/-200 deg/s runs, and over weeks the device's drift, the table's
own calibration and the lot's schedule, none of which the model holds, decide the scale factor."""

LONG_BUDGET_MIN = 24 * 60.0
"""min: a design longer than a day of rate-table time per device is carried out with a note saying so (and
what it is for a lot measured on one table)."""

MIN_NONLINEARITY_RATES = 3
"""Distinct rates below which a design measures no nonlinearity: a straight line through two rates leaves no
residual (seed 000's nonlinearity is the largest residual from the least-squares line)."""

MAX_EXACT_COMBINATIONS = 4096
"""Above this many combinations of runs (`(max_repeats + 1) ** experiments`), the cheapest set is searched
greedily instead of exactly."""

SAME_SHAPE = 0.95
"""|cos| between two candidates' fingerprints on the data given above which they are ambiguous (the
diagnosis's default `ambiguity`)."""


class Recommendation(eqx.Module):
    """Runs of one experiment in a recommended set: how many, their minutes, and the expected chi2 and power
    of the effect's test with only these runs added to the data given."""

    experiment: CandidateExperiment
    runs: int = eqx.field(static=True)
    expected_chi2: float = eqx.field(static=True)
    power: float = eqx.field(static=True)

    @property
    def minutes(self) -> float:
        return self.runs * self.experiment.minutes

    def to_json(self) -> dict:
        return {"sweep": self.experiment.name, "kind": self.experiment.kind,
                "settings": dict(self.experiment.settings), "runs": self.runs, "minutes": self.minutes,
                "expected_chi2": self.expected_chi2, "power": self.power}


class CandidatePlan(eqx.Module):
    """What one candidate effect needs: its test on the data given, what one run of each experiment adds,
    and the cheapest set of runs with which its test reaches the target power.

    `testable` is `gyrojax._numerics.testability`'s rule, the diagnosis's own: a typical size leaves an expected chi2
    of at least `MIN_TYPICAL_CHI2` on the data given. `detected` is the stronger demand the plan works to: the
    test's power at the typical size reaches `target_power`; runs are recommended until it does."""

    effect: str = eqx.field(static=True)
    df: int = eqx.field(static=True)
    expected_chi2: float = eqx.field(static=True)  # on the data given
    power: float = eqx.field(static=True)
    testable: bool = eqx.field(static=True)
    ambiguous_with: tuple = eqx.field(static=True)
    per_experiment: tuple = eqx.field(static=True)  # (name, minutes, expected chi2 with one run, power)
    recommended: tuple = eqx.field(static=True)  # Recommendation per experiment of the cheapest set
    recommended_chi2: float = eqx.field(static=True)
    recommended_power: float = eqx.field(static=True)
    reason: str = eqx.field(static=True)
    detected: bool = eqx.field(static=True, default=False)  # power at the typical size reaches the target

    @property
    def minutes(self) -> float:
        return float(sum(r.minutes for r in self.recommended))

    def to_json(self) -> dict:
        return {"testable": self.testable, "detected": self.detected, "df": self.df,
                "expected_chi2": self.expected_chi2, "power": self.power,
                "ambiguous_with": list(self.ambiguous_with),
                "experiments": {name: {"minutes": m, "expected_chi2": lam, "power": p,
                                       "chi2_per_minute": (lam - self.expected_chi2) / m}
                                for name, m, lam, p in self.per_experiment},
                "recommended": [r.to_json() for r in self.recommended],
                "recommended_minutes": self.minutes, "recommended_expected_chi2": self.recommended_chi2,
                "recommended_power": self.recommended_power, "reason": self.reason}


class ScaleFactorDesign(eqx.Module):
    """The campaign within `budget_min` that minimises the scale factor's standard error, and seed 000's
    protocol at equal time (both predicted for the baseline model, per device; mean over the lot in
    `summary`)."""

    budget_min: float = eqx.field(static=True)
    rates_dps: tuple = eqx.field(static=True)
    rate_runs: int = eqx.field(static=True)
    vcf_rates_dps: tuple = eqx.field(static=True)
    vcf_runs: int = eqx.field(static=True)
    minutes: float = eqx.field(static=True)
    stderr: tuple = eqx.field(static=True)  # per device, LSB per deg/s
    seed000_runs: int = eqx.field(static=True)
    seed000_minutes: float = eqx.field(static=True)
    seed000_stderr: tuple = eqx.field(static=True)
    data_stderr: tuple = eqx.field(static=True)  # on the data given (NaN where identify does not determine it)
    scale_factor: tuple = eqx.field(static=True)
    # identification's reason, per device, where the data given do not determine the scale factor ("" where
    # they do)
    data_not_determined: tuple = eqx.field(static=True, default=())

    @property
    def ratio(self) -> float:
        """The design's stderr over seed 000's, mean over devices (below 1: the design is better)."""
        return float(np.mean(np.asarray(self.stderr) / np.asarray(self.seed000_stderr)))

    def rate_table(self) -> RateTable:
        """The design's rate table, `gyrojax.sweeps.RateTable` at its rates (simulate it with `runs=rate_runs`)."""
        return RateTable(rates_dps=self.rates_dps)

    def to_json(self) -> dict:
        return {"budget_min": self.budget_min, "rates_dps": list(self.rates_dps), "rate_runs": self.rate_runs,
                "vcf_rates_dps": list(self.vcf_rates_dps), "vcf_runs": self.vcf_runs, "minutes": self.minutes,
                "stderr": list(self.stderr), "seed000": {"rates_dps": "seed 000's 22", "runs": self.seed000_runs,
                                                         "minutes": self.seed000_minutes,
                                                         "stderr": list(self.seed000_stderr)},
                "ratio": self.ratio, "data_stderr": list(self.data_stderr),
                "data_not_determined": [w or None for w in self.data_not_determined],
                "scale_factor": [math.nan if w else v for v, w in
                                 zip(self.scale_factor, self.data_not_determined or ("",) * len(self.scale_factor))],
                "unit": "LSB/(deg/s)"}


class Plan(eqx.Module):
    """The solution of `plan`: per candidate effect a `CandidatePlan`, the scale-factor design, the
    experiments considered, the baseline fit, and how the search was made."""

    candidates: tuple  # CandidatePlan
    scale_factor: ScaleFactorDesign | None  # None when plan was told not to design it
    experiments: tuple  # CandidateExperiment
    baseline: Fit  # the fit whose Jacobians the plan used (with every candidate at zero)
    alpha: float = eqx.field(static=True)
    target_power: float = eqx.field(static=True)
    max_repeats: int = eqx.field(static=True)
    devices: tuple = eqx.field(static=True)
    search: str = eqx.field(static=True, default="exact")
    warnings: tuple = eqx.field(static=True, default=())  # what the reader must know before acting on it

    def candidate(self, name: str) -> CandidatePlan:
        for c in self.candidates:
            if c.effect == name:
                return c
        raise ValueError(f"no candidate {name!r} in this plan; it has {', '.join(c.effect for c in self.candidates)}.")

    def runs(self) -> dict:
        """The runs to add: the union of the experiments recommended for the candidates whose test does not
        reach the target power on the data given, per experiment name `(experiment, runs, candidates)`: the
        most runs any candidate asks for, and the candidates asking (in the plan's order)."""
        out = {}
        for c in self.candidates:
            for r in c.recommended:
                e, k, who = out.get(r.experiment.name, (r.experiment, 0, ()))
                out[r.experiment.name] = (e, max(k, r.runs), who + (c.effect,))
        return out

    def free(self, free=DEFAULT_FREE) -> tuple:
        """The `free` argument of `gyrojax.diagnose` (or `identify`) for the data given plus `runs()`: `free`
        and the parameters those runs read (`CandidateExperiment.reads`), as the plan's expected chi2 assumes."""
        read = (p for e, _, _ in self.runs().values() for p in e.reads)
        return tuple(dict.fromkeys(tuple(free) + tuple(read)))

    def simulate(self, gyro, table=None, *, devices: int = 1, runs: int = 1, seed: int = 0,
                 noise_seed: int = 1000) -> Table:
        """A simulation study's next step: `runs()` simulated for the lot that `gyrojax.simulate_table(gyro,
        devices=devices, runs=runs, seed=seed)` drew (`gyrojax.campaign_lot`), each device on its own with
        noise seed `seed + noise_seed + i` (a draw independent of the data's), labelled as that table's
        devices and numbered after its `runs` runs. An experiment at a warmer chamber (`<kind>_hot`) runs
        with the die's ambient (a `ConstantTemperature`) at its chamber's temperature. Returns `table` (the
        data given) with these runs appended (a column missing on either side is NaN there), or the runs
        alone when `table` is None; diagnose it with `free=self.free(...)`. Raises a `ValueError` when
        nothing is recommended."""
        return simulate_runs(self.runs(), gyro, table, devices=devices, runs_given=runs, seed=seed,
                             noise_seed=noise_seed)

    def to_json(self) -> dict:
        """The plan as JSON (numbers that are not finite, e.g. an undetermined stderr, are null)."""
        return _finite({"candidates": {c.effect: c.to_json() for c in self.candidates},
                "scale_factor": None if self.scale_factor is None else self.scale_factor.to_json(),
                "experiments": {e.name: e.to_json() for e in self.experiments},
                "alpha": self.alpha, "target_power": self.target_power, "max_repeats": self.max_repeats,
                "search": self.search, "warnings": list(self.warnings), "min_typical_chi2": MIN_TYPICAL_CHI2,
                "devices": list(self.devices)})

    def summary(self) -> str:
        lines = [f"warning: {w}" for w in self.warnings]
        lines += [f"candidate effects (expected chi2 of a typical-size effect: testable at >= {MIN_TYPICAL_CHI2:g}, "
                  f"as diagnose rules; detected at power {self.target_power:g}, alpha = {self.alpha:g}; "
                  f"{len(self.devices)} device(s)):"]
        for c in self.candidates:
            amb = f", ambiguous with {', '.join(c.ambiguous_with)}" if c.ambiguous_with else ""
            state = (" -> detected" if c.detected else " -> testable, below the target power" if c.testable
                     else " -> not testable")
            lines.append(f"  {c.effect:<20} now: chi2 {c.expected_chi2:10.3g}, power {c.power:.2f}{amb}{state}")
            if c.detected:
                continue
            best = max(c.per_experiment, key=lambda x: (x[2] - c.expected_chi2) / x[1])
            lines.append(f"  {'':<20} best per minute: {best[0]} (+{(best[2] - c.expected_chi2) / best[1]:.3g} "
                         "chi2/min)")
            if c.recommended:
                what = " + ".join(f"{r.runs} x {r.experiment.name}" for r in c.recommended)
                lines.append(f"  {'':<20} add {what} ({c.minutes:.0f} min): chi2 {c.recommended_chi2:.3g}, power "
                             f"{c.recommended_power:.2f}")
            else:
                lines.append(f"  {'':<20} {c.reason}")
        s = self.scale_factor
        if s is None:
            return "\n".join(lines)
        mean = float(np.mean(s.stderr))
        ref = float(np.mean(s.seed000_stderr))
        lines += [f"scale factor in {s.budget_min:g} min (per device, LSB per deg/s, mean over the lot; point "
                  "noise at the data's output_sigma, neighbours sharing the bias wander):",
                  "  on the data given: " + _data_sf_text(s, self.devices),
                  f"  seed 000's 22 rates x {s.seed000_runs} run(s) ({s.seed000_minutes:.0f} min): stderr {ref:.4g}",
                  f"  design: rates {list(s.rates_dps)} x {s.rate_runs} run(s)"
                  + (f" + VCF at {list(s.vcf_rates_dps)} deg/s x {s.vcf_runs} run(s)" if s.vcf_runs else "")
                  + f" ({s.minutes:.0f} min): stderr {mean:.4g}, {s.ratio:.3g} x seed 000's"]
        return "\n".join(lines)


def _data_sf_text(s: ScaleFactorDesign, devices) -> str:
    """The scale factor on the data given, in identification's terms: its stderr where the data determine
    it, else that they do not, and why (identify's reason)."""
    undetermined = [(d, w) for d, w in zip(devices, s.data_not_determined) if w]
    ok = [k for k, w in enumerate(s.data_not_determined or ("",) * len(devices)) if not w]
    text = ""
    if ok:
        se, sf = np.mean([s.data_stderr[k] for k in ok]), np.mean([s.scale_factor[k] for k in ok])
        some = f", {len(ok)} of {len(devices)} devices" if undetermined else ""
        text = f"stderr {se:.4g} (SF {sf:.6g}{some})"
    if undetermined:
        d, why = undetermined[0]
        text += ("; " if text else "") + (f"SF not determined by the data on {len(undetermined)} of {len(devices)} "
                                          f"device(s), as identify rules (e.g. {d}: {why})")
    return text


def _finite(obj):
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _reduce(rows: np.ndarray) -> np.ndarray:
    """A triangular factor R with R^T R = rows^T rows (fewer rows, the same Fisher information, without
    squaring the condition)."""
    rows = np.asarray(rows, dtype=float)
    if rows.shape[0] == 0:
        return np.zeros((0, rows.shape[1]))
    return np.linalg.qr(rows, mode="r")


def _kept(blocks, cols, threshold):
    """Which of `cols` a joint fit would free: identification's rule on the lot's stacked Jacobian (a column
    below `threshold` is held; then, while a combination is, its last member in order of preference).
    `blocks`: per device, a matrix whose Gram matrix is the information."""
    stacked = np.concatenate([b[:, cols] for b in blocks]) / math.sqrt(len(blocks))
    keep = list(range(len(cols)))
    norms = np.linalg.norm(stacked, axis=0)
    top = float(np.max(norms)) if norms.size else 0.0
    keep = [j for j in keep if norms[j] >= threshold and norms[j] >= 1e-12 * top]
    while keep:
        a = stacked[:, keep]
        if a.shape[0] < a.shape[1]:
            a = np.concatenate([a, np.zeros((a.shape[1] - a.shape[0], a.shape[1]))])
        _, s, vt = np.linalg.svd(a, full_matrices=False)
        i = int(np.argmin(s))
        if s[i] >= threshold and s[i] >= 1e-12 * s.max():
            break
        v = np.abs(vt[i])
        keep.remove(keep[int(np.max(np.nonzero(v > 0.3 * v.max())[0]))])
    return [cols[j] for j in keep]


def _nuisances(blocks, counts, base_free, pool, reading, threshold):
    """The columns a joint fit of the data given and `counts` runs of each experiment would free: the
    baseline's free ones without added runs; else identification's rule (`_kept`) over `pool` and the
    columns `reading[j]` of the parameters experiment j reads, for each experiment with runs."""
    if not any(counts):
        return list(base_free)
    read = {i for j, k in enumerate(counts) if k for i in reading[j]}
    return _kept(blocks, sorted(set(pool) | read), threshold)


def _residual_chi2(a, nuisance, effect, theta):
    """|(1 - P_b) A_e theta|^2 for one device's factor `a`: what the effect leaves after the nuisance
    columns (scaled to unit norm for the least squares) took their share."""
    f = a[:, effect] @ theta
    if not nuisance:
        return float(f @ f)
    b = a[:, nuisance]
    norm = np.linalg.norm(b, axis=0)
    b = b / np.where(norm > 0, norm, 1.0)
    c = np.linalg.lstsq(b, f, rcond=None)[0]
    r = f - b @ c
    return float(r @ r)


def _typical(fit: Fit, name: str, cols) -> np.ndarray:
    """The effect at its typical size in internal units: typical(1.0) over each element's scale."""
    entries = [e for e in fit.entries if e.effect_index is not None and e.label.split(".")[0] == name]
    typ = EFFECTS[name].typical(1.0)
    out = [np.ravel(np.asarray(getattr(typ, e.field), dtype=float)) / np.asarray(e.scale) for e in entries]
    theta = np.concatenate(out) if out else np.zeros(0)
    if theta.size != len(cols):
        raise ValueError(f"effect {name!r}: {len(cols)} columns in the fit, {theta.size} typical values.")
    return theta


def _baseline(data, model, fit, candidates, spec, reads, say):
    """The baseline fit with every candidate effect in the model at zero and held (as the diagnosis fits it),
    and a held column for each parameter of `reads` (what the experiments read) that the baseline does not
    free, reusing a given fit's Jacobian when it has those columns. Returns (fit, candidates, the read
    parameters added as held columns)."""
    if fit is not None:
        if data is not None:
            data = data if isinstance(data, FitData) else fit_data(data)
        base = baseline_model(fit, data)
        data = fit.data if data is None else data
    else:
        if data is None:
            raise ValueError("plan needs data (a gyrojax.Table or FitData) or a fit of it; got neither.")
        data = data if isinstance(data, FitData) else fit_data(data)
        base = as_model(model)
    candidates = candidate_effects(base, candidates, "plan")
    free = spec.free if fit is None else tuple(e.label for e in fit.entries if e.effect_index is None)
    added = tuple(p for p in reads if p not in free)
    if fit is not None:
        have = set(fit.names)
        missing = [c for c in candidates if not any(n.startswith(c + ".") for n in have)]
        if not missing and not added:
            return fit, candidates, ()
        say("evaluating the given fit with every candidate effect at zero" + (f" and {', '.join(added)} held"
            if added else "") + f" (its Jacobian lacks {', '.join(missing + list(added))})")
    _, fit = baseline_fit(base, data if fit is None else fit.data, candidates,
                          dataclasses.replace(spec, free=tuple(free) + added), also_held=added,
                          evaluate_only=fit is not None, estimate_noise=None if fit is None else False, say=say)
    return fit, candidates, added


def _data_rows(fit: Fit) -> int:
    return int(sum(int(np.prod(fit.data.blocks[s].inputs.shape[1:])) for s in fit.data.sweeps))


def _sf_variance(info, g, cols, threshold, meat=None):
    """Variance of the scale factor g^T I^+ g over the columns `cols` a fit of this information would free,
    and whether those determine it (its gradient's part along what the design cannot fix is below
    `SF_HELD_TOL` standard errors). `info` is (param, param). With `meat` (param, param: J^T R J, R the
    standardised noise's correlation), the variance of the weighted least-squares estimate under correlated
    noise, g^T I^+ meat I^+ g."""
    sub = info[np.ix_(cols, cols)]
    d = np.sqrt(np.maximum(np.diag(sub), 0.0))
    if not cols or np.any(d <= 0):
        return math.inf
    evals, evecs = np.linalg.eigh(sub / np.outer(d, d))
    keep = evals > evals.max() * 1e-12
    gs = g[cols] / d
    proj = evecs[:, keep].T @ gs
    if meat is None:
        var = float(np.sum(proj**2 / evals[keep]))
    else:
        h = evecs[:, keep] @ (proj / evals[keep])  # I^+ g in the scaled coordinates
        var = float(h @ (meat[np.ix_(cols, cols)] / np.outer(d, d)) @ h)
    # determined: the gradient lies in the span of what the data fix (singular values >= threshold)
    ev_all, vec_all = np.linalg.eigh(sub)
    weak = vec_all[:, np.sqrt(np.maximum(ev_all, 0.0)) < threshold]
    part = float(np.linalg.norm(weak.T @ g[cols])) if weak.size else 0.0
    return var if part <= SF_HELD_TOL * math.sqrt(max(var, 0.0)) else math.inf


def plan(model=DEFAULT_MODEL, data=None, *, fit: Fit | None = None, candidates=None, experiments=None,
         budget_min: float | None = None, alpha: float = 0.01, target_power: float = 0.9, max_repeats: int = 3,
         protocol: Protocol = Protocol(), free=DEFAULT_FREE, identifiability_threshold: float = 1.0,
         scale_factor: bool = True, spec: FitSpec | None = None, progress=True) -> Plan:
    r"""Plan the measurements that make each candidate effect testable, and the scale factor's calibration.

    **Arguments:**

    - `model`: the baseline (a preset name, `Gyroscope` or `gyrojax.Model`) fitted to `data` when no `fit`
      is given, with every candidate effect held at zero (as `gyrojax.diagnose` fits it).
    - `data`: a `gyrojax.Table` (or `FitData`): the measurements made so far. May be None when `fit` is given
      (its data are used). The old order `plan(data, model)` still works, with a `DeprecationWarning`.
    - `fit`: a `gyrojax.Fit` of `data` (from `identify`, `diagnose(...).baseline` or `load_fit`): the
      baseline; its Jacobian is reused (evaluated once more if it lacks the candidates' columns).
    - `candidates`: effect names to plan for (default every registered effect the device supports and the
      baseline lacks).
    - `experiments`: `CandidateExperiment`s that may be added (default `default_experiments` of the baseline's
      device with `protocol`).
    - `budget_min`: test time of the scale factor's design, minutes (default three runs of seed 000's
      protocol, as seed 000 measured: 135 min with the default protocol).
    - `alpha`, `target_power`: an effect is testable when its test at level `alpha` (df = its parameters x
      devices) rejects with probability `target_power` at its typical size.
    - `max_repeats`: the search tries 0 to `max_repeats` runs of each experiment.
    - `protocol`: timing of the default experiments and of seed 000's reference (its rate table: the
      `experiments`' own `rate_table`, else seed 000's 22 rates).
    - `free`: the baseline's free parameters when it is fitted here.
    - `identifiability_threshold`: identification's threshold (what a joint fit would hold).
    - `scale_factor`: False to plan the effects only (`Plan.scale_factor` is then None; the design's greedy
      search is the slow part of a plan on a lot).
    - `spec`: a `gyrojax.FitSpec`: how the baseline is fitted here (solver, recovery, starts, what is free and
      held ...), instead of `free`; the candidates and the parameters the experiments read are held on top of
      its `hold`, and those read are freed on top of its `free`.
    - `progress`: as for `gyrojax.diagnose`.

    **Returns:** a `Plan`.
    """
    _check_arguments(alpha, target_power, max_repeats, protocol, data)
    model, data = model_and_data("plan", model, data, data_required=False)
    spec = fit_spec(spec, "plan", free=free)
    experiments = None if experiments is None else tuple(experiments)
    budget_min = _budget(experiments, protocol, budget_min)
    say = as_progress(progress, "gyrojax.plan")
    # what the experiments read beyond the baseline (default experiments: whatever a kind may read)
    reads = tuple(dict.fromkeys(p for cls in SWEEP_KINDS.values() for p in cls.reads)) if experiments is None else \
        tuple(dict.fromkeys(p for e in experiments if isinstance(e, CandidateExperiment) for p in e.reads))
    fit, candidates, added = _baseline(data, model, fit, candidates, spec, reads, say)
    one = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, fit.model.device)
    experiments = _experiments(experiments, one, protocol, fit, say)
    names = [e.name for e in experiments]
    # The scale-factor design picks its points among the rate table's (and static VCF's) of the default kinds.
    design_exps = tuple(e for e in default_experiments(one, protocol) if e.name in (_RATE, _VCF))
    all_exps = experiments + tuple(e for e in design_exps if e.name not in names)
    say(f"Jacobians of {len(all_exps)} experiments' points ({sum(e.points for e in all_exps)} points per device) "
        f"at the baseline, {len(fit.devices)} device(s)")
    t_sf = sf_temperature(fit.data)  # where identification reports the scale factor
    (jac_e, g), (pred_e, sf) = jacobians(fit.model, fit.entries, all_exps, t_sf)
    noise = noise_levels(fit.data, sf, protocol)
    jac0 = np.asarray(fit.jacobian, dtype=float)
    rows = _information_rows(fit, jac0, candidates, added, experiments, jac_e, pred_e, noise,
                             identifiability_threshold)
    say(f"expected chi2 of {len(candidates)} candidate effects on the data given and with every combination of "
        f"0..{max_repeats} runs of {len(experiments)} experiments")
    thetas = {c: _typical(fit, c, rows.cand_cols[c]) for c in candidates}
    prints = _fingerprints(rows, candidates, thetas)
    exact, combos, search = _search_order(experiments, max_repeats)
    plans = []
    for c in candidates:
        plans.append(_candidate_plan(c, rows, thetas[c], _ambiguous(c, candidates, prints), experiments, alpha,
                                     target_power, max_repeats, combos))
        _say_candidate(say, plans[-1])
    design = None if not scale_factor else _sf_design(fit, jac0, g, sf, all_exps, jac_e, noise, rows.pool,
                                                      budget_min, protocol, identifiability_threshold, say)
    warnings = _warnings(fit, design, len(fit.devices))
    for w in warnings:
        say(f"warning: {w}")
    return Plan(tuple(plans), design, experiments, fit, float(alpha), float(target_power), max_repeats, fit.devices,
                search, warnings)


def _check_arguments(alpha, target_power, max_repeats, protocol, data) -> None:
    """`plan`'s scalar arguments and the type of its data, each with what is expected."""
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha <= 0.5):
        raise ValueError(f"alpha must be a significance level in (0, 0.5], got {alpha!r}.")
    if not (isinstance(target_power, (int, float)) and 0.0 < target_power < 1.0):
        raise ValueError(f"target_power must be in (0, 1), got {target_power!r}.")
    if not isinstance(max_repeats, int) or isinstance(max_repeats, bool) or not 1 <= max_repeats <= 8:
        raise ValueError(f"max_repeats must be an integer in 1..8, got {max_repeats!r}.")
    if not isinstance(protocol, Protocol):
        raise ValueError(f"protocol must be a gyrojax.Protocol, got {protocol!r}.")


def _budget(experiments, protocol: Protocol, budget_min) -> float:
    """The scale factor's design budget, minutes: `budget_min` checked against one run of seed 000's reference
    (the experiments' own rate table, else the default 22 rates) and `MAX_BUDGET_MIN`; default three runs."""
    reference = next((e.sweep for e in experiments or () if isinstance(e, CandidateExperiment)
                      and e.name == _RATE and isinstance(e.sweep, RateTable)), RateTable())
    seed_run_min = reference.run_minutes(protocol)
    if budget_min is None:
        budget_min = 3 * seed_run_min
    if not (isinstance(budget_min, (int, float)) and math.isfinite(budget_min) and budget_min >= seed_run_min):
        raise ValueError(f"budget_min must be at least one run of seed 000's protocol ({seed_run_min:g} min), got "
                         f"{budget_min!r}.")
    if budget_min > MAX_BUDGET_MIN:
        raise ValueError(f"budget_min {budget_min:.6g} min is {_duration(budget_min)} of rate-table time per device; "
                         f"the planner designs at most {MAX_BUDGET_MIN:g} min ({_duration(MAX_BUDGET_MIN)}): over "
                         "longer, drift, the table's calibration and the schedule decide the scale factor, not the "
                         "noise the design averages down.")
    return budget_min


def _experiments(experiments, one, protocol: Protocol, fit: Fit, say) -> tuple:
    """The candidate experiments: those given, each checked, or the defaults of device `one` less the kinds
    with no noise model of their own and no points in the data; distinct names, at least one."""
    defaults = experiments is None
    if defaults:
        experiments = default_experiments(one, protocol)
    experiments = tuple(experiments)
    for e in experiments:
        if not isinstance(e, CandidateExperiment):
            raise ValueError(f"experiments must be gyrojax.CandidateExperiment, got {type(e).__name__}.")
    if defaults:
        # A kind with no noise model of its own (AbstractSweep.point_sigmas, relative_sigma) is planned only
        # where the data give its points' sigmas.
        dropped = [e.name for e in experiments if e.kind not in fit.data.blocks and e.sweep.point_sigmas(
            np.asarray(e.inputs), protocol, RateNoise(), 1.0, 1.0) is None
            and e.sweep.relative_sigma(protocol) is None]
        if dropped:
            say(f"left out (no noise model, none of their points in the data): {', '.join(dropped)}")
        experiments = tuple(e for e in experiments if e.name not in dropped)
    names = [e.name for e in experiments]
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"experiments need distinct names, at least one; got {names}.")
    return experiments


class _Rows(NamedTuple):
    """The information the effects' part of a plan is computed from: per device, the reduced standardised rows
    of the data given (`r0`) and of one run of each experiment (`rk[k]`), and which columns are what."""

    r0: list
    rk: list
    cand_cols: dict  # candidate -> its columns
    base_free: list  # the baseline fit's free columns
    pool: list  # the columns a joint fit may free (identification's rule decides which)
    reading: list  # per experiment, the columns of the parameters only it reads (freed with its runs)
    threshold: float  # identification's threshold
    n_dev: int


def _information_rows(fit: Fit, jac0, candidates, added, experiments, jac_e, pred_e, noise, threshold) -> _Rows:
    """The reduced rows of the data given and of one run of each experiment, per device, and the columns a
    joint fit may free."""
    n_dev = len(fit.devices)
    free_mask = np.asarray(fit.free)
    phys = [i for i, e in enumerate(_columns(fit)) if e is None]
    cand_cols = {c: [i for i, nm in enumerate(fit.names) if nm.startswith(c + ".")] for c in candidates}
    held_cands = {i for cols in cand_cols.values() for i in cols}
    # A parameter only an experiment kind reads (omega_x, by the drive frequency) is a nuisance of the sets
    # with runs of that kind only: as the diagnosis of those data frees it (`Plan.free`).
    by_label = {p: [i for i, nm in enumerate(fit.names) if nm == p or nm.startswith(p + "[")] for p in added}
    added_cols = {i for cols in by_label.values() for i in cols}
    pool = sorted((set(phys) | {i for i in np.nonzero(free_mask)[0] if i not in held_cands}) - added_cols)
    reading = [[i for p in e.reads if p in added for i in by_label[p]] for e in experiments]
    base_free = [int(i) for i in np.nonzero(free_mask)[0]]
    r0 = [_reduce(jac0[d]) for d in range(n_dev)]
    rk = [[_reduce(weighted_rows(e, jac_e[k][d], e.sigmas(noise[d], pred_e[k][d]))) for d in range(n_dev)]
          for k, e in enumerate(experiments)]
    return _Rows(r0, rk, cand_cols, base_free, pool, reading, threshold, n_dev)


def _fingerprints(rows: _Rows, candidates, thetas) -> dict:
    """Each candidate's typical-size fingerprint on the data given, after the baseline's free parameters took
    their share, over the lot's devices (for ambiguity)."""
    prints = {}
    for c in candidates:
        fp = []
        for d in range(rows.n_dev):
            a = rows.r0[d]
            f = a[:, rows.cand_cols[c]] @ thetas[c]
            b = a[:, rows.base_free]
            if rows.base_free:
                f = f - b @ np.linalg.lstsq(b, f, rcond=None)[0]
            fp.append(f)
        prints[c] = np.concatenate(fp)
    return prints


def _ambiguous(c: str, candidates, prints) -> tuple[str, ...]:
    """The candidates ambiguous with `c`: both fingerprints visible on the data given (a typical size changes
    the chi2 by more than 1, the diagnosis's `min_typical_chi2`) and nearly collinear."""
    pn = np.linalg.norm(prints[c])
    return tuple(o for o in candidates if o != c and pn > 1.0 and np.linalg.norm(prints[o]) > 1.0
                 and abs(prints[c] @ prints[o]) / (pn * np.linalg.norm(prints[o])) > SAME_SHAPE)


def _search_order(experiments, max_repeats: int):
    """How the runs are searched: (exact, the combinations cheapest first or None, the search's description).
    Exact over every combination of 0..`max_repeats` runs where they are at most `MAX_EXACT_COMBINATIONS`,
    else greedy."""
    exact = (max_repeats + 1) ** len(experiments) <= MAX_EXACT_COMBINATIONS
    combos = sorted(itertools.product(range(max_repeats + 1), repeat=len(experiments)),
                    key=lambda n: (sum(k * e.minutes for k, e in zip(n, experiments)), sum(n))) if exact else None
    search = (f"exact: every combination of 0..{max_repeats} runs of each experiment, cheapest first" if exact else
              f"greedy: one run at a time, the largest expected-chi2 gain per minute, up to {max_repeats} runs of "
              f"each experiment ({len(experiments)} experiments: more than {MAX_EXACT_COMBINATIONS} combinations)")
    return exact, combos, search


def _expected_chi2(rows: _Rows, counts, cols, amb_cols, theta) -> float:
    """The expected chi2 of an effect (columns `cols`, typical size `theta`) over the lot, with `counts` runs of
    each experiment added and the ambiguous candidates' columns `amb_cols` free beside the nuisances."""
    blocks = [np.concatenate([rows.r0[d]] + [math.sqrt(k) * rows.rk[j][d] for j, k in enumerate(counts) if k])
              for d in range(rows.n_dev)]
    nuis = _nuisances(blocks, counts, rows.base_free, rows.pool, rows.reading, rows.threshold)
    nuis = [i for i in nuis if i not in cols] + amb_cols
    return sum(_residual_chi2(blocks[d], nuis, cols, theta) for d in range(rows.n_dev))


def _cheapest_runs(lam, need: float, now: float, experiments, max_repeats: int, combos):
    """The first run counts (cheapest first over `combos`; greedy, the largest gain per minute, where `combos`
    is None) whose expected chi2 `lam(counts)` reaches `need`: (counts, chi2), or None."""
    if combos is not None:
        for counts in combos[1:]:
            lc = lam(counts)
            if lc >= need:
                return counts, lc
        return None
    counts, lc = (0,) * len(experiments), now
    while True:
        steps = [tuple(k + (i == j) for i, k in enumerate(counts)) for j in range(len(experiments))
                 if counts[j] < max_repeats]
        if not steps:
            return None
        gains = [(lam(c) - lc) / experiments[j].minutes for j, c in
                 zip([j for j in range(len(experiments)) if counts[j] < max_repeats], steps)]
        counts = steps[int(np.argmax(gains))]
        lc = lam(counts)
        if lc >= need:
            return counts, lc


def _unreachable(c: str, amb, top: float, need: float, names, max_repeats: int, target_power: float) -> str:
    """Why no combination of runs makes candidate `c` testable: the chi2 `top` all of them leave against the
    `need`ed one, and what else would reveal it."""
    # What the effect's own text names is not offered where these runs include it and it did not help.
    hidden = (f"with {', '.join(amb)} free (ambiguous: they take what it leaves)" if amb else
              "after the baseline took its share")
    # An ambiguous candidate's own revealing text may name a sweep among these runs: that sweep separates the
    # two at a larger size (diagnose's "X separates them" is at the fitted size), not at the typical size
    # planned here, so it is not offered.
    beyond = (f"at its typical size none of these runs tells it from {', '.join(amb)} (a sweep that "
              "separates them at a larger fitted size, as diagnose may report, does not at this one)"
              if amb else f"revealed by: {EFFECTS[c].revealed_by or 'no measurement named'}")
    return (f"no combination of up to {max_repeats} runs of {', '.join(names)} brings it to power "
            f"{target_power:g}: a typical size leaves chi2 {top:.3g} with all of them {hidden}, "
            f"{need:.3g} is needed" + ("" if is_testable(top) else
                                       f" (below {MIN_TYPICAL_CHI2:g}: not testable)") + f"; {beyond}")


def _candidate_plan(c: str, rows: _Rows, theta, amb, experiments, alpha, target_power, max_repeats,
                    combos) -> CandidatePlan:
    """Candidate `c`'s plan: its expected chi2 and power now and with one run of each experiment, and the
    cheapest runs that bring it to `target_power` (none where it is detected already), or why none do."""
    cols = rows.cand_cols[c]
    df = len(cols) * rows.n_dev
    need = required_noncentrality(df, target_power, alpha)
    amb_cols = [i for o in amb for i in rows.cand_cols[o]]
    lam = functools.partial(_expected_chi2, rows, cols=cols, amb_cols=amb_cols, theta=theta)
    now = lam((0,) * len(experiments))
    p_now = power(now, df, alpha)
    per = []
    for j, e in enumerate(experiments):
        counts = tuple(1 if i == j else 0 for i in range(len(experiments)))
        lj = lam(counts)
        per.append((e.name, e.minutes, lj, power(lj, df, alpha)))
    testable = is_testable(now)  # the diagnosis's rule (gyrojax/_numerics/testability.py)
    detected = p_now >= target_power
    recommended, rec_chi2, rec_power, reason = (), now, p_now, ""
    if detected:
        reason = f"detected on the data given (power {p_now:.2f} >= {target_power:g})"
    else:
        found = _cheapest_runs(lam, need, now, experiments, max_repeats, combos)
        if found is None:
            top = lam((max_repeats,) * len(experiments))
            reason = _unreachable(c, amb, top, need, [e.name for e in experiments], max_repeats, target_power)
        else:
            counts, rec_chi2 = found
            rec_power = power(rec_chi2, df, alpha)
            recs = []
            for j, k in enumerate(counts):
                if k:
                    only = tuple(k if i == j else 0 for i in range(len(experiments)))
                    lk = lam(only)
                    recs.append(Recommendation(experiments[j], k, lk, power(lk, df, alpha)))
            recommended = tuple(recs)
            reason = ("cheapest combination (exact search)" if combos is not None else
                      "greedy search (most chi2 per minute)")
    return CandidatePlan(c, df, now, p_now, testable, amb, tuple(per), recommended, rec_chi2, rec_power, reason,
                         detected)


def _say_candidate(say, cp: CandidatePlan) -> None:
    """One line of progress for a candidate's plan."""
    say(f"{cp.effect}: now chi2 {cp.expected_chi2:.3g} (power {cp.power:.2f})" + ("" if cp.detected else (
        f"; add {' + '.join(f'{r.runs} x {r.experiment.name}' for r in cp.recommended)}" if cp.recommended
        else "; not reachable with these experiments")))


def _duration(minutes: float) -> str:
    """`minutes` in the largest unit that reads well: '3.2 h', '7 days', '1.9e+03 years'."""
    if minutes < 120:
        return f"{minutes:.3g} min"
    if minutes < 2 * 24 * 60:
        return f"{minutes / 60:.3g} h"
    if minutes < 2 * 365.25 * 24 * 60:
        return f"{minutes / (24 * 60):.3g} days"
    return f"{minutes / (365.25 * 24 * 60):.3g} years"


def _warnings(fit: Fit, design, n_dev: int) -> tuple:
    """What the reader must know before acting on the plan: a baseline the data reject (the Jacobians are a
    model's that does not describe the data), a design that measures no nonlinearity, a design longer than a
    day of table time."""
    out = []
    rejected = [d for d, st in zip(fit.devices, fit.status) if st == "model rejected"]
    if rejected:
        p = np.asarray(fit.p_value, dtype=float)
        worst = int(np.nanargmin(np.where(np.isfinite(p), p, np.inf))) if np.any(np.isfinite(p)) else 0
        out.append(f"the data reject the model this plan is made from on {len(rejected)} of {n_dev} device(s) "
                   f"(e.g. {fit.devices[worst]}: chi2_red {float(np.asarray(fit.chi2_red)[worst]):.4g}, "
                   f"{p_text(float(p[worst]))}): its expected chi2 and standard errors are those of a model that "
                   "does not describe the data. Diagnose first (gyrojax diagnose) and plan from the diagnosis's "
                   "final fit (--fit, or plan(fit=d.final))")
    if design is not None:
        if len(set(design.rates_dps)) < MIN_NONLINEARITY_RATES:
            out.append(f"the scale-factor design's rates {list(design.rates_dps)} deg/s carry no nonlinearity "
                       f"information: a straight line through {len(set(design.rates_dps))} rate(s) leaves no "
                       f"residual (at least {MIN_NONLINEARITY_RATES} are needed, seed 000 uses 22). Use it for the "
                       "scale factor only; measure the nonlinearity with seed 000's rates")
        if design.minutes > LONG_BUDGET_MIN:
            out.append(f"the scale-factor design takes {design.minutes:.0f} min ({_duration(design.minutes)}) of "
                       f"rate-table time per device" + (f", {_duration(design.minutes * n_dev)} for the "
                                                        f"{n_dev} devices on one table" if n_dev > 1 else ""))
    return tuple(out)


def _columns(fit: Fit):
    """Per column of the fit: None for a physical parameter, else the effect's name."""
    out = []
    for e in fit.entries:
        out += [None if e.effect_index is None else e.label.split(".")[0]] * e.size
    return out


def _run_info(rows_j, sig, subset, corr=None):
    """Fisher information of one run at the points `subset` (their Jacobian rows and sigmas), its bias
    projected out, and the matching J^T R J of its noise's correlation `corr` (a function of the number of
    points, applied back to back in the listed order; None: independent points)."""
    w = 1.0 / sig[subset] ** 2
    mean = (w @ rows_j[subset]) / np.sum(w)
    jp = (rows_j[subset] - mean) / sig[subset, None]
    info = jp.T @ jp
    return info, (info if corr is None else jp.T @ corr(len(subset)) @ jp)


def _sf_design(fit, jac0, g, sf, exps, jac_e, noise, pool, budget, protocol, threshold, say):
    """The greedy c-optimal design of the scale factor within `budget` minutes (see the module notes)."""
    n_dev = len(fit.devices)
    n_rows = _data_rows(fit)
    prior = [jac0[d, n_rows:].T @ jac0[d, n_rows:] for d in range(n_dev)]
    by_name = {e.name: k for k, e in enumerate(exps)}
    warm, dwell = protocol.warmup_s / 60.0, protocol.dwell_s / 60.0
    rate = exps[by_name[_RATE]]
    levels = {_RATE: np.asarray(rate.sweep.rates_dps)}
    rows = {_RATE: [jac_e[by_name[_RATE]][d] for d in range(n_dev)]}
    sigs = {_RATE: [rate.sigmas(noise[d]) for d in range(n_dev)]}
    if _VCF in by_name:
        v = exps[by_name[_VCF]]
        levels[_VCF] = np.asarray(v.sweep.virtual_rates_dps)
        rows[_VCF] = [jac_e[by_name[_VCF]][d] for d in range(n_dev)]
        sigs[_VCF] = [v.sigmas(noise[d]) for d in range(n_dev)]
    cols = list(pool)
    # Both kinds' points are settled means over back-to-back windows of the protocol's dwell: their noise
    # shares the bias wander between neighbours (window_correlation); the fit weighs them as independent.
    model = noise[0].rate_noise
    corrs = {k: functools.lru_cache(maxsize=None)(
        lambda n: window_correlation(model, n, protocol.dwell_s)) for k in levels}

    def per_device(sets, runs, d):
        return _per_device(prior, rows, sigs, sets, runs, g, cols, threshold, d, corrs)

    def variance(sets, runs):
        return float(np.mean([per_device(sets, runs, d) for d in range(n_dev)]))

    seed_run_min = (protocol.warmup_s + len(levels[_RATE]) * protocol.dwell_s) / 60.0
    seed_runs = int(budget // seed_run_min)
    seed_sets = {_RATE: tuple(range(len(levels[_RATE])))}
    seed_var = [per_device(seed_sets, {_RATE: seed_runs}, d) for d in range(n_dev)]
    best = None
    max_rate_runs = int(budget // (warm + 2 * dwell))
    say(f"scale-factor design within {budget:g} min: up to {max_rate_runs} rate-table runs")
    # Run counts on a roughly geometric grid (every count up to 4, then steps of ~25 %): the variance changes
    # smoothly with the count, and each count costs a greedy search.
    grid = sorted({r for r in range(1, max_rate_runs + 1) if r <= 4 or r == max_rate_runs
                   or int(round(1.25 ** round(math.log(r, 1.25)))) == r})
    for r_runs in grid:
        for q_runs in range(0, 2 if _VCF in levels else 1):
            runs = {_RATE: r_runs, _VCF: q_runs}
            used = (r_runs + q_runs) * warm
            if used + 2 * dwell * (r_runs + q_runs) > budget:
                continue
            current, sets, used = _greedy_points(variance, levels, runs, used, budget, dwell)
            if best is None or current < best[0]:
                best = (current, dict(sets), dict(runs), used)
    _, sets, runs, used = best
    stderr = [math.sqrt(per_device(sets, runs, d)) for d in range(n_dev)]
    data_se, undetermined = _data_sf_errors(fit, jac0, g)
    rates = tuple(float(levels[_RATE][i]) for i in sets[_RATE])
    vcf = tuple(float(levels[_VCF][i]) for i in sets.get(_VCF, ())) if runs.get(_VCF) else ()
    return ScaleFactorDesign(float(budget), rates, runs[_RATE], vcf, runs.get(_VCF, 0), float(used),
                             tuple(stderr), seed_runs,
                             seed_runs * (protocol.warmup_s + len(levels[_RATE]) * protocol.dwell_s) / 60.0,
                             tuple(math.sqrt(v) for v in seed_var), tuple(data_se),
                             tuple(float(x) for x in np.asarray(sf)), tuple(undetermined))


def _greedy_points(variance, levels, runs, used, budget, dwell):
    """The points of one design's runs (`runs`: per kind, how many), `used` minutes spent already: each kind
    starts with its best pair of opposite levels, then single points are added by the largest variance drop
    per minute while `budget` allows. Returns (the scale factor's variance, the points per kind, minutes)."""
    kinds = list(levels)
    sets = {k: () for k in kinds}
    for kind in kinds:
        if not runs.get(kind):
            continue
        lv = list(levels[kind])
        pairs = [(i, lv.index(-x)) for i, x in enumerate(lv) if x < 0 and -x in lv]
        pair = min(pairs, key=lambda p, kind=kind: variance({**sets, kind: tuple(sorted(p))}, runs))
        pair = tuple(sorted(pair))
        sets[kind] = pair
        used += 2 * dwell * runs[kind]
    current = variance(sets, runs)
    while True:
        options = []
        for kind in kinds:
            cost = dwell * runs.get(kind, 0)
            if not runs.get(kind) or used + cost > budget + 1e-9:
                continue
            for i in range(len(levels[kind])):
                if i in sets[kind]:
                    continue
                trial = {**sets, kind: tuple(sorted(sets[kind] + (i,)))}
                options.append(((current - variance(trial, runs)) / cost, kind, trial, cost))
        if not options:
            break
        gain, kind, trial, cost = max(options, key=lambda o: o[0])
        if not gain > 0:
            break
        sets, used = trial, used + cost
        current = variance(sets, runs)
    return current, sets, used


def _data_sf_errors(fit: Fit, jac0, g):
    """The scale factor's standard error per device on the data given, and, where identification says the
    data do not determine it (the baseline's status), its reason: (errors, reasons or '')."""
    data_free = [int(i) for i in np.nonzero(np.asarray(fit.free))[0]]
    data_se, undetermined = [], []
    for d in range(len(fit.devices)):
        info = jac0[d].T @ jac0[d]
        # whether the data determine it is identification's verdict (the baseline's status), not the planner's
        if fit.status[d] == "not determined":
            data_se.append(math.nan)
            undetermined.append(fit.warnings[d][0] if fit.warnings[d] else "identify: not determined")
            continue
        data_se.append(math.sqrt(_sf_variance(info, g[d], data_free, 0.0)) if data_free else math.inf)
        undetermined.append("")
    return data_se, undetermined


def _sqrt_info(info):
    """A matrix whose Gram matrix is `info` (for the hold rule)."""
    evals, evecs = np.linalg.eigh(info)
    return (evecs * np.sqrt(np.maximum(evals, 0.0))).T


def _per_device(prior, rows, sigs, sets, runs, g, cols, threshold, d, corrs=None):
    info = prior[d].copy()
    meat = prior[d].copy()
    for kind, idx in sets.items():
        if runs.get(kind) and len(idx) >= 2:
            a, b = _run_info(rows[kind][d], sigs[kind][d], list(idx), (corrs or {}).get(kind))
            info, meat = info + runs[kind] * a, meat + runs[kind] * b
    kept = _kept([_sqrt_info(info)], cols, threshold)
    return _sf_variance(info, g[d], kept, threshold, meat if corrs else None)
