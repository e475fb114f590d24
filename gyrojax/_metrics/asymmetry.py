"""Scale-factor asymmetry: the slopes of positive and negative inputs compared."""

from __future__ import annotations

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .arrays import as_f64, at_index, fit_weights, mask_like, outputs_flat, raise_if, weighted_line, xp_of


def asymmetry(inputs: Float[ArrayLike, "*batch point"], outputs: Float[ArrayLike, "*batch point"], *,
              mask: Bool[ArrayLike, "*batch point"] | None = None,
              sigmas: Float[ArrayLike, "*batch point"] | None = None,
              common_bias: bool = True) -> Float[Array | np.ndarray, "*batch"]:
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
    xp = xp_of(inputs, outputs, mask, sigmas)
    x, y = xp.broadcast_arrays(as_f64(inputs, xp), as_f64(outputs, xp))
    mask = mask_like(mask, x, xp)
    pos, neg = mask & (x > 0), mask & (x < 0)
    n_pos = xp.sum(pos, axis=-1)
    n_neg = xp.sum(neg, axis=-1)
    n = xp.sum(mask, axis=-1)
    both = (n_pos > 0) & (n_neg > 0)
    few = (n_pos < 2) | (n_neg < 2) if not common_bias else n < 3
    x = raise_if(x, both & few,
                  lambda i: f"asymmetry: a sweep{at_index(i)} has too few points "
                            + ("(need at least 3 with both signs for the common-bias fit)." if common_bias else
                               "(need at least 2 positive and 2 negative inputs for separate fits)."))
    x = xp.where(mask, x, 0.0)
    y = xp.where(mask, y, 0.0)
    w = fit_weights(mask, sigmas, x, xp)
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
        k_pos, _ = weighted_line(x, y, xp.where(pos, w, 0.0), xp)
        k_neg, _ = weighted_line(x, y, xp.where(neg, w, 0.0), xp)
        ok = both & (n_pos >= 2) & (n_neg >= 2)
    mean = 0.5 * (k_pos + k_neg)
    ok = ok & (mean != 0) & ~outputs_flat(y, mask, xp)  # constant outputs: the slopes are round-off, not a measurement
    return xp.where(ok, 1e6 * (k_pos - k_neg) / xp.where(ok, mean, 1.0), xp.nan)
