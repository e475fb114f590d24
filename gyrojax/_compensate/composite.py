r"""`composite`: seed 000's composite compensation (§4): initial calibration, then piecewise compensation.

**How the paper is read here.** Seed 000 describes its method in words (§4.1-4.2, Fig. 7, Eq. 8-9); where the
words leave a choice open, gyrojax takes the following one.

1. *Initial calibration* (Eq. 8, $SF_{new} = SF\,k_t/\omega_x$): every output is multiplied by
   $k_t / f_d$ with $f_d$ the point's measured drive frequency (`drive_freq_hz`) and $k_t$ the mean drive
   frequency of the training points ("a constant used to maintain the order of magnitude of the scale
   factor"), so the calibrated output stays in LSB.
2. *Nonlinear error at each rate* (Fig. 7 step 1, "based on the ideal gyroscope output values"): the ideal
   output is one least-squares straight line $K x + B_r$ through the calibrated training points, with a
   common scale factor $K$ and a bias $B_r$ per training run (turn-on bias changes from run to run). The
   error at each table rate is the calibrated output minus that line, averaged over the training runs.
3. *Segmentation* (step 2). "Starting from the static state", each side of zero (rates >= 0, rates < 0) is
   walked outward from the smallest rate. With the errors $e_i$ in that order, the absolute first
   differences $|e_{i+1}-e_i|$ and their second difference
   $\Delta^2_i = |e_{i+1}-e_i| - |e_i-e_{i-1}|$ (placed at point $i$) are formed. A positive $\Delta^2_i$
   ("increasing nonlinear error"; positive beyond rounding, 1e-9 of the largest $|e_{i+1}-e_i|$) adds one
   to a counter; a non-positive one resets it to zero. When the
   counter reaches 4 (or more: one boundary per unbroken run), a new segment starts at the first point of
   that run. So a segment boundary marks where the error starts to grow faster for at least four
   consecutive rates; an error that accelerates steadily over a whole side leaves that side as one segment.
   The two sides are always separate segments: Eq. (9)'s middle piece $x_{-1} < x < x_1$ is the gap
   between the smallest negative and the smallest positive rate.
4. *A fit per segment* (step 3, Eq. 9): on each segment the error is fitted, as a function of the
   calibrated output, by a polynomial $\sum_{k=0}^{n} a_k x^k$ by linear least squares ("linear fitting" is
   read as linear regression; Eq. 9's order $n$ is not printed: `segment_degree`, default 3). A segment with
   fewer than $n+1$ distinct rates is merged into its inner neighbour (the outer one for the innermost
   segment); a side with fewer than $n+1$ rates is fitted with order (rates - 1).
5. *Hermite interpolation at the boundaries*: between the last point of one segment and the first point of
   the next (and across zero) the error curve is the cubic Hermite interpolant of the two segment
   polynomials' values and slopes at those points, so the compensation curve is C1. Beyond the outermost
   rates the outer segment polynomials extrapolate.

The compensated rate is then $\hat\Omega = (u - f(u)) / K$ with $u = y\,k_t/f_d - \bar B$ ($\bar B$: the mean
training bias) and $f$ the piecewise error curve.
"""

import itertools
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .base import AbstractCompensation, AbstractCompensator, check_side, require_side
from .points import RatePoints


def side_segment_starts(errors: Float[ArrayLike, " n"], threshold: int = 4) -> list[int]:
    """Fig. 7 step 2 on one side: the indices (into `errors`, ordered outward from zero) where a segment
    starts; always includes 0. See the module docstring for the rule."""
    e = np.asarray(errors, dtype=np.float64)
    starts = [0]
    if e.size < 3:
        return starts
    d1 = np.abs(np.diff(e))
    d2 = np.diff(d1)  # d2[k] is the second difference at point k + 1
    tol = 1e-9 * float(np.max(d1))  # "positive" beyond rounding, so exact synthetic curves segment cleanly
    counter, run_start, placed = 0, 0, False
    for k, value in enumerate(d2):
        if value > tol:
            if counter == 0:
                run_start, placed = k + 1, False
            counter += 1
            if counter >= threshold and not placed:
                if run_start not in starts:
                    starts.append(run_start)
                placed = True
        else:
            counter = 0
    return sorted(starts)


def _merge_small(groups: list[list[int]], need: int) -> list[list[int]]:
    """Merge groups (ordered outward) with fewer than `need` members into the inner neighbour (the outer one
    for the innermost group)."""
    groups = [list(g) for g in groups]
    i = 0
    while i < len(groups) and len(groups) > 1:
        if len(groups[i]) >= need:
            i += 1
            continue
        if i == 0:
            groups[1] = groups[0] + groups[1]
            del groups[0]
        else:
            groups[i - 1] = groups[i - 1] + groups[i]
            del groups[i]
            i -= 1
    return groups


def _hermite(u_a, u_b, y0, m0, y1, m1):
    """Cubic Hermite on [u_a, u_b] in t = (u - u_a) / (u_b - u_a), power-basis coefficients c0..c3."""
    d = u_b - u_a
    return np.array([y0, d * m0, -3 * y0 - 2 * d * m0 + 3 * y1 - d * m1, 2 * y0 + d * m0 - 2 * y1 + d * m1])


def _poly(coef, t):
    acc = np.zeros_like(np.asarray(t, dtype=np.float64))
    for a in coef[::-1]:
        acc = acc * t + a
    return acc


def _dpoly(coef, t):
    return _poly(np.arange(1, len(coef)) * np.asarray(coef[1:]), t) if len(coef) > 1 else np.zeros_like(t)


class CompositeCompensation(AbstractCompensation):
    r"""Seed 000's composite compensation, fitted (see the module docstring for the method).

    **Fields:**

    - `k_t_hz`: the calibration constant $k_t$ (mean training drive frequency, Hz).
    - `scale_factor`: $K$, calibrated LSB per deg/s; `bias`: $\bar B$, LSB.
    - `edges`: the calibrated outputs (bias removed, LSB) where one piece of the error curve hands over to
      the next, ascending; `centers`, `widths`, `coefficients`: piece $p$ is
      $\sum_k c_{pk} t^k$ with $t = (u - \mathrm{center}_p)/\mathrm{width}_p$ (segments and Hermite bridges
      alternate).
    - `segments_dps`: (static) the table rates of each segment, ascending.
    """

    k_t_hz: Float[Array, ""]
    scale_factor: Float[Array, ""]
    bias: Float[Array, ""]
    edges: Float[Array, " pieces_minus_one"]
    centers: Float[Array, " pieces"]
    widths: Float[Array, " pieces"]
    coefficients: Float[Array, "pieces degree_plus_one"]
    segments_dps: tuple[tuple[float, ...], ...] = eqx.field(static=True)

    def error_curve(self, u: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """The fitted nonlinear error (LSB) at calibrated, bias-free output `u` (LSB)."""
        u = jnp.asarray(u, dtype=jnp.float64)
        p = jnp.searchsorted(self.edges, u, side="right")
        t = (u - self.centers[p]) / self.widths[p]
        c = self.coefficients[p]
        acc = jnp.zeros_like(u)
        for k in range(self.coefficients.shape[1] - 1, -1, -1):
            acc = acc * t + c[..., k]
        return acc

    def rate(self, output: Float[ArrayLike, " n"], *, drive_freq_hz: Float[ArrayLike, " n"] | None = None,
             temperature_c: Float[ArrayLike, " n"] | None = None) -> Float[Array, " n"]:
        """The rate estimate (deg/s); needs each point's `drive_freq_hz`."""
        f = jnp.asarray(check_side("composite", "drive_freq_hz", drive_freq_hz), dtype=jnp.float64)
        u = jnp.asarray(output, dtype=jnp.float64) * (self.k_t_hz / f) - self.bias
        return (u - self.error_curve(u)) / self.scale_factor

    def summary(self) -> dict[str, Any]:
        return {"k_t_hz": float(self.k_t_hz), "scale_factor_lsb_per_dps": float(self.scale_factor),
                "bias_lsb": float(self.bias), "n_segments": len(self.segments_dps),
                "segments_dps": [[min(s), max(s)] for s in self.segments_dps],
                "edges_lsb": [float(e) for e in np.asarray(self.edges)]}


class CompositeCompensator(AbstractCompensator):
    """Seed 000's composite compensation with initial calibration (§4, Fig. 7, Eq. 8-9).

    **Arguments:**

    - `threshold`: the counter value that starts a segment (seed 000: 4).
    - `segment_degree`: order of each segment's polynomial (Eq. 9's $n$, not printed; default 3, the lowest
      order that can follow the inflection of an S-curve within one segment).

    See the module docstring for how each step of the paper is read.
    """

    threshold: int = eqx.field(static=True, default=4)
    segment_degree: int = eqx.field(static=True, default=3)

    name: ClassVar[str] = "composite"
    requires: ClassVar[tuple[str, ...]] = ("drive_freq_hz",)

    def __check_init__(self):
        for field, low in (("threshold", 1), ("segment_degree", 0)):
            v = getattr(self, field)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < low:
                raise ValueError(f"CompositeCompensator.{field} must be an integer >= {low}, got {v!r}.")

    def fit(self, points: RatePoints) -> CompositeCompensation:
        require_side(points, "drive_freq_hz", "composite")
        x, f = points.rate_dps, points.drive_freq_hz
        rates = np.unique(x)
        if rates.size < 3:
            raise ValueError(f"composite compensation needs at least 3 distinct training rates, got {rates.size}.")
        k_t = float(np.mean(f))
        y = points.output * k_t / f  # Eq. 8: SF_new = SF k_t / w_x
        runs = points.runs
        design = np.column_stack([x] + [(points.run == r).astype(np.float64) for r in runs])
        sol, *_ = np.linalg.lstsq(design, y, rcond=None)
        k, biases = float(sol[0]), sol[1:]
        b_point = np.asarray([biases[runs.index(int(r))] for r in points.run])
        u = y - b_point
        e = u - k * x
        e_mean = np.array([np.mean(e[x == r]) for r in rates])
        u_mean = np.array([np.mean(u[x == r]) for r in rates])

        need = self.segment_degree + 1
        segments: list[list[int]] = []  # indices into `rates`
        for side in (np.flatnonzero(rates < 0)[::-1], np.flatnonzero(rates >= 0)):  # outward from zero
            if side.size == 0:
                continue
            starts = side_segment_starts(e_mean[side], self.threshold) + [side.size]
            groups = [list(side[a:b]) for a, b in itertools.pairwise(starts)]
            segments += _merge_small(groups, need)

        fitted = []  # (lo_u, hi_u, center, width, coefficients, rates) per segment
        for seg in segments:
            seg_rates = rates[seg]
            sel = np.isin(x, seg_rates)
            lo, hi = float(np.min(u_mean[seg])), float(np.max(u_mean[seg]))
            center = 0.5 * (lo + hi)
            width = 0.5 * (hi - lo) if hi > lo else 1.0
            deg = min(self.segment_degree, len(seg) - 1)
            t = (u[sel] - center) / width
            coef, *_ = np.linalg.lstsq(t[:, None] ** np.arange(deg + 1), e[sel], rcond=None)
            fitted.append((lo, hi, center, width, coef, tuple(float(r) for r in np.sort(seg_rates))))
        fitted.sort(key=lambda item: item[0])
        for a, b in itertools.pairwise(fitted):
            if b[0] <= a[1]:
                raise ValueError("composite compensation: the calibrated output is not monotone in the rate "
                                 f"(segments of rates {a[5]} and {b[5]} overlap in output); a piecewise curve "
                                 "in the output cannot undo that.")
        pieces, edges = [], []  # (center, width, coefficients): segments and Hermite bridges alternate
        for i, (lo, hi, center, width, coef, _) in enumerate(fitted):
            pieces.append((center, width, coef))
            if i + 1 < len(fitted):
                lo2, _, center2, width2, coef2, _ = fitted[i + 1]
                t_a, t_b = (hi - center) / width, (lo2 - center2) / width2
                bridge = _hermite(hi, lo2, _poly(coef, t_a), _dpoly(coef, t_a) / width,
                                  _poly(coef2, t_b), _dpoly(coef2, t_b) / width2)
                pieces.append((hi, lo2 - hi, bridge))
                edges += [hi, lo2]
        width_max = max(len(c) for _, _, c in pieces)
        coefs = np.zeros((len(pieces), width_max))
        for i, (_, _, c) in enumerate(pieces):
            coefs[i, :len(c)] = c
        seg_rates = tuple(item[5] for item in fitted)
        return CompositeCompensation(
            k_t_hz=jnp.asarray(k_t), scale_factor=jnp.asarray(k), bias=jnp.asarray(float(np.mean(biases))),
            edges=jnp.asarray(np.asarray(edges, dtype=np.float64)),
            centers=jnp.asarray(np.asarray([p[0] for p in pieces], dtype=np.float64)),
            widths=jnp.asarray(np.asarray([p[1] for p in pieces], dtype=np.float64)),
            coefficients=jnp.asarray(coefs), segments_dps=seg_rates)
