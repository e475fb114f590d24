"""Levenberg-Marquardt whose trust region knows the round-off of the loss.

optimistix's `ClassicalTrustRegion` accepts a step only if the loss fell by at least 1 % of the predicted
fall. At the minimum the predicted fall is ~1e-20 while the computed loss moves by its round-off (the
residuals come out of steady-state root finds, ~1e-10), so about every other step is rejected; each
rejection quarters the step, until the step underflows to exactly zero and the test `0 <= 0.01 * 0` passes.
A lot of 16 devices measured 5 steps for most devices and up to 34 for some, and a vmapped lot runs until
its slowest device has finished. Here a step whose loss change is within `roundoff * (1 + loss)` of the
required fall is accepted; Cauchy termination (optimistix's, unchanged) then ends the solve.

The same solver is Gauss-Newton when its `undamped` flag (an array, so a traced value, not a compiled
constant) is set: no damping (lambda = 1/inf = 0, the normal equations J^T J) and every step accepted. A solve
retried with Gauss-Newton after Levenberg-Marquardt then reuses the compiled program of the first. Its
`step_limit` (also traced) stops it after that many steps: with 1, the solve only evaluates at its start (the
first step is always accepted), which is how `identify` evaluates without a program of its own. Its
`max_steps` (traced too; `with_max_steps`) ends a solve that has not converged after that many steps with
optimistix's `nonlinear_max_steps_reached`, as optimistix's own `max_steps` would, but without a program per
value: a fit retried with more steps reuses the compiled solve. Given a `RunoffBound` as the solve's `args`, it
stops, as diverged, once a coordinate passes its bound.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .linsolve import PivotedLU


class _RadiusState(eqx.Module):
    step_size: jnp.ndarray


class RoundoffTrustRegion(optx.AbstractSearch):
    """`optimistix.ClassicalTrustRegion` (same cutoffs and constants, same predicted reduction) with the
    acceptance test widened by the loss's round-off."""

    roundoff: float = 1e-10
    classical: optx.ClassicalTrustRegion = optx.ClassicalTrustRegion()
    undamped: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(False), converter=jnp.asarray)

    def init(self, y, f_info_struct):
        return _RadiusState(step_size=jnp.array(1.0))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        tr = self.classical
        y_diff = jax.tree.map(lambda a, b: a - b, y_eval, y)
        predicted = tr.predict_reduction(y_diff, f_info)
        f_min = f_info.as_min()
        change = f_eval_info.as_min() - f_min  # negative when the loss fell
        slack = self.roundoff * (1.0 + jnp.abs(f_min))
        accept = (change <= tr.low_cutoff * predicted + slack) | first_step
        good = (change < tr.high_cutoff * predicted) & (predicted < 0) & ~first_step
        mul = jnp.where(accept, jnp.where(good, tr.high_constant, 1.0), tr.low_constant)
        step_size = mul * state.step_size
        # Gauss-Newton: the full step (an infinite radius is a damping of exactly 0), always taken.
        full = jnp.where(self.undamped, jnp.inf, step_size)
        return full, accept | self.undamped, optx.RESULTS.successful, _RadiusState(step_size)


class RunoffBound(eqx.Module):
    """The solve's `args`: where an internal coordinate has run off (`LevenbergMarquardt` stops there, with
    `nonlinear_divergence`), per entry of the solve's vector (`inf`: never)."""

    bound: jax.Array


def _quiet(**kwargs):
    return None


class LevenbergMarquardt(optx.AbstractGaussNewton):
    """optimistix's Levenberg-Marquardt (damped Newton descent, classical trust-region update) with the
    round-off-aware acceptance of `RoundoffTrustRegion`; with `undamped=True`, Gauss-Newton (optimistix's
    `GaussNewton` path: full Newton steps on the normal equations, each accepted) in the same compiled
    program. Its `step_limit` field (none by default) stops the solve after that many steps, reported as converged:
    only for evaluating at the start (`evaluation_step`), never for a fit. Its `max_steps` field (none by
    default; see `with_max_steps`) ends an unconverged solve after that many steps as `nonlinear_max_steps_reached`."""

    rtol: float
    atol: float
    norm: Callable
    descent: optx.DampedNewtonDescent
    search: RoundoffTrustRegion
    verbose: Callable
    step_limit: jax.Array
    max_steps: jax.Array

    def __init__(self, rtol: float, atol: float, linear_solver: lx.AbstractLinearSolver | None = None,
                 roundoff: float = 1e-10, undamped: bool = False):
        if linear_solver is None:
            # Normal equations through an XLA-only LU, not lineax's LAPACK QR: see gyrojax/_numerics/linsolve.py.
            linear_solver = lx.Normal(PivotedLU(zero_pivot_gives_zero=True))
        self.rtol, self.atol = rtol, atol
        self.norm = optx.max_norm
        self.descent = optx.DampedNewtonDescent(linear_solver=linear_solver)
        self.search = RoundoffTrustRegion(roundoff=roundoff, undamped=undamped)
        self.verbose = _quiet
        # No limit; `_identify/evaluation.py::evaluation_step` sets 1 (a traced value: the same program).
        self.step_limit = jnp.asarray(np.iinfo(np.int32).max)
        self.max_steps = jnp.asarray(np.iinfo(np.int32).max)

    def terminate(self, fn, y, args, options, state, tags):
        stop, result = super().terminate(fn, y, args, options, state, tags)
        stop = stop | (state.num_steps >= self.step_limit)
        if isinstance(args, RunoffBound):
            # A run-off: no further step can bring back what a data set does not fix; stop, as diverged.
            ran_off = jnp.any(jnp.abs(y) > args.bound)
            result = optx.RESULTS.where(ran_off & ~stop, optx.RESULTS.nonlinear_divergence, result)
            stop = stop | ran_off
        # Out of steps and not converged: what optimistix reports at its own max_steps.
        out_of_steps = ~stop & (state.num_steps >= self.max_steps)
        result = optx.RESULTS.where(out_of_steps & (result == optx.RESULTS.successful),
                                    optx.RESULTS.nonlinear_max_steps_reached, result)
        return stop | out_of_steps, result


# The static step count handed to optimistix when the step budget is the solver's traced `max_steps`: every
# budget up to it shares one compiled solve.
STEP_CEILING = 100_000


def with_max_steps(solver, max_steps: int):
    """`(solver, static max_steps)` for `optimistix.least_squares`: for gyrojax's Levenberg-Marquardt, the budget
    as its traced `max_steps` and `STEP_CEILING` as optimistix's (one compiled solve for every budget up to it);
    any other solver, or a larger budget, as it is."""
    if isinstance(solver, LevenbergMarquardt) and max_steps <= STEP_CEILING:
        return eqx.tree_at(lambda s: s.max_steps, solver, jnp.asarray(max_steps)), STEP_CEILING
    return solver, max_steps
