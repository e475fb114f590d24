"""A root differentiated by the implicit function theorem, which never raises.

optimistix's `ImplicitAdjoint` solves for the root's tangent with `lineax.linear_solve(throw=True)`. When a
fit's trial step reaches parameters where some point has no steady state (the root find diverges to NaN),
that solve receives NaN and raises inside the compiled fit, ending it, where Levenberg-Marquardt should only
reject the step. Here the tangent solve is a plain XLA LU: NaN in gives NaN out, and the fit sees a NaN
residual, which its trust region rejects.
"""

from collections.abc import Callable

import equinox as eqx
import jax
from jax.flatten_util import ravel_pytree

from .._numerics.linsolve import lu_factor, lu_solve


@eqx.filter_custom_jvp
def implicit_root(inputs, *, find: Callable, residual: Callable):
    """`find(inputs) -> (root, aux)`, a root of `residual(root, inputs)`, with the root's tangent
    -(dF/droot)^-1 (dF/dinputs . t_inputs) at the root (`aux` is not differentiated).

    `find` and `residual` must not close over JAX arrays (pass them through `inputs`)."""
    return find(inputs)


def _is_none(x):
    return x is None


@implicit_root.def_jvp
def _implicit_root_jvp(primals, tangents, *, find, residual):
    (inputs,) = primals
    (t_inputs,) = tangents
    root, aux = implicit_root(inputs, find=find, residual=residual)
    flat, unravel = ravel_pytree(root)

    def of_root(z):
        return ravel_pytree(residual(unravel(z), inputs))[0]

    no_tangent = jax.tree.map(_is_none, t_inputs, is_leaf=_is_none)
    nondiff, diff = eqx.partition(inputs, no_tangent, is_leaf=_is_none)

    def of_inputs(d):
        return ravel_pytree(residual(root, eqx.combine(d, nondiff)))[0]

    _, t_residual = jax.jvp(of_inputs, (diff,), (t_inputs,))
    lu, perm = lu_factor(jax.jacfwd(of_root)(flat))
    t_root = unravel(-lu_solve(lu, perm, t_residual))
    return (root, aux), (t_root, jax.tree.map(lambda _: None, aux))
