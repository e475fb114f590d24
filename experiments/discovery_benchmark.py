"""The discovery benchmark: lots with one hidden effect (or none), run through discovery methods, scored.

Run: python experiments/discovery_benchmark.py [--methods gyrojax,refit_ftest,pysindy] [--snr low,mid,high]
     [--seeds 0-4] [--designs a,b] [--effects NAME,...|all] [--devices 6] [--runs 2] [--out DIR] [--quick]

Lots come from `experiments/_discovery_lot.py` (plain NumPy, its own closed forms; 26 hidden effects, 12 of them
cases of library effects). Each method is a plug-in (`Method`: `name`, `run(table) -> Outcome`):

- `gyrojax`: `gyrojax.diagnose(preset, table)`, read through its JSON (`read_diagnosis`);
- `refit_ftest`: forward selection over the library by refits and an F-test (p < 0.01), no localisation beyond
  the sweep with the largest residual chi2, no formula;
- `pysindy`: a sparse regression (`pysindy.STLSQ`) of the baseline fit's standardised residuals on a dictionary of
  canonical terms (`TERMS`), per sweep (skipped with a message where pysindy is not installed:
  `pip install -e ".[discovery]"`).

Scores per method, by effect class (library / outside / null) and SNR (`score_rows`): library effects found, wrong
confirmations, localisation right (the located sweep set names every sweep carrying >= 30 % of the hidden effect's
visible chi2 and none carrying < 10 %, and the coordinate is right; a library effect found counts as localised; a
second column also counts a coordinate along which a curve takes the hidden effect up as well as along its own
(`coordinate_chi2`, noise-free: no method could tell the two apart), a third the hidden coordinate named among those
the diagnosis says the data confound with the one it gives, as where the sweep order follows the input; the JSON
rows also score the sweep set against one 20 % cut, `localised_strict`), formula recovered, null lots explained,
median final chi2_red, median seconds per lot. Two columns read the generator's noise-free separation of the hidden
effect from each library effect (`look_alike_chi2`, the best any method could see): a library effect confirmed in
the hidden one's place and declared ambiguous with it, where the two lie within 3 sigma, is "found, or declared
ambiguous where no method could tell"; a wrong confirmation of an effect >= 3 sigma away is "wrong, where the data
separate them". DIR/discovery.json and DIR/discovery.md are rewritten (atomically) after every lot.
"""

import abc
import argparse
import dataclasses
import datetime
import json
import math
import os
import sys
import time
import warnings

import numpy as np


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _discovery_blind import BLIND  # noqa: E402  (registers the blind set in EFFECTS)
from _discovery_lot import DESIGNS, EFFECTS, FRESH, HELD_OUT, HIDDEN, TARGET_CHI2, UNSEEN, discovery_lot  # noqa: E402
from _discovery_sealed import SEALED  # noqa: E402  (registers the sealed set in EFFECTS)


LOCATED_SHARE = 0.2  # a sweep carrying at least this share of a misfit is one of the sweeps it is located on
# Scoring a located sweep set: a sweep carrying >= SURE_SHARE of the hidden effect's visible chi2 must be named, one
# carrying < NONE_SHARE must not; between, either answer is right. A single cut at LOCATED_SHARE scored a coin
# flip where physics puts a sweep's share on the cut (design b's VCF sweep spans half the rate range: a gain there
# carries 0.8 / 0.2 of the chi2, and a measured share of 0.2 +/- 0.05 fell either side).
SURE_SHARE, NONE_SHARE = 0.3, 0.1
INDISTINCT_CHI2 = 9.0  # a library effect nearer the hidden one than 3 sigma (`look_alike_chi2`) is indistinct
QUICK_EFFECTS = ("zro_tempco", "feedback_compression", "vcf_gain_tempco", "bias_step", "dac_periodic")


@dataclasses.dataclass
class Outcome:
    """What a method says about one lot."""

    confirmed: list  # library effects confirmed
    verdict: str  # "explained", "partly explained" or "unexplained"
    located: set  # sweeps of the top unexplained misfit (empty: none located)
    coordinate: str | None  # recorded coordinate of the top unexplained misfit
    formula: list  # canonical term names proposed for it ([] for none)
    chi2_red: float  # the final fit's reduced chi2
    seconds: float = math.nan
    note: str = ""
    ambiguous: dict = dataclasses.field(default_factory=dict)  # confirmed -> names it declares it cannot tell apart
    confounded: list = dataclasses.field(default_factory=list)  # coordinates it says the data confound with it


class Method(abc.ABC):
    """A discovery method: `run(table)` returns an `Outcome`."""

    name: str

    @abc.abstractmethod
    def run(self, table) -> Outcome: ...

    def available(self) -> str | None:
        """None where the method can run, else why not."""
        return None


# ---------------------------------------------------------------------------------------------------------------
# gyrojax.diagnose

def _term_name(term) -> str | None:
    if isinstance(term, str):
        return term
    if isinstance(term, dict):
        name = term.get("name")
        return name if isinstance(name, str) else None
    return None


def read_diagnosis(j: dict) -> dict:
    """The `Outcome` fields of a `Diagnosis.to_json()` dict, read defensively: `selected`, `verdict`, `final.chi2_red`,
    and from `discrepancy[0]` its `sweep_shares` ({sweep: share}, the sweeps with a share >= 0.2; else its `sweeps`
    list), `coordinate`, and `formula.terms` (names, or dicts with a `name`), where present."""
    top = (j.get("discrepancy") or [None])[0] or {}
    shares = top.get("sweep_shares")
    if isinstance(shares, dict) and shares:
        located = {s for s, v in shares.items() if v is not None and float(v) >= LOCATED_SHARE}
    elif isinstance(shares, (list, tuple)) and shares:  # [[sweep, share], ...]
        located = {s for s, v in shares if v is not None and float(v) >= LOCATED_SHARE}
    else:
        located = set(s if isinstance(s, str) else s[0] for s in (top.get("sweeps") or ()))
    formula = top.get("formula") if isinstance(top.get("formula"), dict) else j.get("formula")
    terms = (formula or {}).get("terms") or [] if isinstance(formula, dict) else []
    final = j.get("final") or {}
    ambiguous = {}
    for step in j.get("steps") or ():
        ambiguous.setdefault(step.get("effect"), set()).update(step.get("ambiguous_with") or ())
        # a closed form outside the library the diagnosis says it cannot tell from the confirmed effect
        ambiguous[step.get("effect")].update(
            canonical(a["probe"]) for a in step.get("look_alikes") or ()
            if isinstance(a, dict) and isinstance(a.get("probe"), str) and "(" in a["probe"])
    for group in j.get("ambiguous") or ():
        for name in group:
            ambiguous.setdefault(name, set()).update(n for n in group if n != name)
    return {"confirmed": list(j.get("selected") or ()), "verdict": j.get("verdict", "unknown"),
            "ambiguous": ambiguous,
            "located": located, "coordinate": top.get("coordinate") if top else None,
            "confounded": [c for c in (top.get("confounded_with") or ()) if isinstance(c, str)],
            "formula": [n for n in (_term_name(t) for t in terms) if n],
            "chi2_red": float(final.get("chi2_red", math.nan))}


class GyrojaxMethod(Method):
    name = "gyrojax"

    def __init__(self, preset: str = "paper-qmg"):
        self.preset = preset

    def run(self, table) -> Outcome:
        import gyrojax as gj

        t0 = time.perf_counter()
        d = gj.diagnose(self.preset, table, progress=False)
        seconds = time.perf_counter() - t0
        return Outcome(**read_diagnosis(d.to_json()), seconds=seconds)


# ---------------------------------------------------------------------------------------------------------------
# Shared: the baseline fit with every library candidate present at zero (as diagnose builds it)

def _full_model(preset):
    """The preset's device with every effect it supports at zero (as `diagnose` builds its candidates), and their
    names."""
    import gyrojax as gj

    device = gj.preset(preset)
    candidates = tuple(gj.supported_effects(device))
    return gj.Model(device, tuple(gj.effect(c, 0.0) for c in candidates)), candidates


def _free_count(fit) -> int:
    return int(np.sum(fit.free))


def f_test_p(chi2_before: float, chi2_after: float, df: int, dof_after: int) -> float:
    """p of the F-test of a refit that adds `df` parameters: (chi2 drop / df) / (chi2_after / dof_after)."""
    from scipy.stats import f as f_dist

    if df <= 0 or dof_after <= 0 or chi2_after <= 0:
        return 1.0
    stat = ((chi2_before - chi2_after) / df) / (chi2_after / dof_after)
    return float(f_dist.sf(stat, df, dof_after)) if stat > 0 else 1.0


def _sweep_excess(fit) -> dict:
    """Per sweep, the residual chi2 beyond its number of points."""
    out = {}
    for s in fit.data.sweeps:
        r = np.asarray(fit.residuals[s])
        m = np.asarray(fit.data.blocks[s].mask)
        out[s] = float(np.sum(np.where(m, r, 0.0) ** 2) - m.sum())
    return out


class RefitFTest(Method):
    """Plain forward selection: refit with each library effect, keep the best if its F-test has p < alpha; repeat."""

    name = "refit_ftest"

    def __init__(self, preset: str = "paper-qmg", alpha: float = 0.01, max_effects: int = 4):
        self.preset, self.alpha, self.max_effects = preset, alpha, max_effects

    def run(self, table) -> Outcome:
        import gyrojax as gj

        t0 = time.perf_counter()
        full, candidates = _full_model(self.preset)

        def fit_with(selected):  # identify's default free parameters: the baseline's, as in diagnose
            held = tuple(c for c in candidates if c not in selected)
            return gj.identify(full, table, hold=held, progress=False)

        fit = fit_with(())
        selected, remaining, steps = [], list(candidates), []
        while remaining and len(selected) < self.max_effects:
            best = None
            for c in remaining:
                new = fit_with(tuple(selected) + (c,))
                if "not converged" in " ".join(new.status):
                    continue
                df = (_free_count(new) - _free_count(fit)) * len(fit.devices)
                p = f_test_p(fit.chi2_total, new.chi2_total, df, int(new.dof_total))
                if best is None or p < best[1]:
                    best = (c, p, new)
            if best is None or best[1] >= self.alpha:
                break
            steps.append(f"{best[0]} (F-test p = {best[1]:.2g}, chi2 {fit.chi2_total:.1f} -> {best[2].chi2_total:.1f})")
            selected.append(best[0])
            remaining.remove(best[0])
            fit = best[2]
        excess = _sweep_excess(fit)
        top = max(excess, key=excess.get)
        explained = float(fit.p_value_total) >= self.alpha
        verdict = "explained" if explained else ("partly explained" if selected else "unexplained")
        return Outcome(selected, verdict, set() if explained else {top}, None, [], float(fit.chi2_red_total),
                       time.perf_counter() - t0, note="; ".join(steps))


# ---------------------------------------------------------------------------------------------------------------
# pysindy on the baseline's residuals

RELAX_S = 600.0  # the relaxation time of the dictionary's relax(time_s) term
PERIODS = (2.0**16, 2.0**17, 2.0**18, 2.0**19)  # periodic(input): code periods of a segmented DAC


def _coords(fit, sweep):
    """Per valid point of `sweep`: input, temperature, time, drive frequency, run index, device index, model."""
    b = fit.data.blocks[sweep]
    m = np.asarray(b.mask)
    nd, nr, npt = m.shape
    dev = np.broadcast_to(np.arange(nd)[:, None, None], m.shape)
    run = np.broadcast_to(np.arange(nr)[None, :, None], m.shape)

    def col(a):
        return np.asarray(a, dtype=float)[m] if a is not None else np.full(int(m.sum()), np.nan)

    return {"input": col(b.inputs), "temperature_c": col(b.temperatures), "time_s": col(b.times),
            "drive_freq_hz": col(b.drive_freqs), "run": run[m].astype(float), "device": dev[m],
            "model": col(fit.predictions[sweep]), "sigma": col(b.sigmas),
            "residual": np.asarray(fit.residuals[sweep], dtype=float)[m], "biased": sweep != "dac"}


def dictionary(c: dict) -> dict:
    """Canonical term name -> feature column (output units) over one sweep's points (`_coords`)."""
    x = c["input"] / np.max(np.abs(c["input"]))
    model = c["model"] / np.max(np.abs(c["model"]))
    # order matters: a later column within DUPLICATE_COS of an earlier one is dropped (|x| before x^2)
    terms = {"lin(input)": x, "abs(input)": np.abs(x), "sq(input)": x**2, "cube(input)": x**3,
             "sign(input)": np.sign(x), "sign(input)*lin(input)": x * (x > 0)}
    for q in (0.25, 0.5):
        terms[f"step(input)@{q}"] = (x >= q).astype(float)
    for p in PERIODS:
        terms[f"periodic(input)@sin{int(p)}"] = np.sin(2 * np.pi * c["input"] / p)
        terms[f"periodic(input)@cos{int(p)}"] = np.cos(2 * np.pi * c["input"] / p)
    if np.all(np.isfinite(c["temperature_c"])):
        dT = c["temperature_c"] - 25.0
        terms.update({"lin(temperature_c)": dT, "sq(temperature_c)": dT**2, "lin(temperature_c)*model": dT * model,
                      "lin(temperature_c)*abs(input)": dT * np.abs(x)})
    if np.all(np.isfinite(c["time_s"])):
        t = c["time_s"] / np.max(c["time_s"])
        terms.update({"lin(time_s)": t, "sq(time_s)": t**2, "relax(time_s)": np.exp(-c["time_s"] / RELAX_S)})
        for q in (0.25, 0.5, 0.75):
            terms[f"step(time_s)@{q}"] = (t >= q).astype(float)
    if np.all(np.isfinite(c["drive_freq_hz"])):
        f = np.zeros_like(c["drive_freq_hz"])
        for d in np.unique(c["device"]):
            k = c["device"] == d
            f[k] = c["drive_freq_hz"][k] / np.mean(c["drive_freq_hz"][k]) - 1.0
        terms["lin(drive_freq_hz)*model"] = f * model
    if np.unique(c["run"]).size > 1:
        terms["lin(run)*model"] = (c["run"] - np.mean(c["run"])) * model
    return terms


def canonical(term: str) -> str:
    """The canonical name of a dictionary column (its variant after '@' dropped)."""
    return term.split("@")[0]


def _project_out_baseline(c, cols):
    """Columns of `cols` (n, k) with the baseline's own directions removed: per device a gain (the model), and for a
    biased sweep per (device, run) a constant, all in standardised units."""
    out = cols / c["sigma"][:, None]
    for d in np.unique(c["device"]):
        k = c["device"] == d
        base = [c["model"][k] / c["sigma"][k]]
        if c["biased"]:
            base += [(c["run"][k] == r) / c["sigma"][k] for r in np.unique(c["run"][k])]
        a = np.stack(base, axis=1)
        out[k] -= a @ np.linalg.lstsq(a, out[k], rcond=None)[0]
    return out


DUPLICATE_COS = 0.95  # columns this close (after the baseline took its part) are one column to a sparse fit


EMPTY_SHARE = 1e-3  # a column the baseline takes up to this share of its norm is the baseline's own direction


def _distinct_columns(x, names, before):
    """Unit-norm columns of `x`, dropping those the baseline took up (norm below EMPTY_SHARE of `before`, their norm
    before the projection) and any within DUPLICATE_COS of an earlier one (the dictionary's order decides:
    temperature before the drive frequency, which follows it through the TCF)."""
    keep, cols = [], []
    for i in range(x.shape[1]):
        n = np.linalg.norm(x[:, i])
        if not n > EMPTY_SHARE * before[i]:
            continue
        v = x[:, i] / n
        if any(abs(float(v @ w)) > DUPLICATE_COS for w in cols):
            continue
        keep.append(i)
        cols.append(v)
    return (np.stack(cols, axis=1) if cols else np.zeros((x.shape[0], 0))), [names[i] for i in keep]


def coordinate_of(term: str) -> str:
    """The recorded coordinate a canonical term varies with: the first factor other than input or model."""
    coords = [f[f.index("(") + 1:-1] if "(" in f else f for f in term.split("*")]
    others = [x for x in coords if x not in ("input", "model")]
    return others[0] if others else ("input" if "input" in coords else "model")


class PySindy(Method):
    """STLSQ on the baseline's standardised residuals, per sweep, over `dictionary`'s unit-norm columns: a
    coefficient of the threshold explains a chi2 of threshold^2 (16 at the default)."""

    name = "pysindy"

    def __init__(self, preset: str = "paper-qmg", threshold: float = 4.0, ridge: float = 0.05, alpha: float = 0.01):
        self.preset, self.threshold, self.ridge, self.alpha = preset, threshold, ridge, alpha

    def available(self):
        try:
            import pysindy  # noqa: F401
        except ImportError:
            return "pysindy is not installed (pip install -e '.[discovery]'): method pysindy skipped"
        return None

    def run(self, table) -> Outcome:
        import pysindy as ps

        import gyrojax as gj

        t0 = time.perf_counter()
        full, candidates = _full_model(self.preset)
        fit = gj.identify(full, table, hold=candidates, progress=False)
        explained, proposals = {}, {}
        for s in fit.data.sweeps:
            c = _coords(fit, s)
            terms = dictionary(c)
            names = list(terms)
            raw = np.stack([terms[n] for n in names], axis=1)
            x, names = _distinct_columns(_project_out_baseline(c, raw), names,
                                         np.linalg.norm(raw / c["sigma"][:, None], axis=0))
            if not names:
                explained[s], proposals[s] = 0.0, []
                continue
            opt = ps.STLSQ(threshold=self.threshold, alpha=self.ridge)
            with warnings.catch_warnings():  # "eliminated all coefficients" is the null answer, not a problem
                warnings.simplefilter("ignore", UserWarning)
                opt.fit(x, c["residual"][:, None])
            coef = np.ravel(opt.coef_)
            nz = np.flatnonzero(coef)
            explained[s] = float(np.sum((x[:, nz] @ coef[nz]) ** 2)) if nz.size else 0.0
            # each term's own share: its coefficient squared (the columns have unit norm)
            proposals[s] = sorted(((names[i], float(coef[i] ** 2)) for i in nz), key=lambda t: -t[1])
        total = sum(explained.values())
        chi2_left = fit.chi2_total - total
        n_terms = sum(len(v) for v in proposals.values())
        chi2_red = float(chi2_left / max(int(fit.dof_total) - n_terms, 1))
        baseline_ok = float(fit.p_value_total) >= self.alpha
        if total <= 0 or baseline_ok:
            return Outcome([], "explained" if baseline_ok else "unexplained", set(), None, [],
                           float(fit.chi2_red_total), time.perf_counter() - t0)
        located = {s for s, v in explained.items() if v / total >= LOCATED_SHARE}
        top_sweep = max(explained, key=explained.get)
        formula = sorted({canonical(n) for s in located for n, _ in proposals[s]})
        coordinate = coordinate_of(canonical(proposals[top_sweep][0][0]))
        return Outcome([], "unexplained", located, coordinate, formula, chi2_red, time.perf_counter() - t0)


METHODS = {"gyrojax": GyrojaxMethod, "refit_ftest": RefitFTest, "pysindy": PySindy}


# ---------------------------------------------------------------------------------------------------------------
# Scoring

def effect_class(hidden: str | None) -> str:
    if hidden is None:
        return "null"
    return "library" if EFFECTS[hidden].library is not None else "outside"


def sweeps_right(located: set, shares: dict) -> bool:
    """The located sweep set against the hidden effect's visible chi2 shares: every sweep carrying >= SURE_SHARE
    named, none carrying < NONE_SHARE (between, either)."""
    return ({s for s, v in shares.items() if v >= SURE_SHARE} <= set(located)
            <= {s for s, v in shares.items() if v >= NONE_SHARE})


def score(outcome: Outcome, info: dict) -> dict:
    """One lot's scores: found (library effect confirmed; None unless library), wrong (a confirmation that is not
    the hidden library effect), localised (None for null lots), formula (None unless the hidden effect has one),
    explained (None unless null). Beside them, against the generator's noise-free separations
    (`look_alike_chi2`): wrong_separable (a wrong confirmation of an effect the data put >= 3 sigma from the hidden
    one) and found_or_indistinct (found, or a confirmation declared ambiguous with the hidden effect that no method
    could tell from it on this lot); localised_strict (the sweep set exactly those >= LOCATED_SHARE)."""
    hidden = info.get("hidden")
    # a lot from another generator says its class and library effect itself
    cls = info["class"] if "class" in info else effect_class(hidden)
    lib = info["library"] if "library" in info else (EFFECTS[hidden].library if hidden else None)
    found = (lib in outcome.confirmed) if cls == "library" else None
    truth = {lib} if lib else set()
    truth |= set(info.get("formula") or ())  # the closed forms that express the hidden effect
    # a confirmation the method itself declares indistinguishable from the hidden effect (a library effect or a
    # closed form of it) on this data is counted apart ("ambiguous"), not as wrong: it said it could not tell
    wrongs = [c for c in outcome.confirmed if c != lib]
    declared = [c for c in wrongs if truth & set(outcome.ambiguous.get(c, ()))]
    ambiguous = bool(declared)
    wrong = len(declared) < len(wrongs)
    near = info.get("look_alike_chi2") or {}
    wrong_separable = any(near.get(c, math.inf) >= INDISTINCT_CHI2 for c in wrongs)
    found_or_indistinct = None
    if cls == "library":
        found_or_indistinct = bool(found) or (bool(wrongs) and not wrong and all(
            near.get(c, math.inf) < INDISTINCT_CHI2 for c in wrongs))
    localised = confounded = strict = indistinct = None
    if cls != "null":
        shares = info.get("sweep_shares") or {s: 1.0 for s in info["visible_sweeps"]}
        sweeps_ok = sweeps_right(outcome.located, shares)
        localised = bool(found) or (sweeps_ok and outcome.coordinate == info["coordinate"])
        strict = bool(found) or (set(outcome.located) == set(info["visible_sweeps"])
                                 and outcome.coordinate == info["coordinate"])
        # the right sweeps, and the hidden coordinate named with the one given, as confounded with it on this data
        confounded = localised or (sweeps_ok and info["coordinate"] in (outcome.confounded or ()))
        # the right sweeps along a coordinate whose curves take the hidden effect up as well as its own's do
        along = info.get("coordinate_chi2") or {}
        indistinct = localised or (sweeps_ok and outcome.coordinate in along and info["coordinate"] in along
                                   and along[outcome.coordinate] - along[info["coordinate"]] < INDISTINCT_CHI2)
    formula = None
    if hidden and info.get("formula"):
        formula = bool(set(info["formula"]) & set(outcome.formula))
    explained = (outcome.verdict == "explained") if cls == "null" else None
    return {"found": found, "found_or_indistinct": found_or_indistinct, "wrong": wrong,
            "wrong_separable": wrong_separable, "ambiguous": ambiguous, "localised": localised,
            "localised_strict": strict, "localised_or_indistinct": indistinct,
            "localised_or_confounded": confounded, "formula": formula,
            "explained": explained}


def _rate(values):
    vals = [v for v in values if v is not None]
    return (sum(bool(v) for v in vals), len(vals))


def score_rows(records: list) -> list:
    """Table rows per (method, class, snr): counts (k, n) of each score and medians of chi2_red and seconds."""
    groups = {}
    for r in records:
        snr = "-" if r["class"] == "null" else r["snr"]
        groups.setdefault((r["method"], r["class"], snr), []).append(r)
    order = {"library": 0, "outside": 1, "null": 2}
    rows = []
    for (method, cls, snr), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], order[kv[0][1]], kv[0][2])):
        rows.append({"method": method, "class": cls, "snr": snr, "lots": len(rs),
                     "found": _rate(x["scores"]["found"] for x in rs),
                     "found_or_indistinct": _rate(x["scores"].get("found_or_indistinct") for x in rs),
                     "wrong": _rate(x["scores"]["wrong"] for x in rs),
                     "wrong_separable": _rate(x["scores"].get("wrong_separable") for x in rs),
                     "localised_strict": _rate(x["scores"].get("localised_strict") for x in rs),
                     "indistinct": _rate(x["scores"].get("localised_or_indistinct") for x in rs),
                     "ambiguous": _rate(x["scores"].get("ambiguous") for x in rs),
                     "localised": _rate(x["scores"]["localised"] for x in rs),
                     "confounded": _rate(x["scores"].get("localised_or_confounded") for x in rs),
                     "formula": _rate(x["scores"]["formula"] for x in rs),
                     "explained": _rate(x["scores"]["explained"] for x in rs),
                     "chi2_red": float(np.median([x["outcome"]["chi2_red"] for x in rs])),
                     "seconds": float(np.median([x["outcome"]["seconds"] for x in rs]))})
    return rows


def _cell(kn):
    k, n = kn
    return "-" if n == 0 else f"{k}/{n} ({100.0 * k / n:.0f} %)"


def markdown(rows: list) -> str:
    lines = ["| method | class | SNR | lots | library effect found | found, or declared ambiguous where no method "
             "could tell | wrong confirmation | wrong, where the data separate them | confirmed as declared "
             "ambiguous | localised | localised, or along a coordinate no method could tell from it | "
             "localised or named as confounded | formula | "
             "null explained | chi2_red (median) | s per lot (median) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cells = [r["found"], r.get("found_or_indistinct", (0, 0)), r["wrong"], r.get("wrong_separable", (0, 0)),
                 r.get("ambiguous", (0, 0)), r["localised"], r.get("indistinct", (0, 0)),
                 r.get("confounded", (0, 0)), r["formula"], r["explained"]]
        lines.append(f"| {r['method']} | {r['class']} | {r['snr']} | {r['lots']} | "
                     + " | ".join(_cell(c) for c in cells)
                     + f" | {r['chi2_red']:.3f} | {r['seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def _git_describe() -> str | None:
    """The working tree the run used (`git describe --always --dirty`), or None outside a git checkout."""
    import subprocess

    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True, timeout=30,
                              cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def _write_atomic(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


def write_results(directory, stem, payload: dict, table: str):
    """DIR/stem.json (`payload`) and DIR/stem.md (`table`), each rewritten atomically (after every lot)."""
    _write_atomic(os.path.join(directory, stem + ".json"), json.dumps(payload, indent=1, default=str))
    _write_atomic(os.path.join(directory, stem + ".md"), table)


def _parse_seeds(text):
    out = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out += list(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def _list(text, allowed, what):
    items = [x for x in text.split(",") if x]
    bad = [x for x in items if x not in allowed]
    if bad:
        raise SystemExit(f"--{what}: unknown {', '.join(bad)}; expected some of {', '.join(allowed)}.")
    return items


def effect_names(text) -> list:
    """`--effects`: 'all' (the benchmark's 26), 'held-out' (12 written after the guards were tuned), 'fresh' (12
    written after the threshold scans), 'unseen' (12 written after the fresh set's changes), 'blind' (12 written
    without reading the diagnosis's code), 'sealed' (12 more, written without reading the diagnosis's code, after
    the blind set's changes) or names."""
    named = {"all": list(HIDDEN), "held-out": list(HELD_OUT), "fresh": list(FRESH), "unseen": list(UNSEEN),
             "blind": list(BLIND), "sealed": list(SEALED)}
    return named.get(text) or _list(text, list(EFFECTS), "effects")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--methods", default="gyrojax,refit_ftest,pysindy")
    p.add_argument("--snr", default="low,mid,high")
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--designs", default="a,b")
    p.add_argument("--effects", default="all",
                   help="hidden effect names, 'all' (the benchmark's 26), 'held-out' (12 effects written after "
                        "the guards were tuned), 'fresh' (12 more, written after the threshold scans) or "
                        "'unseen' (12 more, written after the fresh set's changes), 'blind' (12 more, written "
                        "without reading the diagnosis's code) or 'sealed' (12 more, written without reading the "
                        "diagnosis's code, after the blind set's changes); null lots always run")
    p.add_argument("--devices", type=int, default=6)
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--preset", default="paper-qmg", help="the preset every method starts from")
    p.add_argument("--out", default="discovery_out")
    p.add_argument("--quick", action="store_true", help="mid SNR, seed 0, design a, a handful of effects")
    a = p.parse_args(argv)
    if a.quick:
        a.snr, a.seeds, a.designs, a.effects = "mid", "0", "a", ",".join(QUICK_EFFECTS)
    methods = _list(a.methods, list(METHODS), "methods")
    snrs = _list(a.snr, list(TARGET_CHI2), "snr")
    designs = _list(a.designs, list(DESIGNS), "designs")
    effects = effect_names(a.effects)
    seeds = _parse_seeds(a.seeds)
    os.makedirs(a.out, exist_ok=True)
    runners = []
    for m in methods:
        inst = METHODS[m](preset=a.preset)
        why = inst.available()
        if why:
            print(why, file=sys.stderr)
        else:
            runners.append(inst)
    cases = [(d, s, None, "-") for d in designs for s in seeds]
    cases += [(d, s, e, snr) for d in designs for s in seeds for snr in snrs for e in effects]
    import jax

    import gyrojax as gj

    settings = {"methods": [m.name for m in runners], "snr": snrs, "seeds": seeds, "designs": designs,
                "effects": effects, "devices": a.devices, "runs": a.runs, "preset": a.preset,
                "target_chi2": TARGET_CHI2, "located_share": LOCATED_SHARE,
                "versions": {"gyrojax": gj.__version__, "jax": jax.__version__, "numpy": np.__version__,
                             "tree": _git_describe()},
                "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "command": " ".join(sys.argv)}
    records, t_start, n_total = [], time.perf_counter(), len(cases) * len(runners)
    settings["skipped"] = []
    for design, seed, hidden, snr in cases:
        try:
            table, info = discovery_lot(hidden, snr="mid" if hidden is None else snr, design=design,
                                        n_devices=a.devices, n_runs=a.runs, seed=seed)
        except ValueError as exc:  # an effect this design's protocol turns into a bias or gain per run
            settings["skipped"].append(f"design {design} seed {seed} {hidden}: {exc}")
            print(f"skipped: design {design} seed {seed} {hidden}: {exc}", flush=True)
            continue
        for m in runners:
            try:
                out = m.run(table)
            except Exception as exc:  # a method that fails on a lot is recorded as failing, never skipped silently
                out = Outcome([], "failed", set(), None, [], math.nan, math.nan, note=f"{type(exc).__name__}: {exc}")
            rec = {"method": m.name, "design": design, "seed": seed, "hidden": hidden, "snr": snr,
                   "class": effect_class(hidden), "info": info,
                   "outcome": {**dataclasses.asdict(out), "located": sorted(out.located),
                               "ambiguous": {k: sorted(v) for k, v in out.ambiguous.items()}},
                   "scores": score(out, info)}
            records.append(rec)
            done = len(records)
            el = time.perf_counter() - t_start
            print(f"[{done}/{n_total}] {m.name} design {design} seed {seed} {hidden or 'null'} {snr}: "
                  f"{out.verdict}, confirmed {out.confirmed or '-'}, located {sorted(out.located) or '-'} "
                  f"on {out.coordinate}, formula {out.formula or '-'}, chi2_red {out.chi2_red:.3f}, "
                  f"{out.seconds:.1f} s; {rec['scores']} | ETA {el / done * (n_total - done) / 60:.1f} min",
                  flush=True)
            rows = score_rows(records)
            write_results(a.out, "discovery", {"settings": settings, "rows": rows, "records": records},
                          "# Discovery benchmark\n\n" + markdown(rows))
    print(markdown(score_rows(records)))


if __name__ == "__main__":
    main()
