r"""`diagnose`: see where a model fails, learn which physical effect is missing, add it, watch the error fall.

Every candidate effect is in the model from the start, nested at zero and held there, so the baseline fit
already carries the Jacobian of the residuals with respect to every candidate's parameters (one compiled
model for the whole loop). At a fitted model, a candidate with parameters psi is ranked by the score
(Lagrange-multiplier) test, per device d and summed over the lot:

    J_e' = (I - P_b) J_e,   s = J_e'^T r,   S = sum_d s^T (J_e'^T J_e')^+ s  ~  chi2(sum_d rank)

where r are the standardised residuals, J_b the Jacobian of the free baseline parameters (P_b its
projector: what the baseline could already absorb is removed) and J_e that of the candidate. The predicted
residual change J_e' (J_e'^T J_e')^+ s is the candidate's fingerprint on this data. Effect parameters are
in units of their typical size, so the largest eigenvalue of J_e'^T J_e', summed over devices, is the chi2
that the most visible typical-size combination of the candidate would leave after the baseline took up what
it could (`typical_chi2`). A candidate whose projected Jacobian is empty, or whose `typical_chi2` is below
`min_typical_chi2` (a typical-size effect changes the lot's chi2 by less than the noise does) while its
score is not significant, is reported as not testable (the baseline absorbs it, or this data cannot see
it at a plausible size); it stays in the ranking and is still selected if significant. The best candidate with p below
alpha / (number of candidates) is refitted; the likelihood-ratio test
(chi2 drop ~ chi2(df)) and BIC confirm it, and the loop repeats until no candidate is significant.
Significant candidates whose fingerprints are nearly collinear (|cos| > `ambiguity`) are reported together,
with the sweep of the data on which their fingerprints differ most, if any.
"""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._compare import chi2_sf, compare, nonlinearity_residual_ppm
from ._data.table import Table
from ._effects.registry import EFFECTS
from ._fitdata import FitData, fit_data
from ._identify import Fit, MultiStart, identify
from ._parameters import DEFAULT_FREE, Model, as_model, zero_effect
from ._probes import PROBES, design, score_columns
from ._progress import as_progress


# ASSUMPTION: each effect's `typical(1.0)` is a realistic size with a provenance; a device more than 20 times
# worse than that is outside what the library's sources support.
IMPLAUSIBLE_MULTIPLE = 20.0

# ASSUMPTION: beyond 100 times its typical size an effect is not physical any more (a 16-bit DAC's INL at
# 100x is ~5 % of full scale, a damping coupling at 100x breaks passivity on paper-qmg): a candidate that
# explains the misfit only there is not confirmed.
MAX_TYPICAL_MULTIPLE = 100.0

# Two fingerprints with |cos| above this describe the same residual shape on this data.
SAME_SHAPE = 0.9

# A candidate "has" a residual shape when the shape, beyond the baseline and the candidate, keeps less than this
# share of the chi2 it explains alone. Not a significance test: at a misfit of 1e7 chi2 every difference between
# two shapes is significant, and the candidate's Jacobian is taken at the baseline, not at the truth, so even
# the right effect leaves a few percent (3.7 % for the demo lot's hidden DAC INL, which its refit then explains
# to the noise).
SHAPE_SHARE_LEFT = 0.1


def chi2_isf(p: float, df: int) -> float:
    """The chi2 value whose survival probability is `p` (bisection on `chi2_sf`)."""
    if df <= 0:
        return 0.0
    lo, hi = 0.0, max(10.0 * df, 100.0)
    while chi2_sf(hi, df) > p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_sf(mid, df) > p else (lo, mid)
    return 0.5 * (lo + hi)


@dataclasses.dataclass(frozen=True)
class CandidateScore:
    """One candidate effect scored against a fitted model (no refit)."""

    effect: str
    statistic: float
    df: int
    p_value: float
    testable: bool
    fingerprint: np.ndarray  # (device, residual): predicted residual change
    description: str
    typical_chi2: float = 0.0  # chi2 left by the most visible typical-size combination, summed over devices
    # The same before the baseline's free parameters take their share (after the run biases), and the free
    # parameters that take it: what hides the candidate when it is not testable.
    visible_chi2: float = 0.0
    absorbed_by: tuple = ()

    @property
    def implied_multiple(self) -> float:
        """The size, in units of its typical size, at which the candidate would explain what its score
        credits it with: sqrt(S / typical_chi2) (its most visible combination)."""
        if self.typical_chi2 <= 0:
            return math.inf
        return math.sqrt(max(self.statistic, 0.0) / self.typical_chi2)

    @property
    def absorption(self) -> str:
        """Why the data cannot test it, in words: what takes up its fingerprint, and what would reveal it."""
        if self.visible_chi2 < 1.0:
            what = (f"a typical size changes the chi2 by {self.visible_chi2:.2g} once the run biases are "
                    "out: the run biases take it up, or this data barely sees it")
        else:
            share = 1.0 - self.typical_chi2 / self.visible_chi2
            who = ", ".join(self.absorbed_by) or "the free parameters together"
            what = (f"a typical size would change the chi2 by {self.visible_chi2:.3g}; {who} "
                    f"{'absorbs' if len(self.absorbed_by) == 1 else 'absorb'} {100 * share:.4g} % of it, "
                    f"leaving {self.typical_chi2:.2g}")
        reveal = EFFECTS[self.effect].revealed_by
        return what + (f". Revealed by: {reveal}" if reveal else "")


@dataclasses.dataclass(frozen=True)
class Discrepancy:
    """Where an unexplained misfit lives: a generic shape (a probe) along a recorded coordinate, with the share
    of the misfit it explains and the size of the term it implies."""

    probe: str
    coordinate: str  # a data column (input, temperature_c, time_s, drive_freq_hz), "order" or "run"
    shape: str
    sweeps: tuple  # (sweep, share of the probe's fingerprint) where it acts on this data, largest first
    chi2_explained: float  # the score S: the chi2 it would remove
    df: int
    share: float  # of the chi2 in excess of the degrees of freedom
    p_value: float
    significant: bool
    coefficient: float  # the lot's mean fitted coefficient (largest |.| for a multi-column probe), in `unit`
    coefficient_spread: float  # standard deviation over the devices
    unit: str
    fingerprint: np.ndarray
    same_shape_as: tuple = ()  # other significant probes this data cannot tell from it
    library: str = ""  # which library effect has this fingerprint, and at what size
    within: str = ""  # a more explanatory probe this one adds nothing beyond (it is part of that misfit)

    @property
    def description(self) -> str:
        where = ", ".join(f"{s} {100 * f:.0f} %" for s, f in self.sweeps)
        size = f"{self.coefficient:.3g} {self.unit}"
        if self.coefficient_spread > 0:
            size += f" (device spread {self.coefficient_spread:.2g})"
        text = f"{100 * self.share:.0f} % of the misfit is {self.shape} ({where}): about {size}"
        if self.same_shape_as:
            text += f"; this data cannot tell it from {', '.join(self.same_shape_as)}"
        return text + (f"; {self.library}" if self.library else "")

    def to_json(self) -> dict:
        return {"coordinate": self.coordinate, "shape": self.shape, "sweeps": [s for s, _ in self.sweeps],
                "chi2_explained": self.chi2_explained, "share": self.share, "p": self.p_value,
                "description": self.description, "probe": self.probe, "df": self.df,
                "coefficient": self.coefficient, "coefficient_spread": self.coefficient_spread, "unit": self.unit,
                "same_shape_as": list(self.same_shape_as), "within": self.within, "library": self.library}


@dataclasses.dataclass(frozen=True)
class Rejection:
    """A candidate that scored but was not confirmed, and why (in physical words)."""

    effect: str
    reason: str
    contradicted_by: tuple = ()  # sweeps whose misfit the refit made significantly worse
    kind: str = ""  # the reason in two words: "implausible size", "not its shape", "contradicted", ...


@dataclasses.dataclass(frozen=True)
class Step:
    """One accepted effect: its score at selection, the refit's likelihood-ratio test and chi2 after."""

    effect: str
    statistic: float
    p_value: float
    lr_statistic: float
    lr_df: int
    lr_p_value: float
    delta_bic: float
    chi2_red_after: float
    nonlinearity_ppm_after: float
    ranking: tuple
    ambiguous_with: tuple
    separated_by: str | None
    # Largest fitted parameter of the effect over the lot, in units of its typical size: far above 1, the
    # effect explains the data only at an implausible size (another effect may leave this fingerprint).
    typical_multiple: float = float("nan")
    implied_multiple: float = float("nan")  # at the score stage, before the refit
    contradicted_by: tuple = ()  # sweeps whose misfit the step made significantly worse (none when accepted)


VERDICTS = ("explained", "partly explained", "unexplained")


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """The solution of `diagnose`: the baseline fit, the ranking at the first step, the accepted steps, the
    final fit, what was ambiguous, untestable or rejected, where the misfit that is left lives, and a
    verdict."""

    baseline: Fit
    final: Fit
    fits: tuple  # baseline, then the fit after each step
    ranking: tuple  # CandidateScore at the first step, best first
    steps: tuple  # Step per accepted effect
    ambiguous: tuple  # groups of names
    untestable: tuple  # names not testable on this data at the first step
    rejected: tuple  # Rejection per candidate that scored but was not confirmed
    alpha: float
    baseline_nonlinearity_ppm: float
    min_typical_chi2: float = 1.0
    comparisons: tuple = ()  # `Comparison` of each fit in `fits`: where it fails, structure in its residuals
    baseline_discrepancy: tuple = ()  # Discrepancy per probe at the baseline, most explanatory first
    discrepancy: tuple = ()  # the same at the final fit: where what is left lives
    verdict: str = "unexplained"
    max_typical_multiple: float = MAX_TYPICAL_MULTIPLE

    @property
    def selected(self) -> tuple[str, ...]:
        return tuple(s.effect for s in self.steps)

    @property
    def absorptions(self) -> dict:
        """Each untestable candidate: what hid it on this data and what would reveal it, in words."""
        scores = {c.effect: c for c in self.ranking}
        return {name: scores[name].absorption for name in self.untestable}

    @property
    def remaining(self) -> tuple:
        """The significant discrepancies of the final fit, most explanatory first (a shape that is only part of
        a more explanatory one is left out)."""
        return tuple(d for d in self.discrepancy if d.significant and not d.within)

    def verdict_text(self) -> str:
        final = self.comparisons[-1] if self.comparisons else None
        tail = (f" (chi2 {final.chi2:.4g} over {final.points} points, p = {final.p_value:.2g})"
                if final is not None else "")
        if self.verdict == "explained":
            what = (f"{', '.join(self.selected)} explain" if self.steps else "the baseline explains")
            return f"verdict: explained: {what} the data at the noise level{tail}"
        left = self.remaining
        where = (f"; what is left: {left[0].description}" if left else
                 "; no generic shape (bias or gain in temperature, time, run; cubics; bow; K+/K-) explains what "
                 "is left: see where the model fails")
        if self.verdict == "partly explained":
            base = max(self.baseline.chi2_total - self.baseline.dof_total, 1e-300)
            gone = (self.baseline.chi2_total - self.final.chi2_total) / base
            return (f"verdict: partly explained: {', '.join(self.selected)} take {100 * min(gone, 1.0):.0f} % of "
                    f"the baseline's excess misfit, but the model still fails{tail}{where}")
        return f"verdict: unexplained: no library effect is confirmed and the model fails{tail}{where}"

    def summary(self, comparisons: bool = True) -> str:
        """A few dozen lines for a terminal; `comparisons=False` leaves out the `compare` blocks of the baseline
        and the final fit."""
        lines = [f"baseline: chi2_red {self.baseline.chi2_red_total:.3f}, model-vs-measurement nonlinearity "
                 f"{self.baseline_nonlinearity_ppm:.2f} ppm"]
        if self.comparisons and comparisons:
            lines += ["  " + x for x in self.comparisons[0].summary().splitlines()]
        found = [d for d in self.baseline_discrepancy if d.significant and not d.within]
        if found:
            lines.append("where the misfit lives (generic shapes, score test, no refit):")
            lines += [f"  {d.coordinate:<14} {d.description} (S = {d.chi2_explained:.4g}, p = {d.p_value:.2g})"
                      for d in found[:4]]
        lines.append("candidates at the first step (score test, no refit):")
        for c in self.ranking:
            what = (f"S = {c.statistic:10.2f}  df {c.df:3d}  p = {c.p_value:.3g}  typical-size chi2 "
                    f"{c.typical_chi2:.3g}, implies ~{c.implied_multiple:.3g}x typical" if c.testable
                    else "not testable on this data")
            lines.append(f"  {c.effect:<18} {what}")
        if self.untestable:
            lines.append(f"not testable on this data (absorbed by the baseline, or a typical-size effect leaves a "
                         f"chi2 below {self.min_typical_chi2:g}):")
            lines += [f"  {name}: {why}" for name, why in self.absorptions.items()]
        for s in self.steps:
            amb = f" (ambiguous with {', '.join(s.ambiguous_with)}" + (
                f"; {s.separated_by} separates them)" if s.separated_by else "; no sweep here separates them)") \
                if s.ambiguous_with else ""
            lines.append(f"+ {s.effect}: LR {s.lr_statistic:.1f} (df {s.lr_df}, p {s.lr_p_value:.2g}), dBIC "
                         f"{s.delta_bic:.1f} -> chi2_red {s.chi2_red_after:.3f}, nonlinearity residual "
                         f"{s.nonlinearity_ppm_after:.2f} ppm{amb}; fitted at {s.typical_multiple:.3g}x its "
                         "typical size")
            if s.typical_multiple > IMPLAUSIBLE_MULTIPLE:
                lines.append(f"  ! {s.effect} explains the data only at {s.typical_multiple:.3g}x its typical size "
                             "(beyond the library's plausible range): another effect, perhaps not among the "
                             "candidates, may leave this fingerprint; see where the model still fails")
        if not self.steps:
            lines.append("no candidate effect is confirmed." if self.rejected else
                         "no candidate effect is significant.")
        for r in self.rejected:
            lines.append(f"  not confirmed: {r.effect}: {r.reason}")
        lines.append(f"final: chi2_red {self.final.chi2_red_total:.3f}, selected: {', '.join(self.selected) or 'none'}")
        if self.steps and self.comparisons and comparisons:
            lines += ["  " + x for x in self.comparisons[-1].summary().splitlines()]
        lines.append(self.verdict_text())
        return "\n".join(lines)

    def write_report(self, out_dir) -> dict:
        """The report folder (Markdown, JSON, PNG plots) of `write_report`; returns the JSON."""
        return write_report(self, out_dir)

    def to_json(self) -> dict:
        """The diagnosis as JSON: baseline, ranking, steps, selected, ambiguous, untestable, rejected, final,
        verdict, discrepancy (what is left, most explanatory first), baseline_discrepancy, compare."""
        return {
            "baseline": {"chi2_red": self.baseline.chi2_red_total,
                         "nonlinearity_ppm": self.baseline_nonlinearity_ppm},
            "ranking": [{"effect": c.effect, "statistic": c.statistic, "df": c.df, "p_value": c.p_value,
                         "testable": c.testable, "typical_chi2": c.typical_chi2, "visible_chi2": c.visible_chi2,
                         "implied_multiple": _finite(c.implied_multiple),
                         "absorbed_by": list(c.absorbed_by), "revealed_by": EFFECTS[c.effect].revealed_by}
                        for c in self.ranking],
            "steps": [{"effect": s.effect, "statistic": s.statistic, "p_value": s.p_value,
                       "chi2_red_after": s.chi2_red_after, "lr_statistic": s.lr_statistic, "lr_df": s.lr_df,
                       "lr_p_value": s.lr_p_value, "delta_bic": s.delta_bic,
                       "nonlinearity_ppm_after": s.nonlinearity_ppm_after,
                       "ambiguous_with": list(s.ambiguous_with), "separated_by": s.separated_by,
                       "typical_multiple": s.typical_multiple, "implied_multiple": _finite(s.implied_multiple),
                       "contradicted_by": list(s.contradicted_by)}
                      for s in self.steps],
            "selected": list(self.selected),
            "ambiguous": [list(g) for g in self.ambiguous],
            "untestable": list(self.untestable),
            "rejected": [{"effect": r.effect, "reason": r.reason, "contradicted_by": list(r.contradicted_by)}
                         for r in self.rejected],
            "final": {"chi2_red": self.final.chi2_red_total,
                      "nonlinearity_ppm": nonlinearity_residual_ppm(self.final)},
            "verdict": self.verdict,
            "verdict_text": self.verdict_text(),
            "discrepancy": [d.to_json() for d in self.remaining],
            "baseline_discrepancy": [d.to_json() for d in self.baseline_discrepancy if d.significant and not d.within],
            "compare": [c.to_json() for c in self.comparisons],
        }


def _finite(x):
    return float(x) if math.isfinite(x) else None


def _row_blocks(data: FitData):
    """(sweep, start, stop) of each sweep's rows in a device's residual vector."""
    out, k = [], 0
    for sweep in data.sweeps:
        shape = data.blocks[sweep].inputs.shape
        n = int(shape[1] * shape[2])
        out.append((sweep, k, k + n))
        k += n
    return out


def _effect_columns(fit: Fit, name: str) -> np.ndarray:
    return np.asarray([i for i, nm in enumerate(fit.names) if nm.startswith(name + ".")], dtype=int)


def _base_columns(fit: Fit) -> np.ndarray:
    """The free columns of the fit's Jacobian (device, residual, free): what it could already absorb."""
    return np.asarray(fit.jacobian)[:, :, np.asarray(fit.free)]


def score_candidates(fit: Fit, candidates, *, rank_tol: float = 1e-4) -> tuple[CandidateScore, ...]:
    """Score test of each candidate (effect name held at zero in `fit.model`) against the fitted model."""
    jac = np.asarray(fit.jacobian)
    res = np.asarray(fit.residual_vector)
    free = np.asarray(fit.free)
    names_free = [nm for nm, f in zip(fit.names, free) if f]
    out = []
    for name in candidates:
        cols = _effect_columns(fit, name)
        visible = 0.0
        share = np.zeros(len(names_free))  # of the most visible fingerprint's chi2, per free parameter
        for d in range(jac.shape[0]):
            jb, je = jac[d][:, free], jac[d][:, cols]
            if je.shape[1]:
                evals, evecs = np.linalg.eigh(je.T @ je)
                visible += max(float(evals[-1]), 0.0)
                if jb.shape[1]:
                    # |P f|^2 = sum_k c_k (b_k . f) with c the least-squares coefficients of f on the columns
                    f = je @ evecs[:, -1]
                    c = np.linalg.lstsq(jb, f, rcond=None)[0]
                    share += c * (jb.T @ f)
        scored = score_columns(jac[:, :, free], jac[:, :, cols], res, rank_tol=rank_tol)
        order = np.argsort(-share)
        absorbed_by = tuple(names_free[k] for k in order if share[k] > 0.1 * max(np.sum(share), 0.0))
        out.append(CandidateScore(name, scored.statistic, scored.df, scored.p_value, scored.df > 0,
                                  scored.fingerprint, EFFECTS[name].description, scored.information, visible,
                                  absorbed_by))
    return tuple(sorted(out, key=lambda c: (not c.testable, c.p_value, -c.statistic)))


def _cos(a, b):
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return 0.0 if na == 0 or nb == 0 else float(np.sum(a * b) / (na * nb))


def _separating_sweep(a, b, data: FitData, ambiguity):
    best, best_cos = None, ambiguity
    for sweep, i, j in _row_blocks(data):
        c = abs(_cos(a[:, i:j], b[:, i:j]))
        if (np.linalg.norm(a[:, i:j]) > 0 or np.linalg.norm(b[:, i:j]) > 0) and c < best_cos:
            best, best_cos = sweep, c
    return best


def _excess(fit: Fit) -> float:
    return max(fit.chi2_total - fit.dof_total, 0.0)


def _sweep_shares(fingerprint, data: FitData):
    total = float(np.sum(fingerprint**2))
    if total <= 0:
        return ()
    shares = [(sweep, float(np.sum(fingerprint[:, i:j] ** 2)) / total) for sweep, i, j in _row_blocks(data)]
    return tuple(sorted(((s, f) for s, f in shares if f > 0.05), key=lambda x: -x[1]))


def score_probes(fit: Fit, probes=PROBES, *, alpha: float = 0.01):
    """Every probe scored against `fit`: (Discrepancy per probe, most explanatory first; their designs by
    name). A probe is significant at p < alpha / (number of probes the data can test)."""
    base = _base_columns(fit)
    res = np.asarray(fit.residual_vector)
    excess = _excess(fit)
    designs, scored = {}, []
    for probe in probes:
        cols = design(fit, probe)
        if cols.shape[-1] == 0 or not np.any(cols):
            continue
        designs[probe.name] = cols
        scored.append((probe, score_columns(base, cols, res)))
    testable = [x for x in scored if x[1].df > 0]
    cut = alpha / max(len(testable), 1)
    out = []
    for probe, sc in testable:
        coef = sc.coefficients
        mag = coef[:, np.argmax(np.max(np.abs(coef), axis=0))] if coef.shape[1] > 1 else coef[:, 0]
        share = min(max(sc.statistic - sc.df, 0.0) / excess, 1.0) if excess > 0 else 0.0
        out.append(Discrepancy(probe.name, probe.coordinate, probe.shape, _sweep_shares(sc.fingerprint, fit.data),
                               sc.statistic, sc.df, share, sc.p_value, sc.p_value < cut, float(np.mean(mag)),
                               float(np.std(mag)) if len(mag) > 1 else 0.0, probe.unit, sc.fingerprint))
    out.sort(key=lambda d: (not d.significant, -d.chi2_explained))
    # A significant shape that adds nothing beyond a more explanatory one is part of it (a drift in time seen
    # through an input swept in time order); two that add nothing beyond each other are the same shape here.
    within, same = {}, {d.probe: [] for d in out}
    significant = [d for d in out if d.significant]
    for i, d in enumerate(significant):
        for e in significant[:i]:
            if e.probe in within:
                continue
            d_beyond = score_columns(np.concatenate([base, designs[e.probe]], -1), designs[d.probe], res)
            if d_beyond.p_value < cut:
                continue
            e_beyond = score_columns(np.concatenate([base, designs[d.probe]], -1), designs[e.probe], res)
            if e_beyond.p_value < cut:
                within[d.probe] = e.probe
                break
            same[d.probe].append(e.probe)
            same[e.probe].append(d.probe)
    final = tuple(dataclasses.replace(d, same_shape_as=tuple(same[d.probe]), within=within.get(d.probe, ""))
                  for d in out)
    return final, designs


def _with_library(fit, discrepancy, designs, scores, rejected, max_multiple, alpha):
    """The discrepancies with `library` filled in: which candidate takes the whole of a shape's misfit (the
    shape adds nothing beyond it, at the probes' significance), and why it does not explain it (implausible
    size, refused), or that none does."""
    reasons = {r.effect: r.kind or r.reason for r in rejected}
    base = _base_columns(fit)
    res = np.asarray(fit.residual_vector)
    jac = np.asarray(fit.jacobian)
    cut = alpha / max(len(discrepancy), 1)
    out = []
    for d in discrepancy:
        if not d.significant or d.within:
            out.append(d)
            continue
        parts, plausible = [], False
        for c in scores:
            if not c.testable:
                continue
            je = jac[:, :, _effect_columns(fit, c.effect)]
            left = score_columns(np.concatenate([base, je], axis=-1), designs[d.probe], res)
            # the shape leaves misfit this candidate cannot take: significant, and a share of what the shape
            # explained (see SHAPE_SHARE_LEFT)
            if left.p_value < cut and left.statistic > SHAPE_SHARE_LEFT * d.chi2_explained:
                continue
            if c.effect in reasons:
                parts.append(f"{c.effect} has it but was not confirmed ({reasons[c.effect]})")
            elif c.implied_multiple > max_multiple:
                parts.append(f"{c.effect} has it only at ~{c.implied_multiple:.3g}x its typical size")
            else:
                parts.append(f"{c.effect} has it")
                plausible = True
        if not parts:
            text = "no effect in the library has this fingerprint"
        elif not plausible:
            text = "no effect in the library explains it: " + "; ".join(parts)
        else:
            text = "; ".join(parts)
        out.append(dataclasses.replace(d, library=text))
    return tuple(out)


def _probe_guard(fit, candidate: CandidateScore, discrepancy, designs, candidate_cut, alpha):
    """A reason not to confirm `candidate`, or None: a significant probe explains the misfit the candidate is
    credited with, and more (what the probe takes beyond the candidate is significant at alpha over the
    probes), while the candidate adds nothing beyond the probe (not significant at `candidate_cut`)."""
    base = _base_columns(fit)
    res = np.asarray(fit.residual_vector)
    je = np.asarray(fit.jacobian)[:, :, _effect_columns(fit, candidate.effect)]
    probe_cut = alpha / max(len(discrepancy), 1)
    worst = None
    for d in (d for d in discrepancy if d.significant):
        gp = designs[d.probe]
        beyond_probe = score_columns(np.concatenate([base, gp], axis=-1), je, res)
        beyond_candidate = score_columns(np.concatenate([base, je], axis=-1), gp, res)
        if beyond_probe.p_value >= candidate_cut and beyond_candidate.p_value < probe_cut:
            if worst is None or beyond_candidate.statistic > worst[1].statistic:
                worst = (d, beyond_candidate, beyond_probe)
    if worst is None:
        return None
    d, extra, own = worst
    excess = _excess(fit)
    share_c = min(candidate.statistic / excess, 1.0) if excess > 0 else 0.0
    return (f"it would take {100 * share_c:.0f} % of the misfit, whose shape it does not have: {d.shape} "
            f"({', '.join(s for s, _ in d.sweeps)}) explains {100 * d.share:.0f} %, leaves chi2 {extra.statistic:.4g} "
            f"that {candidate.effect} cannot take (p = {extra.p_value:.2g}), and {candidate.effect} adds nothing "
            f"beyond it (S = {own.statistic:.3g}, df {own.df}, p = {own.p_value:.2g})")


def _sweep_chi2(fit: Fit) -> dict:
    return {s: float(np.sum(np.asarray(fit.residuals[s]) ** 2)) for s in fit.data.sweeps}


def _contradictions(before: Fit, after: Fit, alpha: float, df: int):
    """Sweeps whose chi2 the refit raised by more than the (1 - alpha) quantile of chi2(df), df the step's
    new parameters over the lot: a real effect, fitted, does not make a sweep's misfit significantly worse."""
    limit = chi2_isf(alpha, max(df, 1))
    a, b = _sweep_chi2(before), _sweep_chi2(after)
    points = {s: int(np.asarray(before.data.blocks[s].mask).sum()) for s in a}
    return tuple((s, a[s], b[s], points[s]) for s in a if b[s] - a[s] > limit)


def _verdict(comparison, steps) -> str:
    if not comparison.fails and not comparison.flagged:
        return "explained"
    return "partly explained" if steps else "unexplained"


def diagnose(data, model="paper-qmg", *, candidates=None, free=DEFAULT_FREE, alpha: float = 0.01,
             max_effects: int = 4, ambiguity: float = 0.95, min_typical_chi2: float = 1.0,
             max_typical_multiple: float = MAX_TYPICAL_MULTIPLE, probes=PROBES, starts: int = 1,
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
      could, changes the lot's chi2 by less than this (and whose score is not significant) is reported as
      not testable on this data.
    - `max_typical_multiple`: a candidate whose score implies a size beyond this many times its typical
      size is not confirmed (the reason says so).
    - `probes`: the generic shapes scored beside the candidates (`gyrojax.PROBES`).
    - `fit`: a `gyrojax.Fit` of this data (from `identify`, or `gyrojax.load_fit`) to use as the baseline
      instead of fitting it again; its model replaces `model`, and its parameters are the refits' start.
    - `progress`: `True` (default) reports each step on standard error (fits, compiles, what was confirmed),
      `False` is silent, a callable receives the messages.

    Guards before a candidate is confirmed: its implied size is plausible; no probe explains the misfit it is
    credited with while it adds nothing beyond that probe; the refit passes the likelihood-ratio test and
    converges; and no sweep's misfit gets significantly worse (else it is "contradicted by" that sweep).

    **Returns:** a `Diagnosis` (with a `verdict`: explained, partly explained or unexplained).
    """
    from ._effects.registry import supported_effects

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
    device = base.device
    one = device if not is_lot(device) else first_device(device)
    available = supported_effects(one)
    present = set(base.effect_names)
    if candidates is None:
        candidates = tuple(c for c in available if c not in present)
    else:
        candidates = tuple(candidates)
        for c in candidates:
            if c not in EFFECTS:
                raise ValueError(f"unknown candidate effect {c!r}; expected names of gyrojax.EFFECTS: "
                                 f"{', '.join(EFFECTS)}.")
            if c not in available:
                raise ValueError(f"candidate effect {c!r} cannot act on device {one.name!r} "
                                 f"(supported: {', '.join(available)}).")
    if not candidates:
        raise ValueError("diagnose needs at least one candidate effect not already in the model.")
    full = Model(base.device, base.effects + tuple(zero_effect(c) for c in candidates))
    say = as_progress(progress, "gyrojax.diagnose")

    weights = {"data": data, "estimate_noise": None}

    def fit_with(selected, evaluate_only=False):
        held = tuple(c for c in candidates if c not in selected)
        return identify(full, weights["data"], free=free, hold=held, start=MultiStart(starts=starts),
                        evaluate_only=evaluate_only, estimate_noise=weights["estimate_noise"], progress=False)

    if fit is None:
        say(f"fitting the baseline: {len(data.devices)} device(s), {data.num_points()} points, every one of "
            f"{len(candidates)} candidate effects held at zero")
        say.compiling(("identify", full_key(full, data)), "the lot's fit with every candidate")
        fit = fit_with(())
    else:  # the saved fit is the baseline: evaluated where it ended, with the candidates at zero
        say("evaluating the given baseline fit with every candidate at zero")
        fit = fit_with((), evaluate_only=True)
    baseline = fit
    if not data.weighted:
        # The noise was estimated from the baseline's residuals: every refit keeps those weights, so that the
        # likelihood-ratio tests compare fits of the same weighted data.
        weights.update(data=baseline.data, estimate_noise=False)
        say("the data give no output_sigma: every fit uses the noise estimated from the baseline's residuals")
    fits, steps, ambiguous, rejected = [fit], [], [], []
    ranking0, untestable = None, ()
    selected: list[str] = []
    remaining = list(candidates)
    discrepancy, designs = score_probes(fit, probes, alpha=alpha)
    baseline_discrepancy, baseline_designs = discrepancy, designs
    def first_ranking(scores, threshold):
        return scores, tuple(c.effect for c in scores if not c.testable or (
            c.typical_chi2 < min_typical_chi2 and c.p_value >= threshold))

    if remaining and max_effects == 0:  # rank at the baseline only
        ranking0, untestable = first_ranking(score_candidates(fit, remaining), alpha / len(remaining))
    while remaining and len(selected) < max_effects:
        scores = score_candidates(fit, remaining)
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
        guard = _probe_guard(fit, best, discrepancy, designs, threshold, alpha)
        if guard is not None:
            rejected.append(Rejection(best.effect, guard, kind="not its shape"))
            remaining.remove(best.effect)
            continue
        group = tuple(c.effect for c in significant[1:]
                      if abs(_cos(best.fingerprint, c.fingerprint)) > ambiguity)
        separated = None
        if group:
            others = [c for c in significant if c.effect in group]
            seps = {_separating_sweep(best.fingerprint, c.fingerprint, data, ambiguity) for c in others}
            separated = seps.pop() if len(seps) == 1 else None
        say(f"refitting with {best.effect} (step {len(selected) + 1}; score S = {best.statistic:.4g}, "
            f"p = {best.p_value:.2g})")
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
        worse = _contradictions(fit, new, alpha, df_total)
        if worse:
            rejected.append(Rejection(best.effect, "contradicted by " + "; ".join(
                f"{s} (its misfit rose from chi2 {a:.4g} to {b:.4g} over {n} points)" for s, a, b, n in worse),
                tuple(s for s, _, _, _ in worse), kind="contradicted by " + ", ".join(s for s, _, _, _ in worse)))
            continue
        if group:
            ambiguous.append((best.effect,) + group)
        selected.append(best.effect)
        fit = new
        fits.append(fit)
        cols = _effect_columns(fit, best.effect)
        multiple = float(np.max(np.abs(np.asarray(fit.u)[:, cols])))
        steps.append(Step(best.effect, best.statistic, best.p_value, lr, df_total, p_lr, delta_bic,
                          fit.chi2_red_total, nonlinearity_residual_ppm(fit), scores, group, separated, multiple,
                          best.implied_multiple))
        discrepancy, designs = score_probes(fit, probes, alpha=alpha)
    if ranking0 is None:
        ranking0 = ()
    # Which library effect has the shape of what is left: every candidate not selected, at the final fit.
    others = [c for c in candidates if c not in selected]
    final_scores = score_candidates(fit, others) if others else ()
    baseline_discrepancy = _with_library(baseline, baseline_discrepancy, baseline_designs, ranking0, rejected,
                                         max_typical_multiple, alpha)
    discrepancy = _with_library(fit, discrepancy, designs, final_scores, rejected, max_typical_multiple, alpha)
    comparisons = tuple(compare(f, alpha=alpha) for f in fits)
    say(f"done: {_verdict(comparisons[-1], steps)}; selected {', '.join(selected) or 'none'}")
    return Diagnosis(baseline, fit, tuple(fits), ranking0, tuple(steps), tuple(ambiguous), untestable,
                     tuple(rejected), alpha, nonlinearity_residual_ppm(baseline), min_typical_chi2, comparisons,
                     baseline_discrepancy, discrepancy, _verdict(comparisons[-1], steps), max_typical_multiple)


def full_key(model: Model, data: FitData):
    """What decides whether a fit of `model` to `data` compiles anew: the model's structure and the data's
    shapes."""
    shapes = tuple((s, tuple(np.shape(data.blocks[s].inputs))) for s in data.sweeps)
    return jax.tree.structure(eqx.filter(model, eqx.is_array)), shapes


def baseline_model(fit: Fit, data: FitData) -> Model:
    """The fitted model of `fit` as the diagnosis's baseline, after checking that it was fitted to `data`."""
    if not isinstance(fit, Fit):
        raise TypeError(f"fit must be a gyrojax.Fit (from identify or load_fit), got {type(fit).__name__}.")
    if tuple(fit.devices) != tuple(data.devices):
        raise ValueError(f"fit: it was fitted to devices {list(fit.devices)}, the data have {list(data.devices)}; "
                         "give the fit of this data (or no fit, to fit the baseline here).")
    theirs = {s: int(np.asarray(fit.data.blocks[s].mask).sum()) for s in fit.data.sweeps}
    ours = {s: int(np.asarray(data.blocks[s].mask).sum()) for s in data.sweeps}
    if theirs != ours:
        raise ValueError(f"fit: it was fitted to {theirs} points per sweep, the data have {ours}; give the fit of "
                         "this data (or no fit, to fit the baseline here).")
    # Effects held at exactly zero (a previous diagnosis's candidates) were never fitted: candidates again.
    kept = tuple(e for e in fit.model.effects
                 if any(np.any(np.asarray(x) != 0) for x in jax.tree.leaves(e)))
    return Model(fit.model.device, kept)


def is_lot(device) -> bool:
    """Whether `device` is a lot: every array leaf has a leading device axis."""
    leaves = [x for x in jax.tree.leaves(device) if eqx.is_array(x)]
    return bool(leaves) and all(jnp.ndim(x) >= 1 for x in leaves)


def first_device(device):
    """The first device of a lot (leaves indexed at 0 on their device axis)."""
    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, device)


def write_report(diagnosis: Diagnosis, out_dir) -> dict:
    """A report folder: `diagnosis.md`, `diagnosis.json` and PNG plots (residuals before and after, where the
    misfit lives, the ranking, the fingerprints, the error falling). The folder appears whole or not at all
    (`out_dir` may be new, empty, or a folder gyrojax wrote before, which is replaced). Returns the JSON."""
    import os

    import matplotlib.pyplot as plt

    from . import plot
    from ._io import atomic_directory, atomic_write_bytes, atomic_write_json

    with atomic_directory(out_dir) as folder:
        sweeps = diagnosis.baseline.data.sweeps
        figures = []
        fig, axes = plt.subplots(len(sweeps), 2, figsize=(12, 3.2 * len(sweeps)), squeeze=False)
        for i, sweep in enumerate(sweeps):
            plot.residuals(diagnosis.baseline, sweep, ax=axes[i, 0])
            axes[i, 0].set_title(f"baseline {sweep}: chi2_red {diagnosis.baseline.chi2_red_total:.3g}", fontsize=9)
            plot.residuals(diagnosis.final, sweep, ax=axes[i, 1])
            axes[i, 1].set_title(f"final {sweep}: chi2_red {diagnosis.final.chi2_red_total:.3g}", fontsize=9)
        plot.save(fig, os.path.join(folder, "residuals.png"))
        figures.append(("Model against measurement, before and after", "residuals.png"))
        if any(d.significant for d in diagnosis.baseline_discrepancy):
            fig, axes = plt.subplots(1, 2, figsize=(12, 3.8))
            plot.discrepancy(diagnosis, final=False, ax=axes[0])
            plot.discrepancy(diagnosis, final=True, ax=axes[1])
            plot.save(fig, os.path.join(folder, "discrepancy.png"))
            figures.append(("Where the misfit lives: the leading generic shape, at the baseline and at the end",
                            "discrepancy.png"))
        if diagnosis.ranking:
            plot.save(plot.ranking(diagnosis.ranking, alpha=diagnosis.alpha,
                                   max_typical_multiple=diagnosis.max_typical_multiple),
                      os.path.join(folder, "ranking.png"))
            figures.append(("Candidate effects ranked by the score test", "ranking.png"))
            plot.save(plot.fingerprints(diagnosis), os.path.join(folder, "fingerprints.png"))
            figures.append(("Predicted residual shape of the top candidates against the residual, per device",
                            "fingerprints.png"))
        plot.save(plot.error_fall(diagnosis), os.path.join(folder, "error_fall.png"))
        figures.append(("The error falling step by step", "error_fall.png"))
        report = diagnosis.to_json()
        atomic_write_json(report, os.path.join(folder, "diagnosis.json"))
        data = diagnosis.baseline.data
        lines = ["# gyrojax diagnosis", "", f"Data: `{data.source}`, {len(diagnosis.baseline.devices)} device(s), "
                 f"sweeps {', '.join(sweeps)}.", "", f"**{diagnosis.verdict_text()}**", ""]
        left = diagnosis.remaining
        found = [d for d in diagnosis.baseline_discrepancy if d.significant and not d.within]
        lines += ["## Where the misfit lives", "",
                  "Generic shapes (a bias or gain in die temperature, time since power-on, drive frequency or run; "
                  "odd cubics after and of the DAC; an even bow; K+ vs K-), scored from the same fit as the "
                  "candidate effects, with the share of the misfit each explains and the size of the term it "
                  "implies.", ""]
        for title, items in (("At the baseline", found), ("What is left at the end", left)):
            lines += [f"{title}:", ""]
            lines += [f"- `{d.coordinate}`: {d.description} (S = {d.chi2_explained:.4g}, p = {d.p_value:.2g})"
                      for d in items] or ["- nothing significant"]
            lines.append("")
        lines += ["## Summary", "", "```", diagnosis.summary(comparisons=False), "```", "",
                  "## Where the model fails, fit by fit", "",
                  "Misfit by sweep, device, run and input band (share of the chi2 in excess of the point count), "
                  "and structure tests on the residuals along every recorded coordinate (`gyrojax.compare`):", ""]
        for k, c in enumerate(diagnosis.comparisons):
            name = "baseline" if k == 0 else f"+ {diagnosis.steps[k - 1].effect}"
            lines += [f"### {name}", "", "```", c.summary(), "```", ""]
        lines += ["## Step by step", "", "| step | effect | chi2_red | nonlinearity residual (ppm) |",
                  "|---|---|---|---|",
                  f"| 0 | baseline | {diagnosis.baseline.chi2_red_total:.3f} | "
                  f"{diagnosis.baseline_nonlinearity_ppm:.2f} |"]
        for k, s in enumerate(diagnosis.steps, 1):
            lines.append(f"| {k} | + {s.effect} | {s.chi2_red_after:.3f} | {s.nonlinearity_ppm_after:.2f} |")
        if diagnosis.rejected:
            lines += ["", "Candidates not confirmed, and why:", ""]
            lines += [f"- `{r.effect}`: {r.reason}." for r in diagnosis.rejected]
        lines += ["", "Effects marked *not testable* leave no fingerprint that the baseline's free parameters "
                  "(gains, per-run biases) cannot absorb on this data. What absorbs each, and the measurement that "
                  "would reveal it:", ""]
        lines += [f"- `{name}`: {why}." for name, why in diagnosis.absorptions.items()] or ["- none"]
        lines += [""]
        for title, name in figures:
            lines += [f"## {title}", "", f"![{title}]({name})", ""]
        atomic_write_bytes(os.path.join(folder, "diagnosis.md"), "\n".join(lines).encode())
    return report
