"""What every metric shares: the array library of its inputs (NumPy or JAX), the mask, the errors for too few
points (a `DataError` when concrete, `eqx.error_if` under `jit`), the weights and the weighted least-squares line."""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import equinox as eqx
import jax
import jax.core  # Tracer: jax.core is not imported by `import jax` for type checkers
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._data.cells import DataError


def xp_of(*arrays: object) -> ModuleType:
    """jax.numpy if any argument is a JAX array or tracer, else NumPy: traceable with JAX inputs, and no
    compilation (seconds for a first call) when a report runs on host data."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def as_f64(x, xp: ModuleType) -> Array | np.ndarray:
    return xp.asarray(x, dtype=xp.float64)


def mask_like(mask, x, xp: ModuleType) -> Array | np.ndarray:
    if mask is None:
        return xp.ones(xp.shape(x), dtype=bool)
    mask = xp.asarray(mask)
    if mask.dtype != xp.bool_:
        raise ValueError(f"mask must be boolean, got dtype {mask.dtype}.")
    return xp.broadcast_to(mask, xp.shape(x))


def raise_if(x, bad, message: Callable[[tuple[int, ...] | None], str]):
    """Raise when `bad` holds anywhere: a DataError if `bad` is concrete, else an eqx.error_if at run time.

    `message(index)` gets the batch index of the first offender when it is known (concrete), else None.
    """
    if isinstance(bad, jax.core.Tracer):
        return eqx.error_if(x, bad, message(None))
    bad = np.asarray(bad)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
        raise DataError(message(index))
    return x


def at_index(index) -> str:
    return "" if not index else f" at batch index {index}"


def fit_weights(mask, sigmas, x, xp: ModuleType) -> Array | np.ndarray:
    if sigmas is None:
        return xp.where(mask, 1.0, 0.0)
    sigmas = xp.broadcast_to(as_f64(sigmas, xp), xp.shape(x))
    bad = mask & ~(sigmas > 0)
    sigmas = raise_if(sigmas, xp.any(bad, axis=-1),
                       lambda i: f"weighted fit: an output_sigma{at_index(i)} is zero, negative or NaN on a valid "
                                 "point; weights are 1/sigma^2, so every sigma must be positive.")
    safe = xp.where(mask, sigmas, 1.0)
    return xp.where(mask, 1.0 / safe**2, 0.0)


def outputs_flat(y, mask, xp: ModuleType):
    """True where a sweep's valid outputs are all equal: they do not change with the input."""
    hi = xp.max(xp.where(mask, y, -xp.inf), axis=-1)
    lo = xp.min(xp.where(mask, y, xp.inf), axis=-1)
    return hi == lo  # False for a fully masked sweep (-inf != inf)


def weighted_line(x, y, w, xp: ModuleType):
    """Weighted least-squares line (centred sums); NaN where fewer than two distinct weighted inputs."""
    sw = xp.sum(w, axis=-1)
    ok = sw > 0
    sw_safe = xp.where(ok, sw, 1.0)
    xm = xp.sum(w * x, axis=-1) / sw_safe
    ym = xp.sum(w * y, axis=-1) / sw_safe
    dx = xp.where(w > 0, x - xm[..., None], 0.0)
    sxx = xp.sum(w * dx**2, axis=-1)
    sxy = xp.sum(w * dx * (y - ym[..., None]), axis=-1)
    ok = ok & (sxx > 0)
    k = xp.where(ok, sxy / xp.where(ok, sxx, 1.0), xp.nan)
    b = xp.where(ok, ym - k * xm, xp.nan)
    return k, b
