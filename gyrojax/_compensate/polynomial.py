"""`polynomial`: the traditional compensation (seed 000's baseline, its ref. 12): a polynomial in the output."""

from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .base import AbstractCompensation, AbstractCompensator
from .points import RatePoints


class PolynomialCompensation(AbstractCompensation):
    r"""A fitted polynomial: $\hat\Omega = \sum_{k=0}^{n} a_k (y / s)^k$ (deg/s), with $y$ the output in LSB
    and $s$ the largest training |output| (scaling keeps the least-squares problem well conditioned).

    **Fields:** `coefficients` ($a_0 \dots a_n$, deg/s), `output_scale` ($s$, LSB).
    """

    coefficients: Float[Array, " order_plus_one"]
    output_scale: Float[Array, ""]

    def rate(self, output: Float[ArrayLike, " n"], *, drive_freq_hz: Float[ArrayLike, " n"] | None = None,
             temperature_c: Float[ArrayLike, " n"] | None = None) -> Float[Array, " n"]:
        """The rate estimate (deg/s); side information is not used by this method."""
        u = jnp.asarray(output, dtype=jnp.float64) / self.output_scale
        acc = jnp.zeros_like(u)
        for a in self.coefficients[::-1]:
            acc = acc * u + a
        return acc

    def summary(self) -> dict[str, Any]:
        return {"order": int(self.coefficients.shape[0] - 1),
                "coefficients_dps": [float(a) for a in np.asarray(self.coefficients)],
                "output_scale_lsb": float(self.output_scale),
                "model": "rate_dps = sum_k coefficients_dps[k] * (output / output_scale_lsb)**k"}


class PolynomialCompensator(AbstractCompensator):
    r"""Traditional polynomial compensation (seed 000 §5 condition (2), its ref. 12): one polynomial mapping
    the raw output to the rate, fitted by least squares to the pooled points of the training runs, then
    applied unchanged to every run. It knows nothing about the thermal state: a run whose scale factor has
    drifted (a different warm-up) is compensated with the training runs' scale factor.

    **Arguments:**

    - `order`: polynomial order $n$ (default 3). Seed 000 does not print the order of its baseline and its
      ref. 12 is not available here; 3 is the lowest order that holds both an even bow (warm-up drift during
      an ordered sweep) and the odd S-curve of a DAC INL, and the usual cubic of rate-table scale-factor
      models. Higher orders are allowed; the fit needs at least `order + 2` distinct outputs so that
      something is left to judge it by.
    """

    order: int = eqx.field(static=True, default=3)

    name: ClassVar[str] = "polynomial"
    requires: ClassVar[tuple[str, ...]] = ()

    def __check_init__(self):
        if not isinstance(self.order, (int, np.integer)) or isinstance(self.order, bool) or self.order < 1:
            raise ValueError(f"PolynomialCompensator.order must be an integer >= 1, got {self.order!r}.")

    def fit(self, points: RatePoints) -> PolynomialCompensation:
        y, x = points.output, points.rate_dps
        distinct = np.unique(y).size
        if distinct < self.order + 2:
            raise ValueError(f"polynomial compensation of order {self.order} needs at least {self.order + 2} "
                             f"distinct training outputs, got {distinct}.")
        scale = float(np.max(np.abs(y)))
        u = y / scale
        vander = u[:, None] ** np.arange(self.order + 1)
        coef, *_ = np.linalg.lstsq(vander, x, rcond=None)
        return PolynomialCompensation(jnp.asarray(coef), jnp.asarray(scale))

