"""Small dense linear solves written in XLA operations only (no LAPACK custom call).

Why: on jaxlib 0.10's CPU runtime a batched LAPACK kernel (`lapack_dgetrf_ffi`, reached through
`jnp.linalg.solve` or lineax's `LU`/`QR` under `vmap`) can run on a worker of XLA's intra-op thread pool,
fan its batch out into that same pool and wait on it: a deadlock with every thread idle. A native stack
of a hung `identify` showed exactly that (`LuDecomposition` -> `jax::ParallelBatchMap` ->
`BlockingCounter::Wait` on the `tf_XLAEigen` worker; PyAutoLabs/PyAutoFit#1530 found the same pattern for
the FFT thunk). gyrojax's systems are small (the slow state, ~20 unknowns; a fit's ~10 parameters), so a
partial-pivoting LU in a `fori_loop` costs nothing measurable and keeps every solve inside plain HLO.
"""

from typing import Any

import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import lineax as lx
from lineax._solver.misc import pack_structures, ravel_vector, transpose_packed_structures, unravel_solution


def lu_factor(a: jax.Array) -> tuple[jax.Array, jax.Array]:
    """LU with partial pivoting of a square matrix (batched over leading axes by `vmap`).

    Returns `(lu, perm)` with `a[perm] = L @ U`: L unit lower (below the diagonal of `lu`), U upper.
    """
    n = a.shape[-1]
    idx = jnp.arange(n)

    def column(k, carry):
        lu, perm = carry
        p = jnp.argmax(jnp.where(idx >= k, jnp.abs(lu[:, k]), -1.0))
        row_k, row_p = lu[k], lu[p]
        lu = lu.at[k].set(row_p).at[p].set(row_k)
        perm_k, perm_p = perm[k], perm[p]
        perm = perm.at[k].set(perm_p).at[p].set(perm_k)
        pivot = lu[k, k]
        safe = jnp.where(pivot == 0, 1.0, pivot)
        below = idx > k
        factors = jnp.where(below, lu[:, k] / safe, 0.0)
        lu = lu - factors[:, None] * jnp.where(below, lu[k], 0.0)[None, :]
        lu = lu.at[:, k].set(jnp.where(below, factors, lu[:, k]))
        return lu, perm

    return jax.lax.fori_loop(0, n, column, (a, idx))


def lu_solve(lu: jax.Array, perm: jax.Array, b: jax.Array, *, transpose: bool = False,
             zero_pivot_gives_zero: bool = False) -> jax.Array:
    """Solve `a x = b` (or `a.T x = b`) from `lu_factor(a)`; `b` is a vector.

    With `zero_pivot_gives_zero`, an exactly zero pivot sets its unknown to 0 instead of dividing by it:
    the right answer for an exactly decoupled null direction (a held parameter's zero Jacobian column).
    """
    n = lu.shape[-1]
    idx = jnp.arange(n)
    diag = jnp.diagonal(lu)
    if zero_pivot_gives_zero:
        diag_inv = jnp.where(diag == 0, 0.0, 1.0 / jnp.where(diag == 0, 1.0, diag))
    else:
        diag_inv = 1.0 / diag

    def forward(unit, mat):  # lower-triangular `mat`, column by column
        def step(k, y):
            yk = y[k] if unit else y[k] * diag_inv[k]
            y = y.at[k].set(yk)
            return y - jnp.where(idx > k, mat[:, k], 0.0) * yk
        return step

    def backward(unit, mat):  # upper-triangular `mat`, last column first
        def step(j, y):
            k = n - 1 - j
            yk = y[k] if unit else y[k] * diag_inv[k]
            y = y.at[k].set(yk)
            return y - jnp.where(idx < k, mat[:, k], 0.0) * yk
        return step

    if not transpose:  # P a = L U:  L U x = P b
        y = jax.lax.fori_loop(0, n, forward(True, lu), b[perm])
        return jax.lax.fori_loop(0, n, backward(False, lu), y)
    # a.T = U.T L.T P:  U.T z = b,  L.T w = z,  x = P.T w
    z = jax.lax.fori_loop(0, n, forward(False, lu.T), b)
    w = jax.lax.fori_loop(0, n, backward(True, lu.T), z)
    return jnp.zeros_like(w).at[perm].set(w)


def solve(a: jax.Array, b: jax.Array) -> jax.Array:
    """`jnp.linalg.solve(a, b)` for one square system (real or complex), `b` a vector or a matrix of
    right-hand sides, without LAPACK."""
    lu, perm = lu_factor(a)
    if b.ndim == 1:
        return lu_solve(lu, perm, b)
    return jax.vmap(lambda col: lu_solve(lu, perm, col), in_axes=1, out_axes=1)(b)


class PivotedLU(lx.AbstractLinearSolver):
    """lineax's `LU` with the factorisation in XLA operations (see the module note): square, nonsingular
    operators. Used by the steady tier's Newton root find, its implicit differentiation, and (through
    `lineax.Normal`) by identify's Gauss-Newton and Levenberg-Marquardt steps.

    `zero_pivot_gives_zero=True` (identify's setting) solves for 0 along an exactly zero pivot: identify
    masks held parameters, whose Jacobian columns, and so normal-matrix rows and columns, are exactly 0.
    """

    zero_pivot_gives_zero: bool = False

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]):
        del options
        if operator.in_size() != operator.out_size():
            raise ValueError("PivotedLU solves square systems only; wrap it in lineax.Normal for least squares")
        return lu_factor(operator.as_matrix()), pack_structures(operator), eqxi.Static(False)

    def compute(self, state, vector, options):
        del options
        (lu, perm), structures, transpose = state
        x = lu_solve(lu, perm, ravel_vector(vector, structures), transpose=transpose.value,
                     zero_pivot_gives_zero=self.zero_pivot_gives_zero)
        ok = jnp.all(jnp.isfinite(x))
        result = lx.RESULTS.where(ok, lx.RESULTS.successful, lx.RESULTS.singular)
        return unravel_solution(x, structures), result, {}

    def transpose(self, state, options):
        del options
        factors, structures, transpose = state
        return (factors, transpose_packed_structures(structures), eqxi.Static(not transpose.value)), {}

    def conj(self, state, options):
        del options
        (lu, perm), structures, transpose = state
        return ((lu.conj(), perm), structures, transpose), {}

    def assume_full_rank(self):
        return True



