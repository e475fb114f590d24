"""Rate bandwidth: the -3 dB frequency of a dynamic sweep and the phase there."""

from __future__ import annotations

import math

import equinox as eqx
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .arrays import as_f64, at_index, mask_like, raise_if, xp_of


MIN_POINTS_BANDWIDTH = 2


class RateBandwidth(eqx.Module):
    """Result of [`gyrojax.metrics.rate_bandwidth`][]: `bandwidth_hz` (the -3 dB frequency), `phase_deg` (the phase
    there, NaN if no phase was given) and `low_frequency_gain` (the reference amplitude)."""

    bandwidth_hz: Float[Array | np.ndarray, "*batch"]
    phase_deg: Float[Array | np.ndarray, "*batch"]
    low_frequency_gain: Float[Array | np.ndarray, "*batch"]


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
    xp = xp_of(freqs_hz, amplitudes, mask, phase_deg)
    f, a = xp.broadcast_arrays(as_f64(freqs_hz, xp), as_f64(amplitudes, xp))
    mask = mask_like(mask, f, xp)
    p = xp.zeros_like(f) if phase_deg is None else xp.broadcast_to(as_f64(phase_deg, xp), f.shape)
    n = xp.sum(mask, axis=-1)
    f = raise_if(f, (n > 0) & (n < MIN_POINTS_BANDWIDTH),
                  lambda i: f"rate_bandwidth: a sweep{at_index(i)} has a single valid point; a bandwidth needs at "
                            "least 2.")
    f = raise_if(f, xp.any(mask & ~((f > 0) & (a > 0)), axis=-1),
                  lambda i: f"rate_bandwidth: a sweep{at_index(i)} has a non-positive frequency or amplitude; both "
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
    f = raise_if(f, (n >= MIN_POINTS_BANDWIDTH) & ~crosses,
                  lambda i: f"rate_bandwidth: a sweep{at_index(i)} never falls below its low-frequency gain / sqrt(2) "
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
