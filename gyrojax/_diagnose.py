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
it at a plausible size); it stays in the ranking and is still selected if significant. The best candidate with p below alpha / (number of candidates) is refitted; the likelihood-ratio test
(chi2 drop ~ chi2(df)) and BIC confirm it, and the loop repeats until no candidate is significant.
Significant candidates whose fingerprints are nearly collinear (|cos| > `ambiguity`) are reported together,
with the sweep of the data on which their fingerprints differ most, if any.
"""

import dataclasses
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._compare import chi2_sf, compare
from ._dataset import Table
from ._effects.registry import EFFECTS
from ._fitdata import FitData, fit_data
from ._identify import Fit, _to_model, identify
from ._parameters import DEFAULT_FREE, Model, zero_effect


# ASSUMPTION: each effect's `typical(1.0)` is a realistic size with a provenance; a device more than 20 times
# worse than that is outside what the library's sources support.
IMPLAUSIBLE_MULTIPLE = 20.0


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


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """The solution of `diagnose`: the baseline fit, the ranking at the first step, the accepted steps, the
    final fit, and what was ambiguous or untestable."""

    baseline: Fit
    final: Fit
    fits: tuple  # baseline, then the fit after each step
    ranking: tuple  # CandidateScore at the first step, best first
    steps: tuple  # Step per accepted effect
    ambiguous: tuple  # groups of names
    untestable: tuple  # names not testable on this data at the first step
    rejected: tuple  # (name, reason) candidates that scored but did not survive the refit
    alpha: float
    baseline_nonlinearity_ppm: float
    min_typical_chi2: float = 1.0
    comparisons: tuple = ()  # `Comparison` of each fit in `fits`: where it fails, structure in its residuals

    @property
    def selected(self) -> tuple[str, ...]:
        return tuple(s.effect for s in self.steps)

    @property
    def absorptions(self) -> dict:
        """Each untestable candidate: what hid it on this data and what would reveal it, in words."""
        scores = {c.effect: c for c in self.ranking}
        return {name: scores[name].absorption for name in self.untestable}

    def summary(self) -> str:
        lines = [f"baseline: chi2_red {self.baseline.chi2_red_total:.3f}, model-vs-measurement nonlinearity "
                 f"{self.baseline_nonlinearity_ppm:.2f} ppm"]
        if self.comparisons:
            lines += ["  " + x for x in self.comparisons[0].summary().splitlines()]
        lines.append("candidates at the first step (score test, no refit):")
        for c in self.ranking:
            what = (f"S = {c.statistic:10.2f}  df {c.df:3d}  p = {c.p_value:.3g}  typical-size chi2 "
                    f"{c.typical_chi2:.3g}" if c.testable else "not testable on this data")
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
            lines.append("no candidate effect is significant: the baseline explains the data.")
        for name, why in self.rejected:
            lines.append(f"  rejected {name}: {why}")
        lines.append(f"final: chi2_red {self.final.chi2_red_total:.3f}, selected: {', '.join(self.selected) or 'none'}")
        if self.steps and self.comparisons:
            lines += ["  " + x for x in self.comparisons[-1].summary().splitlines()]
        return "\n".join(lines)

    def write_report(self, out_dir) -> dict:
        """The report folder (Markdown, JSON, PNG plots) of `write_report`; returns the JSON."""
        return write_report(self, out_dir)

    def to_json(self) -> dict:
        """The JSON of DESIGN.md §7."""
        return {
            "baseline": {"chi2_red": self.baseline.chi2_red_total,
                         "nonlinearity_ppm": self.baseline_nonlinearity_ppm},
            "ranking": [{"effect": c.effect, "statistic": c.statistic, "df": c.df, "p_value": c.p_value,
                         "testable": c.testable, "typical_chi2": c.typical_chi2, "visible_chi2": c.visible_chi2,
                         "absorbed_by": list(c.absorbed_by), "revealed_by": EFFECTS[c.effect].revealed_by}
                        for c in self.ranking],
            "steps": [{"effect": s.effect, "statistic": s.statistic, "p_value": s.p_value,
                       "chi2_red_after": s.chi2_red_after, "lr_statistic": s.lr_statistic, "lr_df": s.lr_df,
                       "lr_p_value": s.lr_p_value, "delta_bic": s.delta_bic,
                       "nonlinearity_ppm_after": s.nonlinearity_ppm_after,
                       "ambiguous_with": list(s.ambiguous_with), "separated_by": s.separated_by,
                       "typical_multiple": s.typical_multiple}
                      for s in self.steps],
            "selected": list(self.selected),
            "ambiguous": [list(g) for g in self.ambiguous],
            "untestable": list(self.untestable),
            "rejected": [{"effect": n, "reason": r} for n, r in self.rejected],
            "final": {"chi2_red": self.final.chi2_red_total,
                      "nonlinearity_ppm": nonlinearity_residual_ppm(self.final)},
            "compare": [c.to_json() for c in self.comparisons],
        }


def _row_blocks(data: FitData):
    """(sweep, start, stop) of each sweep's rows in a device's residual vector."""
    out, k = [], 0
    for sweep in data.sweeps:
        shape = data.blocks[sweep].inputs.shape
        n = int(shape[1] * shape[2])
        out.append((sweep, k, k + n))
        k += n
    return out


def nonlinearity_residual_ppm(fit: Fit) -> float:
    """The worst model-vs-measurement residual of the rate-table points, as ppm of full scale
    (max |y - f - bias| / (|SF| max |rate|)): the scale-factor nonlinearity the model leaves unexplained."""
    if "rate_table" not in fit.residuals:
        return float("nan")
    block = fit.data.blocks["rate_table"]
    raw = np.abs(np.asarray(fit.residuals["rate_table"]) * np.asarray(block.sigmas))
    full = np.abs(np.asarray(fit.scale_factor))[:, None, None] * np.max(
        np.where(np.asarray(block.mask), np.abs(np.asarray(block.inputs)), 0.0), axis=(1, 2), keepdims=True)
    return float(np.max(np.where(np.asarray(block.mask), raw / full, 0.0)) * 1e6)


def score_candidates(fit: Fit, candidates, *, rank_tol: float = 1e-4) -> tuple[CandidateScore, ...]:
    """Score test of each candidate (effect name held at zero in `fit.model`) against the fitted model."""
    jac = np.asarray(fit.jacobian)
    res = np.asarray(fit.residual_vector)
    free = np.asarray(fit.free)
    names_free = [nm for nm, f in zip(fit.names, free) if f]
    out = []
    for name in candidates:
        cols = np.asarray([i for i, nm in enumerate(fit.names) if nm.startswith(name + ".")], dtype=int)
        stat, df, typical, visible = 0.0, 0, 0.0, 0.0
        share = np.zeros(len(names_free))  # of the most visible fingerprint's chi2, per free parameter
        fingerprint = np.zeros_like(res)
        for d in range(jac.shape[0]):
            jb, je, r = jac[d][:, free], jac[d][:, cols], res[d]
            if je.shape[1]:
                evals, evecs = np.linalg.eigh(je.T @ je)
                visible += max(float(evals[-1]), 0.0)
                if jb.shape[1]:
                    # |P f|^2 = sum_k c_k (b_k . f) with c the least-squares coefficients of f on the columns
                    f = je @ evecs[:, -1]
                    c = np.linalg.lstsq(jb, f, rcond=None)[0]
                    share += c * (jb.T @ f)
            if jb.shape[1]:
                q, _ = np.linalg.qr(jb)
                je = je - q @ (q.T @ je)
            info = je.T @ je
            evals, evecs = np.linalg.eigh(info)
            typical += max(float(evals[-1]), 0.0) if evals.size else 0.0
            keep = evals > rank_tol
            if not keep.any():
                continue
            inv = (evecs[:, keep] / evals[keep]) @ evecs[:, keep].T
            s = je.T @ r
            stat += float(s @ inv @ s)
            df += int(keep.sum())
            fingerprint[d] = je @ (inv @ s)
        order = np.argsort(-share)
        absorbed_by = tuple(names_free[k] for k in order if share[k] > 0.1 * max(np.sum(share), 0.0))
        out.append(CandidateScore(name, stat, df, chi2_sf(stat, df), df > 0, fingerprint, EFFECTS[name].description,
                                  typical, visible, absorbed_by))
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


def diagnose(data, model="paper-qmg", *, candidates=None, free=DEFAULT_FREE, alpha: float = 0.01,
             max_effects: int = 4, ambiguity: float = 0.95, min_typical_chi2: float = 1.0, starts: int = 1,
             progress=None) -> Diagnosis:
    r"""Compare `model` with `data`, rank every candidate effect, add the significant ones one at a time.

    **Arguments:**

    - `data`: a `gyrojax.Table` (or `FitData`) of any sweeps.
    - `model`: the baseline: a preset name, a `Gyroscope`, or a `gyrojax.Model` (its effects stay in).
    - `candidates`: effect names to consider (default: every registered effect the device supports).
    - `free`: baseline physical parameters free per device (see `gyrojax.identify`).
    - `alpha`: family-wise significance per step; a candidate must reach p < alpha / n_candidates in the
      score test and p < alpha in the likelihood-ratio test after its refit.
    - `max_effects`: stop after this many.
    - `ambiguity`: |cos| between fingerprints above which two candidates are reported as ambiguous.
    - `min_typical_chi2`: a candidate whose typical-size fingerprint, after the baseline took up what it
      could, changes the lot's chi2 by less than this (and whose score is not significant) is reported as
      not testable on this data.
    - `progress`: optional callable taking a message, called before each (slow) fit.

    **Returns:** a `Diagnosis`.
    """
    from ._effects.registry import supported_effects

    base = _to_model(model)
    if isinstance(data, Table):
        data = fit_data(data)
    device = base.device
    one = device if not _is_lot(device) else _first(device)
    available = supported_effects(one)
    present = set(base.effect_names)
    if candidates is None:
        candidates = tuple(c for c in available if c not in present)
    else:
        candidates = tuple(candidates)
        for c in candidates:
            if c not in EFFECTS:
                raise ValueError(f"unknown candidate effect {c!r}; expected names of gyrojax.EFFECTS: {', '.join(EFFECTS)}.")
            if c not in available:
                raise ValueError(f"candidate effect {c!r} cannot act on device {one.name!r} "
                                 f"(supported: {', '.join(available)}).")
    if not candidates:
        raise ValueError("diagnose needs at least one candidate effect not already in the model.")
    full = Model(base.device, base.effects + tuple(zero_effect(c) for c in candidates))
    say = progress or (lambda msg: None)

    def fit_with(selected):
        held = tuple(c for c in candidates if c not in selected)
        return identify(full, data, free=free, hold=held, starts=starts)

    say("fitting the baseline")
    fit = fit_with(())
    baseline = fit
    fits, steps, ambiguous, rejected = [fit], [], [], []
    ranking0, untestable = None, ()
    selected: list[str] = []
    remaining = list(candidates)
    while remaining and len(selected) < max_effects:
        scores = score_candidates(fit, remaining)
        threshold = alpha / len(remaining)
        if ranking0 is None:
            ranking0 = scores
            untestable = tuple(c.effect for c in scores if not c.testable or (
                c.typical_chi2 < min_typical_chi2 and c.p_value >= threshold))
        significant = [c for c in scores if c.testable and c.p_value < threshold]
        if not significant:
            break
        best = significant[0]
        group = tuple(c.effect for c in significant[1:]
                      if abs(_cos(best.fingerprint, c.fingerprint)) > ambiguity)
        separated = None
        if group:
            others = [c for c in significant if c.effect in group]
            seps = {_separating_sweep(best.fingerprint, c.fingerprint, data, ambiguity) for c in others}
            separated = seps.pop() if len(seps) == 1 else None
            ambiguous.append((best.effect,) + group)
        say(f"refitting with {best.effect}")
        new = fit_with(tuple(selected) + (best.effect,))
        lr = fit.chi2_total - new.chi2_total
        df = int(np.sum(new.free)) - int(np.sum(fit.free))
        df_total = df * len(data.devices)
        p_lr = chi2_sf(lr, df_total)
        n_points = int(np.sum([np.asarray(b.mask).sum() for b in data.blocks.values()]))
        delta_bic = -lr + df_total * math.log(max(n_points, 2))
        remaining.remove(best.effect)
        if df <= 0 or p_lr >= alpha or not new.all_converged:
            why = ("its parameters are not identifiable once fitted" if df <= 0 else
                   f"refit did not converge: {new.result_message}" if not new.all_converged else
                   f"likelihood-ratio p = {p_lr:.3g} >= alpha")
            rejected.append((best.effect, why))
            continue
        selected.append(best.effect)
        fit = new
        fits.append(fit)
        cols = [i for i, nm in enumerate(fit.names) if nm.startswith(best.effect + ".")]
        multiple = float(np.max(np.abs(np.asarray(fit.u)[:, cols])))
        steps.append(Step(best.effect, best.statistic, best.p_value, lr, df_total, p_lr, delta_bic,
                          fit.chi2_red_total, nonlinearity_residual_ppm(fit), scores, group, separated, multiple))
    if ranking0 is None:
        ranking0 = ()
    return Diagnosis(baseline, fit, tuple(fits), ranking0, tuple(steps), tuple(ambiguous), untestable,
                     tuple(rejected), alpha, nonlinearity_residual_ppm(baseline), min_typical_chi2,
                     tuple(compare(f, alpha=alpha) for f in fits))


def _is_lot(device):
    import jax

    leaves = [x for x in jax.tree.leaves(device) if eqx.is_array(x)]
    return bool(leaves) and all(jnp.ndim(x) >= 1 for x in leaves)


def _first(device):
    import jax

    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, device)




def write_report(diagnosis: Diagnosis, out_dir) -> dict:
    """A report folder: `diagnosis.md`, `diagnosis.json` and PNG plots (residuals before and after, the
    ranking, the fingerprints, the error falling). Every file is written atomically. Returns the JSON."""
    import os

    import matplotlib.pyplot as plt

    from . import plot
    from ._io import atomic_write_bytes, atomic_write_json

    os.makedirs(out_dir, exist_ok=True)
    sweeps = diagnosis.baseline.data.sweeps
    figures = []
    fig, axes = plt.subplots(len(sweeps), 2, figsize=(12, 3.2 * len(sweeps)), squeeze=False)
    for i, sweep in enumerate(sweeps):
        plot.residuals(diagnosis.baseline, sweep, ax=axes[i, 0])
        axes[i, 0].set_title(f"baseline {sweep}: chi2_red {diagnosis.baseline.chi2_red_total:.3g}", fontsize=9)
        plot.residuals(diagnosis.final, sweep, ax=axes[i, 1])
        axes[i, 1].set_title(f"final {sweep}: chi2_red {diagnosis.final.chi2_red_total:.3g}", fontsize=9)
    plot.save(fig, os.path.join(out_dir, "residuals.png"))
    figures.append(("Model against measurement, before and after", "residuals.png"))
    if diagnosis.ranking:
        plot.save(plot.ranking(diagnosis.ranking), os.path.join(out_dir, "ranking.png"))
        figures.append(("Candidate effects ranked by the score test", "ranking.png"))
        plot.save(plot.fingerprints(diagnosis), os.path.join(out_dir, "fingerprints.png"))
        figures.append(("Predicted residual shape of the top candidates against the residual", "fingerprints.png"))
    plot.save(plot.error_fall(diagnosis), os.path.join(out_dir, "error_fall.png"))
    figures.append(("The error falling step by step", "error_fall.png"))
    report = diagnosis.to_json()
    atomic_write_json(report, os.path.join(out_dir, "diagnosis.json"))
    lines = ["# gyrojax diagnosis", "", f"Data: `{diagnosis.baseline.data.source}`, "
             f"{len(diagnosis.baseline.devices)} device(s), sweeps {', '.join(sweeps)}.", "",
             "## Summary", "", "```", diagnosis.summary(), "```", "",
             "## Where the model fails", "",
             "Misfit by sweep, device, run and input band (share of the chi2 in excess of the point count), and "
             "structure tests on the residuals ordered by input (`gyrojax.compare`), fit by fit:", ""]
    for k, c in enumerate(diagnosis.comparisons):
        name = "baseline" if k == 0 else f"+ {diagnosis.steps[k - 1].effect}"
        lines += [f"### {name}", "", "```", c.summary(), "```", ""]
    lines += ["## Step by step", "", "| step | effect | chi2_red | nonlinearity residual (ppm) |", "|---|---|---|---|",
              f"| 0 | baseline | {diagnosis.baseline.chi2_red_total:.3f} | {diagnosis.baseline_nonlinearity_ppm:.2f} |"]
    for k, s in enumerate(diagnosis.steps, 1):
        lines.append(f"| {k} | + {s.effect} | {s.chi2_red_after:.3f} | {s.nonlinearity_ppm_after:.2f} |")
    lines += ["", "Effects marked *not testable* leave no fingerprint that the baseline's free parameters "
              "(gains, per-run biases) cannot absorb on this data. What absorbs each, and the measurement that "
              "would reveal it:", ""]
    lines += [f"- `{name}`: {why}." for name, why in diagnosis.absorptions.items()]
    lines += [""]
    for title, name in figures:
        lines += [f"## {title}", "", f"![{title}]({name})", ""]
    atomic_write_bytes(os.path.join(out_dir, "diagnosis.md"), "\n".join(lines).encode())
    return report
