"""An explicit Runge-Kutta step with its stages written out at trace time.

diffrax runs the stages of its explicit Runge-Kutta solvers (`Tsit5`, `Dopri5`, `Dopri8`, ...) as an inner
loop (`eqxi.while_loop` over the stage index, with the tableau and the stage derivatives indexed
dynamically), which keeps compile times short for big vector fields. For the full-waveform tier the
vector field is tiny (25 states, about 0.3 us inside XLA on a CPU) and is called for some 10^4-10^5 steps,
so that inner loop and its per-stage bookkeeping cost several times the field itself. `UnrolledRK` takes
the *same* Butcher tableau and writes every stage as straight-line code, so XLA fuses each step into a few
kernels. Same tableau, same error estimate, same step-size control: the numbers agree with diffrax's own
solver to rounding (the order of the floating-point sums differs). `UnrolledRK.dop853()` adds Hairer's
DOP853, which diffrax does not ship.
"""

from typing import ClassVar

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp


def _combine(coefficients, stages):
    """`sum_i coefficients[i] * stages[i]` leaf by leaf, skipping zero coefficients; None if all zero."""
    used = [(a, k) for a, k in zip(coefficients, stages) if a != 0.0]
    if not used:
        return None

    def leaf(*ks):
        total = used[0][0] * ks[0]
        for (a, _), k in zip(used[1:], ks[1:]):
            total = total + a * k
        return total

    return jax.tree.map(leaf, *[k for _, k in used])


def _floats(array):
    return tuple(float(v) for v in array)


class UnrolledRK(diffrax.AbstractAdaptiveSolver):
    """An explicit Runge-Kutta method (a diffrax tableau) with its stages unrolled at trace time.

    Build it from a diffrax solver with `UnrolledRK.from_solver(diffrax.Dopri8())`. Dense output (used
    only by `SaveAt(ts=...)` / `SaveAt(dense=True)`) is the cubic Hermite interpolant through both ends of
    the step, not the method's own higher-order interpolant; the full-waveform tier saves only at the ends
    of its solves, where no interpolation happens.

    **Fields** (static, Python floats, so that the tableau is part of the compiled program):

    - `c`: the nodes of stages 2, 3, ... (stage 1 is at the start of the step).
    - `a`: row i holds the coefficients of stage i + 2 on the stages before it.
    - `b_sol`, `b_error`: the solution weights and the error-estimate weights over all stages.
    - `b_error_low`: optional second error-estimate weights (a lower-order embedded solution), for
      Hairer's combined estimate of DOP853 (see `dop853`); `None` for the usual single estimate.
    - `fsal`: first-same-as-last (the last stage is the field at the end of the step, reused next step).
    - `method_order`: the order of the solution.
    """

    c: tuple[float, ...] = eqx.field(static=True)
    a: tuple[tuple[float, ...], ...] = eqx.field(static=True)
    b_sol: tuple[float, ...] = eqx.field(static=True)
    b_error: tuple[float, ...] = eqx.field(static=True)
    fsal: bool = eqx.field(static=True)
    method_order: int = eqx.field(static=True)
    b_error_low: tuple[float, ...] | None = eqx.field(static=True, default=None)

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = diffrax.ThirdOrderHermitePolynomialInterpolation

    def __check_init__(self):
        stages = len(self.c) + 1
        if len(self.a) != stages - 1 or any(len(row) != i + 1 for i, row in enumerate(self.a)):
            raise ValueError(f"UnrolledRK.a must be lower-triangular with {stages - 1} rows (row i of length "
                             f"i + 1), got row lengths {[len(r) for r in self.a]}.")
        if len(self.b_sol) != stages or len(self.b_error) != stages:
            raise ValueError(f"UnrolledRK.b_sol and b_error need {stages} weights each, got "
                             f"{len(self.b_sol)} and {len(self.b_error)}.")
        if self.b_error_low is not None and len(self.b_error_low) != stages:
            raise ValueError(f"UnrolledRK.b_error_low needs {stages} weights, got {len(self.b_error_low)}.")
        if self.fsal and (self.c[-1] != 1.0 or self.a[-1] != self.b_sol[:-1] or self.b_sol[-1] != 0.0):
            raise ValueError("UnrolledRK: fsal=True needs a last stage at c = 1 whose coefficients are the "
                             "solution weights (b_sol with a zero last weight).")

    @classmethod
    def from_solver(cls, solver: diffrax.AbstractERK) -> "UnrolledRK":
        """The same method as the diffrax explicit Runge-Kutta `solver` (`Tsit5()`, `Dopri5()`, `Dopri8()`,
        `Bosh3()`, `Heun()`, ...), stages unrolled."""
        tableau = getattr(solver, "tableau", None)
        if not isinstance(solver, diffrax.AbstractERK) or tableau is None or tableau.implicit:
            raise ValueError(f"UnrolledRK.from_solver: solver must be an explicit Runge-Kutta solver of "
                             f"diffrax with a Butcher tableau (Tsit5(), Dopri5(), Dopri8(), ...), got {solver!r}.")
        if tableau.fsal != tableau.ssal:
            raise ValueError(f"UnrolledRK.from_solver: {type(solver).__name__}'s tableau is FSAL without being "
                             "SSAL (or the reverse); only tableaus with both or neither are supported.")
        order = solver.order(diffrax.ODETerm(lambda t, y, args: y))
        if order is None:
            raise ValueError(f"UnrolledRK.from_solver: {type(solver).__name__} does not report its order.")
        return cls(c=_floats(tableau.c), a=tuple(_floats(row) for row in tableau.a_lower),
                   b_sol=_floats(tableau.b_sol), b_error=_floats(tableau.b_error), fsal=bool(tableau.fsal),
                   method_order=int(order))

    @classmethod
    def dop853(cls) -> "UnrolledRK":
        r"""DOP853: Dormand and Prince's order-8 method with Hairer's error estimate, the method of scipy's
        `solve_ivp(method="DOP853")` and of the Fortran `dop853` (coefficients in `_dop853.py`).

        12 stages plus the field at the end of the step (reused as the next step's first stage). The error
        estimate combines the differences e5, e3 of the order-8 solution from embedded solutions of order
        5 and 3 as Hairer does, e5 |e5| / sqrt(|e5|^2 + 0.01 |e3|^2): it follows the error of the order-8
        solution itself, where diffrax's `Dopri8` estimates that of its order-7 companion, so for the same
        tolerance DOP853 takes fewer steps. (Hairer weights |.| by the tolerances; here it is the plain
        root-sum-square over the state, the same thing when the states are scaled to O(1) as in the tiers.)
        """
        from . import _dop853 as d

        return cls(c=d.C + (1.0,), a=d.A + (d.B,), b_sol=d.B + (0.0,), b_error=d.E5, fsal=True, method_order=8,
                   b_error_low=d.E3)

    def order(self, terms):
        return self.method_order

    def init(self, terms, t0, t1, y0, args):
        return terms.vf(t0, y0, args) if self.fsal else None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        dt = t1 - t0

        def add(y, increment):
            return y if increment is None else jax.tree.map(lambda u, v: u + dt * v, y, increment)

        if not self.fsal:
            f0 = terms.vf(t0, y0, args)
        elif made_jump is False:  # diffrax resolves this statically when no jumps can occur
            f0 = solver_state
        else:
            # After a jump (`jump_ts`) the field at t0 is re-evaluated. The predicate is made unbatched, so
            # that under `vmap` this stays a branch (taken by all lanes when any lane jumped) instead of
            # becoming a select that would evaluate the field on every step.
            def fresh():
                f = terms.vf(t0, y0, args)
                return jax.tree.map(lambda a, b: jnp.where(made_jump, a, b), f, solver_state)

            f0 = jax.lax.cond(eqxi.unvmap_any(made_jump), fresh, lambda: solver_state)
        fs = [f0]
        y_stage = y0
        for c, row in zip(self.c, self.a):
            y_stage = add(y0, _combine(row, fs))
            fs.append(terms.vf(t0 + c * dt, y_stage, args))
        if self.fsal:
            y1, f1 = y_stage, fs[-1]
        else:
            y1, f1 = add(y0, _combine(self.b_sol, fs)), None
        error = _combine(self.b_error, fs)
        if self.b_error_low is not None:
            low = _combine(self.b_error_low, fs)
            high2 = sum(jnp.sum(v**2) for v in jax.tree.leaves(error))
            low2 = sum(jnp.sum(v**2) for v in jax.tree.leaves(low))
            denominator = jnp.sqrt(high2 + 0.01 * low2)
            ratio = jnp.where(denominator > 0, jnp.sqrt(high2) / jnp.where(denominator > 0, denominator, 1.0), 0.0)
            error = jax.tree.map(lambda v: ratio * v, error)
        y_error = jax.tree.map(lambda v: dt * v, error)
        k1 = terms.vf(t1, y1, args) if f1 is None else f1
        dense_info = dict(y0=y0, y1=y1, k0=jax.tree.map(lambda v: dt * v, f0),
                          k1=jax.tree.map(lambda v: dt * v, k1))
        return y1, y_error, dense_info, (f1 if self.fsal else None), diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)
