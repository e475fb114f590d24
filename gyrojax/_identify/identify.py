"""`identify`: fit a model's free parameters to every sweep of a lot at once, with uncertainties.

The fit minimises chi2 = sum r^2 over all standardised residuals (see `_residuals.py`; the run biases are
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
  (`noise_scales`), then are re-weighted and fitted again, so that the chi2 tests the model (against its
  Monte Carlo null distribution, since the estimate shares the residuals).
- **plausibility**: fitted physical parameters far outside `Parameter.plausible` of their design values are
  flagged with a likely cause; outputs absurdly far from the rest of their run, and outputs whose slope has the
  opposite sign of the model's, are refused before fitting (`ValueError`: no fit could mean anything).
"""


import contextlib
import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .._dataset import Table
from .._fitdata import FitData, fit_data
from .._linsolve import PivotedLU
from .._lm import LevenbergMarquardt
from .._parameters import (
    DEFAULT_FREE,
    PARAMETERS,
    Model,
    apply_u,
    as_model,
    batched,
    build_entries,
    read_values,
)
from .._progress import as_progress
from .._residuals import (
    block_residuals,
    device_residuals,
    num_biases,
    num_points,
    run_biases,
)
from .._simulate.tiers import Steady
from .._solution import RESULTS, result_code, result_message
from .covariance import chi2_p_value, covariance, gauss_newton_decrement, joint_jacobian
from .fit import Fit, p_text
from .identifiability import hold_unidentifiable, sf_determinacy, undetermined_reason, weak_at_solution, weak_directions
from .noise import estimated_noise, reweighted
from .plausibility import check_absurd_outputs, check_signs, implausible_values


SOLVERS = ("levenberg-marquardt", "gauss-newton", "bfgs")


def _solver(solver, rtol, atol):
    if not isinstance(solver, str):
        return solver
    # Normal equations through an XLA-only LU, not lineax's LAPACK QR: see gyrojax/_linsolve.py.
    linear_solver = lx.Normal(PivotedLU(zero_pivot_gives_zero=True))
    if solver == "levenberg-marquardt":
        return LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=linear_solver)
    if solver == "gauss-newton":
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=linear_solver)
    if solver == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    raise ValueError(f"solver must be one of {SOLVERS} or an optimistix solver, got {solver!r}.")


# --- the noise of data without output_sigma -------------------------------------------------------------


# --- checks of the data before fitting ------------------------------------------------------------------


# --- checks of the result -------------------------------------------------------------------------------


def _message(converged, result_text, unsettled):
    if unsettled > 0:
        return (f"{unsettled} point(s) had no steady state at the solution; check the loop design, or fit "
                "fewer parameters")
    if converged:
        return "converged"
    return (f"{result_text}. Try: more starts (starts=8), a larger max_steps, another solver "
            "(solver='gauss-newton' or 'bfgs'), holding a parameter (free=...), or priors on the design values")


@contextlib.contextmanager
def _nonfinite_explained(stage: str):
    """Turn a runtime error from inside the compiled model (a linear solve of a steady state or of its implicit
    derivative that got NaN/inf) into one that says where and what to try, keeping the original as cause."""
    try:
        yield
    except eqx.EquinoxRuntimeError as e:
        # equinox prefixes the stack; the message is on the line naming the error, or else the last one
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        named = [i for i, ln in enumerate(lines) if "EquinoxRuntimeError:" in ln and "stack" not in ln]
        if named:  # its first sentence, which may wrap onto the next lines
            text = " ".join(lines[named[-1]:]).split("EquinoxRuntimeError:", 1)[1].strip()
            reason = text.split("---")[0].split(". ")[0].strip().rstrip(".")[:300]
        else:
            reason = lines[-1] if lines else type(e).__name__
        raise RuntimeError(
            f"identify: the model's predictions or their derivatives are not finite {stage} (the error inside "
            f"the compiled model: {reason!r}). Some device has no steady "
            "state there, or one whose derivative is singular. Try: starting closer to the data (a Model with "
            "data-based values), holding parameters (hold=...) or priors on the design values, or fitting the "
            "sweeps one at a time (fit_data(table, sweeps=...)) to find the one that fails.") from e


class _Problem(eqx.Module):
    """Everything one device's residual function needs besides the internal vector."""

    model: Model
    start: list
    data: FitData
    free_mask: jax.Array  # (n_dev,) 1.0 where free: the solve runs in the full space with held ones masked
    n_dev: int = eqx.field(static=True)
    entries: tuple = eqx.field(static=True)
    tier: Steady
    prior_index: jax.Array
    prior_mean: jax.Array
    prior_sigma: jax.Array
    sf_temperature: jax.Array  # deg C: where the scale factor is reported (`_sf_temperature`)

    def _evaluate(self, u_free, u_lot):
        """Standardised residuals (data, then priors), the count of points that did not settle, the
        predictions per sweep, the device and its zero-rate scale factor (LSB per deg/s)."""
        return _evaluate_problem(self, u_free, u_lot)

    def residuals(self, u_free, u_lot):
        """Standardised residuals (data, then priors), differentiable (a dense forward-mode Jacobian)."""
        return _residuals(self, u_free, u_lot)


# Its own jit: optimistix and the Jacobians trace the residual function several times inside one outer
# trace; a jitted body is traced once per signature and reused (measured: tracing 55 s of a 132 s fit).
@eqx.filter_jit
def _evaluate_problem(problem, u_free, u_lot):
    u = u_free * problem.free_mask
    gyro = apply_u(problem.model, problem.entries, problem.start, u, u_lot).gyroscope()
    # The scale factor's two points settle with the data's (one program): the solve carries them too, at
    # the cost of two points per device, so that the fit and its evaluation share every compiled settle.
    r, failed, preds, sf = device_residuals(gyro, problem.data, problem.tier, problem.sf_temperature)
    prior = (u[problem.prior_index] - problem.prior_mean) / problem.prior_sigma
    return jnp.concatenate([r, prior]), failed, preds, gyro, sf


@jax.custom_jvp
def _residuals(problem, u_free, u_lot):
    return problem._evaluate(u_free, u_lot)[0]


@_residuals.defjvp
def _residuals_jvp(primals, tangents):
    # The JVP as a materialised Jacobian times the tangent. Optimistix linearises the residual function and,
    # on its first (discarded) step, evaluates the linearisation with zeroed constants; through the steady
    # state's implicit differentiation that would feed NaNs to a linear solve that raises. A dense Jacobian
    # has no such solve, and is what Levenberg-Marquardt builds anyway. The problem's own tangents (data,
    # start values) are not parameters and are ignored.
    problem, u_free, u_lot = primals
    _, t_free, t_lot = tangents

    def value_twice(a, b):  # the value as aux: jacfwd evaluates it once, with the Jacobian
        r = problem._evaluate(a, b)[0]
        return r, r

    (j_free, j_lot), r = jax.jacfwd(value_twice, argnums=(0, 1), has_aux=True)(u_free, u_lot)
    return r, j_free @ t_free + j_lot @ t_lot


class _Evaluation(eqx.Module):
    """Residuals, Jacobians and derived quantities of every device at one point of parameter space."""

    residuals: jax.Array  # (device, residual)
    jac: jax.Array  # (device, residual, n_dev) with respect to every per-device entry
    jac_lot: jax.Array  # (device, residual, n_lot)
    scale_factor: jax.Array  # (device,) LSB per deg/s at zero rate
    sf_grad: jax.Array  # (device, n_dev)
    sf_grad_lot: jax.Array  # (device, n_lot)
    predictions: dict
    biases: dict
    failed: jax.Array  # (device,)


def _map_devices(f, chunk, *trees):
    """`f` vmapped over the leading (device) axis of the array leaves of `trees`; with `chunk`, `chunk`
    devices at a time (`jax.lax.map`), which bounds memory, and each chunk's solve stops at its own slowest
    device. The axis must be a multiple of `chunk` (see `_LotSpread`)."""
    dynamic, static = eqx.partition(trees, eqx.is_array)

    def g(d):
        return f(*eqx.combine(d, static))

    if chunk is None:
        return jax.vmap(g)(dynamic)
    # By hand rather than lax.map(batch_size=...), whose reshape fails on empty leaves (no priors: (n, 0)).
    n = jax.tree.leaves(dynamic)[0].shape[0]
    split = jax.tree.map(lambda x: x.reshape((n // chunk, chunk) + x.shape[1:]), dynamic)
    out = jax.lax.map(jax.vmap(g), split)
    return jax.tree.map(lambda x: x.reshape((n,) + x.shape[2:]), out)


@eqx.filter_jit
def _evaluate(problem_all, u_full, u_lot, chunk):
    """One compiled pass (used at the start and at the solution): residuals, the Jacobian with respect to
    every per-device and lot entry, the zero-rate scale factor and its gradient, predictions and biases."""
    def one(problem, u):
        def outputs(uu, ul):
            r, failed, preds, _, sf = problem._evaluate(uu, ul)
            # The values as aux: jacfwd evaluates the sweeps once, for the Jacobian and the predictions.
            return (r, sf), (r, sf, failed, preds)

        ((j, j_lot), (g, g_lot)), (r, sf, failed, preds) = jax.jacfwd(outputs, argnums=(0, 1), has_aux=True)(
            u, u_lot)
        biases = {sweep: run_biases(sweep, problem.data.blocks[sweep], pred) for sweep, pred in preds.items()}
        return _Evaluation(r, j, j_lot, sf, g, g_lot, preds, biases, failed)

    return _map_devices(one, chunk, problem_all, u_full)


def _solve_device(problem, y0, u_lot, solver, max_steps):
    """One device's fit: (solution, result code, steps, chi2)."""
    def fn(y, _):
        return problem.residuals(y, u_lot)

    sol = optx.least_squares(fn, solver, y0, max_steps=max_steps, throw=False)
    r = problem.residuals(sol.value, u_lot)
    return sol.value, result_code(RESULTS.promote(sol.result)), sol.stats["num_steps"], jnp.sum(r**2)


@eqx.filter_jit
def _solve_independent(problem_batch, u0, u_lot, solver, max_steps, chunk):
    return _map_devices(lambda p, y0: _solve_device(p, y0, u_lot, solver, max_steps), chunk, problem_batch, u0)


_solve_one = eqx.filter_jit(_solve_device)


def _solve_loop(problem_batch, u0, u_lot, solver, max_steps, chunk=None):
    """Device by device (one compiled single-device solve): see `identify(lot_solve=...)`."""
    outs = []
    for d in range(u0.shape[0]):
        problem = jax.tree.map(lambda x: x[d] if eqx.is_array(x) else x, problem_batch)
        outs.append(_solve_one(problem, u0[d], u_lot, solver, max_steps))
    return tuple(jnp.stack([o[i] for o in outs]) for i in range(4))


@eqx.filter_jit
def _solve_joint(problem_batch, u0, u_lot0, solver, max_steps):
    def fn(y, _):
        u_free, u_lot = y
        return eqx.filter_vmap(lambda p, x: p.residuals(x, u_lot))(problem_batch, u_free)

    sol = optx.least_squares(fn, solver, (u0, u_lot0), max_steps=max_steps, throw=False)
    r = fn(sol.value, None)
    n = u0.shape[0]
    return (sol.value[0], sol.value[1], jnp.broadcast_to(result_code(RESULTS.promote(sol.result)), (n,)),
            jnp.broadcast_to(sol.stats["num_steps"], (n,)), jnp.sum(r**2, axis=-1))


class _LotSpread:
    """Pads the device axis to a multiple of `shards` (placing it across a 1-D mesh of JAX devices) or of
    `chunk` (for `_map_devices`); unpads results. With one shard and no chunk it does nothing."""

    def __init__(self, n: int, shards: int, chunk: int | None = None):
        self.n, self.shards = n, shards
        self.chunk = chunk if chunk is not None and chunk < n else None
        self.multiple = shards * (self.chunk or 1)
        if shards > 1:
            mesh = jax.sharding.Mesh(np.asarray(jax.devices()[:shards]), ("lot",))
            self.sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("lot"))

    def pad(self, *trees):
        if self.multiple <= 1:
            return trees
        extra = -self.n % self.multiple

        def put(x):
            if not eqx.is_array(x):
                return x
            x = jnp.asarray(x)
            if extra:  # copies of the last device: solved, then dropped
                x = jnp.concatenate([x, jnp.repeat(x[-1:], extra, axis=0)])
            return jax.device_put(x, self.sharding) if self.shards > 1 else x

        return tuple(jax.tree.map(put, t) for t in trees)

    def unpad(self, tree):
        if self.n % self.multiple == 0:
            return tree
        return jax.tree.map(lambda x: x[: self.n] if eqx.is_array(x) else x, tree)


def identify(model, data, *, free=DEFAULT_FREE, shared=(), priors=None, solver="levenberg-marquardt",
             starts: int = 1, start_spread: float = 0.05, seed: int = 0, rtol: float = 1e-8, atol: float = 1e-8,
             max_steps: int = 200, identifiability_threshold: float = 1.0, hold=(), tier=Steady(),
             evaluate_only: bool = False, lot_solve: str = "vmap", shard: bool | None = None,
             lot_chunk: int | None | str = "auto", restart_runoffs: bool = True,
             retry_solver: str | None = "gauss-newton", decrement_tol: float = 1e-6, reject_alpha: float = 0.01,
             estimate_noise: bool | None = None, progress=True) -> Fit:
    r"""Fit the free parameters of `model` to every sweep in `data`, per device (vmapped) or jointly.

    **Arguments:**

    - `model`: a `gyrojax.Model` (a device and effects), a `Gyroscope`, or a preset name. A single device is
      the start for every device of the data; a lot (leading device axis) gives one start per device.
    - `data`: a `gyrojax.Table` or `FitData`.
    - `free`: names of `gyrojax.PARAMETERS` to fit per device (those the device lacks are skipped). Every
      parameter of every effect in the model is fitted too.
    - `shared`: names (physical, or effect fields like `"dac_inl.coefficients"`) fitted as one value for the
      whole lot: the lot is then fitted jointly.
    - `priors`: `{name: (value, sigma)}` Gaussian priors in physical units (design values with tolerances);
      only for per-device physical parameters.
    - `solver`: `"levenberg-marquardt"` (default), `"gauss-newton"`, `"bfgs"`, or an optimistix solver.
    - `starts`, `start_spread`, `seed`: multi-start: `starts` starts per device, the first at the model, the
      others perturbed by `start_spread` in internal units; the lowest chi2 wins.
    - `identifiability_threshold`: directions with a singular value of the weighted Jacobian below this (in
      internal units: relative change for positive parameters, typical size for effects) are held.
    - `hold`: names held at their start values regardless.
    - `tier`: the settling tier for rate-table and static-VCF points (`Steady()`).
    - `lot_solve`: `"vmap"` (default): all devices' independent fits in one vmapped, compiled solve;
      `"loop"`: one device after another through one compiled single-device solve (less memory).
    - `shard`: spread the device axis over every JAX device (`jax.sharding`, a 1-D mesh named `"lot"`; the
      lot is padded to a multiple of the device count). `None` (default): when more than one JAX device
      exists. Applies to the vmapped solve and the Jacobian passes; a joint (shared-parameter) fit is
      sharded only when the lot divides evenly.
    - `lot_chunk`: with `lot_solve="vmap"`, solve and differentiate at most this many devices at a time
      (`jax.lax.map` over chunks of the vmapped solve; the lot is padded to a multiple of it). It bounds
      memory on large lots and lets each chunk stop at its own slowest device. `None`: the whole lot at
      once. `"auto"` (default), for independent fits on one JAX device: 16 on a CPU backend (measured on 256
      devices: chunks of 16 ran 3-4x faster per device than chunks of 128, whose batched steady solves
      outgrow the cache), 1024 on an accelerator (4096 devices on an H100: 2.2 ms per device in chunks of
      1024, 3.0 ms at once, where every device waits for the slowest's 28 LM steps); else `None`. Not with
      `shard` over several JAX devices, nor for a joint fit.
    - `restart_runoffs`: a device whose solution leaves a direction the data no longer fix (a parameter run
      off towards 0 or infinity, e.g. an open-loop Q_y whose steep sense resonance the first steps overshot)
      is solved again from its start with that direction held, then released from there; the lower chi2
      wins, and its message says so. Independent fits only (default on; costs two more solves when it
      fires).
    - `retry_solver`: a device whose solve did not converge (e.g. Levenberg-Marquardt crawling to
      `max_steps` in a curved valley) is solved again from its start with this solver (`"gauss-newton"`
      by default; `None`: no retry); the retry is kept when it converged at no higher chi2, and the device's
      message says so (a joint fit is retried as a whole). Only with a named `solver` other than this one.
    - `decrement_tol`: a solve that stopped at `max_steps` counts as converged when a full Gauss-Newton step
      from where it stopped would lower chi2 by less than this (the Gauss-Newton decrement
      r^T J (J^T J)^+ J^T r: the point is then within sqrt(decrement_tol) standard errors of the minimum),
      and its message says so. The solver's own test asks every parameter and residual to move by less than
      rtol/atol, which the round-off of the steady-state solves can keep failing on a large joint fit.
    - `evaluate_only`: do not solve; return the `Fit` at the start (residuals, Jacobian, covariance there),
      e.g. to test a candidate effect at zero against an already fitted model.
    - `reject_alpha`: significance level of each device's chi2 test (and the lot's): p below it marks the
      device `"model rejected"` and scales its standard errors by sqrt(chi2_red) in `stderr_scaled`. Each
      device is tested at this level, so a lot of N devices with a right model has about N x reject_alpha
      rejected by chance.
    - `estimate_noise`: estimate each sweep's noise per device from the residuals of a first fit, re-weight
      and fit again (`noise_scales`: differences between runs at repeated inputs, else of neighbouring inputs
      within a run; unbiased for white noise). `None` (default): when the data have no `output_sigma`.
      `False` takes the data's sigmas as the noise (unit weights for a table without `output_sigma`, so the
      chi2 then tests nothing; e.g. for `fit.data` of an earlier fit, whose sigmas were estimated already).

    - `progress`: `True` (default) reports the fit's steps on standard error (what it fits, when it compiles,
      the statuses at the end, the elapsed time), `False` is silent, a callable receives the messages.

    **Returns:** a `Fit`. It never raises on non-convergence: read `fit.status` (or `fit.converged`, or call
    `fit.check()`). A scale factor the data do not determine is NaN, with the reason in `fit.warnings`.

    **Raises:** `ValueError` before fitting for data no fit could mean anything with: an output more than
    `ABSURD_RATIO` times the largest other output of its run, or outputs whose slope has the opposite sign of
    the model's (both named by device, run and input).
    """
    model = as_model(model)
    if isinstance(data, Table):
        data = fit_data(data)
    if not isinstance(data, FitData):
        raise TypeError(f"data must be a gyrojax.Table or FitData, got {type(data).__name__}.")
    if not (isinstance(reject_alpha, (int, float)) and 0.0 < reject_alpha < 1.0):
        raise ValueError(f"reject_alpha must be a significance level in (0, 1), got {reject_alpha!r}.")
    if estimate_noise not in (None, True, False):
        raise ValueError(f"estimate_noise must be None, True or False, got {estimate_noise!r}.")
    if lot_solve not in ("loop", "vmap"):
        raise ValueError(f"lot_solve must be 'loop' or 'vmap', got {lot_solve!r}.")
    if shard and lot_solve == "loop":
        raise ValueError("shard=True needs lot_solve='vmap' (the loop solves one device at a time).")
    if lot_chunk != "auto" and lot_chunk is not None and (not isinstance(lot_chunk, int) or lot_chunk < 1):
        raise ValueError(f"lot_chunk must be 'auto', None or an integer >= 1, got {lot_chunk!r}.")
    if not isinstance(starts, int) or starts < 1:
        raise ValueError(f"starts must be an integer >= 1, got {starts!r}.")
    check_absurd_outputs(data)
    options = dict(free=free, shared=shared, priors=priors, solver=solver, starts=starts, start_spread=start_spread,
                   seed=seed, rtol=rtol, atol=atol, max_steps=max_steps,
                   identifiability_threshold=identifiability_threshold, hold=hold, tier=tier,
                   evaluate_only=evaluate_only, lot_solve=lot_solve, shard=shard, lot_chunk=lot_chunk,
                   restart_runoffs=restart_runoffs, retry_solver=retry_solver, decrement_tol=decrement_tol,
                   reject_alpha=reject_alpha)
    say = as_progress(progress, "gyrojax.identify")
    say(f"{'evaluating' if evaluate_only else 'fitting'} {len(data.devices)} device(s), {data.num_points()} points "
        f"({', '.join(data.sweeps)})")
    say.compiling(("identify", jax.tree.structure(eqx.filter(model, eqx.is_array)), tuple(free), tuple(shared),
                   tuple((s, tuple(np.shape(data.blocks[s].inputs))) for s in data.sweeps)), "the fit")
    if not (not data.weighted if estimate_noise is None else estimate_noise):
        fit = _identify(model, data, noise=None, **options)
    else:
        # The noise from a first fit's residuals; then the points weighted by it and fitted again. The second
        # fit has the first's shapes: it reuses every compiled function.
        first = _identify(model, data, noise=None, **options)
        say("estimating the noise from the first fit's residuals (the data give no output_sigma); fitting again "
            "with those weights")
        kappa, noise = estimated_noise(first, seed)
        fit = _identify(model, reweighted(data, kappa), noise=noise, **options)
    counts = {st: fit.status.count(st) for st in dict.fromkeys(fit.status)}
    say("done: " + ", ".join(f"{k} device(s) {st}" for st, k in counts.items()))
    return fit


def _identify(model, data, *, free, shared, priors, solver, starts, start_spread, seed, rtol, atol, max_steps,
              identifiability_threshold, hold, tier, evaluate_only, lot_solve, shard, lot_chunk, restart_runoffs,
              retry_solver, decrement_tol, reject_alpha, noise) -> Fit:
    """One fit of `identify` (arguments checked there) with the data's sigmas as they are; `noise`: the
    estimated noise's `(degrees of freedom, warnings, determined, p-values)` per device and the lot's p-value
    (`estimated_noise`), or None for given sigmas."""
    n = len(data.devices)
    model = batched(model, n)
    one = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, model)
    free = tuple(name for name in free if PARAMETERS.get(name) is None or PARAMETERS[name].exists_on(one.device))
    for name in free:
        if name not in PARAMETERS:
            raise ValueError(f"unknown parameter {name!r} in free; expected one of {', '.join(PARAMETERS)}.")
    entries = build_entries(one, free, tuple(shared))
    known = {e.label for e in entries} | {e.label.split(".")[0] for e in entries if e.effect_index is not None}
    for name in tuple(shared) + tuple(hold) + tuple(priors or {}):
        if name not in known:
            raise ValueError(f"{name!r} (in shared, hold or priors) is not a parameter of this fit; the fit has "
                             f"{', '.join(sorted(known))}.")
    dev_entries = [e for e in entries if not e.shared]
    lot_entries = [e for e in entries if e.shared]
    names_dev = tuple(nm for e in dev_entries for nm in e.names())
    names_lot = tuple(nm for e in lot_entries for nm in e.names())
    n_dev, n_lot = len(names_dev), len(names_lot)
    start = eqx.filter_vmap(lambda m: read_values(m, entries))(model)
    # Priors: residuals (u - mu) / s in internal coordinates of per-device physical parameters.
    prior_idx, prior_mu, prior_sd = [], [], []
    for name, (value, sigma) in (priors or {}).items():
        e = next(e for e in dev_entries if e.label == name)
        p0 = np.asarray(start[entries.index(e)])
        if e.transform == "log":
            mu, sd = np.log(value / p0), sigma / value * np.ones(n)
        else:
            mu, sd = (value - p0) / e.scale[0], sigma / e.scale[0] * np.ones(n)
        prior_idx.append(names_dev.index(name))
        prior_mu.append(mu)
        prior_sd.append(sd)

    # Names, run ids and the source are static metadata: keep them out of the compiled functions' keys, so
    # that every dataset of the same shapes shares one compile.
    data_jit = dataclasses.replace(data, devices=(), runs=(), source="")

    def problem_for(free_index):
        mask = np.zeros(n_dev)
        mask[np.asarray(free_index, dtype=int)] = 1.0
        pri = (jnp.asarray(prior_idx, dtype=int), jnp.asarray(np.stack(prior_mu, -1) if prior_mu else np.zeros((n, 0))),
               jnp.asarray(np.stack(prior_sd, -1) if prior_sd else np.ones((n, 0))))
        pri = (jnp.broadcast_to(pri[0], (n, len(prior_idx))), pri[1], pri[2])
        return _Problem(model, start, data_jit, jnp.broadcast_to(jnp.asarray(mask), (n, n_dev)),
                        n_dev, entries, tier, *pri, sf_temperature=t_sf)

    # One compiled evaluation, at the start and at the solution: the Jacobian over every per-device entry.
    t_sf = jnp.asarray(_sf_temperature(data))
    problem_all = problem_for(list(range(n_dev)))
    shards = (len(jax.devices()) if shard is None or shard else 1) if lot_solve == "vmap" else 1
    if lot_chunk == "auto":
        independent = shards == 1 and not shared and lot_solve == "vmap"
        # Measured: 256 CPU devices ran 3-4x faster per device in chunks of 16 than of 128; 4096 devices on
        # an H100 ran 2.2 ms/device in chunks of 1024 against 3.0 ms/device at once (the tail's steps).
        lot_chunk = (16 if jax.default_backend() == "cpu" else 1024) if independent else None
    if lot_chunk is not None and (shards > 1 or shared or lot_solve == "loop"):
        raise ValueError("lot_chunk applies to the vmapped solve of independent devices on one JAX device; "
                         "drop it, or drop shard / shared / lot_solve='loop'.")
    spread = _LotSpread(n, shards, lot_chunk)
    problem_all_s, zeros_s = spread.pad(problem_all, jnp.zeros((n, n_dev)))
    with _nonfinite_explained("at the start"):
        at_start = spread.unpad(_evaluate(problem_all_s, zeros_s, jnp.zeros(n_lot), spread.chunk))
    check_signs(data, {s: np.asarray(v) for s, v in at_start.predictions.items()},
                 model.device.name)
    # Identifiability at the start: hold what the data cannot see.
    candidates = [i for i, nm in enumerate(names_dev)
                  if not any(nm == h or nm.startswith(h + "[") or nm.startswith(h + ".") for h in hold)]
    keep, held_reports = hold_unidentifiable(np.asarray(at_start.jac)[:, :, candidates],
                                              [names_dev[i] for i in candidates], identifiability_threshold)
    free_index = [candidates[k] for k in keep]
    problem = problem_for(free_index)
    # A joint fit sums over devices: it is sharded only when the lot divides evenly (padding would add fake
    # devices to the sum).
    solve_spread = spread if not n_lot or n % shards == 0 else _LotSpread(n, 1)
    (problem_s,) = solve_spread.pad(problem)
    solver_ = _solver(solver, rtol, atol)
    rng = np.random.default_rng(seed)
    best = None

    def solve_devices(prob_s, u0, stage, solver=solver_):
        """Independent fits of every device of the padded problem `prob_s` from `u0`: (u, code, steps, chi2)."""
        solve = _solve_loop if lot_solve == "loop" else _solve_independent
        (u0_s,) = solve_spread.pad(jnp.asarray(u0))
        with _nonfinite_explained(stage):
            out = solve_spread.unpad(solve(prob_s, u0_s, jnp.zeros(0), solver, max_steps, solve_spread.chunk))
        return tuple(np.asarray(x) for x in out)

    for k in range(0 if evaluate_only else starts):
        # The solve runs over every per-device entry (held ones masked out of the model), so that a model's
        # compiled solve is shared by every choice of free parameters (diagnose adds effects by unmasking).
        u0 = np.zeros((n, n_dev))
        if k > 0:
            u0[:, free_index] = rng.normal(scale=start_spread, size=(n, len(free_index)))
        if n_lot:
            (u0_s,) = solve_spread.pad(jnp.asarray(u0))
            u0_lot = np.zeros(n_lot) if k == 0 else rng.normal(scale=start_spread, size=n_lot)
            with _nonfinite_explained(f"during the joint solve (start {k})"):
                res = solve_spread.unpad(_solve_joint(problem_s, u0_s, jnp.asarray(u0_lot), solver_, max_steps))
        else:
            v, code, steps, chi2 = solve_devices(problem_s, u0, f"during the solve (start {k})")
            res = (v, jnp.zeros(0), code, steps, chi2)
        res = tuple(np.asarray(x) for x in res)
        if best is None:
            best = res
            continue
        if n_lot:
            if np.nansum(res[4]) < np.nansum(best[4]):
                best = res
        else:
            better = np.nan_to_num(res[4], nan=np.inf) < np.nan_to_num(best[4], nan=np.inf)
            # Per device: the lower chi2 wins (u_lot, index 1, is empty here).
            best = tuple(b if i == 1 else np.where(better.reshape((n,) + (1,) * (b.ndim - 1)), a, b)
                         for i, (a, b) in enumerate(zip(res, best)))
    if evaluate_only:
        best = (np.zeros((n, n_dev)), np.zeros(n_lot), np.full(n, result_code(RESULTS.successful)),
                np.zeros(n, dtype=int), None)
    u_free, u_lot, code, steps, chi2 = best
    notes = [""] * n

    def at(u_free, u_lot):
        u_full = np.zeros((n, n_dev))
        u_full[:, free_index] = u_free[:, free_index]
        with _nonfinite_explained("at the solution"):
            return u_full, at_start if evaluate_only else spread.unpad(
                _evaluate(problem_all_s, spread.pad(jnp.asarray(u_full))[0], jnp.asarray(u_lot),
                          spread.chunk))

    u_full, final = at(u_free, u_lot)
    ok = result_code(RESULTS.successful)
    stopped = (code == result_code(RESULTS.nonlinear_max_steps_reached)) & (np.asarray(final.failed) == 0)
    if stopped.any():
        decrement = gauss_newton_decrement(np.asarray(final.jac)[:, :, free_index], np.asarray(final.jac_lot),
                               np.asarray(final.residuals), joint=bool(n_lot))
        certified = stopped & (decrement < decrement_tol)
        code = np.where(certified, ok, code)
        notes = [f"stopped at max_steps={max_steps}, where a full Gauss-Newton step would lower chi2 by only "
                 f"{dec:.3g} < decrement_tol={decrement_tol:g}" if c else note
                 for note, c, dec in zip(notes, certified, decrement)]
    if retry_solver is not None and not evaluate_only and isinstance(solver, str) and solver != retry_solver:
        # Levenberg-Marquardt can crawl where a full Gauss-Newton step would not (measured: a leaky-rebalance
        # paper-qmg lot with comb_gap free, LM 200 steps at chi2_red 6.3, Gauss-Newton 10 steps to 1.02).
        failed = code != ok
        if failed.any():
            stage, retry = f"during the {retry_solver} retry", _solver(retry_solver, rtol, atol)
            if n_lot:  # one joint solve: all devices or none
                (zeros_s,) = solve_spread.pad(jnp.zeros((n, n_dev)))
                with _nonfinite_explained(stage):
                    v, v_lot, code2, steps2, chi2_2 = (np.asarray(x) for x in solve_spread.unpad(
                        _solve_joint(problem_s, zeros_s, jnp.zeros(n_lot), retry, max_steps)))
                total, total_2 = (np.sum(np.nan_to_num(c, nan=np.inf)) for c in (chi2, chi2_2))
                better = np.full(n, bool(np.all(code2 == ok)) and total_2 <= total * (1 + 1e-6))
                if better[0]:
                    u_lot = v_lot
            else:
                v, code2, steps2, chi2_2 = solve_devices(problem_s, np.zeros((n, n_dev)), stage, retry)
                better = failed & (code2 == ok) & (np.nan_to_num(chi2_2, nan=np.inf) <=
                                                   np.nan_to_num(chi2, nan=np.inf) * (1 + 1e-6))
            u_free = np.where(better[:, None], v, u_free)
            code = np.where(better, code2, code)
            steps = np.where(better, steps + steps2, steps)
            chi2 = np.where(better, chi2_2, chi2)
            notes = [f"re-solved from the start with {retry_solver} after {solver} did not converge" if b else note
                     for note, b in zip(notes, better)]
            if better.any():
                u_full, final = at(u_free, u_lot)
    if restart_runoffs and not evaluate_only and not n_lot:
        weak = weak_directions(np.asarray(final.jac)[:, :, free_index], identifiability_threshold)
        runoff = [sorted({free_index[k] for members, _ in w for k in members}) for w in weak]
        if any(runoff):
            stage = "during the restart of a run-off fit"
            held_mask = np.array(problem.free_mask)
            u_hold = np.array(u_free)
            for d, idx in enumerate(runoff):
                held_mask[d, idx] = 0.0
                if idx:
                    u_hold[d] = 0.0  # from the start again
            (held_s,) = solve_spread.pad(eqx.tree_at(lambda p: p.free_mask, problem, jnp.asarray(held_mask)))
            v1, _, steps1, _ = solve_devices(held_s, u_hold, stage)
            v2, code2, steps2, chi2_2 = solve_devices(problem_s, v1, stage)
            better = np.array([bool(idx) for idx in runoff]) & (np.nan_to_num(chi2_2, nan=np.inf) <
                                                                np.nan_to_num(chi2, nan=np.inf))
            if better.any():
                u_free = np.where(better[:, None], v2, u_free)
                code = np.where(better, code2, code)
                steps = np.where(better, steps + steps1 + steps2, steps)
                u_full, final = at(u_free, u_lot)
                names_runoff = [", ".join(names_dev[i] for i in idx) for idx in runoff]
                notes = ["; ".join(filter(None, (note, f"restarted with {nm} held, then released, after the "
                                                            "first solve ran off along it" if b else "")))
                         for note, nm, b in zip(notes, names_runoff, better)]
    return _finish(problem_all, data, entries, names_dev, names_lot, free_index, u_full, np.asarray(u_lot), code,
                   steps, final, held_reports, identifiability_threshold, tuple(notes), candidates, reject_alpha,
                   noise)


def _sf_temperature(data):
    """Temperature at which the fit's scale factor is reported: the mean of the rate-table points (else of
    all recorded points, else the reference 25 C)."""
    blocks = [data.blocks["rate_table"]] if "rate_table" in data.blocks else list(data.blocks.values())
    total = sum(jnp.sum(jnp.where(b.mask & jnp.isfinite(b.temperatures), b.temperatures, 0.0), axis=(1, 2))
                for b in blocks)
    count = sum(jnp.sum(b.mask & jnp.isfinite(b.temperatures), axis=(1, 2)) for b in blocks).astype(float)
    return jnp.where(count > 0, total / jnp.maximum(count, 1.0), 25.0)


def _finish(problem_all, data, entries, names_dev, names_lot, free_index, u_full, u_lot, code, steps, final,
            held_reports, threshold, notes, candidates, reject_alpha, noise):
    n, n_dev, n_lot = len(data.devices), len(names_dev), len(names_lot)
    f = np.asarray(free_index, dtype=int)
    jac = np.asarray(final.jac)[:, :, f]  # (device, residual, free)
    jac_lot = np.asarray(final.jac_lot)
    chi2 = np.sum(np.asarray(final.residuals) ** 2, axis=-1)
    dof = np.asarray(num_points(data) - num_biases(data)) - f.size
    # Covariance of the internal coordinates: (J^T J)^+, block-diagonal over devices unless some entries
    # are shared (then the whole lot's normal matrix is inverted). Data without output_sigma were weighted by
    # their estimated noise before this (`identify`), so the covariance is that of the weights in both cases.
    if n_lot:
        cov_all = covariance(joint_jacobian(jac, jac_lot))
        cov_dev = np.stack([cov_all[d * f.size:(d + 1) * f.size, d * f.size:(d + 1) * f.size] for d in range(n)])
        cov_lot = cov_all[n * f.size:, n * f.size:]
        cross = np.stack([cov_all[d * f.size:(d + 1) * f.size, n * f.size:] for d in range(n)])
    else:
        cov_dev = covariance(jac)
        cov_lot = np.zeros((0, 0))
        cross = np.zeros((n, f.size, 0))
    cov_full = np.zeros((n, n_dev, n_dev))
    cov_full[:, f[:, None], f[None, :]] = cov_dev
    values, stderr = _physical(problem_all.start, entries, u_full, cov_full, f, shared=False)
    lot_values, lot_stderr = _physical(problem_all.start, entries, u_lot[None], cov_lot[None],
                                       np.arange(n_lot), shared=True)
    fitted = eqx.filter_vmap(lambda p, u: apply_u(p.model, p.entries, p.start, u, jnp.asarray(u_lot)))(
        problem_all, jnp.asarray(u_full))
    residuals = {}
    for sweep in data.sweeps:
        block = data.blocks[sweep]
        residuals[sweep] = jax.vmap(lambda bl, p, s=sweep: block_residuals(s, bl, p))(block, final.predictions[sweep])
    g = np.asarray(final.sf_grad)[:, f]
    g_lot = np.asarray(final.sf_grad_lot)
    var = np.einsum("di,dij,dj->d", g, cov_dev, g)
    if n_lot:
        var = var + np.einsum("di,ij,dj->d", g_lot, cov_lot, g_lot) + 2 * np.einsum("di,dij,dj->d", g, cross, g_lot)
    sf_stderr = np.sqrt(np.maximum(var, 0.0))
    failed = np.asarray(final.failed)
    ok = np.asarray(code) == result_code(RESULTS.successful)
    messages = [_message(bool(o), "" if o else result_message(c).split(".")[0], int(fl))
                for o, c, fl in zip(ok, np.asarray(code), failed)]
    weak = weak_at_solution(jac, [names_dev[i] for i in f], threshold)
    messages = tuple(m if not w else f"{m}; but {w}" for m, w in zip(messages, weak))
    messages = tuple(m if not note else f"{m} ({note})" for m, note in zip(messages, notes))
    free_mask = tuple(bool(i in set(f.tolist())) for i in range(n_dev))

    # What the data determine: the scale factor's gradient over every candidate parameter (free, or held as
    # unidentifiable) against the weighted Jacobian's row space.
    cand = np.asarray(candidates, dtype=int)
    determined, weak_part, _ = sf_determinacy(
        np.asarray(final.jac)[:, :, cand], jac_lot if n_lot else None, np.asarray(final.sf_grad)[:, cand],
        g_lot if n_lot else None, sf_stderr, threshold)
    if noise is None:
        noise_dof, noise_notes, noise_ok = np.full(n, np.inf), [()] * n, [True] * n
        p_value = chi2_p_value(chi2, dof, noise_dof)
        p_lot = float(chi2_p_value(np.asarray(chi2.sum()), np.asarray(int(dof.sum()) - n_lot), np.asarray(np.inf)))
    else:
        noise_dof, noise_notes, noise_ok, p_value, p_lot = noise
    chi2_red = chi2 / np.maximum(dof, 1)
    rejected = np.nan_to_num(p_value, nan=1.0) < reject_alpha
    implausible = implausible_values(entries, problem_all.start, values, lot_values[0], free_mask, n)
    status, warnings = [], []
    for d in range(n):
        notes_d = []
        if not ok[d] or failed[d]:
            status.append("not converged")
        elif not determined[d] or not noise_ok[d]:
            status.append("not determined")
            if not determined[d]:
                notes_d.append(undetermined_reason(data, d, [names_dev[i] for i in cand] + list(names_lot),
                                                    weak_part[d], f.size, threshold))
            else:  # the reason first: the noise (hence every uncertainty) is what the data leave open
                notes_d.append(noise_notes[d][-1])
        elif rejected[d] or implausible[d]:
            status.append("model rejected")
        else:
            status.append("ok")
        if rejected[d] and status[d] != "not converged":
            notes_d.append(f"the model does not describe the data: chi2 {chi2[d]:.4g} over {int(dof[d])} degrees of "
                           f"freedom has {p_text(p_value[d])} < reject_alpha = {reject_alpha:g}; the standard errors "
                           f"are also given scaled by sqrt(chi2_red) = {math.sqrt(chi2_red[d]):.3g} (stderr_scaled). "
                           "gyrojax.compare shows where the misfit sits")
        if dof[d] <= 0 and status[d] != "not converged":
            notes_d.append(f"no degrees of freedom are left ({int(dof[d])}): nothing tests the model")
        notes_d += implausible[d] + [w for w in noise_notes[d] if w not in notes_d]
        warnings.append(tuple(notes_d))
    undetermined = np.array([s == "not determined" for s in status])
    scale = np.where(rejected, np.sqrt(np.maximum(chi2_red, 1.0)), 1.0)
    sf = np.where(undetermined, np.nan, np.asarray(final.scale_factor))
    sf_stderr = np.where(undetermined, np.nan, sf_stderr)
    lot_rejected = bool(n_lot) and np.nan_to_num(p_lot, nan=1.0) < reject_alpha
    lot_scale = math.sqrt(max(float(chi2.sum()) / max(int(dof.sum()) - n_lot, 1), 1.0)) if lot_rejected else 1.0
    return Fit(model=fitted, names=names_dev, lot_names=names_lot, values=values[:, :n_dev],
               stderr=stderr[:, :n_dev], lot_values=lot_values[0], lot_stderr=lot_stderr[0], free=free_mask,
               covariance=jnp.asarray(cov_full), u=jnp.asarray(u_full), u_lot=jnp.asarray(u_lot),
               residuals=residuals, predictions=dict(final.predictions), biases=dict(final.biases),
               chi2=jnp.asarray(chi2), dof=jnp.asarray(dof),
               converged=jnp.asarray(ok & (failed == 0) & ~undetermined),
               result_message=messages, num_steps=jnp.asarray(steps), unsettled=jnp.asarray(failed),
               unidentifiable=held_reports, scale_factor=jnp.asarray(sf), scale_factor_stderr=jnp.asarray(sf_stderr),
               devices=data.devices, data=data, entries=entries, weighted=data.weighted, jacobian=final.jac,
               residual_vector=final.residuals, status=tuple(status), warnings=tuple(warnings),
               reject_alpha=float(reject_alpha), stderr_scaled=jnp.asarray(stderr[:, :n_dev] * scale[:, None]),
               lot_stderr_scaled=jnp.asarray(lot_stderr[0] * lot_scale),
               scale_factor_stderr_scaled=jnp.asarray(sf_stderr * scale),
               noise_dof=jnp.asarray(np.asarray(noise_dof, dtype=float)),
               p_value=jnp.asarray(np.asarray(p_value, dtype=float)), p_value_total=jnp.asarray(float(p_lot)))


def _physical(start, entries, u, cov, free_index, *, shared):
    """Physical values and standard errors (delta method) of the per-device (or shared) entries."""
    values, ses = [], []
    var_all = np.diagonal(cov, axis1=1, axis2=2)
    k = 0
    for e, p0 in zip(entries, start):
        if e.shared != shared:
            continue
        uu = u[:, k:k + e.size]
        var = var_all[:, k:k + e.size]
        p0 = np.reshape(np.asarray(p0), (np.shape(p0)[0], -1))[: uu.shape[0]]
        if e.transform == "log":
            v = p0 * np.exp(uu)
            sd = v * np.sqrt(var)
        else:
            sc = np.asarray(e.scale)
            v, sd = p0 + sc * uu, sc * np.sqrt(var)
        held = ~np.isin(np.arange(k, k + e.size), free_index)
        values.append(v)
        ses.append(np.where(held[None, :], np.nan, sd))
        k += e.size
    if not values:
        return np.zeros((u.shape[0], 0)), np.zeros((u.shape[0], 0))
    return np.concatenate(values, axis=1), np.concatenate(ses, axis=1)
