"""The scale factor's part of a plan: the greedy c-optimal design of its rates, runs and static-VCF
points within a time budget, against seed 000's 22-rate protocol at equal time, and its standard
error on the data given."""

import functools
import math

import numpy as np

from .._identify import Fit
from .._sweeps.rate_table import RateTable
from .._sweeps.vcf_static import VcfStatic
from .experiment import (
    window_correlation,
)
from .information import (
    kept_columns,
    run_info,
    sf_variance,
    sqrt_info,
)
from .results import ScaleFactorDesign


RATE, VCF = RateTable.name, VcfStatic.name
"""The scale-factor design's kinds (their default experiments' names)."""


def _data_rows(fit: Fit) -> int:
    return int(sum(int(np.prod(fit.data.blocks[s].inputs.shape[1:])) for s in fit.data.sweeps))


def sf_design(fit, jac0, g, sf, exps, jac_e, noise, pool, budget, protocol, threshold, say):
    """The greedy c-optimal design of the scale factor within `budget` minutes (see the module notes)."""
    n_dev = len(fit.devices)
    n_rows = _data_rows(fit)
    prior = [jac0[d, n_rows:].T @ jac0[d, n_rows:] for d in range(n_dev)]
    by_name = {e.name: k for k, e in enumerate(exps)}
    warm, dwell = protocol.warmup_s / 60.0, protocol.dwell_s / 60.0
    rate = exps[by_name[RATE]]
    levels = {RATE: np.asarray(rate.sweep.rates_dps)}
    rows = {RATE: [jac_e[by_name[RATE]][d] for d in range(n_dev)]}
    sigs = {RATE: [rate.sigmas(noise[d]) for d in range(n_dev)]}
    if VCF in by_name:
        v = exps[by_name[VCF]]
        levels[VCF] = np.asarray(v.sweep.virtual_rates_dps)
        rows[VCF] = [jac_e[by_name[VCF]][d] for d in range(n_dev)]
        sigs[VCF] = [v.sigmas(noise[d]) for d in range(n_dev)]
    cols = list(pool)
    # Both kinds' points are settled means over back-to-back windows of the protocol's dwell: their noise
    # shares the bias wander between neighbours (window_correlation); the fit weighs them as independent.
    model = noise[0].rate_noise
    corrs = {k: functools.lru_cache(maxsize=None)(
        lambda n: window_correlation(model, n, protocol.dwell_s)) for k in levels}

    def per_device(sets, runs, d):
        return _per_device(prior, rows, sigs, sets, runs, g, cols, threshold, d, corrs)

    def variance(sets, runs):
        return float(np.mean([per_device(sets, runs, d) for d in range(n_dev)]))

    seed_run_min = (protocol.warmup_s + len(levels[RATE]) * protocol.dwell_s) / 60.0
    seed_runs = int(budget // seed_run_min)
    seed_sets = {RATE: tuple(range(len(levels[RATE])))}
    seed_var = [per_device(seed_sets, {RATE: seed_runs}, d) for d in range(n_dev)]
    best = None
    max_rate_runs = int(budget // (warm + 2 * dwell))
    say(f"scale-factor design within {budget:g} min: up to {max_rate_runs} rate-table runs")
    # Run counts on a roughly geometric grid (every count up to 4, then steps of ~25 %): the variance changes
    # smoothly with the count, and each count costs a greedy search.
    grid = sorted({r for r in range(1, max_rate_runs + 1) if r <= 4 or r == max_rate_runs
                   or int(round(1.25 ** round(math.log(r, 1.25)))) == r})
    for r_runs in grid:
        for q_runs in range(0, 2 if VCF in levels else 1):
            runs = {RATE: r_runs, VCF: q_runs}
            used = (r_runs + q_runs) * warm
            if used + 2 * dwell * (r_runs + q_runs) > budget:
                continue
            current, sets, used = _greedy_points(variance, levels, runs, used, budget, dwell)
            if best is None or current < best[0]:
                best = (current, dict(sets), dict(runs), used)
    if best is None:
        raise ValueError(f"scale-factor design: a budget of {budget:g} min holds no rate-table run (a warm-up and "
                         f"two points take {warm + 2 * dwell:g} min).")
    _, sets, runs, used = best
    stderr = [math.sqrt(per_device(sets, runs, d)) for d in range(n_dev)]
    data_se, undetermined = _data_sf_errors(fit, jac0, g)
    rates = tuple(float(levels[RATE][i]) for i in sets[RATE])
    vcf = tuple(float(levels[VCF][i]) for i in sets.get(VCF, ())) if runs.get(VCF) else ()
    return ScaleFactorDesign(budget_min=float(budget), rates_dps=rates, rate_runs=runs[RATE], vcf_rates_dps=vcf,
                             vcf_runs=runs.get(VCF, 0), minutes=float(used), stderr=tuple(stderr),
                             seed000_runs=seed_runs,
                             seed000_minutes=seed_runs * (protocol.warmup_s + len(levels[RATE]) * protocol.dwell_s)
                             / 60.0,
                             seed000_stderr=tuple(math.sqrt(v) for v in seed_var), data_stderr=tuple(data_se),
                             scale_factor=tuple(float(x) for x in np.asarray(sf)),
                             data_not_determined=tuple(undetermined))


def _greedy_points(variance, levels, runs, used, budget, dwell):
    """The points of one design's runs (`runs`: per kind, how many), `used` minutes spent already: each kind
    starts with its best pair of opposite levels, then single points are added by the largest variance drop
    per minute while `budget` allows. Returns (the scale factor's variance, the points per kind, minutes)."""
    kinds = list(levels)
    sets: dict[str, tuple[int, ...]] = {k: () for k in kinds}
    for kind in kinds:
        if not runs.get(kind):
            continue
        lv = list(levels[kind])
        pairs = [(i, lv.index(-x)) for i, x in enumerate(lv) if x < 0 and -x in lv]
        pair = min(pairs, key=lambda p, kind=kind: variance({**sets, kind: tuple(sorted(p))}, runs))
        pair = tuple(sorted(pair))
        sets[kind] = pair
        used += 2 * dwell * runs[kind]
    current = variance(sets, runs)
    while True:
        options = []
        for kind in kinds:
            cost = dwell * runs.get(kind, 0)
            if not runs.get(kind) or used + cost > budget + 1e-9:
                continue
            for i in range(len(levels[kind])):
                if i in sets[kind]:
                    continue
                trial = {**sets, kind: tuple(sorted(sets[kind] + (i,)))}
                options.append(((current - variance(trial, runs)) / cost, kind, trial, cost))
        if not options:
            break
        gain, kind, trial, cost = max(options, key=lambda o: o[0])
        if not gain > 0:
            break
        sets, used = trial, used + cost
        current = variance(sets, runs)
    return current, sets, used


def _data_sf_errors(fit: Fit, jac0, g):
    """The scale factor's standard error per device on the data given, and, where identification says the
    data do not determine it (the baseline's status), its reason: (errors, reasons or '')."""
    data_free = [int(i) for i in np.nonzero(np.asarray(fit.free))[0]]
    data_se, undetermined = [], []
    for d in range(len(fit.devices)):
        info = jac0[d].T @ jac0[d]
        # whether the data determine it is identification's verdict (the baseline's status), not the planner's
        if fit.status[d] == "not determined":
            data_se.append(math.nan)
            undetermined.append(fit.warnings[d][0] if fit.warnings[d] else "identify: not determined")
            continue
        data_se.append(math.sqrt(sf_variance(info, g[d], data_free, 0.0)) if data_free else math.inf)
        undetermined.append("")
    return data_se, undetermined


def _per_device(prior, rows, sigs, sets, runs, g, cols, threshold, d, corrs=None):
    info = prior[d].copy()
    meat = prior[d].copy()
    for kind, idx in sets.items():
        if runs.get(kind) and len(idx) >= 2:
            a, b = run_info(rows[kind][d], sigs[kind][d], list(idx), (corrs or {}).get(kind))
            info, meat = info + runs[kind] * a, meat + runs[kind] * b
    kept = kept_columns([sqrt_info(info)], cols, threshold)
    return sf_variance(info, g[d], kept, threshold, meat if corrs else None)
