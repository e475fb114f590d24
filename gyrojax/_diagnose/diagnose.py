"""`diagnose`: the baseline fit with every candidate at zero, then score, guard, refit and confirm one effect
at a time until no candidate is significant."""

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from .._data.table import Table
from .._effects.plugins import nonfinite_effect
from .._gyroscope import Gyroscope
from .._identify import Fit, MultiStart, identify
from .._identify.order import DEFAULT_MODEL, model_and_data
from .._identify.spec import FitSpec, fit_spec
from .._model.fitdata import FitData, fit_data
from .._model.parameters import Model, as_model
from .._numerics.stats import chi2_sf
from .._runtime.progress import ProgressArg, as_progress
from .candidates import baseline_fit, baseline_model, candidate_effects, first_device, is_lot
from .columns import base_columns, effect_columns
from .compare import compare, nonlinearity_residual_ppm
from .constancy import constancy_guard
from .discrepancy import look_alikes, score_probes, with_shapes
from .encompass import encompassing_guard
from .fdr import bh_q_values, selection_p
from .formula import formula_coordinate, propose_along, term_size
from .guards import (
    MAX_TYPICAL_MULTIPLE,
    Rejection,
    contradictions,
    misfit_beside,
    new_structure,
    one_device_guard,
    probe_guard,
    verdict_of,
)
from .locate import Localisation, locate
from .probes import PROBES, AbstractProbe, score_columns
from .record import record_guard
from .repeat import absent_run_guard, held_out_guard
from .rival import rival_guard
from .score import TYPICAL_RANK_TOL, cosine, score_candidates, separating_sweep
from .solution import Diagnosis, Step


def diagnose(model: Model | Gyroscope | str = DEFAULT_MODEL, data: Table | FitData | None = None, *,
             candidates: Sequence[str] | None = None, free: Sequence[str] | None = None, alpha: float = 0.01,
             max_effects: int = 4, ambiguity: float = 0.95, min_typical_chi2: float = 1.0,
             max_typical_multiple: float = MAX_TYPICAL_MULTIPLE, probes: Sequence[AbstractProbe] = PROBES,
             start: MultiStart = MultiStart(), fit: Fit | None = None, spec: FitSpec | None = None,
             progress: ProgressArg = True) -> Diagnosis:
    r"""Compare `model` with `data`, rank every candidate effect, add the significant ones one at a time, and
    say where what is left lives.

    **Arguments:**

    - `model`: the baseline: a preset name, a `Gyroscope`, or a `gyrojax.Model` (its effects stay in).
    - `data`: a `gyrojax.Table` (or `FitData`) of any sweeps (the old order `diagnose(data, model)` warns).
    - `candidates`: effect names to consider (default: every registered effect the device supports).
    - `free`: baseline physical parameters free per device (see `gyrojax.identify`).
    - `alpha`: family-wise significance per step, in (0, 0.5]; a candidate must reach p < alpha /
      n_candidates in the score test and p < alpha in the likelihood-ratio test after its refit.
    - `max_effects`: stop after this many (0: only rank the candidates at the baseline, no refit).
    - `ambiguity`: |cos| between fingerprints above which two candidates are reported as ambiguous (as are two
      neither of which removes significant chi2 beyond the other).
    - `min_typical_chi2`: a candidate whose typical-size fingerprint, after the baseline took up what it
      could, changes the lot's chi2 by less than this is not testable on this data, whatever its p-value
      (`gyrojax.plan` applies the same rule, `gyrojax/_numerics/testability.py`).
    - `max_typical_multiple`: a candidate whose score implies a size beyond this many times its typical
      size is not confirmed (the reason says so).
    - `probes`: the generic shapes scored beside the candidates (`gyrojax.PROBES`).
    - `start`: the starts of every fit (`gyrojax.MultiStart`, as for `identify`; default one start).
    - `fit`: a `gyrojax.Fit` of this data (from `identify`, or `gyrojax.load_fit`) to use as the baseline
      instead of fitting it again; its model replaces `model`, and its parameters are the refits' start.
    - `spec`: a `gyrojax.FitSpec`: how every fit is made (solver, recovery, starts, what is free and held ...),
      instead of `free` and `start`; the candidates are held on top of its `hold`.
    - `progress`: `True` (default) reports each step on standard error (fits, compiles, what was confirmed),
      `False` is silent, a callable receives the messages.

    Guards before a candidate is confirmed: its implied size is plausible; no probe explains the misfit it is
    credited with while it adds nothing beyond that probe; the refit passes the likelihood-ratio test and
    converges; it stays significant beyond the flexible description of the misfit it leaves; the recorded drive
    frequency (`drive_freq_hz`) moves as the refit says the PLL frequency moves; it fits better than the closed
    form of another shape the data propose for what it takes, by a margin that grows with how different the
    two shapes are; its q-value passes false-discovery control; and no sweep's misfit gets significantly worse.

    **Returns:** a `Diagnosis` (with a `verdict`: explained, partly explained or unexplained).
    """
    _check_arguments(alpha, max_effects, max_typical_multiple)
    model, data = model_and_data("diagnose", model, data, data_required=True)
    spec = fit_spec(spec, "diagnose", free=free, start=start)
    data = fit_data(data) if isinstance(data, Table) else data
    base = baseline_model(fit, data) if fit is not None else as_model(model)
    candidates, broken = _usable_candidates(base, candidates)
    say = as_progress(progress, "gyrojax.diagnose")
    baseline, fit_with = _baseline_and_refits(base, data, candidates, fit, spec, say)
    discrepancy, designs = score_probes(baseline, probes, alpha=alpha)
    located = locate(baseline, alpha=alpha, pooled=False)
    s = _Selection(baseline, discrepancy, designs, located, fits=[baseline], rejected=list(broken))
    compared = {}  # id(fit) -> its comparison: each fit of `fits` is compared once, during the steps or at the end

    def comparison(f):
        if id(f) not in compared:
            compared[id(f)] = compare(f, alpha=alpha)
        return compared[id(f)]

    _select(s, list(candidates), fit_with, comparison, data, probes, alpha=alpha, max_effects=max_effects,
            ambiguity=ambiguity, min_typical_chi2=min_typical_chi2, max_typical_multiple=max_typical_multiple,
            tier=spec.tier, say=say)
    return _solution(s, candidates, located, discrepancy, designs, comparison, alpha=alpha,
                     min_typical_chi2=min_typical_chi2, max_typical_multiple=max_typical_multiple, say=say)


def _solution(s: "_Selection", candidates, located, discrepancy, designs, comparison, *, alpha: float,
              min_typical_chi2: float, max_typical_multiple: float, say) -> Diagnosis:
    """The `Diagnosis` of the selection `s`: what is left at its final fit (with the library's shapes and a
    formula), each fit compared with the data, and the verdict."""
    baseline = s.fits[0]
    ranking0 = () if s.ranking0 is None else s.ranking0
    # Which library effect has the shape of what is left: every candidate not selected, at the final fit.
    others = [c for c in candidates if c not in s.selected]
    final_scores = score_candidates(s.fit, others, min_typical_chi2=min_typical_chi2) if others else ()
    # what is reported is described with the curves shared by every device too (see `_Selection.located_at`)
    baseline_discrepancy = with_shapes(baseline, s.located_at(baseline, alpha, pooled=True).locations, discrepancy,
                                       designs, ranking0, s.rejected, max_typical_multiple, alpha)
    final_discrepancy, formula = _final_discrepancy(s, final_scores, max_typical_multiple, alpha)
    comparisons = tuple(comparison(f) for f in s.fits)
    verdict = verdict_of(comparisons[-1], s.steps)
    if verdict == "explained" and final_discrepancy:  # a located misfit is a failure the omnibus test missed
        verdict = "partly explained" if s.steps else "unexplained"
    say(f"done: {verdict}; selected {', '.join(s.selected) or 'none'}")
    return Diagnosis(baseline=baseline, final=s.fit, fits=tuple(s.fits), ranking=ranking0, steps=tuple(s.steps),
                     ambiguous=tuple(s.ambiguous), untestable=s.untestable, rejected=tuple(s.rejected), alpha=alpha,
                     baseline_nonlinearity_ppm=nonlinearity_residual_ppm(baseline),
                     min_typical_chi2=min_typical_chi2, comparisons=comparisons,
                     baseline_discrepancy=baseline_discrepancy, discrepancy=final_discrepancy, verdict=verdict,
                     max_typical_multiple=max_typical_multiple, formula=formula, notes=s.located.notes)


def _check_arguments(alpha, max_effects, max_typical_multiple) -> None:
    """`diagnose`'s scalar arguments, each with what is expected."""
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha <= 0.5):
        raise ValueError(f"alpha must be a significance level in (0, 0.5], got {alpha!r}.")
    if not isinstance(max_effects, int) or isinstance(max_effects, bool) or max_effects < 0:
        raise ValueError(f"max_effects must be an integer >= 0, got {max_effects!r}.")
    if not (isinstance(max_typical_multiple, (int, float)) and max_typical_multiple > 1.0):
        raise ValueError(f"max_typical_multiple must be a number > 1, got {max_typical_multiple!r}.")


def _usable_candidates(base, candidates) -> tuple[tuple[str, ...], list[Rejection]]:
    """The candidates checked against the baseline `base`, less those that give the device NaN or infinite
    values (a user effect's bug), which are dropped with a note: (candidates, those notes)."""
    candidates = candidate_effects(base, candidates, "diagnose")
    one = first_device(base.device) if is_lot(base.device) else base.device
    broken = [Rejection(effect=c, reason=f"{why}: dropped from the candidates", kind="non-finite model")
              for c in candidates if (why := nonfinite_effect(c, one)) is not None]
    candidates = tuple(c for c in candidates if c not in {r.effect for r in broken})
    return candidates, broken


def _baseline_and_refits(base, data, candidates, fit, spec, say):
    """The baseline fit (of `data`, or the given `fit` evaluated where it ended), with every candidate at zero,
    and the refit with a selection of them freed: (baseline, refit(selected))."""
    weights = {"data": data, "estimate_noise": None}

    def fit_with(selected):
        held = tuple(c for c in candidates if c not in selected)
        return identify(full, weights["data"], spec=spec.holding(held), estimate_noise=weights["estimate_noise"],
                        progress=False)

    if fit is not None:  # the saved fit is the baseline: evaluated where it ended, with the candidates at zero
        say("evaluating the given baseline fit with every candidate at zero")
    # Without output_sigma the noise is the lot's per sweep where the devices agree: a device whose own estimate
    # came out low would carry residuals that every scan reads as structure.
    full, fit = baseline_fit(base, data, candidates, spec, evaluate_only=fit is not None,
                             estimate_noise=None if data.weighted else "lot", say=say)
    baseline = fit
    if not data.weighted:
        # The noise was estimated from the baseline's residuals: every refit keeps those weights, so that the
        # likelihood-ratio tests compare fits of the same weighted data.
        weights.update(data=baseline.data, estimate_noise=False)
        say("the data give no output_sigma: every fit uses the noise estimated from the baseline's residuals")
    return baseline, fit_with


@dataclasses.dataclass
class _Selection:
    """Where the one-at-a-time selection stands: the current fit, the probes' scores and the locations of its
    misfit, and what was fitted, confirmed, found ambiguous and rejected so far."""

    fit: Fit
    discrepancy: tuple
    designs: object
    located: Localisation
    fits: list
    rejected: list
    selected: list = dataclasses.field(default_factory=list)
    steps: list = dataclasses.field(default_factory=list)
    ambiguous: list = dataclasses.field(default_factory=list)
    family: list = dataclasses.field(default_factory=list)  # every refit's selection-corrected p-value (FDR)
    localised: dict = dataclasses.field(default_factory=dict)  # (id(fit), pooled) -> (fit, ...), see `located_at`
    ranking0: tuple | None = None
    untestable: tuple = ()

    def located_at(self, fit: Fit, alpha: float, *, pooled: bool = False) -> Localisation:
        """`locate(fit)`, once per fit: a refit's localisation, read by the guards, is the step's when confirmed.
        The guards read the per-device descriptions alone: a curve shared by every device is a less flexible
        description of the misfit a candidate leaves, and read by the guards it credited candidates with what
        per-device curves take (the two-effect benchmark's wrong confirmations 2 -> 6 of 80). What is reported
        is described with the shared curves too (`pooled=True`)."""
        known = self.localised.get((id(fit), pooled))
        if known is None or known[0] is not fit:
            known = self.localised[(id(fit), pooled)] = (fit, locate(fit, alpha=alpha, pooled=pooled))
        return known[1]


def _first_ranking(scores):
    # one rule (gyrojax._numerics.testability): untestable is what score_candidates marks so, whatever its p-value
    return scores, tuple(c.effect for c in scores if not c.testable)


def _select(s: _Selection, remaining: list, fit_with, comparison, data, probes, *, alpha, max_effects, ambiguity,
            min_typical_chi2, max_typical_multiple, tier, say) -> None:
    """Add the significant candidates of `remaining` to `s` one at a time, each scored at the current fit,
    guarded, refitted (`fit_with`) and confirmed, until none is significant or `max_effects` are."""
    if remaining and max_effects == 0:  # rank at the baseline only
        s.ranking0, s.untestable = _first_ranking(score_candidates(s.fit, remaining,
                                                                   min_typical_chi2=min_typical_chi2))
    while remaining and len(s.selected) < max_effects:
        scores = score_candidates(s.fit, remaining, min_typical_chi2=min_typical_chi2)
        threshold = alpha / len(remaining)
        if s.ranking0 is None:
            s.ranking0, s.untestable = _first_ranking(scores)
        significant = [c for c in scores if c.testable and c.p_value < threshold]
        if not significant:
            break
        best = _first_to_try(s.fit, significant, s.located, alpha)
        if best.implied_multiple > max_typical_multiple:
            s.rejected.append(_implausible(best, max_typical_multiple))
            remaining.remove(best.effect)
            continue
        guard = probe_guard(s.fit, best, s.discrepancy, s.designs, threshold, alpha, s.located)
        if guard is not None:
            s.rejected.append(Rejection(effect=best.effect, reason=guard, kind="not its shape"))
            remaining.remove(best.effect)
            continue
        alone = one_device_guard(s.fit, best.effect, alpha)
        if alone is not None:
            s.rejected.append(Rejection(effect=best.effect, reason=alone, kind="in one device only"))
            remaining.remove(best.effect)
            continue
        unrepeated = held_out_guard(s.fit, best.effect, best.statistic, alpha)
        if unrepeated is not None:
            s.rejected.append(Rejection(effect=best.effect, reason=unrepeated, kind="not repeatable"))
            remaining.remove(best.effect)
            continue
        drifting = constancy_guard(s.fit, best.effect, best.statistic, alpha, s.located,
                                   rivals=[c.effect for c in significant if c is not best])
        if drifting is not None:
            s.rejected.append(Rejection(effect=best.effect, reason=drifting, kind="its size drifts"))
            remaining.remove(best.effect)
            continue
        # after the constancy guard: a size that follows a recorded coordinate is also absent from a run where
        # the coordinate stays small, and the constancy guard names the coordinate
        absent = absent_run_guard(s.fit, best.effect, best.statistic, alpha)
        if absent is not None:
            s.rejected.append(Rejection(effect=best.effect, reason=absent, kind="not repeatable"))
            remaining.remove(best.effect)
            continue
        # alternatives: any candidate significant at alpha alone (ambiguity names explanations, not discoveries)
        alternatives = [best] + [c for c in scores if c.testable and c.p_value < alpha and c is not best]
        group, separated = _ambiguity_group(s.fit, best, alternatives, ambiguity, alpha, data)
        say(f"refitting with {best.effect} (step {len(s.selected) + 1}; score S = {best.statistic:.4g}, "
            f"p = {best.p_value:.2g})")
        n_tried = len(remaining)
        new = fit_with(tuple(s.selected) + (best.effect,))
        lr, df, df_total, p_lr, delta_bic = _likelihood_ratio(s.fit, new, data)
        remaining.remove(best.effect)
        rejection, q, rival_alike = _refit_rejection(s, new, best, df, df_total, p_lr, delta_bic, n_tried,
                                                     comparison, alpha, tier)
        if rejection is not None:
            s.rejected.append(rejection)
            continue
        if group:
            s.ambiguous.append((best.effect,) + group)
        s.selected.append(best.effect)
        alike = look_alikes(s.fit, best.effect, s.discrepancy, s.designs, alpha) + (
            (rival_alike,) if rival_alike is not None else ())
        s.fit = new
        s.fits.append(s.fit)
        cols = effect_columns(s.fit, best.effect)
        multiple = float(np.max(np.abs(np.asarray(s.fit.u)[:, cols])))
        s.steps.append(Step(effect=best.effect, statistic=best.statistic, p_value=best.p_value, lr_statistic=lr,
                            lr_df=df_total, lr_p_value=p_lr, delta_bic=delta_bic, chi2_red_after=s.fit.chi2_red_total,
                            nonlinearity_ppm_after=nonlinearity_residual_ppm(s.fit), ranking=scores,
                            ambiguous_with=group, separated_by=separated, typical_multiple=multiple,
                            implied_multiple=best.implied_multiple, look_alikes=alike,
                            q_value=q if q is not None else math.nan))
        s.discrepancy, s.designs = score_probes(s.fit, probes, alpha=alpha)
        s.located = s.located_at(s.fit, alpha)


def _first_to_try(fit, significant, localisation, alpha):
    """The candidate a step tries first: the most significant, unless another significant one removes significant
    chi2 (at `alpha`) beyond it while it removes none beyond that one, both read beyond the description of the
    misfit located beside them (`misfit_beside`, as it is). The score ranks a flexible candidate (a DAC INL's
    S-curve, 12 parameters per device) first where it takes part of a second misfit (a bias quadratic in time)
    beside the one a less flexible candidate (a compression) describes as well."""
    best = significant[0]
    base, res, jac = base_columns(fit), np.asarray(fit.residual_vector), np.asarray(fit.jacobian)
    jb = jac[:, :, effect_columns(fit, best.effect)]
    for c in significant[1:]:
        jc = jac[:, :, effect_columns(fit, c.effect)]
        held = misfit_beside(fit, np.concatenate([jb, jc], axis=-1), localisation, alpha, projected=False).columns
        beside = np.concatenate([base, held], axis=-1)
        c_beyond = score_columns(np.concatenate([beside, jb], axis=-1), jc, res, rank_tol=TYPICAL_RANK_TOL)
        best_beyond = score_columns(np.concatenate([beside, jc], axis=-1), jb, res, rank_tol=TYPICAL_RANK_TOL)
        if c_beyond.df and c_beyond.p_value < alpha and best_beyond.p_value >= alpha:
            return c
    return best


def _implausible(best, max_typical_multiple) -> Rejection:
    """The rejection of a candidate whose score implies a size beyond `max_typical_multiple` typical sizes."""
    return Rejection(effect=best.effect, reason=(
        f"it explains the misfit only at ~{best.implied_multiple:.3g}x its typical size, beyond "
        f"{max_typical_multiple:g}x, where its physics does not reach: another effect, perhaps not in the "
        "library, leaves a similar fingerprint"),
        kind=f"only at ~{best.implied_multiple:.3g}x its typical size")


def _ambiguity_group(fit, best, significant, ambiguity, alpha, data):
    """The significant candidates the data cannot tell from `best`, and the one sweep of `data` that separates
    them, if one does: (group, sweep or None). A candidate is in the group when its fingerprint is nearly
    collinear with `best`'s (|cosine| > `ambiguity`) or when the two are interchangeable at `fit`: neither
    removes significant chi2 (at `alpha`) beyond the other, so whichever is fitted first takes the misfit."""
    group = tuple(c.effect for c in significant[1:]
                  if abs(cosine(best.fingerprint, c.fingerprint)) > ambiguity
                  or _interchangeable(fit, best.effect, c.effect, alpha))
    separated = None
    if group:
        others = [c for c in significant if c.effect in group]
        seps = {separating_sweep(best.fingerprint, c.fingerprint, data, ambiguity) for c in others}
        separated = seps.pop() if len(seps) == 1 else None
    return group, separated


def _interchangeable(fit, a: str, b: str, alpha: float) -> bool:
    """Whether neither of the candidate effects `a` and `b` removes chi2 significant at `alpha` beyond the
    other (score tests at `fit`, beyond its free columns): two explanations of one misfit."""
    base, res, jac = base_columns(fit), np.asarray(fit.residual_vector), np.asarray(fit.jacobian)
    ja, jb = jac[:, :, effect_columns(fit, a)], jac[:, :, effect_columns(fit, b)]
    a_beyond = score_columns(np.concatenate([base, jb], axis=-1), ja, res, rank_tol=TYPICAL_RANK_TOL)
    b_beyond = score_columns(np.concatenate([base, ja], axis=-1), jb, res, rank_tol=TYPICAL_RANK_TOL)
    return a_beyond.p_value >= alpha and b_beyond.p_value >= alpha


def _likelihood_ratio(fit, new, data):
    """The likelihood-ratio test of the refit `new` against `fit`: (chi2 drop, parameters added per device,
    over the lot, p-value, delta BIC). Where the refit leaves more scatter than the stated uncertainties
    (chi2_red > 1), the drop is read against that scatter, as an F-test does: noise larger than stated, or a misfit
    the step does not take, is not evidence for it."""
    lr = fit.chi2_total - new.chi2_total
    df = int(np.sum(new.free)) - int(np.sum(fit.free))
    df_total = df * len(data.devices)
    p_lr = chi2_sf(lr / max(float(new.chi2_red_total), 1.0), df_total)
    n_points = int(np.sum([np.asarray(b.mask).sum() for b in data.blocks.values()]))
    delta_bic = -lr + df_total * math.log(max(n_points, 2))
    return lr, df, df_total, p_lr, delta_bic


def _refit_rejection(s: "_Selection", new, best, df, df_total, p_lr, delta_bic, n_tried, comparison, alpha, tier):
    """The guards after the refit `new` of the selection's fit with `best`, in order: (the first rejection or
    None, the refit's false-discovery q-value where it was reached, a closed form of another shape about as good or
    None). The selection's `family` (every refit's selection-corrected p-value) gains this refit's where the
    control is reached."""
    fit, located, family = s.fit, s.located, s.family
    if df <= 0:
        return Rejection(effect=best.effect, reason=(
            "the refit cannot fix its parameters: a change of its typical size moves the chi2 by less than the "
            f"noise does, so the score implies ~{best.implied_multiple:.3g}x its typical size"),
            kind="not determined by the data"), None, None
    if "not converged" in new.status:
        return Rejection(effect=best.effect, reason=f"the refit did not converge: {new.result_message}",
                         kind="refit did not converge"), None, None
    if p_lr >= alpha:
        return Rejection(effect=best.effect, reason=f"likelihood-ratio p = {p_lr:.3g} >= alpha: the refit does not "
                                      "confirm what the score promised", kind="refit rejects it"), None, None
    located_after = s.located_at(new, alpha)  # what the refit leaves, for the encompassing test and the rival
    beyond = encompassing_guard(fit, new, best.effect, located, df_total, alpha, located_after)
    if beyond is not None:
        return Rejection(effect=best.effect, reason=beyond, kind="not its shape"), None, None
    recorded = record_guard(fit, new, best.effect, tier)
    if recorded is not None:
        return Rejection(effect=best.effect, reason=recorded, kind="contradicted by drive_freq_hz"), None, None
    against, rival_alike = rival_guard(fit, new, best.effect, df_total, located, alpha=alpha,
                                       located_after=located_after)
    if against is not None:
        return Rejection(effect=best.effect, reason=against[0], kind=against[1]), None, rival_alike
    family.append(selection_p(p_lr, n_tried))
    q = float(bh_q_values(family)[-1])
    if q >= alpha:
        return Rejection(effect=best.effect, reason=(
            f"false-discovery control: the refit's p = {p_lr:.3g}, as the best of {n_tried} candidates "
            f"{family[-1]:.3g}, has q = {q:.3g} >= alpha over the {len(family)} refits of this diagnosis"),
            kind="not significant under false-discovery control"), q, rival_alike
    at_noise = not comparison(fit).fails and not located.locations
    if at_noise and delta_bic >= 0:
        return Rejection(effect=best.effect, reason=(
            f"the model before it already describes the data at the noise level, and the information "
            f"criterion does not prefer it (delta BIC {delta_bic:+.3g}; LR p = {p_lr:.2g})"),
            kind="not preferred at the noise level"), q, rival_alike
    # the misfit beside the candidate, already there before its refit: what the refit moves of it is not evidence
    held = misfit_beside(fit, np.asarray(fit.jacobian)[:, :, effect_columns(fit, best.effect)], located, alpha)
    worse = contradictions(fit, new, alpha, df_total, held=held)
    if worse:
        sweeps = tuple(s for s, _, _, _ in worse)
        return Rejection(effect=best.effect, reason="contradicted by " + "; ".join(
            f"{s} (its misfit rose from chi2 {a:.4g} to {b:.4g} over {n} points)" for s, a, b, n in worse),
            contradicted_by=sweeps, kind="contradicted by " + ", ".join(sweeps)), q, rival_alike
    created = new_structure(comparison(fit), comparison(new), alpha, held=(fit, new, held))
    if created:
        sweeps = tuple(dict.fromkeys(f.sweep for f in created))
        return Rejection(effect=best.effect, reason="contradicted by " + "; ".join(
            f"{f.label} (p = {f.p_value:.2g} after the refit, absent before it: {f.meaning})" for f in created)
            + ": a real effect, fitted, leaves no new structure in a sweep's residuals",
            contradicted_by=sweeps, kind="contradicted by " + ", ".join(sweeps)), q, rival_alike
    return None, q, rival_alike


def _final_discrepancy(s: _Selection, final_scores, max_typical_multiple, alpha):
    """What is left at the final fit, with the library's shapes, a closed-form formula along its coordinate
    (which then names the coordinate) and the misfit's size as the term's coefficient: (discrepancy, formula)."""
    fit = s.fit
    located = s.located_at(fit, alpha, pooled=True)  # the baseline's, computed once, when nothing was confirmed
    discrepancy = with_shapes(fit, located.locations, s.discrepancy, s.designs, final_scores, s.rejected,
                              max_typical_multiple, alpha)
    # a single point off the model (an outlier) has no closed form in the recorded coordinates to propose
    formula = propose_along(fit, discrepancy[0], step_at=located.step_at, periods=located.periods, alpha=alpha) \
        if discrepancy and getattr(discrepancy[0], "family", "") != "single point" else None
    along = formula_coordinate(formula)
    if along is not None and along != discrepancy[0].coordinate and along != "model":
        # a closed form of one coordinate that explains the whole location (fewer degrees of freedom than the
        # flexible description) names its coordinate; the flexible one is said to describe it as well
        top = discrepancy[0]
        terms = " + ".join(dict.fromkeys(t.name for t in formula.terms)) if formula is not None else along
        discrepancy = (dataclasses.replace(top, coordinate=along, shape=f"{terms} ({top.shape})",
                                           confounded_with=tuple(
            dict.fromkeys((top.coordinate, *(c for c in top.confounded_with if c != along))))),) + discrepancy[1:]
    # the size as the term's coefficient, unless a generic shape (in physical units) already gives it
    size = term_size(formula, discrepancy[0]) if discrepancy and not discrepancy[0].probe else None
    if size is not None:  # the misfit's size as the term's coefficient, where one term of its coordinate has it
        discrepancy = (dataclasses.replace(discrepancy[0], size=size),) + discrepancy[1:]
    return discrepancy, formula
