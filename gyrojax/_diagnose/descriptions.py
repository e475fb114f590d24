r"""Flexible descriptions of the standardised residuals, without a list of shapes: what `locate` chooses from.

For each sweep and each coordinate that moves within its runs (`input`, `temperature_c`, its rate of change
`dtemperature_dt`, `time_s`, `drive_freq_hz`, `order`) two descriptions are scored per device: an *offset* along the
coordinate and a *gain* along it (the same basis times the model's prediction), each a piecewise-linear function on
knots at the coordinate's quantiles (a linear spline whose effective degrees of freedom are the directions left
after the fit's own columns are projected out; for a coordinate that mostly tells devices apart, also on each
device's own quantiles, read only to say what a located misfit is confounded with), and the same two as one curve
shared by every device on finer knots (`pooled`: the lot's coefficients, as most physical terms are the same in
every device). Beside them: a curve along the input whose size grows with the temperature or the time, a *gain per
run* (and, on sweeps read without a turn-on bias, an offset per run and an *offset per device*, the same in all of
a device's runs), an offset along time that differs from run to run, an offset and a gain along the input that
differ from run to run (the same in every device), a *change-point scan* along time (a step in the output at one
dwell), a *spectral scan* along the input (a periodic error of the input or the DAC word) and along the time since
power-on (a disturbance that cycles: the lab's air conditioning, a thermal oscillation) and, with the pooled curves,
a *threshold scan* along every coordinate that moves within the devices (a step of the output or of the gain where
it passes one value: `gyrojax._diagnose.thresholds`). Scans carry their own look-elsewhere correction (Bonferroni
over the positions or periods scanned).
"""

import dataclasses
import math

import numpy as np

from .._numerics.stats import log_chi2_sf
from . import changepoints, thresholds
from .compare import recorded_coordinates
from .space import ResidualSpace, Scored


KNOTS = 6  # the linear spline's knots along a coordinate (quantiles): up to 6 directions per device
# The knots of a curve shared by every device: its coefficients are the lot's, not each device's, so it can afford
# to follow a narrow feature (a dead band around zero rate, a step between two set points).
POOLED_KNOTS = 12
# A coordinate whose spread within the runs is below this share of its spread over the lot is a property of runs
# (or devices), not something the output can be described along within a run.
WITHIN_RUN_SHARE = 1e-3
# Within a device less than this share of the lot's spread: the coordinate mostly tells devices apart.
WITHIN_DEVICE_SHARE = 0.1
PERIODS = 24  # periods scanned along the input, log-spaced from 2.5 point spacings to half the span
EACH_RUN = ("offset in each run", "gain in each run")  # a curve along a coordinate, one per run


@dataclasses.dataclass(frozen=True)
class Description:
    """One flexible description: its sweep, coordinate, family ("offset", "gain", "gain per run", "offset per
    run", "offset per device", "offset in each run", "gain in each run", "step", "periodic", ...), columns (device,
    rows, k), score and, for scans, where it sits."""

    sweep: str
    coordinate: str
    family: str
    columns: np.ndarray
    scored: Scored
    p_value: float  # after the scan's own look-elsewhere correction
    where: dict = dataclasses.field(default_factory=dict)
    pooled: bool = False  # one curve for every device (its coefficients the lot's), not one per device


# -- coordinates ---------------------------------------------------------------------------------------------
def coordinates(block) -> dict:
    """The coordinates of a sweep block a description can run along: `input`, the recorded ones, and, where
    both the die temperature and the time are recorded, the rate of change of the temperature
    (`dtemperature_dt`, K/s, by differences along time within each run): a heating die is not a warm one."""
    out = {"input": np.asarray(block.inputs, float), **recorded_coordinates(block)}
    if "temperature_c" in out and "time_s" in out:
        out["dtemperature_dt"] = _rate_of_change(out["temperature_c"], out["time_s"], np.asarray(block.mask))
    return out


def _rate_of_change(temp, time, mask):
    rate = np.zeros(mask.shape)
    for d, r in np.ndindex(mask.shape[:2]):
        m = mask[d, r]
        if m.sum() < 2:
            continue
        idx = np.flatnonzero(m)
        order = idx[np.argsort(time[d, r][idx], kind="stable")]
        t, T = time[d, r][order], temp[d, r][order]
        if np.all(np.diff(t) > 0):
            rate[d, r, order] = np.gradient(T, t)
    return rate


def spread(values, mask):
    """(spread within runs, within devices, over the lot): each the largest range over its groups."""
    v = np.where(mask, values, np.nan)
    with np.errstate(all="ignore"):
        run = np.nanmax(np.nanmax(v, axis=2) - np.nanmin(v, axis=2))
        dev = np.nanmax(np.nanmax(v, axis=(1, 2)) - np.nanmin(v, axis=(1, 2)))
        lot = np.nanmax(v) - np.nanmin(v)
    return float(np.nan_to_num(run)), float(np.nan_to_num(dev)), float(np.nan_to_num(lot))


# Coordinates whose sign is physics (the direction of the rate or force; warming or cooling): their splines also
# have knots at the values next to zero, so that a change of behaviour at zero is a shape they can describe.
SIGNED = ("input", "dtemperature_dt")


def spline_basis(x, mask, knots=KNOTS, signed=False):
    """Piecewise-linear hat functions of `x` (device, run, point) on knots at the quantiles of the real points
    (and, where `signed` and `x` takes both signs, at the values next to zero on either side): (device, run,
    point, k); None when `x` takes fewer than three values."""
    real = x[mask]
    u = np.unique(real)
    if u.size < 3:
        return None
    k = np.unique(np.quantile(real, np.linspace(0.0, 1.0, min(knots, u.size))))
    if signed and u[0] < 0 < u[-1]:
        k = np.unique(np.concatenate([k, [u[u < 0].max(), u[u > 0].min()]]))
    if k.size < 3:
        return None
    eye = np.eye(k.size)
    return np.stack([np.where(mask, np.interp(x, k, eye[j]), 0.0) for j in range(k.size)], axis=-1)


def device_spline_basis(x, mask, knots=KNOTS, signed=False):
    """`spline_basis` with knots at each device's own quantiles, zero-padded to the widest device: (device, run,
    point, k); None when no device has three values. For a coordinate that mostly tells devices apart (the drive
    frequency, tens of Hz between devices and under 1 Hz within one), the lot's quantiles put at most two knots inside
    a device's range, and its curve there is a line."""
    per = [spline_basis(x[d:d + 1], mask[d:d + 1], knots, signed) for d in range(mask.shape[0])]
    k = max((h.shape[-1] for h in per if h is not None), default=0)
    if k == 0:
        return None
    out = np.zeros((*mask.shape, k))
    for d, h in enumerate(per):
        if h is not None:
            out[d, ..., :h.shape[-1]] = h[0]
    return out


# -- the descriptions ----------------------------------------------------------------------------------------
def describe(space: ResidualSpace, *, pooled: bool = True) -> tuple[list, list]:
    """Every flexible description of `space`'s residuals: (descriptions, notes on coordinates that were not
    described along, and why); with `pooled=False` no curve shared by every device, no threshold scan (whose
    threshold is the lot's) and no periodic gain along time: the per-device descriptions the guards read."""
    fit, out, notes = space.fit, [], []
    for sweep in fit.data.sweeps:
        block = fit.data.blocks[sweep]
        mask = np.asarray(block.mask)
        pred = np.asarray(fit.predictions[sweep], float)
        for name, x in coordinates(block).items():
            x = np.where(mask, np.asarray(x, float), 0.0)
            run, dev, lot = spread(x, mask)
            if lot <= 0:
                continue
            if run <= WITHIN_RUN_SHARE * lot:
                notes.append(f"{name} on {sweep} is constant within runs: a property of runs (see 'run')")
                continue
            between = dev < WITHIN_DEVICE_SHARE * lot  # the coordinate mostly tells devices apart
            if between:
                notes.append(f"{name} on {sweep} varies mostly between devices ({dev:.3g} within a device "
                             f"of its {lot:.3g} over the lot): described within each device only")
            hats = spline_basis(x, mask, signed=name in SIGNED)
            if hats is None:
                continue
            if between:
                out.extend(_own_knots(space, sweep, name, x, mask, pred, dev / lot))
            # a gain along the input (x g(x), piecewise quadratic) describes an odd curve with fewer knots than
            # an offset along it: with it the input is not outdone by a coordinate swept with it (time, order)
            families = [("offset", hats), ("gain", hats * pred[..., None])]
            if name == "time_s" and mask.shape[1] >= 2:
                # a shape in time that differs from run to run (a jump, a relaxation after one power-on)
                families.append(in_each_run(hats, pred, mask.shape)[0])
            out.extend(_scored(space, sweep, name, families, {"within_device": dev / lot}))
            # the same curve in every device, on finer knots: what most physical terms are (in output units or
            # as a gain), where a coordinate moves within the devices (not one that mostly tells them apart)
            fine = spline_basis(x, mask, knots=POOLED_KNOTS, signed=name in SIGNED) if pooled and not between else None
            if fine is not None:
                out.extend(_scored(space, sweep, name, (("offset", fine), ("gain", fine * pred[..., None])),
                                   {"within_device": dev / lot}, pooled=True))
            if fine is not None and name == "input" and np.any(mask.any(axis=2).sum(axis=1) >= 2):
                # a curve along the input that differs from run to run, the same in every device (a run with
                # another setup: a sagging supply, another fixture)
                out.extend(_scored(space, sweep, name, in_each_run(hats, pred, mask.shape),
                                   {"within_device": dev / lot}, pooled=True))
            # a step where the coordinate passes one value, at one threshold for the lot (the lot's, as the
            # pooled curves' shape is): offset and gain, in every device or in one
            if fine is not None:
                out.extend(_thresholds(space, sweep, name, x, mask, pred, dev / lot))
        g = interactions(block, mask)
        for name, cols_g in g.items():
            cols = space.columns({sweep: cols_g})
            sc = space.score(cols)
            if sc.df:
                out.append(Description(sweep, name, "input x", cols, sc, sc.p_value, {"within_device": 1.0}))
        out.extend(_runs_and_devices(space, sweep, block, mask, pred))
        coords = coordinates(block)
        if "time_s" in coords:
            d = _step_scan(space, sweep, np.where(mask, coords["time_s"], 0.0), mask)
            if d is not None:
                out.append(d)
        for name in ("input", "time_s"):
            if name not in coords:
                continue
            x = np.where(mask, np.asarray(coords[name], float), 0.0)
            # along time also as a gain: a reference or a pick-off cycling with the lab's air conditioning
            # multiplies the output; along the input a gain is the output's own shape, which the offset reads.
            # Read only for what is reported, as the pooled curves are: a sine of a period near half the span
            # describes part of a smooth trend in fewer directions than a curve, and read by the guards it lets
            # a library effect stand beyond it that the curve would not
            for gain in (None, pred) if name == "time_s" and pooled else (None,):
                d = _periodic_scan(space, sweep, name, x, mask, gain)
                if d is not None and (gain is None or _cycles_beyond_trend(space, sweep, d, x, mask, pred)):
                    out.append(d)
        out.extend(_point_scans(space, sweep, block, mask))
    return out, notes


def _runs_and_devices(space, sweep, block, mask, pred) -> list:
    """What is constant within each run: a gain per run, and on a sweep read without a turn-on bias an offset per
    run and an offset of each device's readings, the same in all its runs (a bench connection's thermal EMF, a
    device's own offset: a property of the device, not of one run)."""
    out = []
    if not block.kind.biased:
        out.extend(_scored(space, sweep, "device", (("offset per device", mask[..., None].astype(float)),), {}))
    if mask.shape[1] >= 2:
        eye = np.eye(mask.shape[1])[None, :, None, :] * mask[..., None]
        per_run = [("gain per run", pred[..., None] * eye)]
        if not block.kind.biased:
            per_run.append(("offset per run", eye.astype(float)))
        out.extend(_scored(space, sweep, "run", per_run, {}))
    return out


def in_each_run(hats, pred, shape) -> tuple:
    """The offset and the gain along a coordinate (`hats`, (device, run, point, k)), one curve per run."""
    eye = np.eye(shape[1])[None, :, None, :, None]
    each = (hats[..., None, :] * eye).reshape(*shape, -1)
    return (("offset in each run", each), ("gain in each run", each * pred[..., None]))


def _own_knots(space, sweep, name, x, mask, pred, within_device) -> list:
    """The offset and the gain along a coordinate that mostly tells devices apart, on each device's own knots
    (`device_spline_basis`), marked `confounding`: a curve along it within a device is a curve along whatever it
    follows there (the drive frequency, the die temperature by the TCF), so these only say which located misfit
    the data confound with it; they are never a location of their own (`gyrojax._diagnose.locate`)."""
    hats = device_spline_basis(x, mask, signed=name in SIGNED)
    if hats is None:
        return []
    return _scored(space, sweep, name, (("offset", hats), ("gain", hats * pred[..., None])),
                   {"within_device": within_device, "confounding": True})


def _scored(space, sweep, name, families, where, pooled=False) -> list:
    """A description of `sweep` along `name` for each (family, basis (device, run, point, k)) of `families` that
    has a direction beyond the fit's span; `pooled`: one curve for every device."""
    out = []
    for family, g in families:
        cols = space.columns({sweep: g})
        sc = space.score(cols, pooled=pooled)
        if sc.df:
            out.append(Description(sweep, name, family, cols, sc, sc.p_value, dict(where), pooled=pooled))
    return out


def _thresholds(space, sweep, name, x, mask, pred, within_device) -> list:
    """The threshold scans along one coordinate (`gyrojax._diagnose.thresholds`) as descriptions."""
    out = []
    for family in thresholds.FAMILIES:
        found = thresholds.scan(space, sweep, x, mask, pred, family)
        if found is not None:
            out.append(threshold_description(space, sweep, name, found, within_device))
    return out


def threshold_description(space, sweep, name, found, within_device) -> Description:
    fit = space.fit
    where = {"at": found.at, "interval": list(found.interval), "device_index": list(found.devices),
             "devices": [fit.devices[d] for d in found.devices], "positions": found.positions,
             "beyond_line_p": found.beyond_line_p, "within_device": within_device}
    return Description(sweep, name, found.family, found.columns, found.scored, found.p_value, where,
                       pooled=found.pooled)


def at_threshold(space, sweep, like: Description) -> Description | None:
    """The step of `like` (a threshold description) on another sweep `sweep`, at the same threshold in the same
    devices, where that sweep records its coordinate and has points on both sides; None elsewhere."""
    block = space.fit.data.blocks[sweep]
    mask = np.asarray(block.mask)
    coords = coordinates(block)
    if like.coordinate not in coords:
        return None
    x = np.where(mask, np.asarray(coords[like.coordinate], float), 0.0)
    at = like.where["at"]
    if like.coordinate == "input" and block.kind.input_unit != space.fit.data.blocks[like.sweep].kind.input_unit:
        # one value of inputs in other units (deg/s, V) is not one threshold; their sign change is
        like_x = coordinates(space.fit.data.blocks[like.sweep])["input"]
        like_mask = np.asarray(space.fit.data.blocks[like.sweep].mask)
        here = thresholds.sign_change(x[mask], at)
        if here is None or not thresholds.is_sign_change(np.asarray(like_x, float)[like_mask], at):
            return None
        at = here
    above = x[mask] >= at
    if above.all() or not above.any():
        return None
    g = thresholds.changes(x, mask, np.asarray(space.fit.predictions[sweep], float), like.family, at,
                           like.where["device_index"])
    cols = space.columns({sweep: g})
    sc = space.score(cols, pooled=like.pooled)
    if not sc.df:
        return None
    found = thresholds.Threshold(like.family, at, tuple(like.where["device_index"]), cols, sc,
                                 sc.p_value, 1, like.pooled, tuple(like.where["interval"]), 0.0)
    return threshold_description(space, sweep, like.coordinate, found, like.where["within_device"])


INTERACTING = ("temperature_c", "time_s")  # coordinates whose product with a curve along the input is described


def interactions(block, mask) -> dict:
    """A curve along the input whose size grows linearly with another coordinate (name -> changes (device, run,
    point, k)): a term in temperature x |input| is neither along the temperature nor along the input alone."""
    coords = coordinates(block)
    hats = spline_basis(np.where(mask, coords["input"], 0.0), mask, signed=True)
    out = {}
    if hats is None:
        return out
    for name in INTERACTING:
        if name not in coords:
            continue
        x = np.where(mask, np.asarray(coords[name], float), 0.0)
        run, _, lot = spread(x, mask)
        if lot <= 0 or run <= WITHIN_RUN_SHARE * lot:
            continue
        out[name] = hats * _device_centred(x, mask)[..., None]
    return out


def _device_centred(x, mask):
    """`x` (device, run, point) less each device's mean over its recorded points, zero where not recorded."""
    centre = np.sum(x, axis=(1, 2), keepdims=True) / np.maximum(mask.sum(axis=(1, 2), keepdims=True), 1)
    return np.where(mask, x - centre, 0.0)


def _step_scan(space, sweep, t, mask):
    """The strongest change point along time of `sweep` (`gyrojax._diagnose.changepoints`) as a description."""
    hats = spline_basis(np.where(mask, t, 0.0), mask)
    found = changepoints.scan(space, sweep, t, mask, hats)
    return None if found is None else Description(sweep, "time_s", "step", *found)


def at_change_points(space, sweep, like: Description) -> Description | None:
    """The steps of `like` (a change-point description) on another sweep `sweep`: in the same (device, run)
    pairs, from the same times on, where that sweep records the time and has points on both sides; None where it
    has none (a jump of a device's bias shows on every sweep recorded after it in that run)."""
    block = space.fit.data.blocks[sweep]
    coords = coordinates(block)
    if "time_s" not in coords:
        return None
    found = changepoints.at_same_steps(space, sweep, np.asarray(coords["time_s"], float), np.asarray(block.mask),
                                       like.where)
    return None if found is None else Description(sweep, "time_s", "step", *found)


def _periodic_scan(space, sweep, name, x, mask, gain=None):
    """The strongest periodic error along the coordinate `name` (values `x`): sin and cos of one period, per
    device, of the output (`gain` None) or of its gain (times the prediction `gain`); the look-elsewhere
    correction is the number of periods scanned."""
    real = np.unique(x[mask])
    if real.size < 8:
        return None
    span = float(real.max() - real.min())
    step = float(np.median(np.diff(real)))
    if span <= 0 or step <= 0:
        return None
    best = None
    # at least two periods over the span: a longer one is a smooth trend, which the splines describe
    if span / 2.0 <= 2.5 * step:
        return None
    periods = np.geomspace(2.5 * step, span / 2.0, PERIODS)
    for period in periods:
        w = 2.0 * np.pi * x / period
        g = np.stack([np.sin(w), np.cos(w)], axis=-1) * mask[..., None]
        if gain is not None:
            g = g * gain[..., None]
        cols = space.columns({sweep: g})
        sc = space.score(cols)
        if sc.df and (best is None
                      or log_chi2_sf(sc.statistic, sc.df) < log_chi2_sf(best[0].statistic, best[0].df)):
            best = (sc, cols, float(period))
    if best is None:
        return None
    sc, cols, period = best
    return Description(sweep, name, "periodic", cols, sc, min(1.0, PERIODS * sc.p_value),
                       {"period": period, "gain": gain is not None})


CYCLE_ALPHA = 0.01  # a periodic gain along time is kept where significant at this level beyond a trend


def _cycles_beyond_trend(space, sweep, d, x, mask, pred) -> bool:
    """Whether the periodic gain `d` adds chi2 significant at `CYCLE_ALPHA` (over the periods scanned) beyond a
    gain quadratic along the same coordinate in each device: a sine whose period is near half the span follows
    part of a trend or of a gain step in one device, which is no cycle (a spline on the curves' knots, which
    follows a cycle of three periods over the span, would refuse the cycle itself)."""
    dx = _device_centred(x, mask)
    scale = np.max(np.abs(dx), axis=(1, 2), keepdims=True)
    u = dx / np.where(scale > 0, scale, 1.0)
    trend = np.stack([u, u ** 2], axis=-1) * pred[..., None]
    beyond = space.with_columns(space.columns({sweep: trend}))
    sc = beyond.score(d.columns)
    return bool(sc.df) and PERIODS * sc.p_value < CYCLE_ALPHA


POINT_CANDIDATES = 3  # the largest residuals scored exactly as single points (their projections differ little)


def _point_scans(space, sweep, block, mask) -> list:
    """Two narrow descriptions, each scored at the residuals most off the model: *one point* of one device (an
    outlier: a glitch in the recording, a transient), whose look-elsewhere correction is the number of points, and
    *one input value* in every device (a narrow error at one setting, as a DAC's missing code), corrected by the
    number of input values. A smooth shape spreads over many points and is outdone here by the splines."""
    i, j = space.blocks[sweep]
    n_dev, n_run, n_pt = mask.shape
    r = np.where(mask.reshape(n_dev, -1), space.residuals[:, i:j], 0.0)
    n_points = int(mask.sum())
    if n_points < 8:
        return []
    out = []
    best = None
    for flat in np.argsort(-np.abs(r), axis=None)[:POINT_CANDIDATES]:
        dv, row = np.unravel_index(int(flat), r.shape)
        rn, pt = divmod(int(row), n_pt)
        g = np.zeros((n_dev, n_run, n_pt, 1))
        g[dv, rn, pt, 0] = 1.0
        cols = space.columns({sweep: g})
        sc = space.score(cols)
        if sc.df and (best is None or sc.statistic > best[0].statistic):
            best = (sc, cols, dv, rn, pt)
    if best is not None:
        sc, cols, dv, rn, pt = best
        coords = {"input": float(np.asarray(block.inputs)[dv, rn, pt]),
                  **{k: float(v[dv, rn, pt]) for k, v in coordinates(block).items()
                     if k in ("time_s", "temperature_c")}}
        where = {"runs": [[space.fit.devices[dv], space.fit.data.run_ids(sweep)[dv][rn]]], "point": coords,
                 "positions": n_points}
        out.append(Description(sweep, "point", "single point", cols, sc, min(1.0, n_points * sc.p_value), where))
    x = np.asarray(block.inputs, float)
    values = np.unique(x[mask])
    if values.size >= 8:
        worst = {}
        for v in values:  # each input value: its residuals' chi2 over the lot, the candidates scored exactly
            worst[float(v)] = float(np.sum(np.where((x == v) & mask, r.reshape(mask.shape), 0.0) ** 2))
        best = None
        for v in sorted(worst, key=lambda v: worst[v], reverse=True)[:POINT_CANDIDATES]:
            g = np.zeros((n_dev, n_run, n_pt, n_dev))
            for dv in range(n_dev):
                g[dv, ..., dv] = np.where(mask[dv] & (x[dv] == v), 1.0, 0.0)
            cols = space.columns({sweep: g})
            sc = space.score(cols)
            if sc.df and (best is None
                          or log_chi2_sf(sc.statistic, sc.df) < log_chi2_sf(best[0].statistic, best[0].df)):
                best = (sc, cols, v)
        if best is not None:
            sc, cols, v = best
            out.append(Description(sweep, "input", "at one input", cols, sc, min(1.0, values.size * sc.p_value),
                                   {"at": v, "positions": int(values.size), "within_device": 1.0}))
    return out


# scans whose p carries their own look-elsewhere correction
NARROW = ("step", "single point", "at one input", *thresholds.FAMILIES)


def strength(d: Description) -> float:
    """-log p of a description (with the scan's look-elsewhere correction), for ranking."""
    lp = log_chi2_sf(d.scored.statistic, d.scored.df)
    if d.family in NARROW:
        lp += math.log(max(d.p_value / max(d.scored.p_value, 1e-300), 1.0))
    elif d.family == "periodic":
        lp += math.log(PERIODS)
    return -lp
