"""The compensator interface: a strategy (`AbstractCompensator`) whose `fit` returns a solution
(`AbstractCompensation`) mapping gyro output + per-point side information to a rate estimate."""

import abc
from typing import Any

import equinox as eqx
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .points import RatePoints


class AbstractCompensation(eqx.Module):
    """A fitted compensator: gyro output (LSB) and side information -> compensated rate estimate (deg/s).

    Solutions hold the fitted coefficients as fields and are pure functions of their inputs (traceable with
    JAX arrays: differentiable in the output and in the coefficients).
    """

    @abc.abstractmethod
    def rate(self, output: Float[ArrayLike, " n"], *, drive_freq_hz: Float[ArrayLike, " n"] | None = None,
             temperature_c: Float[ArrayLike, " n"] | None = None) -> Float[Array, " n"]:
        """The compensated rate estimate in deg/s for each point."""

    @abc.abstractmethod
    def summary(self) -> dict[str, Any]:
        """The fitted coefficients as a JSON-ready dict (Python numbers, lists and strings)."""

    def status(self) -> tuple[bool, str]:
        """`(converged, message)`: whether the fit reached what its method solves for, and if not, what did not
        converge and what to try. Closed-form fits (linear least squares) always converge."""
        return True, ""


class AbstractCompensator(eqx.Module):
    """A compensation method (a strategy, holding only its settings); `fit` returns the fitted solution.

    `name` is the method's name on the command line; `requires` lists the side columns (docs/data_format.md)
    every point must carry, for fitting and for applying.
    """

    name: eqx.AbstractClassVar[str]
    requires: eqx.AbstractClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def fit(self, points: RatePoints) -> AbstractCompensation:
        """Fit on `points` (the training runs of one device) and return the solution."""


def require_side(points: RatePoints, name: str, method: str):
    """ValueError unless `points.<name>` is given (finite) on every point."""
    bad = ~np.isfinite(getattr(points, name))
    if bad.any():
        raise ValueError(f"{method} compensation needs {name} on every point; {int(bad.sum())} of {len(points)} "
                         "points lack it.")


def check_side(method: str, name: str, value):
    """`value` unless it is None: `rate(...)` of a method that needs this side information refuses None."""
    if value is None:
        raise ValueError(f"{method} compensation: rate() needs {name}= (one value per point, or one for all).")
    return value
