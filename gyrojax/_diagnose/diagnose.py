"""`diagnose`: the baseline fit with every candidate at zero, then score, guard, refit and confirm one effect
at a time until no candidate is significant."""

import dataclasses
import math

import numpy as np

from .._data.table import Table
from .._identify import Fit, MultiStart, identify
from .._model.fitdata import fit_data
from .._model.parameters import DEFAULT_FREE, as_model
from .._numerics.stats import chi2_sf
from .._plugins import nonfinite_effect
from .._progress import as_progress
from .candidates import baseline_fit, baseline_model, candidate_effects, first_device, is_lot
from .columns import effect_columns
from .compare import compare, nonlinearity_residual_ppm
from .discrepancy import look_alikes, score_probes, with_shapes
from .encompass import encompassing_guard
from .fdr import bh_q_values, selection_p
from .formula import formula_coordinate, propose_along, term_size
from .guards import MAX_TYPICAL_MULTIPLE, Rejection, contradictions, probe_guard, verdict_of
from .locate import locate
from .probes import PROBES
from .rival import rival_guard
from .score import cosine, score_candidates, separating_sweep
from .solution import Diagnosis, Step


def diagnose(data, model="paper-qmg", *, candidates=None, free=DEFAULT_FREE, alpha: float = 0.01,
             max_effects: int = 4, ambiguity: float = 0.95, min_typical_chi2: float = 1.0,
             max_typical_multiple: float = MAX_TYPICAL_MULTIPLE, probes=PROBES, start: MultiStart = MultiStart(),
             fit: Fit | None = None, progress=True) -> Diagnosis:
    r"""Compare `model` with `data`, rank every candidate effect, add the significant ones one at a time, and
    say where what is left lives.

    **Arguments:**

    - `data`: a `gyrojax.Table` (or `FitData`) of any sweeps.
    - `model`: the baseline: a preset name, a `Gyroscope`, or a `gyrojax.Model` (its effects stay in).
    - `candidates`: effect names to consider (default: every registered effect the device supports).
    - `free`: baseline physical parameters free per device (see `gyrojax.identify`).
    - `alpha`: family-wise significance per step, in (0, 0.5]; a candidate must reach p < alpha /
      n_candidates in the score test and p < alpha in the likelihood-ratio test after its refit.
    - `max_effects`: stop after this many (0: only rank the candidates at the baseline, no refit).
    - `ambiguity`: |cos| between fingerprints above which two candidates are reported as ambiguous.
    - `min_typical_chi2`: a candidate whose typical-size fingerprint, after the baseline took up what it
      could, changes the lot's chi2 by less than this is not testable on this data, whatever its p-value
      (`gyrojax.plan` applies the same rule, `gyrojax/_numerics/testability.py`).
    - `max_typical_multiple`: a candidate whose score implies a size beyond this many times its typical
      size is not confirmed (the reason says so).
    - `probes`: the generic shapes scored beside the candidates (`gyrojax.PROBES`).
    - `start`: the starts of every fit (`gyrojax.MultiStart`, as for `identify`; default one start).
    - `fit`: a `gyrojax.Fit` of this data (from `identify`, or `gyrojax.load_fit`) to use as the baseline
      instead of fitting it again; its model replaces `model`, and its parameters are the refits' start.
    - `progress`: `True` (default) reports each step on standard error (fits, compiles, what was confirmed),
      `False` is silent, a callable receives the messages.

    Guards before a candidate is confirmed: its implied size is plausible; no probe explains the misfit it is
    credited with while it adds nothing beyond that probe; the refit passes the likelihood-ratio test and
    converges; and no sweep's misfit gets significantly worse (else it is "contradicted by" that sweep).

    **Returns:** a `Diagnosis` (with a `verdict`: explained, partly explained or unexplained).
    """
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha <= 0.5):
        raise ValueError(f"alpha must be a significance level in (0, 0.5], got {alpha!r}.")
    if not isinstance(max_effects, int) or isinstance(max_effects, bool) or max_effects < 0:
        raise ValueError(f"max_effects must be an integer >= 0, got {max_effects!r}.")
    if not (isinstance(max_typical_multiple, (int, float)) and max_typical_multiple > 1.0):
        raise ValueError(f"max_typical_multiple must be a number > 1, got {max_typical_multiple!r}.")
    if isinstance(data, Table):
        data = fit_data(data)
    if fit is not None:
        base = baseline_model(fit, data)
    else:
        base = as_model(model)
    candidates = candidate_effects(base, candidates, "diagnose")
    # A candidate that gives the device NaN or infinite values (a user effect's bug) is dropped with a note.
    one = first_device(base.device) if is_lot(base.device) else base.device
    broken = [Rejection(c, f"{why}: dropped from the candidates", kind="non-finite model")
              for c in candidates if (why := nonfinite_effect(c, one)) is not None]
    candidates = tuple(c for c in candidates if c not in {r.effect for r in broken})
    say = as_progress(progress, "gyrojax.diagnose")

    weights = {"data": data, "estimate_noise": None}

    def fit_with(selected):
        held = tuple(c for c in candidates if c not in selected)
        return identify(full, weights["data"], free=free, hold=held, start=start,
                        estimate_noise=weights["estimate_noise"], progress=False)

    if fit is not None:  # the saved fit is the baseline: evaluated where it ended, with the candidates at zero
        say("evaluating the given baseline fit with every candidate at zero")
    full, fit = baseline_fit(base, data, candidates, free=free, start=start, evaluate_only=fit is not None, say=say)
    baseline = fit
    if not data.weighted:
        # The noise was estimated from the baseline's residuals: every refit keeps those weights, so that the
        # likelihood-ratio tests compare fits of the same weighted data.
        weights.update(data=baseline.data, estimate_noise=False)
        say("the data give no output_sigma: every fit uses the noise estimated from the baseline's residuals")
    fits, steps, ambiguous, rejected = [fit], [], [], list(broken)
    ranking0, untestable = None, ()
    selected: list[str] = []
    remaining = list(candidates)
    discrepancy, designs = score_probes(fit, probes, alpha=alpha)
    located = locate(fit, alpha=alpha)
    baseline_discrepancy, baseline_designs, baseline_located = discrepancy, designs, located
    family: list[float] = []  # every refit's selection-corrected p-value, for the false-discovery control
    compared = {}  # id(fit) -> its comparison: each fit of `fits` is compared once, during the steps or at the end

    def comparison(f):
        if id(f) not in compared:
            compared[id(f)] = compare(f, alpha=alpha)
        return compared[id(f)]

    def first_ranking(scores, threshold):
        # one rule (gyrojax._numerics.testability): untestable is what score_candidates marks so, whatever its p-value
        return scores, tuple(c.effect for c in scores if not c.testable)

    if remaining and max_effects == 0:  # rank at the baseline only
        ranking0, untestable = first_ranking(score_candidates(fit, remaining, min_typical_chi2=min_typical_chi2),
                                             alpha / len(remaining))
    while remaining and len(selected) < max_effects:
        scores = score_candidates(fit, remaining, min_typical_chi2=min_typical_chi2)
        threshold = alpha / len(remaining)
        if ranking0 is None:
            ranking0, untestable = first_ranking(scores, threshold)
        significant = [c for c in scores if c.testable and c.p_value < threshold]
        if not significant:
            break
        best = significant[0]
        if best.implied_multiple > max_typical_multiple:
            rejected.append(Rejection(best.effect, (
                f"it explains the misfit only at ~{best.implied_multiple:.3g}x its typical size, beyond "
                f"{max_typical_multiple:g}x, where its physics does not reach: another effect, perhaps not in the "
                "library, leaves a similar fingerprint"),
                kind=f"only at ~{best.implied_multiple:.3g}x its typical size"))
            remaining.remove(best.effect)
            continue
        guard = probe_guard(fit, best, discrepancy, designs, threshold, alpha)
        if guard is not None:
            rejected.append(Rejection(best.effect, guard, kind="not its shape"))
            remaining.remove(best.effect)
            continue
        group = tuple(c.effect for c in significant[1:]
                      if abs(cosine(best.fingerprint, c.fingerprint)) > ambiguity)
        separated = None
        if group:
            others = [c for c in significant if c.effect in group]
            seps = {separating_sweep(best.fingerprint, c.fingerprint, data, ambiguity) for c in others}
            separated = seps.pop() if len(seps) == 1 else None
        say(f"refitting with {best.effect} (step {len(selected) + 1}; score S = {best.statistic:.4g}, "
            f"p = {best.p_value:.2g})")
        n_tried = len(remaining)
        new = fit_with(tuple(selected) + (best.effect,))
        lr = fit.chi2_total - new.chi2_total
        df = int(np.sum(new.free)) - int(np.sum(fit.free))
        df_total = df * len(data.devices)
        p_lr = chi2_sf(lr, df_total)
        n_points = int(np.sum([np.asarray(b.mask).sum() for b in data.blocks.values()]))
        delta_bic = -lr + df_total * math.log(max(n_points, 2))
        remaining.remove(best.effect)
        if df <= 0:
            rejected.append(Rejection(best.effect, (
                "the refit cannot fix its parameters: a change of its typical size moves the chi2 by less than the "
                f"noise does, so the score implies ~{best.implied_multiple:.3g}x its typical size"),
                kind="not determined by the data"))
            continue
        if "not converged" in new.status:
            rejected.append(Rejection(best.effect, f"the refit did not converge: {new.result_message}",
                                      kind="refit did not converge"))
            continue
        if p_lr >= alpha:
            rejected.append(Rejection(best.effect, f"likelihood-ratio p = {p_lr:.3g} >= alpha: the refit does not "
                                                   "confirm what the score promised", kind="refit rejects it"))
            continue
        beyond = encompassing_guard(fit, new, best.effect, located, df_total, alpha)
        if beyond is not None:
            rejected.append(Rejection(best.effect, beyond, kind="not its shape"))
            continue
        against, rival_alike = rival_guard(fit, new, best.effect, df_total, located, alpha=alpha)
        if against is not None:
            rejected.append(Rejection(best.effect, against, kind="a closed form of another shape as good"))
            continue
        family.append(selection_p(p_lr, n_tried))
        q = float(bh_q_values(family)[-1])
        if q >= alpha:
            rejected.append(Rejection(best.effect, (
                f"false-discovery control: the refit's p = {p_lr:.3g}, as the best of {n_tried} candidates "
                f"{family[-1]:.3g}, has q = {q:.3g} >= alpha over the {len(family)} refits of this diagnosis"),
                kind="not significant under false-discovery control"))
            continue
        at_noise = not comparison(fit).fails and not located.locations
        if at_noise and delta_bic >= 0:
            rejected.append(Rejection(best.effect, (
                f"the model before it already describes the data at the noise level, and the information "
                f"criterion does not prefer it (delta BIC {delta_bic:+.3g}; LR p = {p_lr:.2g})"),
                kind="not preferred at the noise level"))
            continue
        worse = contradictions(fit, new, alpha, df_total)
        if worse:
            rejected.append(Rejection(best.effect, "contradicted by " + "; ".join(
                f"{s} (its misfit rose from chi2 {a:.4g} to {b:.4g} over {n} points)" for s, a, b, n in worse),
                tuple(s for s, _, _, _ in worse), kind="contradicted by " + ", ".join(s for s, _, _, _ in worse)))
            continue
        if group:
            ambiguous.append((best.effect,) + group)
        selected.append(best.effect)
        alike = look_alikes(fit, best.effect, discrepancy, designs, alpha) + (
            (rival_alike,) if rival_alike is not None else ())
        fit = new
        fits.append(fit)
        cols = effect_columns(fit, best.effect)
        multiple = float(np.max(np.abs(np.asarray(fit.u)[:, cols])))
        steps.append(Step(best.effect, best.statistic, best.p_value, lr, df_total, p_lr, delta_bic,
                          fit.chi2_red_total, nonlinearity_residual_ppm(fit), scores, group, separated, multiple,
                          best.implied_multiple, look_alikes=alike, q_value=q))
        discrepancy, designs = score_probes(fit, probes, alpha=alpha)
        located = locate(fit, alpha=alpha)
    if ranking0 is None:
        ranking0 = ()
    # Which library effect has the shape of what is left: every candidate not selected, at the final fit.
    others = [c for c in candidates if c not in selected]
    final_scores = score_candidates(fit, others, min_typical_chi2=min_typical_chi2) if others else ()
    baseline_discrepancy = with_shapes(baseline, baseline_located.locations, baseline_discrepancy, baseline_designs,
                                       ranking0, rejected, max_typical_multiple, alpha)
    discrepancy = with_shapes(fit, located.locations, discrepancy, designs, final_scores, rejected,
                              max_typical_multiple, alpha)
    formula = propose_along(fit, discrepancy[0], step_at=located.step_at, period=located.period, alpha=alpha) \
        if discrepancy else None
    along = formula_coordinate(formula)
    if along is not None and along != discrepancy[0].coordinate and along != "model":
        # a closed form of one coordinate that explains the whole location (fewer degrees of freedom than the
        # flexible description) names its coordinate; the flexible one is said to describe it as well
        top = discrepancy[0]
        discrepancy = (dataclasses.replace(top, coordinate=along, confounded_with=tuple(
            dict.fromkeys((top.coordinate, *(c for c in top.confounded_with if c != along))))),) + discrepancy[1:]
    # the size as the term's coefficient, unless a generic shape (in physical units) already gives it
    size = term_size(formula, discrepancy[0]) if discrepancy and not discrepancy[0].probe else None
    if size is not None:  # the misfit's size as the term's coefficient, where one term of its coordinate has it
        discrepancy = (dataclasses.replace(discrepancy[0], size=size),) + discrepancy[1:]
    comparisons = tuple(comparison(f) for f in fits)
    verdict = verdict_of(comparisons[-1], steps)
    if verdict == "explained" and discrepancy:  # a located misfit is a failure the omnibus test missed
        verdict = "partly explained" if steps else "unexplained"
    say(f"done: {verdict}; selected {', '.join(selected) or 'none'}")
    return Diagnosis(baseline, fit, tuple(fits), ranking0, tuple(steps), tuple(ambiguous), untestable,
                     tuple(rejected), alpha, nonlinearity_residual_ppm(baseline), min_typical_chi2, comparisons,
                     baseline_discrepancy, discrepancy, verdict, max_typical_multiple, formula=formula,
                     notes=located.notes)
