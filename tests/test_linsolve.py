"""The XLA-only LU (gyrojax/_numerics/linsolve.py) against numpy's LAPACK, transposed and batched, inside lineax's
differentiable linear_solve, and free of LAPACK custom calls in the compiled program."""

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import pytest

from gyrojax._numerics.linsolve import PivotedLU, lu_factor, lu_solve, solve


RNG = np.random.default_rng(3)


@pytest.mark.parametrize("n", [1, 2, 7, 24])
def test_solve_matches_lapack(n):
    a = RNG.normal(size=(n, n))
    if n > 1:
        a[0, 0] = 0.0  # needs a row swap
    b = RNG.normal(size=n)
    lu, perm = lu_factor(jnp.asarray(a))
    np.testing.assert_allclose(lu_solve(lu, perm, jnp.asarray(b)), np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(lu_solve(lu, perm, jnp.asarray(b), transpose=True), np.linalg.solve(a.T, b),
                               rtol=1e-10, atol=1e-12)


def test_batched_complex_and_matrix_rhs():
    a = RNG.normal(size=(6, 5, 5)) + 1j * RNG.normal(size=(6, 5, 5))
    b = RNG.normal(size=(6, 5, 2)) + 1j * RNG.normal(size=(6, 5, 2))
    np.testing.assert_allclose(jax.vmap(solve)(jnp.asarray(a), jnp.asarray(b)), np.linalg.solve(a, b),
                               rtol=1e-10, atol=1e-12)


def test_zero_pivot_gives_zero_for_a_decoupled_null_direction():
    # A normal matrix with a held parameter: its row and column are exactly zero.
    j = RNG.normal(size=(10, 3))
    j[:, 1] = 0.0
    op = lx.MatrixLinearOperator(jnp.asarray(j))
    r = jnp.asarray(RNG.normal(size=10))
    x = lx.linear_solve(op, r, lx.Normal(PivotedLU(zero_pivot_gives_zero=True))).value
    ref = np.linalg.lstsq(j[:, [0, 2]], np.asarray(r), rcond=None)[0]
    np.testing.assert_allclose(x, [ref[0], 0.0, ref[1]], rtol=1e-10, atol=1e-12)
    # without the option the singular system is reported, not silently solved
    sol = lx.linear_solve(op, r, lx.Normal(PivotedLU()), throw=False)
    assert sol.result != lx.RESULTS.successful


def test_gradient_through_linear_solve_matches_finite_differences():
    a = jnp.asarray(RNG.normal(size=(4, 4)) + 4 * np.eye(4))
    b = jnp.asarray(RNG.normal(size=4))

    def f(m):
        return jnp.sum(lx.linear_solve(lx.MatrixLinearOperator(m), b, PivotedLU()).value ** 2)

    g = jax.grad(f)(a)
    h, e = 1e-6, np.zeros((4, 4))
    e[1, 2] = 1.0
    fd = (f(a + h * e) - f(a - h * e)) / (2 * h)
    np.testing.assert_allclose(g[1, 2], fd, rtol=1e-6)


def test_no_lapack_custom_call_in_the_compiled_solve():
    # The reason the module exists: batched LAPACK kernels can deadlock XLA's CPU thread pool.
    f = jax.jit(jax.vmap(solve))
    text = f.lower(jnp.ones((3, 4, 4)) + jnp.eye(4), jnp.ones((3, 4))).as_text()
    assert "lapack" not in text.lower() and "custom_call" not in text
    assert "lapack" in jax.jit(jax.vmap(jnp.linalg.solve)).lower(jnp.ones((3, 4, 4)), jnp.ones((3, 4))).as_text()
