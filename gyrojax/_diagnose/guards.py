"""What stops a significant candidate from being confirmed (an implausible size, a probe that explains its
misfit better, a sweep its refit makes worse), the `Rejection` that says why, and the verdict."""

import equinox as eqx
import numpy as np

from .._identify import Fit
from .._numerics.stats import chi2_isf, chi2_sf
from .columns import base_columns, effect_columns, excess_chi2
from .compare import compare
from .probes import project_out, score_columns, span_basis
from .score import TYPICAL_RANK_TOL, CandidateScore
from .space import EXPLAINED_SHARE_LEFT, ResidualSpace


# ASSUMPTION: beyond 100 times its typical size an effect is not physical any more (a 16-bit DAC's INL at
# 100x is ~5 % of full scale, a damping coupling at 100x breaks passivity on paper-qmg): a candidate that
# explains the misfit only there is not confirmed.
MAX_TYPICAL_MULTIPLE = 100.0


class Rejection(eqx.Module):
    """A candidate that scored but was not confirmed, and why (in physical words)."""

    effect: str
    reason: str
    contradicted_by: tuple[str, ...] = ()  # sweeps whose misfit the refit made significantly worse
    kind: str = ""  # the reason in two words: "implausible size", "not its shape", "contradicted", ...


def probe_guard(fit, candidate: CandidateScore, discrepancy, designs, candidate_cut, alpha, localisation=None):
    """A reason not to confirm `candidate`, or None: a significant probe explains the misfit the candidate is
    credited with, and more (what the probe takes beyond the candidate is significant at alpha over the
    probes), while the candidate adds nothing beyond the probe (not significant at `candidate_cut`).

    Both are compared beyond the misfit located elsewhere (`localisation`'s locations the candidate does not
    take, `other_misfit`): a probe more flexible than the candidate (a bias in temperature per sweep) also takes
    part of a second, unrelated misfit (a step partway through a run), which is no evidence against the
    candidate's shape."""
    res = np.asarray(fit.residual_vector)
    je = np.asarray(fit.jacobian)[:, :, effect_columns(fit, candidate.effect)]
    own = base_columns(fit)
    other = other_misfit(fit, je, localisation, alpha)
    beside = np.concatenate([own, other], axis=-1)
    probe_cut = alpha / max(len(discrepancy), 1)
    worst = None
    for d in (d for d in discrepancy if d.significant):
        gp = designs[d.probe]
        base = beside
        beyond_probe = score_columns(np.concatenate([base, gp], axis=-1), je, res, rank_tol=TYPICAL_RANK_TOL)
        if beyond_probe.df == 0 and other.shape[-1]:
            # no direction of the candidate's own is left: where that is the other misfit's doing (it and the
            # probe together span the candidate, which the probe alone does not), the two are compared as they
            # stand, without it
            alone = score_columns(np.concatenate([own, gp], axis=-1), je, res, rank_tol=TYPICAL_RANK_TOL)
            if alone.df > 0:
                base, beyond_probe = own, alone
        beyond_candidate = score_columns(np.concatenate([base, je], axis=-1), gp, res)
        if beyond_probe.p_value >= candidate_cut and beyond_candidate.p_value < probe_cut:
            if worst is None or beyond_candidate.statistic > worst[1].statistic:
                worst = (d, beyond_candidate, beyond_probe)
    if worst is None:
        return None
    d, extra, own = worst
    excess = excess_chi2(fit)
    share_c = min(candidate.statistic / excess, 1.0) if excess > 0 else 0.0
    return (f"it would take {100 * share_c:.0f} % of the misfit, whose shape it does not have: {d.shape} "
            f"({', '.join(s for s, _ in d.sweeps)}) explains {100 * d.share:.0f} %, leaves chi2 {extra.statistic:.4g} "
            f"that {candidate.effect} cannot take (p = {extra.p_value:.2g}), and {candidate.effect} adds nothing "
            f"beyond it (S = {own.statistic:.3g}, df {own.df}, p = {own.p_value:.2g})")


def other_misfit(fit, columns, localisation, alpha, taken_by=None) -> np.ndarray:
    """The columns (device, rows, k) of the locations of `localisation` that `columns` (a candidate's, in the
    fit's residual layout) do not take: still significant beyond them, keeping more than `EXPLAINED_SHARE_LEFT` of
    their chi2 (as the encompassing test reads what a refit leaves). `taken_by`, where given, decides what is
    taken instead of `columns` (the candidate with a variant of its own: its coefficient drifting)."""
    return misfit_beside(fit, columns, localisation, alpha, taken_by).columns


class Beside(eqx.Module):
    """A second misfit beside a candidate: its description's `columns` (device, rows, k) and the `sweeps` it was
    located on."""

    columns: np.ndarray
    sweeps: frozenset


def misfit_beside(fit, columns, localisation, alpha, taken_by=None, *, projected=True) -> Beside:
    """`other_misfit`'s columns with the sweeps of the locations they describe; with `projected` False, the
    descriptions as they are, the candidate's own directions not removed."""
    empty = Beside(np.zeros(np.shape(columns)[:2] + (0,)), frozenset())
    if localisation is None or not localisation.locations:
        return empty
    space = ResidualSpace(fit)
    joined = space.with_columns(np.asarray(columns if taken_by is None else taken_by, float))
    cut = alpha / len(localisation.locations)
    keep = []
    for loc in localisation.locations:
        now = joined.score(loc.columns)
        if now.p_value < cut and now.statistic > EXPLAINED_SHARE_LEFT * space.score(loc.columns).statistic:
            keep.append(loc)
    if not keep:
        return empty
    if not projected:
        return Beside(np.concatenate([loc.columns for loc in keep], axis=-1),
                      frozenset(s for loc in keep for s in loc.located_on))
    # without the candidate's own directions: a flexible description that also spans the candidate (an offset
    # along the input growing with temperature, beside a bias in temperature) must not absorb it. Its directions
    # beyond the fit's own span are what the guards read, so those are removed (the raw columns would leave the
    # description and the fit's span together spanning the candidate: a gain per run beside a reference drift)
    out = np.concatenate([loc.columns for loc in keep], axis=-1)
    cand = np.asarray(columns, float)
    base = base_columns(fit)
    for d in range(out.shape[0]):
        u = span_basis(project_out(cand[d], base[d]))
        out[d] = out[d] - u @ (u.T @ out[d])
    return Beside(out, frozenset(s for loc in keep for s in loc.located_on))


def _sweep_chi2(fit: Fit) -> dict:
    return {s: float(np.sum(np.asarray(fit.residuals[s]) ** 2)) for s in fit.data.sweeps}


def contradictions(before: Fit, after: Fit, alpha: float, df: int, held: Beside | None = None):
    """Sweeps whose chi2 the refit raised by more than the (1 - alpha) quantile of chi2(df), df the step's
    new parameters over the lot: a real effect, fitted, does not make a sweep's misfit significantly worse.

    `held`: a second misfit already there before the refit (`misfit_beside`), described flexibly in both fits. A
    sweep it was located on counts as made worse only where its chi2 also rises beyond that description: a true
    effect's refit moves the shared parameters that had bent towards the second misfit, which redistributes that
    misfit's chi2 between sweeps without contradicting the effect. Another sweep's rise counts as it stands."""
    limit = chi2_isf(alpha, max(df, 1))
    a, b = _sweep_chi2(before), _sweep_chi2(after)
    points = {s: int(np.asarray(before.data.blocks[s].mask).sum()) for s in a}
    worse = [s for s in a if b[s] - a[s] > limit]
    if worse and held is not None and held.sweeps:
        a_held, b_held = _sweep_chi2_beyond(before, held.columns), _sweep_chi2_beyond(after, held.columns)
        worse = [s for s in worse if s not in held.sweeps or b_held[s] - a_held[s] > limit]
    return tuple((s, a[s], b[s], points[s]) for s in worse)


def _sweep_chi2_beyond(fit: Fit, held: np.ndarray) -> dict:
    """Each sweep's chi2 once the columns `held` (device, rows, k) are fitted beyond the fit's own span."""
    return {s: float(np.sum(r**2)) for s, r in _residuals_beyond(fit, held).items()}


def new_structure(before, after, alpha: float, held=None) -> tuple:
    """The structure findings (`gyrojax.compare`'s) flagged in the refit's residuals that the residuals before it
    did not show at all (p >= `alpha`, not even nominally significant): a real effect, fitted, whitens the
    residuals; one fitted where it is not takes its shape out of some sweeps and leaves it, reversed, on a sweep
    that does not have it (an INL fitted to a rate-only saturation writes an odd cubic on the DAC bench).

    `before`, `after`: the two fits' comparisons; `held`, where given, (before fit, after fit, `Beside`): a
    second misfit already there before the refit (`misfit_beside`). A finding on a sweep it was located on counts
    as created only where it also stands in both fits' residuals beyond that misfit's description: a true effect,
    fitted, unmasks a second misfit that the fit's own parameters had bent towards (a bias quadratic in time shows
    as an even bow of an ordered sweep once a reference drift is fitted), which is no structure the effect made."""
    p_before = {(f.sweep, f.test, f.coordinate): f.p_value for f in before.findings}
    created = tuple(f for f in after.flagged if p_before.get((f.sweep, f.test, f.coordinate), 0.0) >= alpha)
    if not created or held is None or not held[2].sweeps:
        return created
    fit_b, fit_a, beside = held
    beyond_b, beyond_a = (compare(f, alpha=alpha, residuals=_residuals_beyond(f, beside.columns))
                          for f in (fit_b, fit_a))
    p_b = {(f.sweep, f.test, f.coordinate): f.p_value for f in beyond_b.findings}
    still = {(f.sweep, f.test, f.coordinate) for f in beyond_a.flagged}
    return tuple(f for f in created if f.sweep not in beside.sweeps
                 or ((key := (f.sweep, f.test, f.coordinate)) in still and p_b.get(key, 0.0) >= alpha))


def _residuals_beyond(fit: Fit, held: np.ndarray) -> dict:
    """Each sweep's standardised residuals (device, run, point) once the columns `held` are fitted beyond the fit's
    own span."""
    space = ResidualSpace(fit)
    left = space.residuals - space.score(held).fingerprint
    return {s: left[:, i:j].reshape(np.shape(fit.residuals[s])) for s, (i, j) in space.blocks.items()}


def verdict_of(comparison, steps) -> str:
    if not comparison.fails and not comparison.flagged:
        return "explained"
    return "partly explained" if steps else "unexplained"


MIN_DEVICES_FOR_LOT = 3  # with fewer devices, "one device only" cannot be told from a lot effect
ONE_DEVICE_SHARE = 0.9  # the share of a candidate's score (or a location's chi2) one device carries to be its


def one_device_guard(fit: Fit, effect: str, alpha: float) -> str | None:
    """A reason not to confirm `effect` for the lot, or None: one device carries its score (>= `ONE_DEVICE_SHARE`
    of it) and the other devices together are consistent with none of it (p >= `alpha`). A library effect is a
    property of the design, present in every device with a part-to-part spread; a misfit of its shape in one
    device of a lot is that device's anomaly (a cracked die attach, a bad reference), reported there, not a
    discovery about the lot."""
    n = len(fit.devices)
    if n < MIN_DEVICES_FOR_LOT:
        return None
    res = np.asarray(fit.residual_vector)
    je = np.asarray(fit.jacobian)[:, :, effect_columns(fit, effect)]
    own = base_columns(fit)
    per = [score_columns(own[d:d + 1], je[d:d + 1], res[d:d + 1], rank_tol=TYPICAL_RANK_TOL) for d in range(n)]
    total = sum(p.statistic for p in per)
    top = int(np.argmax([p.statistic for p in per]))
    if total <= 0 or per[top].statistic < ONE_DEVICE_SHARE * total or per[top].p_value >= alpha:
        return None
    others = [p for d, p in enumerate(per) if d != top]
    stat, df = sum(p.statistic for p in others), sum(p.df for p in others)
    if not df:
        return None
    p_others = float(chi2_sf(stat, df))
    if p_others < alpha:
        return None
    return (f"one device carries it: {fit.devices[top]} gives {per[top].statistic / total:.0%} of its score "
            f"(S = {per[top].statistic:.4g}, p = {per[top].p_value:.2g}); the other {n - 1} together S = {stat:.3g} "
            f"on {df} df (p = {p_others:.2g}), consistent with none of it: a misfit of its shape in that device "
            "alone is that device's anomaly, not an effect of the lot")
