#!/usr/bin/env python
"""A lot whose solves run off: identify on open-loop vcf-2018 devices with the run-off stop and without it
(a script, not a test).

    python benchmarks/bench_runoff.py [--devices 3] [--runs 2] [--seed 7] [--json PATH]

The lot: `vcf-2018` (seed 003's open-loop device) with the default process spread, measured with the rate table,
the static and the dynamic virtual-Coriolis sweeps (`experiments/diagnose_confusion.py`'s sweeps for this preset),
noise on; `diagnose`'s default free parameters. The preset's sense resonance is ~0.1 Hz wide and the spread moves
it by several widths, so from the preset most devices' first solve runs Q_y off towards infinity before omega_y
is right; `RestartRunoffs` then solves them again with Q_y held, then released.

Two settings, each in a fresh process with an empty compilation cache of its own (the run-off bound is a
constant of the compiled solve): the default (`gyrojax._identify.strategies.RUNOFF_LOG` = 20: a solve stops, as
diverged, once a positive parameter passes e^20 times its start) and none (`inf`: it creeps on to `max_steps`
while the vmapped lot waits for it). Each process simulates the lot, then runs `identify` twice: the first call
(compile included) and the second (timed: the run). Printed: the run time, the first call, each device's LM steps
(all solves) and status, chi2, and the largest difference between the two settings' fitted parameters in
standard errors. `--json` is written atomically.
"""

import argparse
import json
import math
import os
import platform
import time

from _fresh import run_fresh


SWEEPS = ("rate_table", "vcf_static", "vcf_dynamic")


def _worker(bound, devices, runs, seed, out):
    import numpy as np

    import gyrojax as gj
    from gyrojax._identify import strategies as lot  # RUNOFF_LOG, read at each fit

    lot.RUNOFF_LOG = float(bound)
    g = gj.preset("vcf-2018")
    table = gj.simulate_table(g, devices=devices, runs=runs, sweeps=SWEEPS, seed=seed, progress=False)
    free = None  # identify's default: DEFAULT_FREE and what the sweeps read (the dynamic VCF's angular gain)
    t0 = time.perf_counter()
    gj.identify(g, table, free=free, progress=False)
    t1 = time.perf_counter()
    fit = gj.identify(g, table, free=free, progress=False)
    t2 = time.perf_counter()
    record = {"bound": bound, "first_s": t1 - t0, "run_s": t2 - t1, "steps": np.asarray(fit.num_steps).tolist(),
              "status": list(fit.status), "chi2_red": float(fit.chi2_red_total), "names": list(fit.names),
              "values": np.asarray(fit.values).tolist(), "stderr": np.asarray(fit.stderr).tolist(),
              "notes": list(fit.result_message)}
    with open(out, "w") as f:
        json.dump(record, f)


def _run(bound, args):
    return run_fresh(__file__, ["--worker", str(bound), "--devices", str(args.devices), "--runs", str(args.runs),
                                "--seed", str(args.seed)])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", type=int, default=3)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--result", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker is not None:
        _worker(float(args.worker), args.devices, args.runs, args.seed, args.result)
        return
    import numpy as np

    import gyrojax as gj

    print(f"gyrojax {gj.__version__}, python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()}")
    print(f"vcf-2018, {args.devices} device(s) x {args.runs} run(s), sweeps {', '.join(SWEEPS)}, seed {args.seed}")
    results = {}
    for name, bound in (("run-off stop (e^20)", 20.0), ("none", math.inf)):
        r = _run(bound, args)
        results[name] = r
        print(f"{name:>20}: run {r['run_s']:6.2f} s, first call {r['first_s']:6.1f} s, LM steps {r['steps']}, "
              f"chi2_red {r['chi2_red']:.4f}, status {r['status']}", flush=True)
    a, b = (results[k] for k in results)
    du = np.abs(np.asarray(a["values"]) - np.asarray(b["values"])) / np.asarray(a["stderr"])
    worst = float(np.nanmax(du)) if np.isfinite(du).any() else float("nan")
    print(f"largest difference between the two fits: {worst:.2g} standard errors; run time ratio "
          f"{b['run_s'] / a['run_s']:.2f}x")
    if args.json:
        tmp = args.json + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"results": results, "worst_sigma": worst, "devices": args.devices, "runs": args.runs,
                       "seed": args.seed, "load_average": os.getloadavg()}, f, indent=1)
        os.replace(tmp, args.json)


if __name__ == "__main__":
    main()
