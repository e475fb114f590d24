#!/usr/bin/env python
"""Does a second lot of the same shapes reuse the first lot's compiled fit? `identify` of lot A, then of lot B:
the same table with other device names, other run ids and another source (a script, not a test).

    python benchmarks/bench_relabel.py [--devices 2] [--runs 2]

Lot A is a simulated paper-qmg lot (rate table + static virtual-Coriolis sweeps). It is fitted twice (the
second time every program is traced and compiled already: the floor), then lot B once; then both without their
`output_sigma` column (the noise is estimated: two fits each). JAX's monitoring events
count the top-level traces and sum their time during each fit: a fit that reuses every trace shows 0 traces
and takes the floor's time.

Measured on 2 CPU cores shared with other work (persistent compilation cache warm), wall time, traces (their
time) per fit; chi2 identical in both versions:

    fit                before (labels stripped, weighted kept)   after (FitData.unlabelled(): weighted too)
    A (first)          30.5-74.6 s  51 traces                     56.1 s  51 traces (46.5 s)
    A (again)           0.5 s        0                             0.2 s   0
    B (relabelled)      0.5 s        0                             0.2 s   0
    A, no sigma        86.8 s       17 traces (70.2 s)            1.0 s  14 traces (0.0 s: the noise estimate's
                                                                                    small NumPy-side ops)
    B, no sigma         1.7 s        0                             0.5 s   0
"""

import argparse
import time

import jax
import numpy as np


TRACE = "/jax/core/compile/jaxpr_trace_duration"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, default=2)
    parser.add_argument("--runs", type=int, default=2)
    args = parser.parse_args()
    record = {"on": False, "traces": 0, "trace_s": 0.0}

    def duration(event, secs, **kw):
        if record["on"] and event == TRACE:
            record["traces"] += 1
            record["trace_s"] += secs

    jax.monitoring.register_event_duration_secs_listener(duration)
    import gyrojax as gj

    a = gj.simulate_table(gj.preset("paper-qmg"), devices=args.devices, runs=args.runs,
                          sweeps=("rate_table", "vcf_static"), seed=3, progress=False)
    cols = dict(a.columns)
    cols["device"] = np.asarray([f"B{d}" for d in cols["device"]])
    cols["run"] = cols["run"] + 100
    b = gj.Table(cols, source="another_lot.csv")
    unweighted = [gj.Table({k: v for k, v in t.columns.items() if k != "output_sigma"}, source=t.source + "'")
                  for t in (a, b)]
    for name, table in (("A (first)", a), ("A (again)", a), ("B (relabelled)", b),
                        ("A, no sigma", unweighted[0]), ("B, no sigma", unweighted[1])):
        record.update(on=True, traces=0, trace_s=0.0)
        t = time.perf_counter()
        fit = gj.identify("paper-qmg", table, progress=False)
        wall = time.perf_counter() - t
        record["on"] = False
        print(f"{name:16s} {wall:7.1f} s   {record['traces']:4d} traces ({record['trace_s']:.1f} s)   "
              f"devices {fit.devices}   chi2 {np.round(np.asarray(fit.chi2), 6)}")


if __name__ == "__main__":
    main()
