r"""Threshold scans: a step of the output, or of its gain, where a recorded coordinate passes one value.

Many physical changes of behaviour happen at a value of a coordinate rather than smoothly along it: a parasitic
mode that hops when the die passes a temperature, a range relay that switches the gain at a time or a rate, a
missing code of a DAC word. A spline along the coordinate spreads such a step over its knots; the scan here tries
the step itself, at every position between two of the coordinate's values (`THRESHOLDS` at most, evenly spread over
its distinct values, with `MIN_SIDE` points on either side), as an *offset step* (the output moves by a height) and
a *gain step* (the gain does), read three ways: at one threshold with one height for every device (a property of
the design), each device its own height, or in one device only (a fault of one part). The threshold and the reading
with the smallest tail probability are kept; the look-elsewhere correction is the number of positions tried times
the three readings (Bonferroni). A step is a location only where it is also significant beyond the straight line of
its coordinate (the same family, reading and devices: a ramp of the output or of the gain; `beyond_line_p`, at the
same correction): a monotone trend that one well-placed step follows closely (a gain drifting in time, whose
largest changes sit on the largest inputs) is not a step. Where the step sits is given with the range of thresholds
the data do not tell from the best one (its chi2 within `POSITION_CHI2` of the best's: a profile-likelihood
interval of about 95 %).
"""

import dataclasses

import numpy as np

from .._numerics.stats import log_chi2_sf
from .space import ResidualSpace, Scored


THRESHOLDS = 32  # positions scanned along a coordinate
MIN_SIDE = 3  # real points of the lot on either side of a threshold
FAMILIES = ("offset step", "gain step")
READINGS = 3  # one height for every device, a height per device, one device: the look-elsewhere count's factor
POSITION_CHI2 = 3.84  # chi2(1)'s 95 % point: thresholds this close to the best one's chi2 are where it may sit


@dataclasses.dataclass(frozen=True)
class Threshold:
    """The strongest step of one family along one coordinate of one sweep: where (`at`: the output changes for
    the coordinate at or above it, and the `interval` of thresholds the data do not tell from it), in which
    devices (indices; `pooled`: one height for all of them), its columns (device, rows, 1), score, and the
    p-values (alone and beyond the straight line) after the scan's look-elsewhere correction over `positions`
    thresholds."""

    family: str
    at: float
    devices: tuple[int, ...]
    columns: np.ndarray
    scored: Scored
    p_value: float
    positions: int
    pooled: bool = False
    interval: tuple[float, float] = (float("nan"), float("nan"))
    beyond_line_p: float = 1.0  # beyond the coordinate's straight line, after the same correction


def positions(real: np.ndarray) -> np.ndarray:
    """The thresholds tried along a coordinate whose real points are `real`: midpoints between consecutive
    distinct values with at least `MIN_SIDE` points on either side, at most `THRESHOLDS` of them, evenly spread
    over the distinct values."""
    u = np.unique(real)
    if u.size < 4:
        return np.zeros(0)
    mids = (u[1:] + u[:-1]) / 2.0
    below = np.searchsorted(np.sort(real), mids)
    mids = mids[(below >= MIN_SIDE) & (real.size - below >= MIN_SIDE)]
    if mids.size > THRESHOLDS:
        mids = mids[np.unique(np.round(np.linspace(0, mids.size - 1, THRESHOLDS)).astype(int))]
    return mids


def is_sign_change(values: np.ndarray, at: float) -> bool:
    """Whether the threshold `at` separates the negative values of a coordinate that takes both signs from its
    positive ones (zero on either side): the one threshold that means the same in every unit."""
    values = np.asarray(values, float)
    if not (values.min() < 0.0 < values.max()):
        return False
    lo, hi = min(0.0, at), max(0.0, at)
    return not np.any((values > lo) & (values < hi))


def sign_change(values: np.ndarray, like: float) -> float | None:
    """The sign-change threshold of `values` on the side of zero `like` (a sign change of another coordinate)
    puts zero: zero itself, or the midpoint between zero and the nearest value above (below) it; None where
    `values` do not take both signs."""
    values = np.asarray(values, float)
    if not (values.min() < 0.0 < values.max()):
        return None
    if like == 0.0:
        return 0.0
    edge = values[values > 0.0].min() if like > 0.0 else values[values < 0.0].max()
    return edge / 2.0


def changes(x: np.ndarray, mask: np.ndarray, pred: np.ndarray, family: str, at, devices=None) -> np.ndarray:
    """The step's change of the predictions per unit height (device, run, point, len(at)): 1 (offset step) or
    the model's prediction (gain step) where the coordinate `x` is at or above each threshold of `at`, on the
    devices `devices` (all where None)."""
    at = np.atleast_1d(np.asarray(at, float))
    base = pred if family == "gain step" else np.ones_like(x)
    g = np.where(mask[..., None] & (x[..., None] >= at), base[..., None], 0.0)
    if devices is not None:
        keep = np.zeros(mask.shape[0], bool)
        keep[list(devices)] = True
        g = np.where(keep[:, None, None, None], g, 0.0)
    return g


def scan(space: ResidualSpace, sweep: str, x: np.ndarray, mask: np.ndarray, pred: np.ndarray,
         family: str) -> Threshold | None:
    """The strongest step of `family` along the coordinate `x` (device, run, point) of `sweep` (see the module
    docstring), or None where no threshold carries information beyond the fit's span."""
    cuts = positions(x[mask])
    if not cuts.size:
        return None
    cols = space.columns({sweep: changes(x, mask, pred, family, cuts)})  # (device, rows, position)
    pc = space.project(cols)
    info = np.einsum("dnp,dnp->dp", pc, pc)
    own = np.einsum("dnp,dnp->dp", cols, cols)
    ok = (own > 0) & (info > 1e-9 * np.maximum(own, 1e-300))
    dot = np.where(ok, np.einsum("dnp,dn->dp", pc, space.residuals), 0.0)
    per_dev = np.where(ok, dot**2 / np.where(ok, info, 1.0), 0.0)
    tried = np.flatnonzero(ok.any(axis=0))
    if not tried.size:
        return None
    # per threshold, each reading's chi2 and degrees of freedom
    ones = np.ones(cuts.size, int)
    readings = {"shared": (dot.sum(axis=0) ** 2 / np.maximum(np.where(ok, info, 0.0).sum(axis=0), 1e-300), ones),
                "every": (per_dev.sum(axis=0), ok.sum(axis=0)), "one": (per_dev.max(axis=0), ones)}
    _, name, p = min((log_chi2_sf(float(stat[p]), int(df[p])), name, int(p))
                     for name, (stat, df) in readings.items() for p in tried)
    stat = readings[name][0]
    near_p = tried[stat[tried] >= stat[p] - POSITION_CHI2]
    near = cuts[near_p]
    # a threshold the data place anywhere over a range that holds the sign change is named there: a gain that
    # differs for positive and negative inputs (or warming and cooling) is the simplest step of a signed
    # coordinate, and points near zero carry no gain to place it by
    crossing = [q for q in near_p if is_sign_change(x[mask], float(cuts[q]))]
    if crossing:
        p = int(crossing[0])
    devs = np.array([int(np.argmax(per_dev[:, p]))]) if name == "one" else np.flatnonzero(ok[:, p])
    keep = np.zeros(cols.shape[0], bool)
    keep[devs] = True
    chosen = np.where(keep[:, None, None], cols[..., p:p + 1], 0.0)
    pooled = name == "shared"
    sc = space.score(chosen, pooled=pooled)
    if not sc.df:
        return None
    # beyond the straight line of the coordinate in the same reading: a step, not a trend it follows
    ramp = space.columns({sweep: np.where(mask, x * (pred if family == "gain step" else 1.0), 0.0)[..., None]})
    ramp = np.where(keep[:, None, None], ramp, 0.0)
    beyond = space.with_columns(ramp).score(chosen, pooled=pooled) if np.any(ramp) else sc
    n = int(tried.size)
    return Threshold(family, float(cuts[p]), tuple(int(d) for d in devs), chosen, sc,
                     min(1.0, READINGS * n * sc.p_value), n, pooled, (float(near.min()), float(near.max())),
                     min(1.0, READINGS * n * beyond.p_value) if beyond.df else 1.0)
