#!/usr/bin/env python
"""The population fit's time against the independent fit's, at a few lot sizes (a script, not a test).

    python benchmarks/bench_population.py [--sizes 8 32 128] [--with-undetermined] [--json PATH]

The data per size: a simulated paper-qmg lot (rate table and static VCF sweep, 1 run, seed 7, electrodes
spread 1 %, mass and Ag not spread). Timed, one after another in one process, each twice (the first call
compiles, the second is warm):

- `independent`: `identify(..., lot_solve=VmapSolve())` of the lot, every device with its rate table;
- `population`: `identify(..., lot_solve=PopulationSolve(random=("k_vf",)))` of the same data: a first fit
  (weak prior), one refit with the lot as prior (the model is linear in log k_vf to round-off, so one refit
  converges), and one evaluation per lot mean and spread for the scale factors' sensitivity to them
  (`propagate=True`; the solution moved to first order, no refit);
- `population_predicting`: the same with a quarter of the devices without a rate table (their scale factors
  predicted from the lot);
- `--with-undetermined`: also the independent fit of that lot, whose rate-table-less devices have no
  determined scale factor: Levenberg-Marquardt crawls along their null direction to `max_steps` and is
  retried (`RetryWithSolver`), which makes it many times slower than the fit of determined devices and no
  useful baseline (measured at 16 devices: 116 s against the population fit's 5.4 s).

Printed per size: the warm times and the ratio population / independent; `--json` is written atomically.
"""

import argparse
import platform
import time


def _timed(fn, repeats=2):
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return {"first_s": times[0], "warm_s": times[-1]}, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 32, 128])
    ap.add_argument("--with-undetermined", action="store_true",
                    help="also time the independent fit of the lot with rate-table-less devices (slow)")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)

    import jax
    import numpy as np

    import gyrojax as gj

    print(f"gyrojax {gj.__version__}, jax {jax.__version__}, {platform.machine()} {jax.default_backend()}")
    spread = gj.ProcessSpread(mass=0.0, angular_gain=0.0)
    rows = []
    for n in args.sizes:
        full = gj.simulate_table(gj.paper_qmg(), devices=n, runs=1, sweeps=("rate_table", "vcf_static"), seed=7,
                                 spread=spread, progress=False)
        names = list(dict.fromkeys(full["device"].tolist()))
        drop = set(names[: n // 4])
        keep = [i for i, (d, s) in enumerate(zip(full["device"].tolist(), full["sweep"].tolist()))
                if not (s == "rate_table" and d in drop)]
        missing = full.select(keep)
        row = {"devices": n, "without_rate_table": len(drop)}
        solve = gj.PopulationSolve(random=("k_vf",))
        row["independent"], fit = _timed(lambda: gj.identify("paper-qmg", full, progress=False))
        row["independent"]["max_lm_steps"] = int(np.max(np.asarray(fit.num_steps)))
        row["population"], pf = _timed(lambda: gj.identify("paper-qmg", full, lot_solve=solve, progress=False))
        row["population"] |= {"converged": pf.converged, "refits": pf.refits}
        row["population_predicting"], pf = _timed(lambda: gj.identify("paper-qmg", missing, lot_solve=solve,
                                                                      progress=False))
        p = pf.parameters[0]
        # the devices without a rate table by what the fit says they miss (identify orders devices by first
        # appearance in the table, so they are not the first ones there)
        predicted = np.array([bool(m) for m in pf.missing])
        row["population_predicting"] |= {
            "converged": pf.converged, "refits": pf.refits, "k_vf_relative_spread": p.relative_spread,
            "k_vf_relative_spread_stderr": p.spread_stderr / p.mean, "predicted": int(predicted.sum()),
            "predicted_sf_rel_stderr": float(np.median(np.asarray(pf.sf_stderr)[predicted]
                                                       / np.asarray(pf.sf)[predicted]))}
        if args.with_undetermined:
            row["independent_undetermined"], _ = _timed(lambda: gj.identify("paper-qmg", missing, progress=False))
        row["ratio_warm"] = row["population"]["warm_s"] / row["independent"]["warm_s"]
        row["ratio_warm_predicting"] = row["population_predicting"]["warm_s"] / row["independent"]["warm_s"]
        rows.append(row)
        print(f"{n:5d} devices: independent {row['independent']['first_s']:.1f} s / {row['independent']['warm_s']:.1f}"
              f" s warm; population {row['population']['first_s']:.1f} / {row['population']['warm_s']:.1f} s "
              f"(x{row['ratio_warm']:.2f} warm); with {len(drop)} predicted "
              f"{row['population_predicting']['warm_s']:.1f} s warm (x{row['ratio_warm_predicting']:.2f})",
              flush=True)
        if args.json:
            gj.io.atomic_write_json({"rows": rows, "machine": platform.platform()}, args.json)
    return rows


if __name__ == "__main__":
    main()
