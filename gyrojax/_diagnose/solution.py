"""The solution of `diagnose`: the accepted steps and the `Diagnosis`, with its summary, verdict in words and
JSON."""

import math
import os
from typing import ClassVar

import equinox as eqx
import numpy as np

from .._effects.registry import EFFECTS
from .._identify import Fit
from .._identify.assemble import REJECTED_NOTE
from .compare import Comparison, nonlinearity_residual_ppm
from .discrepancy import LookAlike
from .formula import Formula
from .guards import MAX_TYPICAL_MULTIPLE, Rejection
from .location import Location
from .report import discrepancy_text, markdown_text, nonlinearity_not_determined, write_report
from .score import CandidateScore


# ASSUMPTION: each effect's `typical(1.0)` is a realistic size with a provenance; a device more than 20 times
# worse than that is outside what the library's sources support.
IMPLAUSIBLE_MULTIPLE = 20.0


class Step(eqx.Module):
    """One accepted effect: its score at selection, the refit's likelihood-ratio test and chi2 after (a record of
    `Diagnosis.steps`)."""

    effect: str
    statistic: float
    p_value: float
    lr_statistic: float
    lr_df: int
    lr_p_value: float
    delta_bic: float
    chi2_red_after: float
    nonlinearity_ppm_after: float
    ranking: tuple[CandidateScore, ...]  # every candidate scored at this step, best first
    ambiguous_with: tuple[str, ...]
    separated_by: str | None
    # Largest fitted parameter of the effect over the lot, in units of its typical size: far above 1, the
    # effect explains the data only at an implausible size (another effect may leave this fingerprint).
    typical_multiple: float = float("nan")
    implied_multiple: float = float("nan")  # at the score stage, before the refit
    contradicted_by: tuple[str, ...] = ()  # sweeps whose misfit the step made significantly worse (none when accepted)
    look_alikes: tuple[LookAlike, ...] = ()  # LookAlike: shapes the data cannot tell from this effect (`look_alikes`)
    # Benjamini-Hochberg q-value of the step's selection-corrected likelihood-ratio p-value over every refit
    q_value: float = float("nan")


VERDICTS = ("explained", "partly explained", "unexplained")


class Diagnosis(eqx.Module):
    """The solution of `diagnose`: the baseline fit, the ranking at the first step, the accepted steps, the
    final fit, what was ambiguous, untestable or rejected, where the misfit that is left lives, and a
    verdict."""

    baseline: Fit
    final: Fit
    fits: tuple[Fit, ...]  # baseline, then the fit after each step
    ranking: tuple[CandidateScore, ...]  # at the first step, best first
    steps: tuple[Step, ...]  # per accepted effect
    ambiguous: tuple[tuple[str, ...], ...]  # groups of names
    untestable: tuple[str, ...]  # names not testable on this data at the first step
    rejected: tuple[Rejection, ...]  # per candidate that scored but was not confirmed
    alpha: float
    baseline_nonlinearity_ppm: float
    min_typical_chi2: float = 1.0
    comparisons: tuple[Comparison, ...] = ()  # of each fit in `fits`: where it fails, structure in its residuals
    baseline_discrepancy: tuple[Location, ...] = ()  # per probe at the baseline, most explanatory first
    discrepancy: tuple[Location, ...] = ()  # the same at the final fit: where what is left lives
    verdict: str = "unexplained"
    max_typical_multiple: float = MAX_TYPICAL_MULTIPLE
    formula: Formula | None = None  # proposed for the leading discrepancy
    notes: tuple[str, ...] = ()  # coordinates the localisation did not describe along, and why

    kind: ClassVar[str] = "diagnosis"  # the result's name for output formats (gyrojax.io.AbstractResult)

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
        alike = "".join(f"; but this data cannot tell {s.effect} from {a.description}"
                        for s in self.steps for a in s.look_alikes)
        if self.verdict == "explained":
            verb = "explains" if len(self.selected) == 1 else "explain"
            what = (f"{', '.join(self.selected)} {verb}" if self.steps else "the baseline explains")
            return f"verdict: explained: {what} the data at the noise level{tail}{alike}"
        left = self.remaining
        where = (f"; what is left: {discrepancy_text(left[0])}" if left else
                 "; no generic shape (bias or gain in temperature, time, run; cubics; bow; K+/K-) explains what "
                 "is left: see where the model fails")
        if not left and final is not None and final.fails:
            # every shape is read against the residuals' own scatter: none stands out of a uniform excess
            where = (f"; the residuals scatter {math.sqrt(max(float(self.final.chi2_red_total), 0.0)):.3g} times "
                     "the stated uncertainties with no shape along any recorded coordinate: the stated output_sigma "
                     "is too small, or the noise is not white (correlated in time, heavy-tailed)")
        # A chi2 at the noise level is no failure: the verdict then rests on structure in the residuals alone.
        fails = final is None or final.fails
        if left and fails and round(100 * left[0].share) < 1:
            where = (f"; no generic shape takes 1 % of what is left (the most significant: "
                     f"{discrepancy_text(left[0])}): see where the model fails")
        state = "the model still fails" if fails else "the residuals keep structure"
        if not fails:
            worst = min(final.flagged if final is not None else (), key=lambda f: f.p_value, default=None)
            state += f" ({worst.label}: p = {worst.p_value:.2g}, {worst.meaning})" if worst is not None else ""
            tail = f" though the chi2 is at the noise level{tail}"
        fails_now = "the model fails" if fails else state
        if self.verdict == "partly explained":
            base = max(self.baseline.chi2_total - self.baseline.dof_total, 1e-300)
            gone = (self.baseline.chi2_total - self.final.chi2_total) / base
            return (f"verdict: partly explained: {', '.join(self.selected)} take {100 * min(gone, 1.0):.0f} % of "
                    f"the baseline's excess misfit, but {state}{tail}{where}{self._formula_text()}"
                    f"{alike}")
        return (f"verdict: unexplained: no library effect is confirmed and {fails_now}{tail}{where}"
                f"{self._formula_text()}")

    @property
    def baseline_notes(self) -> dict[str, list[str]]:
        """The baseline fit's warnings about its data (the noise estimated where the data give no output_sigma,
        a temperature not recorded, ...), each with the devices that carry it; not its rejection of the model,
        which the diagnosis is about."""
        notes = {}
        for device, warnings in zip(self.baseline.devices, self.baseline.warnings):
            for w in warnings:
                if not w.startswith(REJECTED_NOTE):
                    notes.setdefault(w, []).append(device)
        return notes

    def _formula_text(self) -> str:
        f = self.formula
        if f is None:
            return ""
        if not f.complete:
            return f"; no term of the dictionary has its shape (the closest: {f.description})"
        return f"; a term that would explain it: {f.description}"

    def summary(self, comparisons: bool = True) -> str:
        """A few dozen lines for a terminal; `comparisons=False` leaves out the `compare` blocks of the baseline
        and the final fit."""
        lines = [f"baseline: chi2_red {self.baseline.chi2_red_total:.3f}, model-vs-measurement nonlinearity "
                 f"{ppm_text(self.baseline_nonlinearity_ppm, self.baseline)}"]
        lines += _notes_text(self.baseline_notes)
        if self.comparisons and comparisons:
            lines += ["  " + x for x in self.comparisons[0].summary().splitlines()]
        found = [d for d in self.baseline_discrepancy if d.significant and not d.within]
        if found:
            lines.append("where the misfit lives (generic shapes, score test, no refit):")
            lines += [f"  {d.coordinate:<14} {discrepancy_text(d)} (S = {d.chi2_explained:.4g}, p = {d.p_value:.2g})"
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
                         f"{ppm_text(s.nonlinearity_ppm_after, self.final)}{amb}; fitted "
                         f"at {s.typical_multiple:.3g}x its "
                         "typical size")
            lines += [f"  {line}" for line in sizes_text(effect_sizes(self.final, s.effect))]
            lines += [f"  ~ this data cannot tell {s.effect} from {a.description}" for a in s.look_alikes]
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

    def draft_effect(self, path: str | os.PathLike, *, name: str = "drafted_term") -> str:
        """Write the proposed missing term (`formula`) as an effect module at `path` (a readout term named
        `name`, its typical size the fitted formula), ready for `gyrojax.load_effects_module`; returns its text.
        Raises a `ValueError` saying why when there is no complete formula or a readout term cannot hold it."""
        from .draft import DraftError, write_draft

        if self.formula is None:
            raise DraftError(f"no term of the dictionary is significant in what is left (verdict: {self.verdict}): "
                             "there is no formula to draft.")
        return write_draft(self.formula, path, name=name, source=str(self.baseline.data.source or ""))

    def markdown(self) -> str:
        """The Markdown page of the report folder (`diagnosis.md`) without its plots."""
        return markdown_text(self)

    def write_report(self, out_dir: str | os.PathLike) -> dict:
        """The report folder (Markdown, JSON, PNG plots) of `write_report`; returns the JSON."""
        return write_report(self, out_dir)

    def to_json(self) -> dict:
        """The diagnosis as JSON: baseline, ranking, steps, selected, ambiguous, untestable, rejected, final,
        verdict, discrepancy (what is left, most explanatory first), baseline_discrepancy, compare."""
        return {
            "baseline": {"chi2_red": self.baseline.chi2_red_total,
                         **_ppm_json(self.baseline_nonlinearity_ppm, self.baseline),
                         "notes": [{"note": note, "devices": devices}
                                   for note, devices in self.baseline_notes.items()]},
            "ranking": [{"effect": c.effect, "statistic": c.statistic, "df": c.df, "p_value": c.p_value,
                         "testable": c.testable, "typical_chi2": c.typical_chi2, "visible_chi2": c.visible_chi2,
                         "implied_multiple": _finite(c.implied_multiple),
                         "absorbed_by": list(c.absorbed_by), "revealed_by": EFFECTS[c.effect].revealed_by}
                        for c in self.ranking],
            "steps": [{"effect": s.effect, "statistic": s.statistic, "p_value": s.p_value,
                       "chi2_red_after": s.chi2_red_after, "lr_statistic": s.lr_statistic, "lr_df": s.lr_df,
                       "lr_p_value": s.lr_p_value, "delta_bic": s.delta_bic,
                       **_ppm_json(s.nonlinearity_ppm_after, self.final, "nonlinearity_ppm_after"),
                       "ambiguous_with": list(s.ambiguous_with), "separated_by": s.separated_by,
                       "typical_multiple": s.typical_multiple, "implied_multiple": _finite(s.implied_multiple),
                       "contradicted_by": list(s.contradicted_by), "q_value": _finite(s.q_value),
                       "look_alikes": [a.to_json() for a in s.look_alikes],
                       "sizes": effect_sizes(self.final, s.effect)}
                      for s in self.steps],
            "selected": list(self.selected),
            "ambiguous": [list(g) for g in self.ambiguous],
            "untestable": list(self.untestable),
            "rejected": [{"effect": r.effect, "reason": r.reason, "kind": r.kind,
                          "contradicted_by": list(r.contradicted_by)}
                         for r in self.rejected],
            "final": {"chi2_red": self.final.chi2_red_total,
                      **_ppm_json(nonlinearity_residual_ppm(self.final), self.final)},
            "verdict": self.verdict,
            "verdict_text": self.verdict_text(),
            "discrepancy": [d.to_json() for d in self.remaining],
            "formula": self.formula.to_json() if self.formula is not None else None,
            "localisation_notes": list(self.notes),
            "baseline_discrepancy": [d.to_json() for d in self.baseline_discrepancy if d.significant and not d.within],
            "compare": [c.to_json() for c in self.comparisons],
        }


def _finite(x):
    return float(x) if math.isfinite(x) else None


def effect_sizes(fit: Fit, effect: str) -> list:
    """Per device, each fitted parameter of `effect` in `fit`: `device`, `parameter`, `value` and `stderr`
    (physical units), `typical_multiple` and `typical_multiple_stderr` (the internal coordinate: the size in
    units of the effect's typical size, from the fit's covariance); `stderr_scaled` where the model is rejected
    (the standard error times sqrt(chi2_red)). None where a standard error is not determined (a held
    parameter)."""
    names = list(fit.names)
    cols = [i for i, name in enumerate(names) if name.startswith(effect + ".")]
    u = np.asarray(fit.u)
    values, stderr = np.asarray(fit.values), np.asarray(fit.stderr)
    scaled = np.asarray(getattr(fit, "stderr_scaled", fit.stderr))
    cov = np.asarray(fit.covariance)
    u_se = np.sqrt(np.abs(np.diagonal(cov, axis1=-2, axis2=-1)))
    free = np.asarray(fit.free)
    out = []
    for d, device in enumerate(fit.devices):
        for i in cols:
            held = not bool(free[i])
            out.append({"device": str(device), "parameter": names[i], "value": _finite(float(values[d, i])),
                        "stderr": None if held else _finite(float(stderr[d, i])),
                        "stderr_scaled": None if held else _finite(float(scaled[d, i])),
                        "typical_multiple": _finite(float(u[d, i])),
                        "typical_multiple_stderr": None if held else _finite(float(u_se[d, i]))})
    return out


def sizes_text(sizes: list) -> list:
    """`effect_sizes` as lines of text, one per device: each parameter's value +/- its standard error, and its
    size in units of the typical one."""

    def pm(value, se, spec):
        if value is None:
            return "n/a"
        return format(value, spec) + (f" +/- {se:.2g}" if se is not None else " (no standard error)")

    lines, by_device = [], {}
    for s in sizes:
        by_device.setdefault(s["device"], []).append(s)
    for device, items in by_device.items():
        parts = [f"{s['parameter']} = {pm(s['value'], s['stderr'], '.4g')} "
                 f"({pm(s['typical_multiple'], s['typical_multiple_stderr'], '.3g')} x typical)"
                 for s in items if s["stderr"] is not None]
        held = [s["parameter"] for s in items if s["stderr"] is None]
        if held:  # held by the fit: the data do not determine them
            parts.append(f"held, no standard error: {', '.join(held)}")
        lines.append(f"fitted, {device}: " + "; ".join(parts))
    return lines


def ppm_text(value: float, fit: Fit) -> str:
    """A nonlinearity for text: "1.88 ppm", or "n/a (the reason)" where it is not a number."""
    return f"{value:.2f} ppm" if math.isfinite(value) else f"n/a ({nonlinearity_not_determined(fit)})"


def _ppm_json(value: float, fit: Fit, key: str = "nonlinearity_ppm") -> dict:
    """`{key: value}`, or `{key: None, "not_determined": {key: reason}}` where it is not a number (as identify
    writes a scale factor the data do not determine)."""
    if math.isfinite(value):
        return {key: float(value)}
    return {key: None, "not_determined": {key: nonlinearity_not_determined(fit)}}


def _notes_text(notes: dict[str, list[str]]) -> list[str]:
    """The summary's lines of the baseline's notes: each note once with its devices; notes of one kind (the same
    words before the first ':') that differ only in their values per device, the first in full and how many
    more there are (every one is in the JSON's `baseline.notes`)."""
    kinds: dict[str, list[tuple[str, list[str]]]] = {}
    for note, devices in notes.items():
        kinds.setdefault(note.split(":")[0], []).append((note, devices))
    lines = []
    for group in kinds.values():
        note, devices = group[0]
        more = sum(len(d) for _, d in group[1:])
        tail = (f" (and {more} more device(s) alike, each with its own values: baseline.notes in the JSON)"
                if more else "")
        lines.append(f"  note ({', '.join(devices)}): {note}{tail}")
    return lines
