#!/usr/bin/env python
"""The population fit's time against the independent fit's, at a few lot sizes (a script, not a test).

    python benchmarks/bench_population.py [--sizes 8 32 128] [--json PATH]

The data per size: a simulated paper-qmg lot (rate table and static VCF sweep, 1 run, seed 7, electrodes
spread 1 %, mass and Ag not spread), a quarter of its devices without a rate table. Timed, one after another in
one process (each compiles on its first call; both share the fit's compiled program at one size): the
independent fit `identify(..., lot_solve=VmapSolve())` and the population fit
`identify(..., lot_solve=PopulationSolve(random=("k_vf",)))`, each twice (the second call is warm). The
population fit is a first fit, one refit per iteration (one here: the model is linear in log k_vf to round-off)
and two refits for the scale factor's sensitivity to the lot mean and spread (`propagate=True`; `propagate=False`
drops them). The independent fit of a lot with rate-table-less devices leaves their scale factor undetermined and
retries them (`RetryWithSolver`), so it is not the lower bound it looks like. Measured on the loaded 2-core VM
(`--sizes 8 16`, warm): independent 24.6 s and 116 s, population 0.8 s and 5.4 s (propagate off: 0.5 s, 1.8 s):
timings under load, not a 1,000-device figure. Printed per size: the times and their ratios; `--json` is
written atomically.
"""

import argparse
import platform
import time


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 32, 128])
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)

    import jax
    import numpy as np

    import gyrojax as gj

    print(f"gyrojax {gj.__version__}, jax {jax.__version__}, {platform.machine()} {jax.default_backend()}")
    spread = gj.ProcessSpread(mass=0.0, angular_gain=0.0)
    rows = []
    for n in args.sizes:
        table = gj.simulate_table(gj.paper_qmg(), devices=n, runs=1, sweeps=("rate_table", "vcf_static"), seed=7,
                                  spread=spread, progress=False)
        names = list(dict.fromkeys(table["device"].tolist()))
        drop = set(names[: n // 4])
        keep = [i for i, (d, s) in enumerate(zip(table["device"].tolist(), table["sweep"].tolist()))
                if not (s == "rate_table" and d in drop)]
        table = table.select(keep)
        row = {"devices": n, "without_rate_table": len(drop)}
        for label, solve in (("independent", gj.VmapSolve()),
                             ("population", gj.PopulationSolve(random=("k_vf",))),
                             ("population_no_propagate", gj.PopulationSolve(random=("k_vf",), propagate=False))):
            times = []
            for _ in range(2):
                t = time.perf_counter()
                out = gj.identify("paper-qmg", table, lot_solve=solve, progress=False)
                times.append(time.perf_counter() - t)
            row[label] = {"first_s": times[0], "warm_s": times[1]}
            if label == "population":
                p = out.parameters[0]
                row[label] |= {"converged": out.converged, "refits": out.refits,
                               "k_vf_relative_spread": p.relative_spread,
                               "k_vf_relative_spread_stderr": p.spread_stderr / p.mean,
                               "predicted_sf_rel_stderr": float(np.median(
                                   np.asarray(out.sf_stderr)[: n // 4] / np.asarray(out.sf)[: n // 4]))}
        row["ratio_warm"] = row["population"]["warm_s"] / row["independent"]["warm_s"]
        row["ratio_warm_no_propagate"] = row["population_no_propagate"]["warm_s"] / row["independent"]["warm_s"]
        rows.append(row)
        print(f"{n:5d} devices: independent {row['independent']['first_s']:.1f} s / {row['independent']['warm_s']:.1f}"
              f" s warm; population {row['population']['first_s']:.1f} / {row['population']['warm_s']:.1f} s "
              f"(x{row['ratio_warm']:.2f} warm), without propagate "
              f"{row['population_no_propagate']['warm_s']:.1f} s (x{row['ratio_warm_no_propagate']:.2f})", flush=True)
        if args.json:
            gj.atomic_write_json({"rows": rows, "machine": platform.platform()}, args.json)
    return rows


if __name__ == "__main__":
    main()
