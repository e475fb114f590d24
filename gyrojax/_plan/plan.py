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
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import numpy as np

from .._data.table import Table
from .._diagnose.candidates import baseline_fit, baseline_model, candidate_effects
from .._gyroscope import Gyroscope
from .._identify import Fit
from .._identify.fit import p_text
from .._identify.order import DEFAULT_MODEL, model_and_data
from .._identify.problem import sf_temperature
from .._identify.spec import FitSpec, default_free, fit_spec
from .._lots.noise import RateNoise
from .._model.fitdata import FitData, fit_data
from .._model.parameters import Model, as_model
from .._runtime.progress import ProgressArg, as_progress
from .._sweeps.protocol import Protocol
from .._sweeps.rate_table import RateTable
from .._sweeps.registry import SWEEP_KINDS
from .candidate_plans import (
    ambiguous,
    candidate_plan,
    fingerprints,
    information_rows,
    say_candidate,
    search_order,
    typical,
)
from .experiment import (
    CandidateExperiment,
    default_experiments,
    jacobians,
    noise_levels,
)
from .results import Plan
from .sf_design import RATE, VCF, sf_design


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
    if fit is None:
        free = default_free(base.device, data) if spec.free is None else spec.free
    else:
        free = tuple(e.label for e in fit.entries if e.effect_index is None)
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


def _reads(experiments, model) -> tuple[str, ...]:
    """What the experiments read beyond the baseline on the model's device (default experiments: whatever a
    kind may read there)."""
    kinds = [cls() for cls in SWEEP_KINDS.values()] if experiments is None else \
        [e.sweep for e in experiments if isinstance(e, CandidateExperiment)]
    device = as_model(model).device
    return tuple(dict.fromkeys(p for kind in kinds for p in kind.reads_on(device)))


def plan(model: Model | Gyroscope | str = DEFAULT_MODEL, data: Table | FitData | None = None, *,
         fit: Fit | None = None, candidates: Sequence[str] | None = None,
         experiments: Sequence[CandidateExperiment] | None = None, budget_min: float | None = None,
         alpha: float = 0.01, target_power: float = 0.9, max_repeats: int = 3, protocol: Protocol = Protocol(),
         free: Sequence[str] | None = None, identifiability_threshold: float = 1.0, scale_factor: bool = True,
         spec: FitSpec | None = None, progress: ProgressArg = True) -> Plan:
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
    - `free`: the baseline's free parameters when it is fitted here (`None`: as `gyrojax.identify`'s).
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
    fit, candidates, added = _baseline(data, model, fit, candidates, spec, _reads(experiments, model), say)
    one = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, fit.model.device)
    experiments = _experiments(experiments, one, protocol, fit, say)
    names = [e.name for e in experiments]
    # The scale-factor design picks its points among the rate table's (and static VCF's) of the default kinds.
    design_exps = tuple(e for e in default_experiments(one, protocol) if e.name in (RATE, VCF))
    all_exps = experiments + tuple(e for e in design_exps if e.name not in names)
    say(f"Jacobians of {len(all_exps)} experiments' points ({sum(e.points for e in all_exps)} points per device) "
        f"at the baseline, {len(fit.devices)} device(s)")
    t_sf = sf_temperature(fit.data)  # where identification reports the scale factor
    (jac_e, g), (pred_e, sf) = jacobians(fit.model, fit.entries, all_exps, t_sf)
    noise = noise_levels(fit.data, sf, protocol)
    jac0 = np.asarray(fit.jacobian, dtype=float)
    rows = information_rows(fit, jac0, candidates, added, experiments, jac_e, pred_e, noise,
                             identifiability_threshold)
    say(f"expected chi2 of {len(candidates)} candidate effects on the data given and with every combination of "
        f"0..{max_repeats} runs of {len(experiments)} experiments")
    thetas = {c: typical(fit, c, rows.cand_cols[c]) for c in candidates}
    prints = fingerprints(rows, candidates, thetas)
    exact, combos, search = search_order(experiments, max_repeats)
    plans = []
    for c in candidates:
        plans.append(candidate_plan(c, rows, thetas[c], ambiguous(c, candidates, prints), experiments, alpha,
                                     target_power, max_repeats, combos))
        say_candidate(say, plans[-1])
    design = None if not scale_factor else sf_design(fit, jac0, g, sf, all_exps, jac_e, noise, rows.pool,
                                                      budget_min, protocol, identifiability_threshold, say)
    warnings = _warnings(fit, design, len(fit.devices))
    for w in warnings:
        say(f"warning: {w}")
    return Plan(candidates=tuple(plans), scale_factor=design, experiments=experiments, baseline=fit,
                alpha=float(alpha), target_power=float(target_power), max_repeats=max_repeats, devices=fit.devices,
                search=search, warnings=warnings)


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
                      and e.name == RATE and isinstance(e.sweep, RateTable)), RateTable())
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
