"""Scale-factor metrics: scale factor, bias, nonlinearity, asymmetry, repeatability and rate bandwidth.

Every function takes NumPy or JAX arrays whose *last* axis runs over the points of one sweep; leading axes are
batch axes, so the padded `(device, run, point)` arrays of [`gyrojax.io.SweepArrays`][] go straight in with their
`mask`. They are pure functions written once for both array libraries: given any JAX array (or tracer) they
run in `jax.numpy` and are safe under `jit`, `vmap` and `grad` (masked entries never reach a division or a log);
given only NumPy arrays they run in NumPy, which spares a host-side report the seconds of first-call
compilation. Results come back in the library that went in.

**Too few points.** A sweep with some but too few valid points is an error: a [`gyrojax.DataError`][] when the
mask is concrete, an `eqx.error_if` runtime error under `jit`. A *fully* masked sweep is padding and gives NaN.
[`gyrojax.metrics.metrics_report`][] checks the counts first and names the offending device, run and sweep.

**Sources.** Terms follow IEEE Std 528 (inertial sensor terminology) and the rate-table practice of
IEEE Std 952-1997 (single-axis FOG test procedure), which seed 000 (Ding & Zhou, Micromachines 16, 851, 2025)
follows for its closed-loop MEMS gyro. Where a definition leaves a choice open (which "full scale", which
standard deviation), the choice is gyrojax's and is written down here. (The wording of the standards is from
memory of their definitions, not checked against their text here.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._data.cells import DataError
from ._data.table import Table, padded_columns
from ._data.validate import check_outputs_change
from ._sweeps.registry import SWEEP_KINDS, sweep_kind


FULL_SCALE_CONVENTIONS = ("half_range", "span", "output")
"""Choices of the full scale that nonlinearity is divided by; see [`gyrojax.fit_scale_factor`][]."""

MIN_POINTS_LINEAR = 3
"""Points a sweep needs for a scale factor with a nonlinearity (two points always fit a line exactly)."""

MIN_POINTS_BANDWIDTH = 2


# ---------------------------------------------------------------------------------------------------------------
# Helpers.


def _xp(*arrays):
    """jax.numpy if any argument is a JAX array or tracer, else NumPy: traceable with JAX inputs, and no
    compilation (seconds for a first call) when a report runs on host data."""
    return jnp if any(isinstance(a, jax.Array) for a in arrays) else np


def _f64(x, xp) -> Array:
    return xp.asarray(x, dtype=xp.float64)


def _mask_like(mask, x, xp) -> Array:
    if mask is None:
        return xp.ones(xp.shape(x), dtype=bool)
    mask = xp.asarray(mask)
    if mask.dtype != xp.bool_:
        raise ValueError(f"mask must be boolean, got dtype {mask.dtype}.")
    return xp.broadcast_to(mask, xp.shape(x))


def _raise_if(x, bad, message: Callable[[tuple[int, ...] | None], str]):
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


def _at(index) -> str:
    return "" if not index else f" at batch index {index}"


def _weights(mask, sigmas, x, xp) -> Array:
    if sigmas is None:
        return xp.where(mask, 1.0, 0.0)
    sigmas = xp.broadcast_to(_f64(sigmas, xp), xp.shape(x))
    bad = mask & ~(sigmas > 0)
    sigmas = _raise_if(sigmas, xp.any(bad, axis=-1),
                       lambda i: f"weighted fit: an output_sigma{_at(i)} is zero, negative or NaN on a valid "
                                 "point; weights are 1/sigma^2, so every sigma must be positive.")
    safe = xp.where(mask, sigmas, 1.0)
    return xp.where(mask, 1.0 / safe**2, 0.0)


def _flat(y, mask, xp):
    """True where a sweep's valid outputs are all equal: they do not change with the input."""
    hi = xp.max(xp.where(mask, y, -xp.inf), axis=-1)
    lo = xp.min(xp.where(mask, y, xp.inf), axis=-1)
    return hi == lo  # False for a fully masked sweep (-inf != inf)


def _line(x, y, w, xp):
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


# ---------------------------------------------------------------------------------------------------------------
# Scale factor, bias, nonlinearity.


class ScaleFactorFit(eqx.Module):
    """Result of [`gyrojax.fit_scale_factor`][]; every field has the batch shape of the input (the point axis
    removed), except `residuals` which keeps it (0 on masked points).

    **Fields:** `scale_factor`, `bias`, `residuals`, `full_scale`, `nonlinearity_max_ppm`,
    `nonlinearity_rms_ppm`, `n_points` (valid points per sweep).
    """

    scale_factor: Float[Array, "*batch"]
    bias: Float[Array, "*batch"]
    residuals: Float[Array, "*batch point"]
    full_scale: Float[Array, "*batch"]
    nonlinearity_max_ppm: Float[Array, "*batch"]
    nonlinearity_rms_ppm: Float[Array, "*batch"]
    n_points: Float[Array, "*batch"]


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
    xp = _xp(inputs, outputs, mask, sigmas)
    x, y = _f64(inputs, xp), _f64(outputs, xp)
    x, y = xp.broadcast_arrays(x, y)
    if x.ndim < 1:
        raise ValueError("inputs and outputs need a point axis (the last axis).")
    mask = _mask_like(mask, x, xp)
    n = xp.sum(mask, axis=-1).astype(xp.float64)
    x = _raise_if(x, (n > 0) & (n < MIN_POINTS_LINEAR),
                  lambda i: f"fit_scale_factor: a sweep{_at(i)} has fewer than {MIN_POINTS_LINEAR} valid points; "
                            "a scale factor with a nonlinearity needs at least 3 (fully masked sweeps are "
                            "padding and give NaN).")
    x = xp.where(mask, x, 0.0)
    y = xp.where(mask, y, 0.0)
    w = _weights(mask, sigmas, x, xp)
    k, b = _line(x, y, w, xp)
    # Constant outputs have slope 0 exactly; the fit would give a round-off slope (1e-35) that turns into a
    # nonlinearity of 1e21 ppm. With k = 0 the full scale is 0 and the nonlinearity NaN (not applicable).
    flat = _flat(y, mask, xp) & ~xp.isnan(k)
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


# ---------------------------------------------------------------------------------------------------------------
# Asymmetry.


def asymmetry(inputs: Float[ArrayLike, "*batch point"], outputs: Float[ArrayLike, "*batch point"], *,
              mask: Bool[ArrayLike, "*batch point"] | None = None,
              sigmas: Float[ArrayLike, "*batch point"] | None = None,
              common_bias: bool = True) -> Float[Array, "*batch"]:
    r"""Scale-factor asymmetry in ppm.

    IEEE Std 528 defines scale-factor asymmetry as the difference between the scale factors measured with
    positive and with negative inputs, relative to the scale factor. Here

    $$\text{asymmetry} = 10^6 \frac{K_+ - K_-}{(K_+ + K_-)/2},$$

    positive when the positive-input slope is the larger in magnitude (for either sign of the scale factor).
    The mean of $K_\pm$ as the reference differs from the full-range $K$ only at second order.

    $K_\pm$ come from one least-squares fit (weighted by $1/\sigma^2$ if `sigmas` is given) of the continuous
    two-slope line $y = K_+ \max(x, 0) + K_- \min(x, 0) + B$ with a *common* bias $B$ (default): the zero-rate
    output does not depend on the sign of the rate, and sharing it keeps the bias from trading against the
    slopes (zero-input points inform $B$). With `common_bias=False`, $K_+$ and $K_-$ are separate straight-line
    fits (own intercepts) of the positive and of the negative points, zero inputs unused: the recipe of many
    test reports. The two agree for a straight line with any bias; they differ when the curve bends.

    **Arguments:** `inputs`, `outputs`, `mask`, `sigmas` as for [`gyrojax.fit_scale_factor`][];
    `common_bias` as above.

    **Returns:**

    Asymmetry in ppm, batch shape. NaN where a sweep has no positive or no negative input (not applicable: an
    asymmetry needs both signs), where its outputs are all equal, or where it is fully masked. An error where it has
    both signs but too few points (common bias: fewer than 3 in all; separate fits: fewer than 2 on a side).
    """
    xp = _xp(inputs, outputs, mask, sigmas)
    x, y = xp.broadcast_arrays(_f64(inputs, xp), _f64(outputs, xp))
    mask = _mask_like(mask, x, xp)
    pos, neg = mask & (x > 0), mask & (x < 0)
    n_pos = xp.sum(pos, axis=-1)
    n_neg = xp.sum(neg, axis=-1)
    n = xp.sum(mask, axis=-1)
    both = (n_pos > 0) & (n_neg > 0)
    few = (n_pos < 2) | (n_neg < 2) if not common_bias else n < 3
    x = _raise_if(x, both & few,
                  lambda i: f"asymmetry: a sweep{_at(i)} has too few points "
                            + ("(need at least 3 with both signs for the common-bias fit)." if common_bias else
                               "(need at least 2 positive and 2 negative inputs for separate fits)."))
    x = xp.where(mask, x, 0.0)
    y = xp.where(mask, y, 0.0)
    w = _weights(mask, sigmas, x, xp)
    if common_bias:
        # Scale the inputs to O(1) first: with DAC words (~1e6) the normal matrix would span 1e13.
        s = xp.max(xp.abs(x), axis=-1, keepdims=True)
        s = xp.where(s > 0, s, 1.0)
        u = x / s
        phi = xp.stack([xp.maximum(u, 0.0), xp.minimum(u, 0.0), xp.ones_like(u)], axis=-1)
        a = xp.einsum("...p,...pi,...pj->...ij", w, phi, phi)
        c = xp.einsum("...p,...pi,...p->...i", w, phi, y)
        ok = both & (n >= 3)
        eye = xp.broadcast_to(xp.eye(3), a.shape)
        a = xp.where(ok[..., None, None], a, eye)
        coef = xp.linalg.solve(a, c[..., None])[..., 0]
        k_pos, k_neg = coef[..., 0] / s[..., 0], coef[..., 1] / s[..., 0]
    else:
        k_pos, _ = _line(x, y, xp.where(pos, w, 0.0), xp)
        k_neg, _ = _line(x, y, xp.where(neg, w, 0.0), xp)
        ok = both & (n_pos >= 2) & (n_neg >= 2)
    mean = 0.5 * (k_pos + k_neg)
    ok = ok & (mean != 0) & ~_flat(y, mask, xp)  # constant outputs: the slopes are round-off, not a measurement
    return xp.where(ok, 1e6 * (k_pos - k_neg) / xp.where(ok, mean, 1.0), xp.nan)


# ---------------------------------------------------------------------------------------------------------------
# Repeatability.


def repeatability(scale_factors: Float[ArrayLike, "*batch run"], *,
                  mask: Bool[ArrayLike, "*batch run"] | None = None, ddof: int = 1) -> Float[Array, "*batch"]:
    r"""Scale-factor repeatability in ppm: the standard deviation of the runs' scale factors over their mean.

    $$10^6 \, \frac{\operatorname{std}_{\mathrm{ddof}}(K_1, \dots, K_R)}{|\bar K|}$$

    Seed 000 §5: "three sets of repeated experiments ...; the scale factor was calculated based on the
    measurement results from each group; then, the standard deviation of the scale factors obtained from the
    three tests was computed; this value is defined as the repeatability error" (its Table 3 gives it in ppm,
    so relative to the scale factor). The paper does not say which standard deviation; gyrojax uses the sample
    standard deviation (`ddof=1`, unbiased variance), the usual choice for three runs; `ddof=0` gives the
    population one (smaller by sqrt(2/3) for three runs). Seed 000's Table 3 values (1230.656 ppm etc.) cannot
    be checked: the per-run scale factors are not published. IEEE Std 528 calls this the scale-factor
    repeatability (agreement of repeated measurements under the same conditions, with changes in conditions or
    off periods between them).

    **Arguments:**

    - `scale_factors`: one scale factor per run on the last axis.
    - `mask`: True on runs that exist.
    - `ddof`: delta degrees of freedom of the standard deviation.

    **Returns:**

    Repeatability in ppm; NaN where there are `ddof` runs or fewer (one run shows no repeatability).
    """
    xp = _xp(scale_factors, mask)
    k = _f64(scale_factors, xp)
    mask = _mask_like(mask, k, xp)
    n = xp.sum(mask, axis=-1).astype(xp.float64)
    k = xp.where(mask, k, 0.0)
    ok = n > ddof
    mean = xp.sum(k, axis=-1) / xp.where(n > 0, n, 1.0)
    var = xp.sum(xp.where(mask, k - mean[..., None], 0.0) ** 2, axis=-1) / xp.where(ok, n - ddof, 1.0)
    ok = ok & (mean != 0)
    return xp.where(ok, 1e6 * xp.sqrt(var) / xp.abs(xp.where(ok, mean, 1.0)), xp.nan)


# ---------------------------------------------------------------------------------------------------------------
# Rate bandwidth.


class RateBandwidth(eqx.Module):
    """Result of [`gyrojax.metrics.rate_bandwidth`][]: `bandwidth_hz` (the -3 dB frequency), `phase_deg` (the phase
    there, NaN if no phase was given) and `low_frequency_gain` (the reference amplitude)."""

    bandwidth_hz: Float[Array, "*batch"]
    phase_deg: Float[Array, "*batch"]
    low_frequency_gain: Float[Array, "*batch"]


def rate_bandwidth(freqs_hz: Float[ArrayLike, "*batch point"], amplitudes: Float[ArrayLike, "*batch point"], *,
                   mask: Bool[ArrayLike, "*batch point"] | None = None,
                   phase_deg: Float[ArrayLike, "*batch point"] | None = None) -> RateBandwidth:
    r"""Rate bandwidth (-3 dB) and the phase there, from a dynamic sweep (e.g. a `vcf_dynamic` sweep).

    IEEE Std 528: bandwidth is the range of input frequency over which the amplitude response stays within
    3 dB of its low-frequency value. Here the points are sorted by frequency; the low-frequency gain $G_0$ is
    the amplitude at the lowest valid frequency; the bandwidth is the first downward crossing of
    $G_0/\sqrt2$, interpolated linearly in (log frequency, dB) between the last point at or above and the
    first point below it (a straight line on a Bode plot). A resonant peak before the roll-off (open-loop
    gyros peak near the mode split) is passed over: only the first fall below $G_0/\sqrt2$ counts. The phase is
    interpolated linearly in log frequency at the same place (unwrap it first if it wraps).

    **Arguments:**

    - `freqs_hz`: modulation frequencies (> 0), any order.
    - `amplitudes`: output amplitudes (> 0).
    - `mask`: True on valid points.
    - `phase_deg`: optional phase of the output, degrees.

    **Returns:**

    A [`gyrojax.metrics.RateBandwidth`][]. An error where a sweep has a single point, a non-positive frequency or
    amplitude, or never falls below $G_0/\sqrt2$ (extend the sweep to higher frequencies).
    """
    xp = _xp(freqs_hz, amplitudes, mask, phase_deg)
    f, a = xp.broadcast_arrays(_f64(freqs_hz, xp), _f64(amplitudes, xp))
    mask = _mask_like(mask, f, xp)
    p = xp.zeros_like(f) if phase_deg is None else xp.broadcast_to(_f64(phase_deg, xp), f.shape)
    n = xp.sum(mask, axis=-1)
    f = _raise_if(f, (n > 0) & (n < MIN_POINTS_BANDWIDTH),
                  lambda i: f"rate_bandwidth: a sweep{_at(i)} has a single valid point; a bandwidth needs at "
                            "least 2.")
    f = _raise_if(f, xp.any(mask & ~((f > 0) & (a > 0)), axis=-1),
                  lambda i: f"rate_bandwidth: a sweep{_at(i)} has a non-positive frequency or amplitude; both "
                            "must be > 0 (the interpolation is in log frequency and dB).")
    key = xp.where(mask, f, xp.inf)
    order = xp.argsort(key, axis=-1)
    f = xp.take_along_axis(xp.where(mask, f, 1.0), order, axis=-1)
    a = xp.take_along_axis(xp.where(mask, a, 1.0), order, axis=-1)
    p = xp.take_along_axis(xp.where(mask, p, 0.0), order, axis=-1)
    m = xp.take_along_axis(mask, order, axis=-1)
    g0 = a[..., 0]
    target = g0 / math.sqrt(2.0)
    below = m & (a < target[..., None])
    crosses = xp.any(below, axis=-1)
    f = _raise_if(f, (n >= MIN_POINTS_BANDWIDTH) & ~crosses,
                  lambda i: f"rate_bandwidth: a sweep{_at(i)} never falls below its low-frequency gain / sqrt(2) "
                            "(-3 dB); extend the sweep to higher frequencies.")
    i1 = xp.argmax(below, axis=-1)  # first point below; >= 1 since point 0 is the reference
    i0 = xp.maximum(i1 - 1, 0)

    def take(v, i):
        return xp.take_along_axis(v, i[..., None], axis=-1)[..., 0]

    lf0, lf1 = xp.log(take(f, i0)), xp.log(take(f, i1))
    db0, db1 = 20 * xp.log10(take(a, i0)), 20 * xp.log10(take(a, i1))
    db_t = 20 * xp.log10(target)
    ok = crosses & (n >= MIN_POINTS_BANDWIDTH) & (db1 < db0)
    t = xp.where(ok, (db_t - db0) / xp.where(ok, db1 - db0, 1.0), 0.0)
    f3 = xp.exp(lf0 + t * (lf1 - lf0))
    ph = take(p, i0) + t * (take(p, i1) - take(p, i0))
    nan = xp.nan
    return RateBandwidth(bandwidth_hz=xp.where(ok, f3, nan),
                         phase_deg=xp.where(ok, ph, nan) if phase_deg is not None else xp.full_like(f3, nan),
                         low_frequency_gain=xp.where(n > 0, g0, nan))


# ---------------------------------------------------------------------------------------------------------------
# Report.


def scale_factor_units() -> dict[str, str]:
    """The unit of `scale_factor` per sweep kind with a straight-line fit (output unit per input unit), and
    `{name}_vs_rate` for the kinds also fitted against `rate_dps`."""
    units = {}
    for cls in SWEEP_KINDS.values():
        kind = cls()
        if kind.straight_line:
            units[kind.name] = kind.scale_factor_unit
    for cls in SWEEP_KINDS.values():
        if cls.fit_against_rate:
            units[f"{cls.name}_vs_rate"] = f"{cls.output_unit}/(deg/s)"
    return units


def _num(x) -> float | None:
    v = float(np.asarray(x))
    return None if math.isnan(v) else v


_FLAT = "the outputs do not change with the input (scale factor 0)"

# The figures a sweep should give where they apply: one of them None is a number the data did not determine.
_DETERMINED = ("scale_factor", "bias", "nonlinearity_max_ppm", "nonlinearity_rms_ppm", "bandwidth_hz")

# The report's keys of each metric an `AbstractSweep.applicable_metrics` names.
_METRIC_KEYS = {
    "scale_factor": ("scale_factor", "scale_factor_vs_rate", "scale_factor_mean"),
    "bias": ("bias", "bias_vs_rate"),
    "nonlinearity": ("nonlinearity_max_ppm", "nonlinearity_rms_ppm", "nonlinearity_max_ppm_vs_rate",
                     "nonlinearity_rms_ppm_vs_rate"),
    "asymmetry": ("asymmetry_ppm",),
    "repeatability": ("repeatability_ppm",),
    "bandwidth": ("bandwidth_hz", "phase_deg_at_bandwidth", "low_frequency_gain"),
}


def _drop_inapplicable(rec: dict[str, Any], sweep: str, brief: bool = False) -> dict[str, str]:
    """Set to None the numbers of `rec` that are no measurement on this sweep kind (its `applicable_metrics`);
    returns the reason for each (`brief`: the kind's reason in full for the first key only, the others refer to
    it, so that a line of text says it once)."""
    kind = sweep_kind(sweep)
    applies = kind.applicable_metrics()
    reasons = {}
    for metric, keys in _METRIC_KEYS.items():
        if metric in applies:
            continue
        for key in keys:
            if key in rec:
                rec[key] = None
                first = next(iter(reasons), None)
                reasons[key] = (f"not a measurement on a {sweep} sweep (see {first})" if brief and first
                                else kind.metric_not_applicable(metric))
    return reasons


def _why_not(rec: dict[str, Any], outputs: np.ndarray, inputs: np.ndarray) -> dict[str, str]:
    """The reason for each None among a point record's numbers (see `metrics_report`)."""
    flat = bool(np.all(outputs == outputs[0]))
    reasons = {}
    for key, value in rec.items():
        if value is not None or key in ("device", "run", "sweep", "n_points"):
            continue
        if not sweep_kind(rec["sweep"]).straight_line:
            why = ("no phase_deg was given for every point of this sweep" if key == "phase_deg_at_bandwidth"
                   else f"a {rec['sweep']} sweep gives a bandwidth, not a straight-line fit")
        elif flat and key.startswith("nonlinearity"):
            why = f"{_FLAT}: there is no full scale to divide the residuals by"
        elif flat and key == "asymmetry_ppm":
            why = f"{_FLAT}: there are no slopes to compare"
        elif key == "asymmetry_ppm" and not (np.any(inputs > 0) and np.any(inputs < 0)):
            why = "the sweep lacks positive or negative inputs; an asymmetry needs both signs"
        elif key.startswith("scale_factor") or key.startswith("bias"):
            why = "fewer than two distinct inputs: no slope can be fitted"
        else:
            why = "not determined by these points"
        reasons[key] = why
    return reasons


def metrics_report(table: Table, *, full_scale: str = "half_range", weighted: bool = False,
                   common_bias: bool = True, ddof: int = 1) -> dict[str, Any]:
    """The `metrics` JSON of docs/cli.md for a table: per-sweep metrics and per-device repeatability.

    **Arguments:**

    - `table`: a [`gyrojax.Table`][].
    - `full_scale`: nonlinearity full scale, see [`gyrojax.fit_scale_factor`][].
    - `weighted`: weight fits by `1/output_sigma**2` (the table must give `output_sigma` for every point of
      the sweeps with a linear fit); default unweighted, as the standards do.
    - `common_bias`: asymmetry model, see [`gyrojax.metrics.asymmetry`][].
    - `ddof`: repeatability standard deviation, see [`gyrojax.metrics.repeatability`][].

    **Returns:**

    A JSON-ready dict (Python numbers, None for "not applicable"):

    - `points`: one record per (device, run, sweep), in order of first appearance in the table: `device`,
      `run`, `sweep`, `n_points`, `scale_factor`, `bias`, `nonlinearity_max_ppm`, `nonlinearity_rms_ppm`,
      `asymmetry_ppm` (None when the sweep lacks positive or negative inputs). For `dac` sweeps with a
      `rate_dps` column also `scale_factor_vs_rate`, `bias_vs_rate`, `nonlinearity_max_ppm_vs_rate`,
      `nonlinearity_rms_ppm_vs_rate` (output against the rate the word stands for). For `vcf_dynamic` sweeps
      the linear keys are None and `bandwidth_hz`, `phase_deg_at_bandwidth`, `low_frequency_gain` are given.
      A metric that is no measurement on the sweep's kind (`AbstractSweep.applicable_metrics`: e.g. none on
      `drive_frequency`) is None. A sweep whose outputs are all equal has `scale_factor` 0 and None
      nonlinearities and asymmetry (a kind whose slope's sign a convention sets refuses it: see below).
      `not_applicable` maps each key that is None to the reason, in words; `undetermined` lists the keys of
      metrics that apply to the kind but that the points did not give.
    - `devices`: one record per (device, sweep) with a linear fit: `device`, `sweep`, `n_runs`,
      `scale_factor_mean`, `repeatability_ppm` (None with a single run, or when the mean scale factor is 0),
      and `not_applicable` as above.
    - `conventions`: the choices above and the unit of `scale_factor` per sweep kind.

    Raises [`gyrojax.DataError`][] naming the device, run, sweep and rows when a run of a rate-table, VCF, DAC or
    drive-amplitude sweep has outputs that are all equal (a dead output, refused as `compensate` refuses it),
    when a sweep has too few points
    (3 for a linear fit, 2 for a bandwidth), when `rate_dps` is given for some but not all points of a `dac`
    sweep, when a weighted fit lacks a positive `output_sigma`, or when a dynamic sweep never reaches -3 dB.
    """
    if not isinstance(table, Table):
        raise TypeError(f"metrics_report expects a gyrojax.Table, got {type(table).__name__}.")
    if full_scale not in FULL_SCALE_CONVENTIONS:
        raise ValueError(f"full_scale must be one of {', '.join(FULL_SCALE_CONVENTIONS)}, got {full_scale!r}.")
    groups = table.groups()
    _check_groups(table, groups, weighted)
    check_outputs_change(table, groups)

    records: dict[tuple, dict[str, Any]] = {}
    device_records: list[dict[str, Any]] = []
    for sweep in SWEEP_KINDS:
        if not any(k[2] == sweep for k in groups):
            continue
        arr = SimpleNamespace(**padded_columns(table, sweep))  # NumPy: no compilation for a report
        if not sweep_kind(sweep).straight_line:
            records.update(_bandwidth_records(table, groups, arr, sweep))
            continue
        sig = arr.sigmas if weighted else None
        fit = fit_scale_factor(arr.inputs, arr.outputs, mask=arr.mask, sigmas=sig, full_scale=full_scale)
        records.update(_linear_records(arr, sweep, fit, sig, full_scale, common_bias))
        device_records.extend(_device_records(arr, sweep, fit, ddof))
    order = {}
    for dev, _, sweep in groups:
        order.setdefault((dev, sweep), len(order))
    device_records.sort(key=lambda rec: order[(rec["device"], rec["sweep"])])
    return {
        "points": [records[key] for key in groups],
        "devices": device_records,
        "conventions": {
            "full_scale": full_scale, "weighted": weighted,
            "asymmetry": "common_bias" if common_bias else "separate_fits", "repeatability_ddof": ddof,
            "nonlinearity_rms": "population RMS of residuals (divided by n)",
            "scale_factor_units": scale_factor_units(),
        },
    }


def _group_name(table: Table, key, rows) -> str:
    """A (device, run, sweep) group of `table` in words, with the rows it spans."""
    dev, run, sweep = key
    first = table.locate(int(rows[0]), with_source=False)
    last = table.locate(int(rows[-1]), with_source=False)
    span = first if len(rows) == 1 else f"{first} to {last}"
    return f"device {dev!r}, run {run}, sweep {sweep!r} ({span})"


def _check_groups(table: Table, groups, weighted: bool) -> None:
    """Checks with names, before any arithmetic: enough points per group, a positive `output_sigma` on every
    point of a weighted fit, `rate_dps` on all or none of a group's points where the kind is fitted against it."""
    for key, rows in groups.items():
        sweep = key[2]
        line = sweep_kind(sweep).straight_line
        need = MIN_POINTS_LINEAR if line else MIN_POINTS_BANDWIDTH
        what = "a scale factor with a nonlinearity" if line else "a rate bandwidth"
        if len(rows) < need:
            raise DataError(f"{table.source}: {_group_name(table, key, rows)} has {len(rows)} "
                            f"point{'s' * (len(rows) != 1)}; {what} needs at least {need}.",
                            source=table.source, row=int(rows[0]) + 1)
        if weighted and line:
            sig = table["output_sigma"] if "output_sigma" in table else None
            bad = rows if sig is None else rows[~(sig[rows] > 0)]
            if bad.size:
                raise DataError(f"{table.locate(int(bad[0]), 'output_sigma')}: weighted=True needs a positive "
                                f"output_sigma on every point; {_group_name(table, key, rows)} lacks one.",
                                source=table.source, row=int(bad[0]) + 1, column="output_sigma")
        if sweep_kind(sweep).fit_against_rate and "rate_dps" in table:
            given = ~np.isnan(table["rate_dps"][rows])
            if given.any() and not given.all():
                r = int(rows[~given][0])
                raise DataError(f"{table.locate(r, 'rate_dps')}: rate_dps is given for some points of "
                                f"{_group_name(table, key, rows)} but not this one; give it for all or none.",
                                source=table.source, row=r + 1, column="rate_dps")


def _run_index(arr) -> dict:
    """(device, run) -> (its index on the device axis, on the run axis) of a sweep's padded arrays."""
    return {(dev, r): (d, k) for d, dev in enumerate(arr.devices) for k, r in enumerate(arr.runs[d])}


def _bandwidth_records(table: Table, groups, arr, sweep: str) -> dict:
    """The point records of a dynamic sweep: its rate bandwidth, phase there and low-frequency gain per run."""
    phase = arr.aux.get("phase_deg")
    if phase is not None:
        phase = np.where(np.isnan(phase), 0.0, phase)
    try:
        bw = rate_bandwidth(arr.inputs, arr.outputs, mask=arr.mask, phase_deg=phase)
    except DataError as e:
        key = _first_failing_bandwidth(arr, table, groups)
        raise DataError(f"{table.source}: {_group_name(table, key, groups[key])}: {e}",
                        source=table.source) from None
    records = {}
    for (dev, r), (d, k) in _run_index(arr).items():
        has_phase = phase is not None and not np.isnan(arr.aux["phase_deg"][d, k][arr.mask[d, k]]).any()
        records[(dev, r, sweep)] = {
            "device": dev, "run": r, "sweep": sweep, "n_points": int(arr.mask[d, k].sum()),
            "scale_factor": None, "bias": None, "nonlinearity_max_ppm": None,
            "nonlinearity_rms_ppm": None, "asymmetry_ppm": None,
            "bandwidth_hz": _num(bw.bandwidth_hz[d, k]),
            "phase_deg_at_bandwidth": _num(bw.phase_deg[d, k]) if has_phase else None,
            "low_frequency_gain": _num(bw.low_frequency_gain[d, k])}
        sel = arr.mask[d, k]
        why = _why_not(records[(dev, r, sweep)], arr.outputs[d, k][sel], arr.inputs[d, k][sel])
        records[(dev, r, sweep)]["undetermined"] = [key for key in why if key in _DETERMINED]
        records[(dev, r, sweep)]["not_applicable"] = why
    return records


def _linear_records(arr, sweep: str, fit, sig, full_scale: str, common_bias: bool) -> dict:
    """The point records of a sweep with a linear fit (`fit`): scale factor, bias, nonlinearity and asymmetry
    per run, and against `rate_dps` where the kind is fitted against it and the data give it."""
    asym = asymmetry(arr.inputs, arr.outputs, mask=arr.mask, sigmas=sig, common_bias=common_bias)
    vs_rate = None
    if sweep_kind(sweep).fit_against_rate and "rate_dps" in arr.aux:
        rate = arr.aux["rate_dps"]
        has = arr.mask & ~np.isnan(rate)
        vs_rate = fit_scale_factor(np.where(has, rate, 0.0), arr.outputs, mask=has, sigmas=sig,
                                   full_scale=full_scale)
    records = {}
    for (dev, r), (d, k) in _run_index(arr).items():
        rec = {"device": dev, "run": r, "sweep": sweep, "n_points": int(arr.mask[d, k].sum()),
               "scale_factor": _num(fit.scale_factor[d, k]), "bias": _num(fit.bias[d, k]),
               "nonlinearity_max_ppm": _num(fit.nonlinearity_max_ppm[d, k]),
               "nonlinearity_rms_ppm": _num(fit.nonlinearity_rms_ppm[d, k]),
               "asymmetry_ppm": _num(asym[d, k])}
        if vs_rate is not None and _num(vs_rate.n_points[d, k]):
            rec.update({"scale_factor_vs_rate": _num(vs_rate.scale_factor[d, k]),
                        "bias_vs_rate": _num(vs_rate.bias[d, k]),
                        "nonlinearity_max_ppm_vs_rate": _num(vs_rate.nonlinearity_max_ppm[d, k]),
                        "nonlinearity_rms_ppm_vs_rate": _num(vs_rate.nonlinearity_rms_ppm[d, k])})
        sel = arr.mask[d, k]
        kind_reasons = _drop_inapplicable(rec, sweep, brief=True)
        why = _why_not({key: v for key, v in rec.items() if key not in kind_reasons}, arr.outputs[d, k][sel],
                       arr.inputs[d, k][sel])
        rec["undetermined"] = [key for key in why if key in _DETERMINED]
        rec["not_applicable"] = {**why, **kind_reasons}
        records[(dev, r, sweep)] = rec
    return records


def _device_records(arr, sweep: str, fit, ddof: int) -> list:
    """The device records of a sweep with a linear fit: mean scale factor and repeatability over its runs."""
    out = []
    run_mask = arr.mask.any(axis=-1)
    rep = repeatability(np.where(run_mask, fit.scale_factor, 0.0), mask=run_mask, ddof=ddof)
    n_runs = run_mask.sum(axis=-1)
    for d, dev in enumerate(arr.devices):
        sf = fit.scale_factor[d][run_mask[d]]
        rec = {"device": dev, "sweep": sweep, "n_runs": int(n_runs[d]),
               "scale_factor_mean": _num(np.mean(sf)), "repeatability_ppm": _num(rep[d])}
        rec["not_applicable"] = _drop_inapplicable(rec, sweep)
        if rec["repeatability_ppm"] is None and "repeatability_ppm" not in rec["not_applicable"]:
            rec["not_applicable"]["repeatability_ppm"] = (
                f"{int(n_runs[d])} run{'s' * (int(n_runs[d]) != 1)}: a repeatability needs at least {ddof + 1}"
                if int(n_runs[d]) <= ddof else "the mean scale factor is 0: there is nothing to be relative to")
        out.append(rec)
    return out


def _first_failing_bandwidth(arr, table, groups):
    """The (device, run, sweep) key of the first dynamic sweep that rate_bandwidth refuses."""
    for d, dev in enumerate(arr.devices):
        for k, r in enumerate(arr.runs[d]):
            try:
                rate_bandwidth(arr.inputs[d, k], arr.outputs[d, k], mask=arr.mask[d, k])
            except DataError:
                return (dev, r, arr.sweep)
    return next(iter(groups))
