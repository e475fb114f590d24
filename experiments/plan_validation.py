"""The planner's promises against simulation: its scale-factor design against a Monte Carlo of actual fits
(`sf`), and its effect plan against simulated detections (`detection`).

`gyrojax.plan` predicts, from the Fisher information of a baseline fit, the scale factor's standard error of
seed 000's 22-rate protocol and of its own design at equal test time. Here both protocols are simulated on
`DEVICES` identical paper-qmg devices (no process spread: each device is an independent noise draw of the
same truth), each device is fitted with `gyrojax.identify`, and the spread of the fitted scale factors over
the devices is compared with the prediction (its Monte Carlo uncertainty: std / sqrt(2 (N - 1))).

**Detections.** For an (effect, experiment) pair, `gyrojax.plan` predicts on the data given (one rate-table
run of one paper-qmg device) the expected chi2 `lambda` that a typical-size effect leaves for the score test
after one run of the experiment is added, and so the test's power at alpha = 0.01. The effect is set to the size
at which the predicted power is `TARGET_POWER` (lambda scales with the size squared), the data given plus one
run of the experiment are simulated for `SEEDS` noise seeds, and the diagnosis's own score test at the
baseline (`gyrojax.diagnose(..., max_effects=0)`: its ranking, no refit) is counted: the detection fraction
against the predicted power, the mean statistic against df + lambda.

Run: `python experiments/plan_validation.py sf [DEVICES [OUT.json]]` (about 15 minutes on a 2-core CPU, most of
it compiling) or
`python experiments/plan_validation.py detection [OUT.json]` (about 5 minutes once compiled);
`python experiments/plan_validation.py more SEED DEVICES PREVIOUS.json OUT.json` adds a Monte Carlo draw to
an `sf` run's JSON (pooled).
"""

import json
import math
import sys
import time

import numpy as np
from scipy.stats import chi2, ncx2

import gyrojax as gj


DEVICES = 16


def spread(rates_dps, runs, seed):
    table = gj.simulate_table(gj.preset("paper-qmg"), devices=DEVICES, runs=runs, rates_dps=rates_dps, seed=seed,
                              spread=gj.ProcessSpread(omega=0.0, q=0.0, mass=0.0, electrode=0.0, angular_gain=0.0,
                                                      split=0.0, vcf_electrode=0.0), progress=False)
    fit = gj.identify("paper-qmg", table, progress=False)
    sf = np.asarray(fit.scale_factor)
    return float(np.std(sf, ddof=1)), float(np.mean(np.asarray(fit.scale_factor_stderr))), fit.status


def scale_factor(devices=None, out=None):
    global DEVICES
    DEVICES = devices or DEVICES
    t0 = time.time()
    given = gj.simulate_table(gj.preset("paper-qmg"), runs=2, seed=1, progress=False)
    plan = gj.plan("paper-qmg", given, max_repeats=2, progress=False)
    design = plan.scale_factor
    print(plan.summary())
    print(f"[{time.time() - t0:.0f} s] Monte Carlo, {DEVICES} devices per protocol")
    rows = []
    for name, rates, runs, predicted in (
            ("seed 000", None, design.seed000_runs, float(np.mean(design.seed000_stderr))),
            ("design", design.rates_dps, design.rate_runs, float(np.mean(design.stderr)))):
        sd, fit_se, status = spread(rates, runs, seed=11)
        mc = sd / math.sqrt(2 * (DEVICES - 1))
        rows.append((name, runs, predicted, sd, mc, fit_se))
        print(f"[{time.time() - t0:.0f} s] {name}: {runs} run(s); predicted stderr {predicted:.4g}, Monte Carlo "
              f"std {sd:.4g} +/- {mc:.2g} ({(sd - predicted) / mc:+.2f} sigma), the fits' own stderr "
              f"{fit_se:.4g}; statuses {sorted(set(status))}")
    ratio_pred = rows[1][2] / rows[0][2]
    ratio_mc = rows[1][3] / rows[0][3]
    ratio_unc = ratio_mc * math.sqrt((rows[0][4] / rows[0][3]) ** 2 + (rows[1][4] / rows[1][3]) ** 2)
    print(f"stderr ratio design / seed 000: predicted {ratio_pred:.3f}, Monte Carlo {ratio_mc:.3f} +/- "
          f"{ratio_unc:.2f}")
    if out:
        gj.io.atomic_write_json({"devices": DEVICES, "seed_of_the_data_given": 1, "seed_of_the_monte_carlo": 11,
                              "rows": [dict(zip(("protocol", "runs", "predicted_stderr", "mc_std", "mc_std_unc",
                                                 "fits_stderr"), r)) for r in rows],
                              "ratio_predicted": ratio_pred, "ratio_mc": ratio_mc, "ratio_mc_unc": ratio_unc,
                              "design": design.to_json()}, out)
        print(f"wrote {out}")


def more_monte_carlo(seed, devices, previous, out):
    """Another Monte Carlo draw (`seed`, `devices`) of the two protocols of a previous `sf` run's JSON, pooled
    with it: the scatter's variance averaged over the draws (each with its own mean), its uncertainty
    std / sqrt(2 (N - draws))."""
    global DEVICES
    DEVICES = devices
    with open(previous) as f:
        prev = json.load(f)
    design = prev["design"]
    draws = prev.get("draws", [{"seed": prev["seed_of_the_monte_carlo"], "devices": prev["devices"],
                                "mc_std": [r["mc_std"] for r in prev["rows"]]}])
    new = []
    for row, rates, runs in zip(prev["rows"], (None, tuple(design["rates_dps"])),
                                (design["seed000"]["runs"], design["rate_runs"])):
        sd, fit_se, status = spread(rates, runs, seed=seed)
        new.append(sd)
        print(f"{row['protocol']}: seed {seed}, {devices} devices: std {sd:.4g}; statuses {sorted(set(status))}")
    draws.append({"seed": seed, "devices": devices, "mc_std": new})
    rows = []
    for k, row in enumerate(prev["rows"]):
        n = sum(d["devices"] for d in draws)
        var = sum((d["devices"] - 1) * d["mc_std"][k] ** 2 for d in draws) / (n - len(draws))
        sd = math.sqrt(var)
        rows.append({**row, "mc_std": sd, "mc_std_unc": sd / math.sqrt(2 * (n - len(draws))), "devices": n})
        print(f"{row['protocol']}: pooled over {n} devices: std {sd:.4g} +/- {rows[-1]['mc_std_unc']:.2g}, "
              f"predicted {row['predicted_stderr']:.4g} ({row['predicted_stderr'] / sd:.3f} x)")
    ratio_mc = rows[1]["mc_std"] / rows[0]["mc_std"]
    ratio_unc = ratio_mc * math.hypot(rows[0]["mc_std_unc"] / rows[0]["mc_std"],
                                      rows[1]["mc_std_unc"] / rows[1]["mc_std"])
    print(f"stderr ratio design / seed 000: predicted {prev['ratio_predicted']:.3f}, Monte Carlo {ratio_mc:.3f} "
          f"+/- {ratio_unc:.3f}")
    gj.io.atomic_write_json({**prev, "rows": rows, "draws": draws, "ratio_mc": ratio_mc, "ratio_mc_unc": ratio_unc},
                         out)


SEEDS = 16
ALPHA = 0.01
TARGET_POWER = 0.6
PAIRS = (("quadrature_phase", "vcf_dynamic"),)


def size_for_power(lam_typical, df, target):
    """The multiple of the typical size whose expected chi2 gives `target` power."""
    crit = chi2.isf(ALPHA, df)
    lo, hi = 0.0, 1e6
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if ncx2.sf(crit, df, mid) < target:
            lo = mid
        else:
            hi = mid
    return math.sqrt(hi / lam_typical), hi


def detection(effect, experiment, t0):
    gyro = gj.preset("paper-qmg")
    given = gj.simulate_table(gyro, runs=1, seed=1, progress=False)
    exps = tuple(e for e in gj.default_experiments(gyro) if e.name == experiment)
    plan = gj.plan("paper-qmg", given, candidates=(effect,), experiments=exps, max_repeats=1, progress=False)
    cand = plan.candidate(effect)
    lam_typical = {g.name: g.expected_chi2 for g in cand.per_experiment}[experiment]
    multiple, lam = size_for_power(lam_typical, cand.df, TARGET_POWER)
    print(f"[{time.time() - t0:.0f} s] {effect} with 1 x {experiment}: planner chi2 at typical size "
          f"{lam_typical:.4g} (df {cand.df}; {cand.expected_chi2:.3g} on the data given); size {multiple:.4g} x "
          f"typical gives lambda {lam:.3g}, power {TARGET_POWER}")
    model = gj.Model(gyro, (gj.EFFECTS[effect].typical(multiple),))
    truth = model.gyroscope()
    stats, pvals, seen = [], [], []
    for seed in range(SEEDS):
        table = gj.simulate_table(truth, runs=1, sweeps=("rate_table", experiment), seed=100 + seed, progress=False)
        diag = gj.diagnose("paper-qmg", table, candidates=(effect,), max_effects=0, progress=False)
        score = next(s for s in diag.ranking if s.effect == effect)
        stats.append(float(score.statistic))
        pvals.append(float(score.p_value))
        seen.append(float(score.typical_chi2))
        print(f"[{time.time() - t0:.0f} s]   seed {seed}: statistic {score.statistic:.3g} (df {score.df}), "
              f"p {score.p_value:.3g}; typical-size chi2 at this baseline {score.typical_chi2:.3g}")
    stats, pvals = np.asarray(stats), np.asarray(pvals)
    detected = float(np.mean(pvals < ALPHA))
    row = {"effect": effect, "experiment": experiment, "runs_added": 1, "seeds": SEEDS, "alpha": ALPHA,
           "size_multiple_of_typical": multiple, "df": cand.df,
           "planned_chi2_typical": lam_typical, "planned_chi2": lam, "planned_power": TARGET_POWER,
           "planned_mean_statistic": cand.df + lam,
           "mean_statistic": float(np.mean(stats)),
           "mean_statistic_stderr": float(np.std(stats, ddof=1) / math.sqrt(SEEDS)),
           "detected_fraction": detected,
           "detected_fraction_stderr": math.sqrt(TARGET_POWER * (1 - TARGET_POWER) / SEEDS),
           "statistics": stats.tolist(), "typical_chi2_at_each_baseline": seen}
    print(f"[{time.time() - t0:.0f} s] {effect}: detected {detected:.2f} (planned {TARGET_POWER} +/- "
          f"{row['detected_fraction_stderr']:.2f}); mean statistic {row['mean_statistic']:.3g} +/- "
          f"{row['mean_statistic_stderr']:.2g} (planned df + lambda = {cand.df + lam:.3g})")
    return row


def detections(out=None):
    t0 = time.time()
    rows = [detection(effect, experiment, t0) for effect, experiment in PAIRS]
    if out:
        gj.io.atomic_write_json({"pairs": rows, "seed_of_the_data_given": 1,
                              "seeds": list(range(100, 100 + SEEDS))}, out)
        print(f"wrote {out}")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what == "sf":
        scale_factor(int(sys.argv[2]) if len(sys.argv) > 2 else None, sys.argv[3] if len(sys.argv) > 3 else None)
    elif what == "more":
        more_monte_carlo(int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5])
    elif what == "detection":
        detections(sys.argv[2] if len(sys.argv) > 2 else None)
    else:
        sys.exit("usage: python experiments/plan_validation.py sf [DEVICES [OUT.json]] | more SEED DEVICES "
                 "PREVIOUS.json OUT.json | detection [OUT.json]")
