"""Coverage audit of identify's 95 % intervals (issue 38 point 3) on the demo's campaign: 3 paper-qmg devices x 2
runs, rate table, static VCF sweep and DAC sweep, seed 7 (the campaign of `gyrojax demo`).

Run: python experiments/coverage_audit.py [--draws 100] [--seeds 0 1 2] [--out DIR]

Two lots: the campaign on the plain paper-qmg device fitted with the baseline model, and the demo's lot (a DAC
INL hidden, `dac_inl` at its typical size) fitted with the effect added (the model the demo's diagnosis ends
with, its INL coefficients free from zero). `gyrojax.coverage` simulates each fit `--draws` times with the data's
noise, refits every draw (one vmapped identify) and reports per free parameter, per effect coefficient and for
the scale factor the share of 95 % Wald intervals that cover the values the draws came from, with its binomial
standard error; `undercovered` names those below 93 %.
"""

import argparse
import math
import os
import sys
import time

import gyrojax as gj


LOT = {"devices": 3, "runs": 2, "sweeps": ("rate_table", "vcf_static", "dac"), "seed": 7}
"""The demo's campaign (what `gyrojax demo` simulates)."""


def audit(hidden: bool, draws: int, seeds=(0,)):
    """(fit, [Coverage per seed], pooled report) of one lot: plain (`hidden` False) or with the demo's hidden DAC
    INL fitted; each seed's draws refitted separately, their intervals pooled."""
    truth = gj.add_effect(gj.paper_qmg(), "dac_inl") if hidden else gj.paper_qmg()
    table = gj.simulate_table(truth, progress=False, **LOT)
    model = gj.Model(gj.paper_qmg(), (gj.effect("dac_inl", 0.0),)) if hidden else "paper-qmg"
    fit = gj.identify(model, table, progress=False)
    audits = [gj.coverage(fit, draws=draws, seed=seed) for seed in seeds]
    pooled = {}
    for k, name in enumerate(audits[0].names):
        n = sum(int(a.count[k]) for a in audits)
        cov = sum(float(a.coverage[k]) * int(a.count[k]) for a in audits) / n
        z = math.sqrt(sum(float(a.z_rms[k]) ** 2 * int(a.count[k]) for a in audits) / n)
        pooled[name] = {"coverage_95": cov, "count": n, "binomial_se": math.sqrt(0.95 * 0.05 / n), "z_rms": z,
                        "per_seed": [float(a.coverage[k]) for a in audits]}
    return fit, audits, pooled


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=100, help="simulated lots per seed (default 100: 300 intervals)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="PRNG seeds of the draws' noise, pooled")
    ap.add_argument("--out", help="folder for coverage_audit.json")
    args = ap.parse_args(argv)
    out = {}
    for label, hidden in (("demo campaign, baseline model", False), ("demo lot, DAC INL hidden and fitted", True)):
        t = time.perf_counter()
        fit, audits, pooled = audit(hidden, args.draws, tuple(args.seeds))
        print(f"{label}: fit {fit.status}, {time.perf_counter() - t:.0f} s")
        for a in audits:
            print(a.summary())
        print("pooled over the seeds:")
        for name, p in pooled.items():
            flag = "" if 0.93 <= p["coverage_95"] <= 0.97 else "  OUTSIDE 93-97 %"
            print(f"  {name}: {p['coverage_95'] * 100:.1f} % (+/- {p['binomial_se'] * 100:.1f} %) of {p['count']}, "
                  f"z RMS {p['z_rms']:.2f}{flag}", flush=True)
        out[label] = {"pooled": pooled, "per_seed": [a.report() for a in audits], "seeds": args.seeds,
                      "seconds": time.perf_counter() - t, "status": list(fit.status)}
        if args.out:
            os.makedirs(args.out, exist_ok=True)
            gj.io.atomic_write_json(out, os.path.join(args.out, "coverage_audit.json"))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
