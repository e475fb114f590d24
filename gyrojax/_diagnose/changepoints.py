"""Change points along time: a step of the output at one dwell of one run (in every device, each its own height,
or in one device), or steps in several (device, run) pairs each at its own dwell (bias jumps at random times,
popcorn charging events), or pulses there (the output switching on and back off: a two-level trap). Array in,
columns and score out; `gyrojax._diagnose.descriptions` makes them descriptions."""

import math

import numpy as np

from .._numerics.stats import chi2_isf, chi2_sf, log_chi2_sf
from .space import ResidualSpace


MAX_OWN_STEPS = 8  # the most (device, run) pairs a reading of steps at their own dwells holds
OWN_STEP_ALPHA = 0.01  # each of them significant alone at this level, over the pairs and positions tried


def scan(space: ResidualSpace, sweep: str, t: np.ndarray, mask: np.ndarray, hats: np.ndarray | None):
    """The strongest change point along the time `t` (device, run, point) of `sweep`: a step at one position (in
    time order) of one run index, in every device (each its own height) or in one device, or steps in several
    (device, run) pairs each at its own position (`_steps_each_own_dwell`, read beyond the smooth curve `hats`
    of the time in each run); the look-elsewhere correction is the number of positions tried (and for several
    pairs their choice). (columns, score, corrected p-value, where) or None."""
    n_dev, n_run, n_pt = mask.shape
    r = space.residuals
    stats = {}  # (run, position) -> per-device statistics
    projected = {}  # (run, position) -> the step's column beyond the fit's span, per device
    positions = 0
    for rn in range(n_run):
        for j in range(2, n_pt - 1):
            g = np.zeros((n_dev, n_run, n_pt, 1))
            for dv in range(n_dev):
                m = mask[dv, rn]
                if m.sum() < 6 or j >= m.sum() - 1:
                    continue
                g[dv, rn, :, 0] = _from_position(t[dv, rn], m, j)
            if not g.any():
                continue
            cols = space.columns({sweep: g})
            pc = space.project(cols)[..., 0]
            info = np.einsum("dr,dr->d", pc, pc)
            own = np.einsum("dr,dr->d", cols[..., 0], cols[..., 0])
            ok = info > 1e-9 * np.maximum(own, 1e-300)
            per_dev = np.where(ok, np.einsum("dr,dr->d", pc, r) ** 2 / np.where(ok, info, 1.0), 0.0)
            if ok.any():
                stats[(rn, j)] = (per_dev, ok, cols)
                projected[(rn, j)] = pc
                positions += 1
    if not stats:
        return None
    # each position read in every device (each its own height) and in its strongest device alone; the first best
    best = min(((p, rn, j, devs, cols) for (rn, j), (per_dev, ok, cols) in stats.items()
                for p, devs in ((chi2_sf(float(per_dev.sum()), int(ok.sum())), np.flatnonzero(ok)),
                                (chi2_sf(float(per_dev.max()), 1), np.array([int(np.argmax(per_dev))])))),
               key=lambda b: b[0])
    fit = space.fit

    def own_dwells(pairs):  # the columns of steps (or pulses) in (device, run) pairs, each at its own dwells
        g = np.zeros((n_dev, n_run, n_pt, n_run))
        for dv, rn, (j, end) in pairs:
            g[dv, rn, :, rn] = _from_position(t[dv, rn], mask[dv, rn], j)
            if end is not None:  # a pulse: back to where it was from the end-th point on
                g[dv, rn, :, rn] -= _from_position(t[dv, rn], mask[dv, rn], end)
        return space.columns({sweep: g})

    def time_at(dv, rn, j):  # the time of the j-th point of a run
        return float(np.sort(t[dv, rn][mask[dv, rn]])[j])

    beyond_smooth = _beyond_smooth(space, sweep, mask, hats)
    joint = lambda pairs: space.score(own_dwells(pairs)).statistic  # noqa: E731
    is_step = lambda pair: beyond_smooth.score(own_dwells([pair])).p_value < OWN_STEP_ALPHA  # noqa: E731
    # two readings of the jumps at their own dwells: steps, and pulses (a bias that switches on and back off, a
    # two-level trap), each with its own look-elsewhere correction, and 2x for the choice of the reading
    readings = [r for r in (_steps_each_own_dwell(_per_pair(stats), joint, is_step),
                            _steps_each_own_dwell(_per_pair(stats, _pulses(stats, projected, r)), joint, is_step))
                if r is not None]
    several = min(readings, key=lambda r: r[0], default=None)
    if several is not None and several[0] + math.log(2.0) < math.log(max(2 * positions * best[0], 1e-300)):
        log_p, pairs = several
        cols = own_dwells(pairs)
        at = [time_at(dv, rn, j) for dv, rn, (j, _) in pairs]
        where = {"runs": [[fit.devices[dv], fit.data.run_ids(sweep)[dv][rn]] for dv, rn, _ in pairs],
                 "at": float(np.median(at)), "at_each": at, "run_index": None}
        if any(end is not None for _, _, (_, end) in pairs):
            where["until_each"] = [None if end is None else time_at(dv, rn, end) for dv, rn, (_, end) in pairs]
        return cols, space.score(cols), min(1.0, 2.0 * math.exp(log_p)), where
    p, rn, j, devs, cols = best
    keep = np.zeros(n_dev, bool)
    keep[devs] = True
    cols = np.where(keep[:, None, None], cols, 0.0)
    sc = space.score(cols)
    at = [time_at(dv, rn, j) for dv in devs]
    where = {"runs": [[fit.devices[dv], fit.data.run_ids(sweep)[dv][rn]] for dv in devs],
             "at": float(np.median(at)), "at_each": at, "run_index": rn}
    return cols, sc, min(1.0, 2 * positions * p), where


def _from_position(t_run: np.ndarray, m: np.ndarray, j: int) -> np.ndarray:
    """1 on the points of one run (times `t_run`, recorded where `m`) from its j-th point in time order on."""
    order = np.argsort(np.where(m, t_run, np.inf), kind="stable")
    return np.where(m & (t_run >= t_run[order[j]]), 1.0, 0.0)


def at_same_steps(space: ResidualSpace, sweep: str, t: np.ndarray, mask: np.ndarray, like: dict):
    """The steps of a change point located elsewhere (`like`: its `runs` and `at_each`) on `sweep` (time `t`):
    in the same (device, run) pairs from the same times, where `sweep` has points on both sides. (columns,
    score, p-value, where) or None."""
    fit = space.fit
    t = np.where(mask, t, np.nan)
    run_ids = fit.data.run_ids(sweep)
    g = np.zeros(mask.shape + (mask.shape[1],))
    pairs = []
    for (device, run), at, end in zip(like["runs"], like["at_each"], ends(like)):
        dv = fit.devices.index(device)
        if run not in run_ids[dv]:
            continue
        rn = run_ids[dv].index(run)
        above = mask[dv, rn] & (t[dv, rn] >= at) & (t[dv, rn] < (np.inf if end is None else end))
        if above.any() and (mask[dv, rn] & ~above).any():
            g[dv, rn, :, rn] = above
            pairs.append(([device, run], at, end))
    if not pairs:
        return None
    cols = space.columns({sweep: g})
    sc = space.score(cols)
    if not sc.df:
        return None
    where = {"runs": [r for r, _, _ in pairs], "at": like["at"], "at_each": [a for _, a, _ in pairs],
             "run_index": like.get("run_index")}
    if any(end is not None for _, _, end in pairs):
        where["until_each"] = [end for _, _, end in pairs]
    return cols, sc, sc.p_value, where


def _beyond_smooth(space, sweep, mask, hats):
    """`space` beyond a smooth curve along time in each run (`hats`, the spline of the diagnosis's "offset in
    each run"): a jump is a step only where it stays significant beyond it; a die relaxing after a chamber step
    is a smooth change that a step at some dwell of each run also follows."""
    if hats is None:
        return space
    eye = np.eye(mask.shape[1])[None, :, None, :, None]
    return space.with_columns(space.columns({sweep: (hats[..., None, :] * eye).reshape(*mask.shape, -1)}))


def ends(where: dict) -> list:
    """Each (device, run)'s end of a change point's `where` (its `until_each`: the time a pulse is back), None
    for a step; a location without pulses has no `until_each`."""
    return where.get("until_each") or [None] * len(where["at_each"])


MIN_PULSE_POINTS = 2  # a pulse holds at least this many dwells (one alone is an outlier: the single-point scan)


def _per_pair(stats, pulses=None):
    """Per (device, run): its strongest step (statistic, (position, None)), or with `pulses` its strongest step
    or pulse; and per run the number of positions tried (the look-elsewhere count)."""
    best, tried = {}, {}
    for (rn, j), (per_dev, ok, _) in stats.items():
        tried[rn] = tried.get(rn, 0) + 1
        for dv in np.flatnonzero(ok):
            if (dv, rn) not in best or per_dev[dv] > best[(dv, rn)][0]:
                best[(dv, rn)] = (float(per_dev[dv]), (j, None))
    for (dv, rn), (stat, where, n) in (pulses or {}).items():
        tried[rn] = max(tried[rn], n)  # the pulses' starts and ends are tried besides the steps
        if stat > best.get((dv, rn), (-1.0,))[0]:
            best[(dv, rn)] = (stat, where)
    return best, tried


def _pulses(stats, projected, r):
    """Per (device, run): the strongest pulse (the output 1 from one position to another, at least
    `MIN_PULSE_POINTS` dwells, and back), read from the projected step columns (a pulse is the difference of two
    steps): (statistic, (start, end), positions tried: the steps and the pulses)."""
    out = {}
    for rn in sorted({rn for rn, _ in stats}):
        js = sorted(j for q, j in stats if q == rn)
        if len(js) < 2:
            continue
        ok = np.all([stats[(rn, j)][1] for j in js], axis=0)
        p = np.stack([projected[(rn, j)] for j in js])  # (positions, device, rows)
        a = np.einsum("jdr,dr->jd", p, r)
        gram = np.einsum("jdr,kdr->djk", p, p)
        pairs = [(u, v) for u in range(len(js)) for v in range(u + 1, len(js)) if js[v] - js[u] >= MIN_PULSE_POINTS]
        if not pairs:
            continue
        u, v = np.array(pairs).T
        num = (a[u] - a[v]) ** 2  # (pairs, device)
        den = (gram[:, u, u] + gram[:, v, v] - 2.0 * gram[:, u, v]).T
        stat = np.where(den > 1e-12 * np.maximum(gram[:, u, u].T, 1e-300), num / np.where(den > 0, den, 1.0), 0.0)
        for dv in np.flatnonzero(ok):
            k = int(np.argmax(stat[:, dv]))
            out[(dv, rn)] = (float(stat[k, dv]), (js[u[k]], js[v[k]]), len(js) + len(pairs))
    return out


def _steps_each_own_dwell(per_pair, joint, is_step):
    """Steps in several (device, run) pairs, each at its own dwell (bias jumps at random times: popcorn
    charging events): the pairs at their best positions, strongest first, each kept only where it adds chi2
    significant alone (at `OWN_STEP_ALPHA` over the pairs and positions tried) beyond those before it (`joint`:
    the chi2 of a list of (device, run, position) together; a jump in one run moves the device's fitted gain,
    which leaves a step-like trend in its other run that adds nothing beyond the jump) and a step, not a
    smooth change (`is_step` of the (device, run, position)), at most
    `MAX_OWN_STEPS`; `per_pair` (`_per_pair`): each pair's strongest statistic and position (start, end: None
    for a step, the end of a pulse) and the positions tried per run. The look-elsewhere correction is the choice
    of K of the pairs and a position in each, times the two readings of one dwell. (log of the corrected
    p-value, [(device, run, position)]) of the best K >= 2, or None."""
    pair_best, per_run = per_pair
    n_pairs, n_pos = len(pair_best), max(per_run.values(), default=1)
    alone = chi2_isf(OWN_STEP_ALPHA / max(n_pairs * n_pos, 1), 1)
    ranked = sorted(((k, v) for k, v in pair_best.items() if v[0] > alone), key=lambda kv: -kv[1][0])
    chosen, total, best = [], 0.0, None
    for (dv, rn), (_, j) in ranked:
        if len(chosen) == MAX_OWN_STEPS:
            break
        if not is_step((dv, rn, j)):
            continue
        with_it = joint(chosen + [(dv, rn, j)])
        if with_it - total <= alone:
            continue
        chosen, total = chosen + [(dv, rn, j)], with_it
        k = len(chosen)
        if k < 2:
            continue
        choose = math.lgamma(n_pairs + 1) - math.lgamma(k + 1) - math.lgamma(n_pairs - k + 1)
        log_p = log_chi2_sf(total, k) + choose + k * math.log(n_pos) + math.log(2.0)
        if best is None or log_p < best[0]:
            best = (log_p, list(chosen))
    return best
