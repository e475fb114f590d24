#!/usr/bin/env python
"""Lots of nearby sizes in one session: identify (or diagnose, or simulate_table) on lots of 3, 4, 2 and 5
devices, one after another, with the lot padded to the next power of two (the default for a lot of up to 16
devices) and without it (`gyrojax._lots.stack.BUCKET_MAX = 0`, as `VmapSolve(bucket=False)`; a script, not a test).

    python benchmarks/bench_lot_sizes.py [--entry identify|diagnose|simulate_table] [--sizes 3 4 2 5] [--repeats 3]
                                         [--json PATH]

The data: one simulated paper-qmg campaign of max(sizes) devices (the demo's sweeps: rate table, static VCF and
DAC, 2 runs, seed 7, noise on; for `diagnose`, with a typical DAC INL hidden, as in the demo); each call fits
(or diagnoses) the table's first `n` devices with the entry's defaults, as a notebook does when it refits a lot
without a device or fits the next lot; `simulate_table` simulates a campaign of `n` devices. Each setting runs
in a fresh process with an empty compilation cache of its own, so every lot size either reuses a compiled
program of that process or traces and compiles one. Printed per setting: each call's wall time, then the first
size again `--repeats` times (the run alone, warm: what the padding devices cost), and the largest difference
between the two settings' fitted values (or simulated outputs). `--json` is written atomically.
"""

import argparse
import json
import os
import platform
import time

from _fresh import run_fresh


def _worker(entry, bucket, sizes, repeats, out):
    import numpy as np

    import gyrojax as gj
    from gyrojax._cli.demo_job import DEMO_LOT

    gyro = gj.add_effect(gj.paper_qmg(), "dac_inl") if entry == "diagnose" else gj.paper_qmg()
    if not bucket:  # as VmapSolve(bucket=False), for diagnose's fits and the settle too (nothing compiled yet)
        from gyrojax._lots import stack as _lot
        _lot.BUCKET_MAX = 0
    if entry != "simulate_table":
        table = gj.simulate_table(gyro, **{**DEMO_LOT, "devices": max(sizes)}, progress=False)
        names = sorted(set(np.asarray(table["device"]).tolist()))

    def call(n):
        t = time.perf_counter()
        if entry == "simulate_table":
            out = gj.simulate_table(gyro, **{**DEMO_LOT, "devices": n}, progress=False)["output"]
            return time.perf_counter() - t, ["ok"], out
        sub = table.select(np.flatnonzero(np.isin(np.asarray(table["device"]), names[:n])))
        if entry == "diagnose":
            f = gj.diagnose("paper-qmg", sub, progress=False).final
        else:
            f = gj.identify("paper-qmg", sub, progress=False)
        return time.perf_counter() - t, list(f.status), f.values

    calls, values = [], {}
    for n in sizes:
        secs, status, v = call(n)
        calls.append({"devices": n, "seconds": secs, "status": status})
        values[n] = np.asarray(v).tolist()
    warm = [call(sizes[0])[0] for _ in range(repeats)]
    with open(out, "w") as fh:
        json.dump({"bucket": bucket, "calls": calls, "warm_s": warm, "values": values}, fh)


def _run(bucket, args):
    return run_fresh(__file__, ["--entry", args.entry, "--worker", str(int(bucket)), "--repeats", str(args.repeats),
                                "--sizes", *map(str, args.sizes)])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--entry", choices=("identify", "diagnose", "simulate_table"), default="identify")
    ap.add_argument("--sizes", type=int, nargs="+", default=[3, 4, 2, 5])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--result", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if any(n < 1 for n in args.sizes) or args.repeats < 1:
        ap.error("--sizes must be device counts >= 1 and --repeats >= 1")
    if args.worker is not None:
        _worker(args.entry, args.worker == "1", args.sizes, args.repeats, args.result)
        return
    import numpy as np

    import gyrojax as gj

    print(f"gyrojax {gj.__version__}, python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()}")
    print(f"{args.entry}: paper-qmg, the demo's sweeps, sub-lots of {args.sizes} devices, one process per setting")
    results = {}
    for name, bucket in (("bucket (default)", True), ("no bucket", False)):
        r = _run(bucket, args)
        results[name] = r
        calls = ", ".join(f"{c['devices']}: {c['seconds']:.1f} s" for c in r["calls"])
        warm = ", ".join(f"{s:.2f}" for s in r["warm_s"])
        print(f"{name:>16}: {calls}; {args.sizes[0]} devices again, warm: {warm} s", flush=True)
    a, b = (results[k] for k in results)
    worst = max(float(np.max(np.abs(np.asarray(a["values"][k]) - np.asarray(b["values"][k]))
                             / np.maximum(np.abs(np.asarray(b["values"][k])), 1e-300)))
                for k in a["values"])
    total = [sum(c["seconds"] for c in r["calls"]) for r in (a, b)]
    print(f"all calls: {total[0]:.1f} s against {total[1]:.1f} s; largest relative difference between the two "
          f"settings' fitted values: {worst:.2g}")
    if args.json:
        tmp = args.json + ".tmp"
        with open(tmp, "w") as f:
            json.dump({"entry": args.entry, "results": results, "worst_relative": worst, "sizes": args.sizes,
                       "load_average": os.getloadavg()}, f, indent=1)
        os.replace(tmp, args.json)


if __name__ == "__main__":
    main()
