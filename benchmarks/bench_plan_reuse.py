#!/usr/bin/env python
"""Does a plan on a second lot of the same shapes reuse the first plan's compiled Jacobians? `gj.plan(fit=...)`
on lot A, then on lot B (a script, not a test).

    python benchmarks/bench_plan_reuse.py [--effects agc_finite_gain,dac_inl] [--devices 1] [--json PATH]

Each lot is simulated paper-qmg (rate table + static VCF + DAC, one run, seed 7, noise on) with one effect
hidden at its typical size, as `experiments/diagnose_confusion.py --plan` makes its cases; its baseline is
fitted with every candidate effect held at zero (the plan's own baseline, outside the timing). The plans use
the default experiments, whose DAC words and VCF voltages follow each lot's fitted device. JAX's monitoring
events count the traces and compiles of the plan's Jacobians (`_jacobians`) during each plan.

Measured on 2 CPU cores shared with other work (load average 5 to 6), 1 device, persistent compilation cache
warm for `identify` only, wall time of each plan (2026-11-26):

    plan                         before (experiments static)                 after (their numbers as arrays)
    A: agc_finite_gain hidden    287 s  1 trace (83 s), 1 compile (187 s)    257 s  1 trace (59 s), 1 compile (185 s)
    B: dac_inl hidden            254 s  1 trace (55 s), 1 compile (187 s)    2.0 s  0 traces, 0 compiles

Both versions give the same plans (every recommendation; every number within 1.3e-10 relative). Run again
(after) in a new process with the persistent cache holding the Jacobians: A 75.4 s (1 trace, 59.1 s; the
executable loaded in 5.1 s), B 1.3 s, nothing traced (load average 4.8 to 5.0). Before, B's program misses that
cache (its experiments' numbers differ from A's).
"""

import argparse
import json
import os
import time

import jax


TRACE = "/jax/core/compile/jaxpr_trace_duration"
COMPILE = "/jax/core/compile/backend_compile_duration"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effects", default="agc_finite_gain,dac_inl", help="one hidden effect per lot")
    parser.add_argument("--devices", type=int, default=1)
    parser.add_argument("--json", default=None, help="write each plan's figures and JSON here")
    args = parser.parse_args()
    record = {"on": False, "trace": [], "compile": []}

    def duration(event, secs, **kw):
        if record["on"] and event in (TRACE, COMPILE) and "_jacobians" in str(kw.get("fun_name")):
            record["trace" if event == TRACE else "compile"].append(secs)

    jax.monitoring.register_event_duration_secs_listener(duration)
    import gyrojax as gj
    from gyrojax._model.parameters import DEFAULT_FREE
    from gyrojax._plan.plan import _baseline  # the plan's own baseline fit, timed apart
    from gyrojax._runtime.progress import as_progress

    print(f"jax {jax.__version__}, gyrojax {gj.__version__}, load average {os.getloadavg()}")
    rows = []
    for effect in args.effects.split(","):
        table = gj.simulate_table(gj.add_effect(gj.paper_qmg(), effect, 1.0), devices=args.devices, runs=1,
                                  sweeps=("rate_table", "vcf_static", "dac"), seed=7, progress=False)
        fit, _ = _baseline(table, "paper-qmg", None, None, DEFAULT_FREE, as_progress(False, "bench"))
        record.update(on=True, trace=[], compile=[])
        t = time.perf_counter()
        plan = gj.plan(fit=fit, max_repeats=2, scale_factor=False, progress=False)
        wall = time.perf_counter() - t
        record["on"] = False
        row = {"hidden": effect, "plan_s": wall, "traces": len(record["trace"]), "trace_s": sum(record["trace"]),
               "compiles": len(record["compile"]), "compile_s": sum(record["compile"]), "plan": plan.to_json()}
        rows.append(row)
        print(f"{effect:20s} plan {wall:7.1f} s   _jacobians: {row['traces']} trace(s) ({row['trace_s']:.1f} s), "
              f"{row['compiles']} compile(s) ({row['compile_s']:.1f} s)   load average {os.getloadavg()}",
              flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
