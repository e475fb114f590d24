r"""Where the misfit lives, without a list of shapes: the flexible descriptions of the standardised residuals
(`gyrojax._diagnose.descriptions`) along every recorded coordinate of every sweep, scored beyond what the fit
could absorb, and the locations chosen from them.

Every description is significant at `alpha` over the number of descriptions.

The most significant description (by its tail probability) is a misfit's *location*; the same description on
the other sweeps joins it when it stays significant beyond it; descriptions along other coordinates that the
data cannot tell from it are named as confounded with it; then its columns join the absorbable span and the
next location is sought. What each location reports is measured on the residuals: the share of the misfit
each sweep carries along that coordinate (fitted to that sweep's residuals alone), where on the coordinate it
sits (the interval where the fitted description exceeds half its peak, the runs and devices that carry it),
and its size in output units and ppm of the sweep's full scale with a standard error, or no size with the
reason where the data do not determine it.
"""

import dataclasses
import math

import numpy as np

from . import changepoints, thresholds
from .descriptions import (
    EACH_RUN,
    SIGNED,
    WITHIN_RUN_SHARE,
    Description,
    at_change_points,
    at_threshold,
    coordinates,
    describe,
    in_each_run,
    interactions,
    spline_basis,
    spread,
    strength,
)
from .guards import ONE_DEVICE_SHARE
from .location import Location, shape_words
from .space import ResidualSpace


# A size whose standard error is above this share of its value is not determined by the data.
SIZE_REL_STDERR = 0.5
# Descriptions of what is constant within each run: of the runs, and of the devices (an offset of a sweep read
# without a turn-on bias, the same in all of a device's runs).
CONSTANT_IN_RUNS = ("run", "device")
MAX_LOCATIONS = 3
# Scans (one position, one period, one point): described alone, never joined across sweeps or confounded.
SCANS = ("step", "periodic", "single point", "at one input")


# -- locations -----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Localisation:
    """`locate`'s result: the `locations`, most significant first; `notes` on coordinates not described along;
    and what the first round's scans found (`step_at`: the time of the strongest step, `periods`: the strongest
    period along each coordinate scanned, the input and the time), for the formula's dictionary."""

    locations: tuple
    notes: tuple
    step_at: float | None
    periods: dict


def locate(fit, *, alpha: float = 0.01, max_locations: int = MAX_LOCATIONS, pooled: bool = True) -> Localisation:
    """The misfit's locations at `fit`, most significant first (see the module docstring); with `pooled=False`
    from the per-device descriptions alone (what the diagnosis's guards read)."""
    space = ResidualSpace(fit)
    found = []
    notes, hints = (), None
    while len(found) < max_locations:
        described, new_notes = describe(space, pooled=pooled)
        # curves on each device's own knots along a coordinate that mostly tells devices apart only say what a
        # location is confounded with (`descriptions._own_knots`)
        descs = [d for d in described if not d.where.get("confounding")]
        if hints is None:
            hints = _hints(descs)
            notes = tuple(dict.fromkeys(new_notes))
        if not descs:
            break
        cut = alpha / len(descs)
        # a threshold step also beyond the straight line of its coordinate (not a trend it follows)
        significant = [d for d in descs if d.p_value < cut and d.where.get("beyond_line_p", 0.0) < cut]
        if not significant:
            break
        best = max(significant, key=strength)
        # Of coordinates the data cannot tell apart, name the one that moves most within each device: a
        # coordinate that mostly tells devices apart (a drive frequency) is seen here only through its small
        # excursions within a device, which another coordinate (the temperature behind them) explains as well.
        confounded = _confounded(space, best, described, cut)
        # the coordinate named first among those of the best description's kind: a step where one coordinate
        # passes a value is not replaced by a smooth curve along another (named as confounded all the same)
        primary = _primary([best] + [d for d in confounded if _is_step(d) == _is_step(best)])
        confounded = tuple(dict.fromkeys(d.coordinate for d in [best] + confounded
                                         if d.coordinate != primary.coordinate))
        best = primary
        if best.coordinate == "run":  # a coordinate constant within runs is described only as the run
            confounded = tuple(dict.fromkeys(confounded + run_properties(fit.data.blocks[best.sweep])))
        members, joined = [best], space.with_columns(best.columns)
        step = _is_step(best)  # a step joins at the best one's threshold and reading, whatever its own
        for d in sorted(significant, key=strength, reverse=True):
            if d.sweep in {m.sweep for m in members} or (d.coordinate, d.family, step or d.pooled) != (
                    best.coordinate, best.family, step or best.pooled):
                continue
            if d.family == "step" or step:  # joined at the same change points or threshold, nowhere else
                d = _same_step(space, d.sweep, best)
                if d is None:
                    continue
            elif d.family in SCANS:
                continue
            if joined.score(d.columns, d.pooled).p_value < cut:
                members.append(d)
                joined = joined.with_columns(d.columns)
        found.append(_location(space, fit, members, confounded))
        space = joined
    hints = hints or (None, {})
    return Localisation(tuple(found), notes, *hints)


def run_properties(block) -> tuple:
    """The coordinates of a sweep block that are constant within each run but differ between the runs of a
    device (a chamber that steps between runs: its temperature's rate of change): what a misfit that changes
    from run to run may follow."""
    mask = np.asarray(block.mask)
    out = []
    for name, x in coordinates(block).items():
        x = np.where(mask, np.asarray(x, float), 0.0)
        run, _, lot = spread(x, mask)
        if lot <= 0 or run > WITHIN_RUN_SHARE * lot:
            continue
        v = np.where(mask, x, np.nan)
        with np.errstate(all="ignore"):
            means = np.nanmean(v, axis=2)  # (device, run)
            between = np.nanmax(np.nanmax(means, axis=1) - np.nanmin(means, axis=1))
        if np.isfinite(between) and between > WITHIN_RUN_SHARE * lot:
            out.append(name)
    return tuple(out)


def _hints(descs):
    step = [d for d in descs if d.family == "step"]
    best_step = min(step, key=lambda d: d.p_value).where["at"] if step else None
    periods = {}  # per coordinate, the most significant sweep's period
    for d in sorted((d for d in descs if d.family == "periodic"), key=lambda d: d.p_value):
        periods.setdefault(d.coordinate, d.where["period"])
    return best_step, periods


# Of coordinates the data cannot tell apart, the one named first: what the experiment sets (the input), then the
# die's state (temperature, its rate of change), then the clock (time since power-on, the point's order), then
# the drive frequency (a reading that follows the temperature).
PREFERENCE = ("input", "temperature_c", "dtemperature_dt", "time_s", "order", "drive_freq_hz")


def _preference(d: Description):
    """Sort key among confounded descriptions: one that moves mostly within each device first (a coordinate that
    mostly tells devices apart is seen here only through its small excursions, which another coordinate, the
    temperature behind them, explains as well), then `PREFERENCE`."""
    mostly_between = d.where.get("within_device", 1.0) < 0.5
    rank = PREFERENCE.index(d.coordinate) if d.coordinate in PREFERENCE else len(PREFERENCE)
    return (mostly_between, rank)


SIMPLER = 0.5  # a description with at most this share of the other's degrees of freedom is the simpler one


def _primary(candidates: list) -> Description:
    """The description named first among those the data cannot tell apart: by `_preference`, unless a
    description of the runs (constant within each) needs at most `SIMPLER` of its degrees of freedom (a gain per
    run, 1 per device, against a curve along dT/dt in every device, 7 per device): what the data cannot tell from
    a change between power-ons needs nothing to vary within a run; and a curve that differs from run to run only
    where no curve shared by the runs says the same (one curve for every run is the simpler shape)."""
    shared = [d for d in candidates if d.family not in EACH_RUN]
    first = min(shared or candidates, key=_preference)
    per_run = [d for d in candidates if d.coordinate in CONSTANT_IN_RUNS]
    simplest = min(per_run, key=lambda d: d.scored.df) if per_run else first
    if _preference(simplest)[0] == _preference(first)[0] and simplest.scored.df <= SIMPLER * first.scored.df:
        return simplest
    return first


def _is_step(d: Description) -> bool:
    return d.family in thresholds.FAMILIES


def _same_step(space, sweep, best: Description) -> Description | None:
    """The step of `best` on `sweep`: a change point in the same runs from the same times, or a threshold step
    at the same threshold in the same devices; None where `sweep` cannot hold it."""
    if best.family == "step":
        return best if sweep == best.sweep else at_change_points(space, sweep, best)
    return at_threshold(space, sweep, best)


def _confounded(space, best, descs, cut) -> list:
    """The descriptions of `best`'s sweep along other coordinates that the data cannot tell from it: neither is
    significant beyond the other (of each coordinate, its first such step and its first other description)."""
    out = []
    if best.family in SCANS:
        return out
    beyond_best = space.with_columns(best.columns)
    for d in descs:
        # along best's own coordinate only a curve shared by the runs, where best differs from run to run
        own = d.coordinate == best.coordinate and not (best.family in EACH_RUN and d.family not in EACH_RUN)
        if (own or (d.coordinate, _is_step(d)) in {(o.coordinate, _is_step(o)) for o in out}
                or d.sweep != best.sweep):
            continue
        if d.family in SCANS and not (_is_step(best) and d.family == "step"):
            continue  # a threshold step and a change point in time are both one step: they may be one
        if (beyond_best.score(d.columns, d.pooled).p_value >= cut
                and space.with_columns(d.columns).score(best.columns, best.pooled).p_value >= cut):
            out.append(d)
    return out


def _location(space, fit, members, confounded) -> Location:
    best = members[0]
    cols = np.concatenate([m.columns for m in members], axis=-1)
    sc = space.score(cols, best.pooled)
    excess = space.excess
    share = min(max(sc.statistic - sc.df, 0.0) / excess, 1.0) if excess > 0 else 0.0
    shares = _measured_shares(space, fit, best, sc)
    location = _where(fit, space, best, members, sc)
    size, reason = _size(fit, space, members, sc)
    return Location(coordinate=best.coordinate, family=best.family, shape=shape_words(best), sweeps=shares,
                    chi2_explained=sc.statistic, df=sc.df, share=share,
                    p_value=max(min(d.p_value for d in members), 0.0), fingerprint=sc.fingerprint, columns=cols,
                    located_on=tuple(m.sweep for m in members), location=location, size=size, size_reason=reason,
                    confounded_with=tuple(confounded), pooled=best.pooled)


def _measured_shares(space, fit, best: Description, sc) -> tuple:
    """Each sweep's share of the misfit along `best`'s coordinate and family, fitted to its own residuals.
    Where those fits together find under `MEASURED_FLOOR` of the location's chi2 `sc` (a misfit seen only beyond
    the fit's own span: a gain that changes with a coordinate the fit's gains nearly follow), the shares of the
    location's own description (`sc`'s fingerprint) instead: a sweep's residuals as they are say nothing there."""
    if best.family in SCANS and best.family != "step":
        return ((best.sweep, 1.0),)
    found = {}
    for sweep in fit.data.sweeps:
        block = fit.data.blocks[sweep]
        mask = np.asarray(block.mask)
        coords = coordinates(block)
        pred = np.asarray(fit.predictions[sweep], float)
        if best.family == "step" or _is_step(best):
            d = _same_step(space, sweep, best)
            if d is not None:
                found[sweep] = space.raw_excess(d.columns, sweep)
            continue
        if best.family == "input x":
            g = interactions(block, mask).get(best.coordinate)
            if g is None:
                continue
        elif best.coordinate == "device":
            if block.kind.biased:
                continue
            g = mask[..., None].astype(float)
        elif best.coordinate == "run":
            if mask.shape[1] < 2:
                continue
            eye = np.eye(mask.shape[1])[None, :, None, :] * mask[..., None]
            g = pred[..., None] * eye if best.family == "gain per run" else eye.astype(float)
        else:
            if best.coordinate not in coords:
                continue
            hats = spline_basis(np.where(mask, coords[best.coordinate], 0.0), mask, signed=best.coordinate in SIGNED)
            if hats is None:
                continue
            if best.family in EACH_RUN:
                g = dict(in_each_run(hats, pred, mask.shape))[best.family]
            else:
                g = hats * pred[..., None] if best.family == "gain" else hats
        found[sweep] = space.raw_excess(space.columns({sweep: g}), sweep)
    total = sum(found.values())
    if total < MEASURED_FLOOR * sc.statistic:
        fp = np.asarray(sc.fingerprint, float) ** 2
        found = {s: float(np.sum(fp[:, i:j])) for s, (i, j) in space.blocks.items()}
        total = sum(found.values())
    if total <= 0:
        return ()
    return tuple(sorted(((s, v / total) for s, v in found.items() if v / total >= 0.05), key=lambda x: -x[1]))


# Below this share of a location's chi2, the sweeps' own residuals do not measure where it lives (see
# `_measured_shares`).
MEASURED_FLOOR = 0.1


def _rows_of(space, sweep):
    i, j = space.blocks[sweep]
    return i, j


def _where(fit, space, best, members, sc) -> dict:
    out = {"coordinate": best.coordinate, "sweeps": [m.sweep for m in members]}
    if best.family == "step":
        first = {}  # (device, run) -> the time of its step (and of a pulse's end)
        for m in members:
            for r, a, e in zip(m.where["runs"], m.where["at_each"], changepoints.ends(m.where)):
                first.setdefault(tuple(r), (a, e))
        out.update(at=best.where["at"], runs=[list(r) for r in first])
        pulses = any(e is not None for _, e in first.values())  # back where it was from these times on
        if pulses or len({a for a, _ in first.values()}) > 1:  # steps (or pulses) at their own times
            out["at_each"] = [a for a, _ in first.values()]
        if pulses:
            out["until_each"] = [e for _, e in first.values()]
        return out
    if best.family == "periodic":
        out["period"] = best.where["period"]
        return out
    if best.family == "single point":
        out.update(runs=best.where["runs"], point=best.where["point"])
        return out
    if best.family == "at one input":
        out.update(at=best.where["at"])
        return out
    if _is_step(best):
        out.update(at=best.where["at"], at_range=best.where["interval"], side="at or above",
                   devices=best.where["devices"])
    fp = sc.fingerprint
    chi_dev_run = []
    values = []
    for m in members:
        block = fit.data.blocks[m.sweep]
        mask = np.asarray(block.mask)
        i, j = _rows_of(space, m.sweep)
        f = fp[:, i:j].reshape(mask.shape)
        for dv, rn in np.ndindex(mask.shape[:2]):
            chi_dev_run.append((float(np.sum(f[dv, rn][mask[dv, rn]] ** 2)), fit.devices[dv],
                                fit.data.run_ids(m.sweep)[dv][rn]))
        if best.coordinate not in CONSTANT_IN_RUNS and not _is_step(best):
            x = coordinates(block)[best.coordinate]
            values.append((np.abs(f)[mask], np.asarray(x)[mask]))
    total = sum(c for c, _, _ in chi_dev_run) or 1.0
    runs = sorted(((c / total, d, r) for c, d, r in chi_dev_run), reverse=True)
    out["runs"] = [list(k) for k in dict.fromkeys((d, r) for s, d, r in runs if s >= 0.1)]
    by_device = {}
    for c, d, _ in chi_dev_run:
        by_device[d] = by_device.get(d, 0.0) + c
    # what each device holds beyond the noise its share of the description's degrees of freedom fits
    by_device = {d: max(c - sc.df / len(fit.devices), 0.0) for d, c in by_device.items()}
    top = max(by_device, key=lambda d: by_device[d])
    excess_total = sum(by_device.values())
    if ("devices" not in out and len(by_device) > 1 and excess_total > 0
            and by_device[top] >= ONE_DEVICE_SHARE * excess_total):
        out["devices"] = [top]  # the misfit lives in one device
    if values:
        a = np.concatenate([v[0] for v in values])
        x = np.concatenate([v[1] for v in values])
        if a.size and a.max() > 0:
            sel = a >= 0.5 * a.max()
            out["interval"] = [float(x[sel].min()), float(x[sel].max())]
    return out


def _size(fit, space, members, sc):
    """The peak of the fitted description in output units (and ppm of the sweep's full scale), with its
    standard error; None and the reason when the data do not determine it."""
    best = None
    pc = space.project(np.concatenate([m.columns for m in members], axis=-1))
    for m in members:
        block = fit.data.blocks[m.sweep]
        mask = np.asarray(block.mask).reshape(len(fit.devices), -1)
        sig = np.asarray(block.sigmas, float).reshape(len(fit.devices), -1)
        i, j = _rows_of(space, m.sweep)
        f = np.where(mask, sc.fingerprint[:, i:j] * sig, 0.0)
        dv, row = np.unravel_index(int(np.argmax(np.abs(f))), f.shape)
        value = float(f[dv, row])
        if best is None or abs(value) > abs(best[0]):
            g = pc[dv, i + row]
            var = float(g @ sc.covariance[dv] @ g)
            full = float(np.max(np.abs(np.asarray(fit.predictions[m.sweep])[dv][np.asarray(block.mask)[dv]])))
            best = (value, math.sqrt(max(var, 0.0)) * float(sig[dv, row]), fit.data.kind(m.sweep).output_unit, full,
                    m.sweep)
    if best is None:
        return None, "no coefficient of the description is on a recorded row"
    value, stderr, unit, full, sweep = best
    if not math.isfinite(value) or abs(value) == 0:
        return None, "the fitted description is zero"
    if not math.isfinite(stderr) or stderr > SIZE_REL_STDERR * abs(value):
        return None, (f"its standard error ({stderr:.3g} {unit}) is more than {100 * SIZE_REL_STDERR:.0f} % of its "
                      f"peak ({abs(value):.3g} {unit})")
    # ppm of full scale only where the output is proportional to the input by design (its nonlinearity is a
    # measurement there; a zero-rate output's "full scale" is its own small slope)
    relative = "nonlinearity" in fit.data.kind(sweep).applicable_metrics() and full > 0
    return {"value": abs(value), "unit": unit, "stderr": stderr, "measure": "peak of the fitted description",
            "sweep": sweep, "ppm_of_full_scale": 1e6 * abs(value) / full if relative else None}, ""
