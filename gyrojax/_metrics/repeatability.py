"""Scale-factor repeatability: the spread of the runs' scale factors."""

from __future__ import annotations

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .arrays import as_f64, mask_like, xp_of


def repeatability(scale_factors: Float[ArrayLike, "*batch run"], *,
                  mask: Bool[ArrayLike, "*batch run"] | None = None, ddof: int = 1
                  ) -> Float[Array | np.ndarray, "*batch"]:
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
    xp = xp_of(scale_factors, mask)
    k = as_f64(scale_factors, xp)
    mask = mask_like(mask, k, xp)
    n = xp.sum(mask, axis=-1).astype(xp.float64)
    k = xp.where(mask, k, 0.0)
    ok = n > ddof
    mean = xp.sum(k, axis=-1) / xp.where(n > 0, n, 1.0)
    var = xp.sum(xp.where(mask, k - mean[..., None], 0.0) ** 2, axis=-1) / xp.where(ok, n - ddof, 1.0)
    ok = ok & (mean != 0)
    return xp.where(ok, 1e6 * xp.sqrt(var) / xp.abs(xp.where(ok, mean, 1.0)), xp.nan)
