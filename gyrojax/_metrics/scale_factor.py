"""Scale factor, bias and nonlinearity: the least-squares line of a sweep and its residuals over a full scale."""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .arrays import as_f64, at_index, fit_weights, mask_like, outputs_flat, raise_if, weighted_line, xp_of


FULL_SCALE_CONVENTIONS = ("half_range", "span", "output")
"""Choices of the full scale that nonlinearity is divided by; see [`gyrojax.fit_scale_factor`][]."""

MIN_POINTS_LINEAR = 3
"""Points a sweep needs for a scale factor with a nonlinearity (two points always fit a line exactly)."""


class ScaleFactorFit(eqx.Module):
    """Result of [`gyrojax.fit_scale_factor`][]; every field has the batch shape of the input (the point axis
    removed), except `residuals` which keeps it (0 on masked points).

    **Fields:** `scale_factor`, `bias`, `residuals`, `full_scale`, `nonlinearity_max_ppm`,
    `nonlinearity_rms_ppm`, `n_points` (valid points per sweep).
    """

    scale_factor: Float[Array | np.ndarray, "*batch"]
    bias: Float[Array | np.ndarray, "*batch"]
    residuals: Float[Array | np.ndarray, "*batch point"]
    full_scale: Float[Array | np.ndarray, "*batch"]
    nonlinearity_max_ppm: Float[Array | np.ndarray, "*batch"]
    nonlinearity_rms_ppm: Float[Array | np.ndarray, "*batch"]
    n_points: Float[Array | np.ndarray, "*batch"]


def fit_scale_factor(inputs: Float[ArrayLike, "*batch point"], outputs: Float[ArrayLike, "*batch point"], *,
                     mask: Bool[ArrayLike, "*batch point"] | None = None,
                     sigmas: Float[ArrayLike, "*batch point"] | None = None,
                     full_scale: str = "half_range") -> ScaleFactorFit:
    r"""Scale factor, bias and scale-factor nonlinearity of a sweep.

    **Scale factor and bias** (IEEE Std 528: scale factor is the ratio of a change in output to the change in
    input, taken as the slope of the least-squares straight line; IEEE Std 952-1997 fits the rate-table points
    the same way; seed 000 §5 computes one scale factor per run from its 22 rates): the least-squares line
    $y_i \approx K x_i + B$ over the valid points, weighted by $1/\sigma_i^2$ when `sigmas` is given,
    otherwise unweighted (the standard's fit). $K$ is the scale factor, $B$ the bias (the output at zero input).

    **Nonlinearity** (IEEE Std 528: the systematic deviation from that least-squares line), with residuals
    $r_i = y_i - (K x_i + B)$ over the $n$ valid points and a full scale $F$:

    - `nonlinearity_max_ppm` $= 10^6 \max_i |r_i| / F$ (the usual specification figure, IEEE Std 952-1997 and
      seed 000's "worst scale-factor nonlinearity");
    - `nonlinearity_rms_ppm` $= 10^6 \sqrt{\tfrac1n \sum_i r_i^2} / F$ (population RMS: divided by $n$, not
      $n-2$; the residual RMS is a property of the curve, so it is never weighted, even for a weighted fit).

    The full scale $F$ (the definitions leave it open):

    - `"half_range"` (default): $|K| \max_i |x_i|$, the straight-line output at the largest input magnitude,
      i.e. full-scale output for a symmetric $\pm$ range. On seed 000 Table 2 against the rate this gives the
      RMS 465 ppm that matches the paper's 460.679 ppm (see `experiments/seed000_table2_dac_nonlinearity.py`).
    - `"span"`: $|K| (\max_i x_i - \min_i x_i)$, the full output span; half of `"half_range"` for a
      symmetric sweep.
    - `"output"`: $\max_i |y_i|$, the largest measured output magnitude.

    **Arguments:**

    - `inputs`, `outputs`: the sweep, points on the last axis.
    - `mask`: True on valid points (default: all).
    - `sigmas`: standard uncertainties of `outputs`; given, the fit is weighted by $1/\sigma^2$.
    - `full_scale`: one of [`FULL_SCALE_CONVENTIONS`][].

    **Returns:**

    A [`gyrojax.metrics.ScaleFactorFit`][]. A sweep with 1 or 2 valid points is an error (a line through two points has
    no nonlinearity); a fully masked one gives NaN. A sweep whose outputs are all equal has scale factor 0
    exactly, bias the output, and NaN nonlinearity (there is no full scale to divide by).
    """
    if full_scale not in FULL_SCALE_CONVENTIONS:
        raise ValueError(f"full_scale must be one of {', '.join(FULL_SCALE_CONVENTIONS)}, got {full_scale!r}.")
    xp = xp_of(inputs, outputs, mask, sigmas)
    x, y = as_f64(inputs, xp), as_f64(outputs, xp)
    x, y = xp.broadcast_arrays(x, y)
    if x.ndim < 1:
        raise ValueError("inputs and outputs need a point axis (the last axis).")
    mask = mask_like(mask, x, xp)
    n = xp.sum(mask, axis=-1).astype(xp.float64)
    x = raise_if(x, (n > 0) & (n < MIN_POINTS_LINEAR),
                  lambda i: f"fit_scale_factor: a sweep{at_index(i)} has fewer than {MIN_POINTS_LINEAR} valid points; "
                            "a scale factor with a nonlinearity needs at least 3 (fully masked sweeps are "
                            "padding and give NaN).")
    x = xp.where(mask, x, 0.0)
    y = xp.where(mask, y, 0.0)
    w = fit_weights(mask, sigmas, x, xp)
    k, b = weighted_line(x, y, w, xp)
    # Constant outputs have slope 0 exactly; the fit would give a round-off slope (1e-35) that turns into a
    # nonlinearity of 1e21 ppm. With k = 0 the full scale is 0 and the nonlinearity NaN (not applicable).
    flat = outputs_flat(y, mask, xp) & ~xp.isnan(k)
    k = xp.where(flat, 0.0, k)
    b = xp.where(flat, xp.max(xp.where(mask, y, -xp.inf), axis=-1), b)
    r = xp.where(mask, y - (k[..., None] * x + b[..., None]), 0.0)
    if full_scale == "half_range":
        fs = xp.abs(k) * xp.max(xp.abs(x), axis=-1)
    elif full_scale == "span":
        hi = xp.max(xp.where(mask, x, -xp.inf), axis=-1)
        lo = xp.min(xp.where(mask, x, xp.inf), axis=-1)
        fs = xp.abs(k) * xp.where(n > 0, hi - lo, xp.nan)
    else:
        fs = xp.max(xp.abs(y), axis=-1)
    ok = (n > 0) & (fs > 0)
    fs_safe = xp.where(ok, fs, 1.0)
    n_safe = xp.where(n > 0, n, 1.0)
    max_ppm = xp.where(ok, 1e6 * xp.max(xp.abs(r), axis=-1) / fs_safe, xp.nan)
    rms_ppm = xp.where(ok, 1e6 * xp.sqrt(xp.sum(r**2, axis=-1) / n_safe) / fs_safe, xp.nan)
    return ScaleFactorFit(scale_factor=k, bias=b, residuals=r, full_scale=xp.where(n > 0, fs, xp.nan),
                          nonlinearity_max_ppm=max_ppm, nonlinearity_rms_ppm=rms_ppm, n_points=n)
