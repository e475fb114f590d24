"""The effects' part of a plan: each candidate effect's expected chi2 and power on the data given and with
runs of each experiment added, the cheapest runs that make it testable (exact or greedy search), or why
none do."""

import functools
import itertools
import math
from typing import NamedTuple

import numpy as np

from .._effects.registry import EFFECTS
from .._identify import Fit
from .._numerics.testability import MIN_TYPICAL_CHI2, is_testable
from .experiment import (
    weighted_rows,
)
from .information import (
    nuisances,
    reduce_rows,
    residual_chi2,
)
from .power import power, required_noncentrality
from .results import CandidatePlan, ExperimentGain, Recommendation


MAX_EXACT_COMBINATIONS = 4096
"""Above this many combinations of runs (`(max_repeats + 1) ** experiments`), the cheapest set is searched
greedily instead of exactly."""

SAME_SHAPE = 0.95
"""|cos| between two candidates' fingerprints on the data given above which they are ambiguous (the
diagnosis's default `ambiguity`)."""


def typical(fit: Fit, name: str, cols) -> np.ndarray:
    """The effect at its typical size in internal units: typical(1.0) over each element's scale."""
    entries = [e for e in fit.entries if e.effect_index is not None and e.label.split(".")[0] == name]
    typ = EFFECTS[name].typical(1.0)
    out = [np.ravel(np.asarray(getattr(typ, e.effect_field), dtype=float)) / np.asarray(e.scale) for e in entries]
    theta = np.concatenate(out) if out else np.zeros(0)
    if theta.size != len(cols):
        raise ValueError(f"effect {name!r}: {len(cols)} columns in the fit, {theta.size} typical values.")
    return theta


class _Rows(NamedTuple):
    """The information the effects' part of a plan is computed from: per device, the reduced standardised rows
    of the data given (`r0`) and of one run of each experiment (`rk[k]`), and which columns are what."""

    r0: list
    rk: list
    cand_cols: dict  # candidate -> its columns
    base_free: list  # the baseline fit's free columns
    pool: list  # the columns a joint fit may free (identification's rule decides which)
    reading: list  # per experiment, the columns of the parameters only it reads (freed with its runs)
    threshold: float  # identification's threshold
    n_dev: int


def information_rows(fit: Fit, jac0, candidates, added, experiments, jac_e, pred_e, noise, threshold) -> _Rows:
    """The reduced rows of the data given and of one run of each experiment, per device, and the columns a
    joint fit may free."""
    n_dev = len(fit.devices)
    free_mask = np.asarray(fit.free)
    phys = [i for i, e in enumerate(_columns(fit)) if e is None]
    cand_cols = {c: [i for i, nm in enumerate(fit.names) if nm.startswith(c + ".")] for c in candidates}
    held_cands = {i for cols in cand_cols.values() for i in cols}
    # A parameter only an experiment kind reads (omega_x, by the drive frequency) is a nuisance of the sets
    # with runs of that kind only: as the diagnosis of those data frees it (`Plan.free`).
    by_label = {p: [i for i, nm in enumerate(fit.names) if nm == p or nm.startswith(p + "[")] for p in added}
    added_cols = {i for cols in by_label.values() for i in cols}
    pool = sorted((set(phys) | {i for i in np.nonzero(free_mask)[0] if i not in held_cands}) - added_cols)
    reading = [[i for p in e.reads if p in added for i in by_label[p]] for e in experiments]
    base_free = [int(i) for i in np.nonzero(free_mask)[0]]
    r0 = [reduce_rows(jac0[d]) for d in range(n_dev)]
    rk = [[reduce_rows(weighted_rows(e, jac_e[k][d], e.sigmas(noise[d], pred_e[k][d]))) for d in range(n_dev)]
          for k, e in enumerate(experiments)]
    return _Rows(r0, rk, cand_cols, base_free, pool, reading, threshold, n_dev)


def fingerprints(rows: _Rows, candidates, thetas) -> dict:
    """Each candidate's typical-size fingerprint on the data given, after the baseline's free parameters took
    their share, over the lot's devices (for ambiguity)."""
    prints = {}
    for c in candidates:
        fp = []
        for d in range(rows.n_dev):
            a = rows.r0[d]
            f = a[:, rows.cand_cols[c]] @ thetas[c]
            b = a[:, rows.base_free]
            if rows.base_free:
                f = f - b @ np.linalg.lstsq(b, f, rcond=None)[0]
            fp.append(f)
        prints[c] = np.concatenate(fp)
    return prints


def ambiguous(c: str, candidates, prints) -> tuple[str, ...]:
    """The candidates ambiguous with `c`: both fingerprints visible on the data given (a typical size changes
    the chi2 by more than 1, the diagnosis's `min_typical_chi2`) and nearly collinear."""
    pn = np.linalg.norm(prints[c])
    return tuple(o for o in candidates if o != c and pn > 1.0 and np.linalg.norm(prints[o]) > 1.0
                 and abs(prints[c] @ prints[o]) / (pn * np.linalg.norm(prints[o])) > SAME_SHAPE)


def search_order(experiments, max_repeats: int):
    """How the runs are searched: (exact, the combinations cheapest first or None, the search's description).
    Exact over every combination of 0..`max_repeats` runs where they are at most `MAX_EXACT_COMBINATIONS`,
    else greedy."""
    exact = (max_repeats + 1) ** len(experiments) <= MAX_EXACT_COMBINATIONS
    combos = sorted(itertools.product(range(max_repeats + 1), repeat=len(experiments)),
                    key=lambda n: (sum(k * e.minutes for k, e in zip(n, experiments)), sum(n))) if exact else None
    search = (f"exact: every combination of 0..{max_repeats} runs of each experiment, cheapest first" if exact else
              f"greedy: one run at a time, the largest expected-chi2 gain per minute, up to {max_repeats} runs of "
              f"each experiment ({len(experiments)} experiments: more than {MAX_EXACT_COMBINATIONS} combinations)")
    return exact, combos, search


def _expected_chi2(rows: _Rows, counts, cols, amb_cols, theta) -> float:
    """The expected chi2 of an effect (columns `cols`, typical size `theta`) over the lot, with `counts` runs of
    each experiment added and the ambiguous candidates' columns `amb_cols` free beside the nuisances."""
    blocks = [np.concatenate([rows.r0[d]] + [math.sqrt(k) * rows.rk[j][d] for j, k in enumerate(counts) if k])
              for d in range(rows.n_dev)]
    nuis = nuisances(blocks, counts, rows.base_free, rows.pool, rows.reading, rows.threshold)
    nuis = [i for i in nuis if i not in cols] + amb_cols
    return sum(residual_chi2(blocks[d], nuis, cols, theta) for d in range(rows.n_dev))


def _cheapest_runs(lam, need: float, now: float, experiments, max_repeats: int, combos):
    """The first run counts (cheapest first over `combos`; greedy, the largest gain per minute, where `combos`
    is None) whose expected chi2 `lam(counts)` reaches `need`: (counts, chi2), or None."""
    if combos is not None:
        for counts in combos[1:]:
            lc = lam(counts)
            if lc >= need:
                return counts, lc
        return None
    counts, lc = (0,) * len(experiments), now
    while True:
        steps = [tuple(k + (i == j) for i, k in enumerate(counts)) for j in range(len(experiments))
                 if counts[j] < max_repeats]
        if not steps:
            return None
        gains = [(lam(c) - lc) / experiments[j].minutes for j, c in
                 zip([j for j in range(len(experiments)) if counts[j] < max_repeats], steps)]
        counts = steps[int(np.argmax(gains))]
        lc = lam(counts)
        if lc >= need:
            return counts, lc


def _unreachable(c: str, amb, top: float, need: float, names, max_repeats: int, target_power: float) -> str:
    """Why no combination of runs makes candidate `c` testable: the chi2 `top` all of them leave against the
    `need`ed one, and what else would reveal it."""
    # What the effect's own text names is not offered where these runs include it and it did not help.
    hidden = (f"with {', '.join(amb)} free (ambiguous: they take what it leaves)" if amb else
              "after the baseline took its share")
    # An ambiguous candidate's own revealing text may name a sweep among these runs: that sweep separates the
    # two at a larger size (diagnose's "X separates them" is at the fitted size), not at the typical size
    # planned here, so it is not offered.
    beyond = (f"at its typical size none of these runs tells it from {', '.join(amb)} (a sweep that "
              "separates them at a larger fitted size, as diagnose may report, does not at this one)"
              if amb else f"revealed by: {EFFECTS[c].revealed_by or 'no measurement named'}")
    return (f"no combination of up to {max_repeats} runs of {', '.join(names)} brings it to power "
            f"{target_power:g}: a typical size leaves chi2 {top:.3g} with all of them {hidden}, "
            f"{need:.3g} is needed" + ("" if is_testable(top) else
                                       f" (below {MIN_TYPICAL_CHI2:g}: not testable)") + f"; {beyond}")


def candidate_plan(c: str, rows: _Rows, theta, amb, experiments, alpha, target_power, max_repeats,
                    combos) -> CandidatePlan:
    """Candidate `c`'s plan: its expected chi2 and power now and with one run of each experiment, and the
    cheapest runs that bring it to `target_power` (none where it is detected already), or why none do."""
    cols = rows.cand_cols[c]
    df = len(cols) * rows.n_dev
    need = required_noncentrality(df, target_power, alpha)
    amb_cols = [i for o in amb for i in rows.cand_cols[o]]
    lam = functools.partial(_expected_chi2, rows, cols=cols, amb_cols=amb_cols, theta=theta)
    now = lam((0,) * len(experiments))
    p_now = power(now, df, alpha)
    per = []
    for j, e in enumerate(experiments):
        counts = tuple(1 if i == j else 0 for i in range(len(experiments)))
        lj = lam(counts)
        per.append(ExperimentGain(name=e.name, minutes=e.minutes, expected_chi2=lj, power=power(lj, df, alpha)))
    testable = is_testable(now)  # the diagnosis's rule (gyrojax/_numerics/testability.py)
    detected = p_now >= target_power
    recommended, rec_chi2, rec_power, reason = (), now, p_now, ""
    if detected:
        reason = f"detected on the data given (power {p_now:.2f} >= {target_power:g})"
    else:
        found = _cheapest_runs(lam, need, now, experiments, max_repeats, combos)
        if found is None:
            top = lam((max_repeats,) * len(experiments))
            reason = _unreachable(c, amb, top, need, [e.name for e in experiments], max_repeats, target_power)
        else:
            counts, rec_chi2 = found
            rec_power = power(rec_chi2, df, alpha)
            recs = []
            for j, k in enumerate(counts):
                if k:
                    only = tuple(k if i == j else 0 for i in range(len(experiments)))
                    lk = lam(only)
                    recs.append(Recommendation(experiment=experiments[j], runs=k, expected_chi2=lk,
                                               power=power(lk, df, alpha)))
            recommended = tuple(recs)
            reason = ("cheapest combination (exact search)" if combos is not None else
                      "greedy search (most chi2 per minute)")
    return CandidatePlan(effect=c, df=df, expected_chi2=now, power=p_now, testable=testable, ambiguous_with=amb,
                         per_experiment=tuple(per), recommended=recommended, recommended_chi2=rec_chi2,
                         recommended_power=rec_power, reason=reason, detected=detected)


def say_candidate(say, cp: CandidatePlan) -> None:
    """One line of progress for a candidate's plan."""
    say(f"{cp.effect}: now chi2 {cp.expected_chi2:.3g} (power {cp.power:.2f})" + ("" if cp.detected else (
        f"; add {' + '.join(f'{r.runs} x {r.experiment.name}' for r in cp.recommended)}" if cp.recommended
        else "; not reachable with these experiments")))


def _columns(fit: Fit):
    """Per column of the fit: None for a physical parameter, else the effect's name."""
    out = []
    for e in fit.entries:
        out += [None if e.effect_index is None else e.label.split(".")[0]] * e.size
    return out
