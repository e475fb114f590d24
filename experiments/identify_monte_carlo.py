"""Monte Carlo check of identify's uncertainties (issue 4 acceptance).

One device (the preset, no process spread) measured `--draws` times with independent noise: the draws are
the "devices" of one table, so the whole Monte Carlo is one vmapped, compiled identify call. For every free
parameter it compares

- the scatter of the fitted values over the draws (sample standard deviation),
- the standard error identify reports (root-mean-square over the draws),
- the Cramer-Rao bound: sqrt of the diagonal of (J^T J)^-1 with J the weighted Jacobian at the truth
  (identify(..., evaluate_only=True) from the true device).

Acceptance: reported standard errors within 20 % of the scatter, scatter within 1.2x of the CRB.

    python experiments/identify_monte_carlo.py [--draws 100] [--sweeps rate_table,vcf_static,dac] [--runs 2]
                                               [--json OUT]
"""

import argparse
import sys
import time

import numpy as np


def run(draws=100, sweeps=("rate_table", "vcf_static", "dac"), runs=2, seed=0, preset="paper-qmg"):
    """Returns a dict: per parameter `scatter`, `reported`, `crb` (internal units: relative for log
    parameters), the two ratios, and the timings."""
    import gyrojax as gj

    zero = gj.ProcessSpread(omega=0.0, q=0.0, mass=0.0, electrode=0.0, angular_gain=0.0, split=0.0,
                            vcf_electrode=0.0)
    t0 = time.perf_counter()
    table = gj.simulate_table(gj.preset(preset), devices=draws, runs=runs, sweeps=sweeps, seed=seed, spread=zero)
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = gj.identify(preset, table)
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    # The start is the true device: the Jacobian there gives the Cramer-Rao bound.
    at_truth = gj.identify(preset, table, evaluate_only=True)
    t_crb = time.perf_counter() - t0
    free = [i for i, f in enumerate(fit.free) if f]
    u = np.asarray(fit.u)[:, free]
    cov = np.asarray(fit.covariance)[:, free][:, :, free]
    crb = np.asarray(at_truth.covariance)[0][np.ix_(free, free)]
    out = {"draws": draws, "sweeps": list(sweeps), "runs": runs, "converged": int(np.sum(np.asarray(fit.converged))),
           "chi2_red": fit.chi2_red_total, "seconds_simulate": t_sim, "seconds_fit": t_fit,
           "seconds_crb": t_crb, "parameters": {}}
    for k, i in enumerate(free):
        scatter = float(np.std(u[:, k], ddof=1))
        reported = float(np.sqrt(np.mean(cov[:, k, k])))
        bound = float(np.sqrt(crb[k, k]))
        out["parameters"][fit.names[i]] = {
            "scatter": scatter, "reported": reported, "crb": bound,
            "reported_over_scatter": reported / scatter, "scatter_over_crb": scatter / bound,
            "mean_offset_over_scatter": float(np.mean(u[:, k])) / scatter * np.sqrt(draws),
        }
    # and the zero-rate scale factor
    sf = np.asarray(fit.scale_factor)
    out["parameters"]["scale_factor"] = {
        "scatter": float(np.std(sf, ddof=1)),
        "reported": float(np.sqrt(np.mean(np.asarray(fit.scale_factor_stderr)**2))),
        "crb": float(at_truth.scale_factor_stderr[0]),
    }
    p = out["parameters"]["scale_factor"]
    p["reported_over_scatter"] = p["reported"] / p["scatter"]
    p["scatter_over_crb"] = p["scatter"] / p["crb"]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--sweeps", default="rate_table,vcf_static,dac")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the figures as JSON here")
    args = ap.parse_args(argv)
    out = run(args.draws, tuple(s for s in args.sweeps.split(",") if s), args.runs, args.seed)
    print(f"{out['draws']} noise draws of one paper-qmg device, sweeps {', '.join(out['sweeps'])} x {out['runs']} "
          f"run(s): {out['converged']} converged, chi2_red {out['chi2_red']:.3f}; fit {out['seconds_fit']:.1f} s, "
          f"CRB {out['seconds_crb']:.1f} s")
    print(f"{'parameter':>16} {'scatter':>11} {'reported':>11} {'CRB':>11} {'rep/scat':>9} {'scat/CRB':>9}")
    for name, p in out["parameters"].items():
        print(f"{name:>16} {p['scatter']:11.4g} {p['reported']:11.4g} {p['crb']:11.4g} "
              f"{p['reported_over_scatter']:9.3f} {p['scatter_over_crb']:9.3f}")
    if args.json:
        import gyrojax as gj

        gj.io.atomic_write_json(out, args.json)
    ok = all(abs(p["reported_over_scatter"] - 1) <= 0.2 and p["scatter_over_crb"] <= 1.2
             for p in out["parameters"].values())
    print("acceptance (reported within 20 % of scatter, scatter within 1.2x CRB):", "PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
