"""What a fit knows about one device at one point of parameter space (`Evaluation`: residuals, the Jacobian over
every per-device and lot entry, the zero-rate scale factor and its gradient, predictions, run biases), and
`evaluated`, the residual function the solvers run, which carries the evaluation along as its aux.

Why one function for both: the evaluation at the start (identifiability), at the solution (covariance,
determinacy of the scale factor) and the solver's own residuals and Jacobian are the same forward-mode pass of
the model. Levenberg-Marquardt keeps the aux of its last accepted step, so the solve's compiled program
returns the evaluation at its solution, and the same program with a step limit of one (`evaluation_step`) is
the evaluation at the start: one traced and compiled copy of the model per fit instead of two.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._model.residuals import run_biases
from .._numerics.lm import LevenbergMarquardt
from .problem import evaluate_at


class Evaluation(eqx.Module):
    """Residuals, Jacobians and derived quantities of a device (or, device axis first, of every device) at one
    point of parameter space."""

    residuals: jax.Array  # (device, residual)
    jac: jax.Array  # (device, residual, n_dev) with respect to every per-device entry, held ones too
    jac_lot: jax.Array  # (device, residual, n_lot)
    scale_factor: jax.Array  # (device,) LSB per deg/s at zero rate
    sf_grad: jax.Array  # (device, n_dev)
    sf_grad_lot: jax.Array  # (device, n_lot)
    predictions: dict
    biases: dict
    failed: jax.Array  # (device,) points that did not settle


# Its own jit: optimistix traces the residual function three times (its output's shape, the linearisation's
# shape, the step), the primal and the JVP rule each time; a jitted body is traced once per signature.
@eqx.filter_jit
def _evaluation(problem, u_free, u_lot) -> Evaluation:
    # Differentiated with respect to the model's coordinates (held entries masked to their start), so that the
    # Jacobian has a column for every per-device entry: the solver's is this one with the held columns zeroed.
    u = u_free * problem.free_mask

    def outputs(uu, ul):
        r, failed, preds, _, sf = evaluate_at(problem, uu, ul)
        # The values as aux: jacfwd evaluates the sweeps once, for the Jacobian and the predictions.
        return (r, sf), (r, sf, failed, preds)

    ((j, j_lot), (g, g_lot)), (r, sf, failed, preds) = jax.jacfwd(outputs, argnums=(0, 1), has_aux=True)(u, u_lot)
    biases = {sweep: run_biases(sweep, problem.data.blocks[sweep], pred) for sweep, pred in preds.items()}
    return Evaluation(r, j, j_lot, sf, g, g_lot, preds, biases, failed)


@jax.custom_jvp
def evaluated(problem, u_free, u_lot) -> tuple[jax.Array, Evaluation]:
    """One device's standardised residuals (data, then priors) at `u_free` (held entries masked), and the
    `Evaluation` there as aux (not differentiated)."""
    ev = _evaluation(problem, u_free, u_lot)
    return ev.residuals, ev


@evaluated.defjvp
def _evaluated_jvp(primals, tangents):
    # The JVP as the materialised Jacobian times the tangent. Optimistix linearises the residual function and,
    # on its first (discarded) step, evaluates the linearisation with zeroed constants; through the steady
    # state's implicit differentiation that would feed NaNs to a linear solve that raises. A dense Jacobian
    # has no such solve, and is what Levenberg-Marquardt builds anyway. The problem's own tangents (data,
    # start values) are not parameters and are ignored; the evaluation is aux, with zero tangents.
    problem, u_free, u_lot = primals
    _, t_free, t_lot = tangents
    ev = _evaluation(problem, u_free, u_lot)
    t_r = ev.jac @ (problem.free_mask * t_free) + ev.jac_lot @ t_lot
    zeros = jax.tree.map(lambda x: jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact)
                         else np.zeros(x.shape, jax.dtypes.float0), ev)
    return (ev.residuals, ev), (t_r, zeros)


def one_trace():
    """The context to trace a solve of `evaluated` in. JAX keys its cache of traced inner jits on the abstract
    mesh of the context; optimistix traces the residual function first as it is (closure conversion) and
    then its JVP rule under linearisation, which runs under an empty `AbstractMesh` where a plain trace has
    none: without this the evaluation, most of a fit's program, is traced twice (measured on the demo lot:
    2-3 s of a 10 s trace)."""
    return jax.sharding.use_abstract_mesh(jax.sharding.AbstractMesh((), ()))


def final_evaluation(sol, fn) -> Evaluation:
    """The evaluation at a least-squares solution of `fn` (`evaluated`'s form). A Gauss-Newton-type solver
    (Levenberg-Marquardt, Gauss-Newton) keeps the aux of its last accepted step, which is the solution:
    evaluating `fn` again would put a second copy of the model into the compiled solve. BFGS keeps only the
    loss."""
    state = sol.state
    if isinstance(getattr(state, "f_info", None), optx.FunctionInfo.ResidualJac) and hasattr(state, "aux"):
        return state.aux
    return fn(sol.value, None)[1]


def evaluation_step(solver) -> LevenbergMarquardt:
    """The solver that evaluates at its start: gyrojax's Levenberg-Marquardt stopped after its first step,
    whose accepted point is the start. `solver` itself when it is one (its step limit is a traced value, so
    this is the solve's own compiled program), else a default one."""
    if not isinstance(solver, LevenbergMarquardt):
        solver = LevenbergMarquardt(rtol=1e-8, atol=1e-8)
    return eqx.tree_at(lambda s: s.step_limit, solver, jnp.asarray(1))
