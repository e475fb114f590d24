"""Construction-time parameter checks that stay silent under tracing (jit, vmap, grad)."""

import jax
import jax.core  # Tracer: jax.core is not imported by `import jax` for type checkers
import numpy as np


def _concrete(value):
    """The value as a NumPy array, or None when it is traced (then it cannot be checked here)."""
    if isinstance(value, jax.core.Tracer):
        return None
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None


def check_positive(owner: str, name: str, value):
    """Raise a ValueError naming `owner.name` when a concrete value is not strictly positive and finite."""
    v = _concrete(value)
    if v is not None and (not np.all(np.isfinite(v)) or np.any(v <= 0)):
        raise ValueError(f"{owner}.{name} must be positive and finite, got {value!r}.")


def check_nonnegative(owner: str, name: str, value):
    """Raise a ValueError naming `owner.name` when a concrete value is negative or not finite."""
    v = _concrete(value)
    if v is not None and (not np.all(np.isfinite(v)) or np.any(v < 0)):
        raise ValueError(f"{owner}.{name} must be non-negative and finite, got {value!r}.")


def check_finite(owner: str, name: str, value):
    """Raise a ValueError naming `owner.name` when a concrete value is NaN or infinite."""
    v = _concrete(value)
    if v is not None and not np.all(np.isfinite(v)):
        raise ValueError(f"{owner}.{name} must be finite, got {value!r}.")


def check_range(owner: str, name: str, value, lo, hi):
    """Raise a ValueError when a concrete value lies outside the half-open interval [lo, hi)."""
    v = _concrete(value)
    if v is not None and (not np.all(np.isfinite(v)) or np.any(v < lo) or np.any(v >= hi)):
        raise ValueError(f"{owner}.{name} must lie in [{lo}, {hi}), got {value!r}.")


def check_positive_or_inf(owner: str, name: str, value):
    """Raise a ValueError naming `owner.name` when a concrete value is NaN, zero or negative (inf is allowed)."""
    v = _concrete(value)
    if v is not None and (np.any(np.isnan(v)) or np.any(v <= 0)):
        raise ValueError(f"{owner}.{name} must be positive (inf allowed), got {value!r}.")
