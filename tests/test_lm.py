"""The round-off-aware Levenberg-Marquardt of gyrojax/_numerics/lm.py."""

import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from gyrojax._numerics.linsolve import PivotedLU
from gyrojax._numerics.lm import LevenbergMarquardt, RunoffBound


RNG = np.random.default_rng(0)
# Columns scaled like identify's (a k_vf, a K_svf and a DAC gain error: curvatures 1e4 apart).
A = RNG.normal(size=(60, 3)) * np.array([1e5, 1e6, 1e2])
B = RNG.normal(size=60)
STARTS = RNG.normal(size=(10, 3)) * np.array([1e-5, 1e-6, 1e-2])
NORMAL = lx.Normal(PivotedLU(zero_pivot_gives_zero=True))


def _noisy_linear(y, _):
    # Residuals as a root find delivers them: exact up to deterministic round-off of 1e-11 relative.
    r = jnp.asarray(A) @ y - jnp.asarray(B)
    return r + 1e-11 * jnp.sin(1e9 * y[0] + 3e8 * y[1] + 1e6 * y[2]) * jnp.abs(r)


def _steps(solver):
    out = []
    for y0 in STARTS:
        sol = optx.least_squares(_noisy_linear, solver, jnp.asarray(y0), max_steps=200, throw=False)
        assert sol.result == optx.RESULTS.successful
        out.append((int(sol.stats["num_steps"]), np.asarray(sol.value)))
    return out


def test_round_off_does_not_stall_the_trust_region():
    exact = np.linalg.lstsq(A, B, rcond=None)[0]
    stderr = np.sqrt(np.diag(np.linalg.inv(A.T @ A)))
    ours = _steps(LevenbergMarquardt(1e-8, 1e-8, NORMAL))
    classical = _steps(optx.LevenbergMarquardt(1e-8, 1e-8, linear_solver=NORMAL))
    for steps, value in ours:
        assert steps <= 5
        assert np.max(np.abs(value - exact) / stderr) < 1e-5  # the least-squares solution, in sigma
    # optimistix's own test rejects steps whose loss change is round-off until the step underflows.
    assert max(s for s, _ in classical) > max(s for s, _ in ours)


def test_same_path_as_optimistix_away_from_round_off():
    # Rosenbrock: every step's loss change is far above round-off, so both accept and reject alike.
    def rosenbrock(y, _):
        return jnp.stack([10 * (y[1] - y[0] ** 2), 1 - y[0]])

    y0 = jnp.asarray([-1.2, 1.0])
    a = optx.least_squares(rosenbrock, LevenbergMarquardt(1e-10, 1e-10, NORMAL), y0, max_steps=200)
    b = optx.least_squares(rosenbrock, optx.LevenbergMarquardt(1e-10, 1e-10, linear_solver=NORMAL), y0,
                           max_steps=200)
    assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
    np.testing.assert_allclose(np.asarray(a.value), [1.0, 1.0], rtol=1e-9)


def test_the_solve_reports_the_evaluation_at_its_solution():
    """identify's solve takes the evaluation at the solution (residuals, Jacobian, predictions: the residual
    function's aux) from the solver's state (no second copy of the model in the compiled solve): it must be
    that of `sol.value`, also when the solve stops early on a rejected step, and a solver that keeps only the
    loss (BFGS) evaluates it."""
    from gyrojax._identify.evaluation import final_evaluation

    def rosenbrock(y, _):
        r = jnp.stack([10 * (y[1] - y[0] ** 2), 1 - y[0]])
        return r, {"residuals": r, "at": y}

    y0 = jnp.asarray([-1.2, 1.0])
    solvers = (LevenbergMarquardt(1e-10, 1e-10, NORMAL), optx.GaussNewton(1e-10, 1e-10, linear_solver=NORMAL),
               optx.BFGS(1e-10, 1e-10))
    rejected = 0
    # Levenberg-Marquardt's third step on Rosenbrock from (-1.2, 1) is rejected; each max_steps compiles anew.
    for solver, max_steps in [(solvers[0], 3), (solvers[0], 200), (solvers[1], 200), (solvers[2], 200)]:
        sol = optx.least_squares(rosenbrock, solver, y0, has_aux=True, max_steps=max_steps, throw=False)
        kept = isinstance(getattr(sol.state, "f_info", None), optx.FunctionInfo.ResidualJac)
        assert kept == (not isinstance(solver, optx.BFGS))
        if kept:
            rejected += int(sol.state.num_steps_since_acceptance > 0)
        got, want = final_evaluation(sol, rosenbrock), rosenbrock(sol.value, None)[1]
        np.testing.assert_array_equal(np.asarray(got["at"]), np.asarray(sol.value))
        # equal up to the round-off of the same expression in another program (terms of ~10)
        np.testing.assert_allclose(np.asarray(got["residuals"]), np.asarray(want["residuals"]), rtol=1e-14,
                                   atol=1e-13)
    assert rejected > 0  # some solve above stopped on a rejected step


def test_a_step_limit_of_one_evaluates_at_the_start():
    """`evaluation_step`: the solver stopped after its first (always accepted) step returns the start and the
    evaluation there, as converged; the limit is a traced value (the same compiled solve as the full one)."""
    import equinox as eqx

    from gyrojax._identify.evaluation import evaluation_step, final_evaluation

    def rosenbrock(y, _):
        r = jnp.stack([10 * (y[1] - y[0] ** 2), 1 - y[0]])
        return r, r

    y0 = jnp.asarray([-1.2, 1.0])
    traces = []

    @eqx.filter_jit
    def solve(solver):
        traces.append(1)
        return optx.least_squares(rosenbrock, solver, y0, has_aux=True, max_steps=50, throw=False)

    full = solve(LevenbergMarquardt(1e-10, 1e-10, NORMAL))
    assert int(full.stats["num_steps"]) > 5 and float(full.value[0]) == pytest.approx(1.0, abs=1e-8)
    for solver in (LevenbergMarquardt(1e-10, 1e-10, NORMAL), optx.BFGS(1e-10, 1e-10)):
        sol = solve(evaluation_step(solver))
        assert int(sol.stats["num_steps"]) == 1 and sol.result == optx.RESULTS.successful
        np.testing.assert_array_equal(np.asarray(sol.value), np.asarray(y0))
        np.testing.assert_allclose(np.asarray(final_evaluation(sol, rosenbrock)),
                                   np.asarray(rosenbrock(y0, None)[0]), rtol=1e-15)
    assert len(traces) == 2  # one program for the full solve and its evaluation, one for BFGS's evaluation


def test_the_undamped_flag_is_gauss_newton_in_the_same_compiled_solve():
    """`undamped=True` takes optimistix's Gauss-Newton path (same steps, same solution), and it is an array
    leaf: a Gauss-Newton retry after a Levenberg-Marquardt solve runs the same compiled program."""
    import equinox as eqx

    def rosenbrock(y, _):
        return jnp.stack([10 * (y[1] - y[0] ** 2), 1 - y[0]])

    traces = []

    @eqx.filter_jit
    def solve(solver, y0):
        traces.append(1)
        sol = optx.least_squares(rosenbrock, solver, y0, max_steps=200, throw=False)
        return sol.value, sol.stats["num_steps"], sol.result

    y0 = jnp.asarray([-1.2, 1.0])
    lm = solve(LevenbergMarquardt(1e-10, 1e-10, NORMAL), y0)
    gn = solve(LevenbergMarquardt(1e-10, 1e-10, NORMAL, undamped=True), y0)
    assert len(traces) == 1
    ref = optx.least_squares(rosenbrock, optx.GaussNewton(1e-10, 1e-10, linear_solver=NORMAL), y0, max_steps=200)
    assert int(gn[1]) == int(ref.stats["num_steps"]) != int(lm[1])
    np.testing.assert_allclose(np.asarray(gn[0]), np.asarray(ref.value), rtol=1e-12)
    assert gn[2] == optx.RESULTS.successful
    # On the scaled linear problem a Gauss-Newton step is the solution: one step, then the Cauchy test.
    for y_start in STARTS[:3]:
        a = optx.least_squares(_noisy_linear, LevenbergMarquardt(1e-8, 1e-8, NORMAL, undamped=True),
                               jnp.asarray(y_start), max_steps=50)
        b = optx.least_squares(_noisy_linear, optx.GaussNewton(1e-8, 1e-8, linear_solver=NORMAL),
                               jnp.asarray(y_start), max_steps=50)
        assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
        np.testing.assert_allclose(np.asarray(a.value), np.asarray(b.value), rtol=1e-9)


def test_a_coordinate_past_its_runoff_bound_stops_the_solve_as_diverged():
    # The minimum of (exp(-y0), y1 - 1) lies at y0 = infinity: without a bound the solve creeps on to max_steps;
    # with one it stops at the first step past it, as diverged, and a coordinate without a bound is unaffected.
    def runs_off(y, _):
        return jnp.stack([jnp.exp(-y[0]), y[1] - 1.0])

    y0 = jnp.asarray([0.0, 0.0])
    solver = LevenbergMarquardt(1e-12, 1e-12, NORMAL)
    free = optx.least_squares(runs_off, solver, y0, max_steps=100, throw=False)
    assert int(free.stats["num_steps"]) == 100 and float(free.value[0]) > 4.0
    bounded = optx.least_squares(runs_off, solver, y0, RunoffBound(jnp.asarray([3.0, jnp.inf])), max_steps=100,
                                 throw=False)
    assert bounded.result == optx.RESULTS.nonlinear_divergence
    assert 3.0 < float(bounded.value[0]) < 3.5 and int(bounded.stats["num_steps"]) < 80
    untouched = optx.least_squares(runs_off, solver, y0, RunoffBound(jnp.asarray([jnp.inf, 2.0])), max_steps=100,
                                   throw=False)
    assert int(untouched.stats["num_steps"]) == 100


def test_a_traced_step_budget_ends_the_solve_as_optimistix_max_steps_does():
    """`with_max_steps`: the budget as the solver's traced `max_steps` ends an unconverged solve after exactly
    that many steps with `nonlinear_max_steps_reached` and the same iterate as optimistix's static `max_steps`;
    a solve that converges within it is untouched; every budget runs one compiled solve. Other solvers keep
    optimistix's static budget."""
    import equinox as eqx

    from gyrojax._numerics.lm import STEP_CEILING, with_max_steps

    def rosenbrock(y, _):
        return jnp.stack([10 * (y[1] - y[0] ** 2), 1 - y[0]])

    y0 = jnp.asarray([-1.2, 1.0])
    traces = []

    @eqx.filter_jit
    def solve(solver, max_steps):
        traces.append(1)
        return optx.least_squares(rosenbrock, solver, y0, max_steps=max_steps, throw=False)

    lm = LevenbergMarquardt(1e-10, 1e-10, NORMAL)
    needs = int(solve(lm, 200).stats["num_steps"])  # 35 measured
    assert 5 < needs < 200
    for budget in (3, needs - 1, needs, 200):  # out of steps one short, converged on its last step
        solver, static = with_max_steps(lm, budget)
        assert static == STEP_CEILING
        got, want = solve(solver, static), solve(lm, budget)
        assert int(got.stats["num_steps"]) == int(want.stats["num_steps"]) == min(budget, needs)
        assert got.result == want.result
        assert (got.result == optx.RESULTS.nonlinear_max_steps_reached) == (budget < needs)
        np.testing.assert_array_equal(np.asarray(got.value), np.asarray(want.value))
    assert len(traces) == 4 + 1  # optimistix's budget: a program per value; the traced one: one for all
    bfgs = optx.BFGS(1e-10, 1e-10)
    assert with_max_steps(bfgs, 5) == (bfgs, 5) and with_max_steps(lm, STEP_CEILING + 1)[1] == STEP_CEILING + 1
