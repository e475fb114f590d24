"""`identify`: fit a model's free parameters to every sweep of a lot at once, with uncertainties.

The fit minimises chi2 = sum r^2 over all standardised residuals (see `gyrojax/_model/residuals.py`; the run biases are
projected out exactly) with optimistix, per device in one vmapped, compiled call, or jointly for the whole lot
when some parameters are shared. Before solving, the weighted Jacobian at the start is decomposed: a
direction of parameter space the data cannot fix to better than its natural size (singular value below
`identifiability_threshold` in internal units) is named, and the parameter of it that comes last in
`gyrojax.PARAMETERS`' order of preference is held at its start value, so the fit does not wander along it.

What the fit reports is checked before it is called a result (`Fit.status`, `Fit.warnings`):

- **determined**: the scale factor is reported only if the data fix it. Its gradient over the parameters that
  were candidates for the fit must have no part along the directions the data cannot fix (those held as
  unidentifiable); else it rests on a design value and is NaN, with the reason.
- **misfit**: the chi2 of each device is tested (`reject_alpha`); a rejected model keeps its fitted standard
  errors and gets them scaled by sqrt(chi2_red) too (`stderr_scaled`).
- **noise**: data without `output_sigma` get their noise estimated per sweep from a first fit's residuals
  (`noise.py`), then are re-weighted and fitted again, so that the chi2 tests the model (against its
  Monte Carlo null distribution, since the estimate shares the residuals).
- **plausibility**: fitted physical parameters far outside `Parameter.plausible` of their design values are
  flagged with a likely cause; outputs absurdly far from the rest of their run, and outputs whose slope has the
  opposite sign of the model's, are refused before fitting (`ValueError`: no fit could mean anything).
"""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import numpy as np

from .._data.table import Table
from .._gyroscope import Gyroscope
from .._model.fitdata import FitData, fit_data
from .._model.parameters import Model, as_model
from .._runtime.progress import ProgressArg, as_progress
from .._simulate.tiers import AbstractTier, Steady
from .._solution import RESULTS, result_code
from .assemble import assemble_fit
from .fit import Fit
from .identifiability import hold_unidentifiable
from .noise import estimated_noise, first_fit_scale, reweighted
from .plausibility import check_absurd_outputs, check_signs
from .population import PopulationFit, PopulationSolve, population_fit
from .problem import make_problem, with_free
from .recovery import RECOVERY, AbstractRecovery, DecrementCertificate, MultiStart, RetryWithSolver, Solution, Solving
from .shortcuts import lot_solve_from, solver_from
from .spec import FitSpec, default_free, fit_spec
from .strategies import AbstractLotSolve, Lot, Solver


def identify(model: Model | Gyroscope | str, data: Table | FitData, *, spec: FitSpec | None = None,
             free: Sequence[str] | None = None, shared: Sequence[str] = (), hold: Sequence[str] = (),
             priors: dict | None = None, tier: AbstractTier = Steady(), solver: str | Solver = "levenberg-marquardt",
             rtol: float = 1e-8, atol: float = 1e-8, max_steps: int = 200, start: MultiStart = MultiStart(),
             lot_solve: str | AbstractLotSolve = "vmap", recovery: tuple[AbstractRecovery, ...] = RECOVERY,
             identifiability_threshold: float = 1.0, reject_alpha: float = 0.01,
             estimate_noise: bool | str | None = None, evaluate_only: bool = False,
             progress: ProgressArg = True) -> Fit | PopulationFit:
    r"""Fit the free parameters of `model` to every sweep in `data`, per device (vmapped) or jointly.

    **Arguments:**

    - `model`: a `gyrojax.Model` (a device and effects), a `Gyroscope`, or a preset name. A single device is
      the start for every device of the data; a lot (leading device axis) gives one start per device.
    - `data`: a `gyrojax.Table` or `FitData`.
    - `spec`: a `gyrojax.FitSpec`: every argument below from `free` to `reject_alpha` at once (give those
      either there or as keywords, not both).
    - `free`: names of `gyrojax.PARAMETERS` to fit per device (those the device lacks are skipped). Every
      parameter of every effect in the model is fitted too. `None`: `identification.default_free(device, data)`,
      the default ones and those the data's sweep kinds read (a closed-loop dynamic VCF's angular gain).
    - `shared`: names (physical, or effect fields like `"dac_inl.coefficients"`) fitted as one value for the
      whole lot: the lot is then fitted jointly.
    - `hold`: names held at their start values regardless.
    - `priors`: `{name: (value, sigma)}` Gaussian priors in physical units (design values with tolerances);
      only for per-device physical parameters.
    - `tier`: the settling tier for rate-table and static-VCF points (`Steady()`).
    - `solver`: `"levenberg-marquardt"` (default), `"gauss-newton"`, `"bfgs"`, or an optimistix solver;
      `rtol`, `atol` for a named one; `max_steps` for any.
    - `start`: the first solve, `gyrojax.MultiStart(starts=1, spread=0.05, seed=0)`: `starts` starts per
      device, the first at the model, the others perturbed by `spread` in internal units; the lowest chi2
      wins.
    - `lot_solve`: how the lot's devices are solved: a strategy, `gyrojax.VmapSolve(chunk=..., shard=...)`
      (all devices' independent fits in one vmapped, compiled solve, in chunks of devices and sharded over
      JAX devices: see `VmapSolve`), `gyrojax.LoopSolve()` (one device after another through one compiled
      single-device solve: less memory) or `gyrojax.JointSolve(shard=...)` (one fit of the whole lot; the
      only one for `shared` parameters), `gyrojax.PopulationSolve(random=(...))` (a population fit: the `random`
      parameters drawn from a lot distribution estimated with them; `identify` then returns a
      `gyrojax.PopulationFit`, see docs/population.md); or a shortcut: `"vmap"` (default: `VmapSolve()`, or
      `JointSolve()` where parameters are shared), `"loop"`.
    - `recovery`: what is tried, in turn, after the first solve (`gyrojax.AbstractRecovery` policies); the
      default is `(DecrementCertificate(tol=1e-6), RetryWithSolver("gauss-newton"), RestartRunoffs())`:
      a solve stopped at `max_steps` where a full Gauss-Newton step would lower chi2 by less than `tol` counts
      as converged; a device that did not converge is solved again with Gauss-Newton (only after a named
      solver other than it); a device whose solution ran off along a direction the data no longer fix is
      restarted with it held, then released. `()`: none. With `evaluate_only`, only `DecrementCertificate`
      applies.
    - `identifiability_threshold`: directions with a singular value of the weighted Jacobian below this (in
      internal units: relative change for positive parameters, typical size for effects) are held.
    - `reject_alpha`: significance level of each device's chi2 test (and the lot's): p below it marks the
      device `"model rejected"` and scales its standard errors by sqrt(chi2_red) in `stderr_scaled` (a lot of
      N devices with a right model has about N x reject_alpha rejected by chance).
    - `estimate_noise`: estimate each sweep's noise per device from a first fit's residuals (differences
      between runs at repeated inputs, else of neighbouring inputs in a run; unbiased for white noise; its chi2
      null drawn with `start.seed`), re-weight, fit again. `None` (default): when the data have no
      `output_sigma`. `False` takes the data's sigmas as the noise (unit weights without `output_sigma`: the
      chi2 then tests nothing; e.g. an earlier fit's `fit.data`, its sigmas estimated already). `"lot"`
      (`diagnose`'s): each sweep's pooled over the devices where Bartlett's test at 1 % does not tell them apart.
    - `evaluate_only`: do not solve; return the `Fit` at the start (residuals, Jacobian, covariance there),
      e.g. to test a candidate effect at zero against an already fitted model.
    - `progress`: `True` (default) reports the fit's steps on standard error (what it fits, when it compiles,
      the statuses at the end, the elapsed time), `False` is silent, a callable receives the messages.

    **Returns:** a `Fit` (a `PopulationFit` for `lot_solve=PopulationSolve(...)`). It never raises on
    non-convergence: read `fit.status` (or `fit.converged`, or call `fit.check()`). A scale factor the data do
    not determine is NaN, with the reason in `fit.warnings`.

    **Raises:** `ValueError` before fitting for data no fit could mean anything with: an output more than
    1e8 times the largest other output of its run, or outputs whose slope has the opposite sign of
    the model's (both named by device, run and input).
    """
    model, data = as_model(model), _as_fit_data(data)
    spec = fit_spec(spec, "identify", free=free, shared=shared, hold=hold, priors=priors, tier=tier, solver=solver,
                    rtol=rtol, atol=atol, max_steps=max_steps, start=start, lot_solve=lot_solve, recovery=recovery,
                    identifiability_threshold=identifiability_threshold, reject_alpha=reject_alpha)
    if not any(estimate_noise is v for v in (None, True, False)) and estimate_noise != "lot":
        raise ValueError(f"estimate_noise must be None, True, False or 'lot', got {estimate_noise!r}.")
    check_absurd_outputs(data)
    if isinstance(spec.lot_solve, PopulationSolve):
        return _population(model, data, spec, spec.lot_solve, estimate_noise, evaluate_only, progress)
    return _identify(model, data, spec, estimate_noise, evaluate_only, progress)


def _as_fit_data(data) -> FitData:
    """`data` as `FitData` (a `Table` converted), else a TypeError that says what is expected."""
    if isinstance(data, Table):
        data = fit_data(data)
    if not isinstance(data, FitData):
        raise TypeError(f"data must be a gyrojax.Table or FitData, got {type(data).__name__}.")
    return data


def _population(model, data, spec: FitSpec, strategy: PopulationSolve, estimate_noise, evaluate_only, progress):
    """The population fit of `spec.lot_solve` (`population.py`), whose independent fits are `identify`'s."""
    options = {k: v for k, v in spec.options().items() if k != "lot_solve"}
    return population_fit(identify, as_model(model), data, strategy, dict(
        **options, estimate_noise=estimate_noise, evaluate_only=evaluate_only, progress=progress),
        as_progress(progress, "gyrojax.identify"))


def _identify(model, data, spec: FitSpec, estimate_noise, evaluate_only, progress):
    """`identify` of checked arguments, without a population: the strategies composed from `spec`, then the fit
    (twice more where the noise is estimated from a first fit's residuals)."""
    start = spec.start
    # The strategies, composed once for every fit below: the solver, the first solve, the recovery policies.
    solver = spec.solver
    recoveries = tuple(_with_tolerances(r, spec.rtol, spec.atol) for r in spec.recovery
                       if not (isinstance(r, RetryWithSolver) and not (isinstance(solver, str) and solver != r.solver))
                       and not (evaluate_only and not isinstance(r, DecrementCertificate)))
    free = default_free(model.device, data) if spec.free is None else tuple(spec.free)
    options = dict(free=free, shared=spec.shared, priors=spec.priors, hold=spec.hold, tier=spec.tier,
                   solver=solver_from(solver, spec.rtol, spec.atol), solver_name=solver, lot_solve=spec.lot_solve,
                   first=None if evaluate_only else start, recoveries=recoveries, max_steps=spec.max_steps,
                   threshold=spec.identifiability_threshold, reject_alpha=spec.reject_alpha)
    say = as_progress(progress, "gyrojax.identify")
    say(f"{'evaluating' if evaluate_only else 'fitting'} {len(data.devices)} device(s), {data.num_points()} points "
        f"({', '.join(data.sweeps)})")
    say.compiling(("identify", jax.tree.structure(eqx.filter(model, eqx.is_array)), free,
                   tuple(spec.shared),
                   tuple((s, tuple(np.shape(data.blocks[s].inputs))) for s in data.sweeps)), "the fit")
    if not (not data.weighted if estimate_noise is None else estimate_noise):
        fit = _fit_once(model, data, noise=None, **options)
    else:
        # The noise from a first fit's residuals; then the points weighted by it and fitted again. The second
        # fit has the first's shapes: it reuses every compiled function.
        # Its weights are on the scale of the model's outputs, so that a unit of the outputs (mLSB, or Hz for
        # kHz) does not change the solve: unit weights on outputs 100x the model's make the first fit stop far
        # from them (the damping is absolute), and the noise estimated from its residuals with it.
        at_start = _fit_once(model, data, noise=None, **{**options, "first": None, "recoveries": ()})
        data = first_fit_scale(data, at_start.predictions)
        first_fit = _fit_once(model, data, noise=None, **options)
        say("estimating the noise from the first fit's residuals (the data give no output_sigma); fitting again "
            "with those weights")
        kappa, noise = estimated_noise(first_fit, start.seed, start.first_device, pool=estimate_noise == "lot")
        fit = _fit_once(model, reweighted(data, kappa), noise=noise, **options)
    counts = {st: fit.status.count(st) for st in dict.fromkeys(fit.status)}
    say("done: " + ", ".join(f"{k} device(s) {st}" for st, k in counts.items()))
    return fit


def _with_tolerances(policy, rtol, atol):
    """A `RetryWithSolver` without tolerances of its own gets `identify`'s."""
    if isinstance(policy, RetryWithSolver):
        return dataclasses.replace(policy, rtol=rtol if policy.rtol is None else policy.rtol,
                                   atol=atol if policy.atol is None else policy.atol)
    return policy


def _fit_once(model, data, *, free, shared, priors, hold, tier, solver, solver_name, lot_solve, first, recoveries,
              max_steps, threshold, reject_alpha, noise) -> Fit:
    """One fit of `identify` (arguments checked there) with the data's sigmas as they are: the problem, the lot
    strategy, what to hold, the first solve (`first`; None: evaluate at the start) and the `recoveries` in
    turn. `noise`: the estimated noise's `(degrees of freedom, warnings, determined, null draws of the chi2)` per
    device (`estimated_noise`), or None for given sigmas."""
    n = len(data.devices)
    problem_all, layout = make_problem(model, data, free=free, shared=shared, hold=hold, priors=priors, tier=tier)
    n_dev, n_lot = len(layout.names_dev), len(layout.names_lot)
    lot = Lot(lot_solve_from(lot_solve, joint=bool(n_lot)), n)
    # The evaluation at the start (the Jacobian over every per-device entry) is the solve's own program,
    # stopped after its first step: one compiled copy of the model per fit.
    at_start = lot.evaluate(problem_all, np.zeros((n, n_dev)), np.zeros(n_lot), solver, max_steps, "at the start")
    check_signs(data, {s: np.asarray(v) for s, v in at_start.predictions.items()}, problem_all.model.device.name)
    # Identifiability at the start: hold what the data cannot see.
    candidates = list(layout.candidates)
    keep, held_reports = hold_unidentifiable(np.asarray(at_start.jac)[:, :, candidates],
                                             [layout.names_dev[i] for i in candidates], threshold)
    free_index = tuple(candidates[k] for k in keep)
    solving = Solving(with_free(problem_all, free_index), lot, solver, solver_name, max_steps, n_lot, free_index,
                      layout.names_dev, threshold)
    if first is None:
        ok = np.full(n, result_code(RESULTS.successful))
        solution = Solution(np.zeros((n, n_dev)), np.zeros(n_lot), ok, np.zeros(n, dtype=int), None,
                            np.zeros((n, n_dev)), at_start, ("",) * n)
    else:
        solution = first(solving)
    for recover in recoveries:
        solution = recover(solving, solution)
    return assemble_fit(problem_all, data, layout, free_index, solution, held_reports, threshold, reject_alpha, noise)
