#!/usr/bin/env python
"""Is a lot fitted on a Dask cluster the fit of one process? (a script, not a test; issue 39)

    python benchmarks/distributed_identity.py [--devices 2000] [--workers 2] [--chunks 16,64] [--json PATH]

Simulates a `paper_qmg()` lot (`--devices`, rate table, one run, noise on, seed 39), fits it with `identify` in
this process (`VmapSolve`, chunks of 16 on a CPU), then with `identify_lot` on a local cluster of `--workers`
worker processes for each chunk size of `--chunks`, and compares every device's status, fitted values,
standard errors, scale factor, chi2_red and p-value, and the lot's chi2_red and p-value: how many are equal bit
for bit, and the largest relative difference of the others. Prints one line per comparison; `--json` keeps
them with the timings.
"""

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np


def _num(x):
    return np.nan if x is None else float(x)


def compare(fit, report) -> dict:
    """Per quantity: values compared, equal bit for bit, largest relative difference (NaN vs NaN: equal)."""
    names = list(fit.names)
    got = {"value": [], "stderr": [], "scale_factor": [], "chi2_red": [], "p_value": []}
    want = {k: [] for k in got}
    for i, d in enumerate(report["devices"]):
        for k, name in enumerate(names):
            got["value"].append(_num(d["parameters"][name]["value"]))
            got["stderr"].append(_num(d["parameters"][name]["stderr"]))
            want["value"].append(float(fit.values[i, k]))
            want["stderr"].append(float(fit.stderr[i, k]))
        got["scale_factor"].append(_num(d["scale_factor_lsb_per_dps"]))
        want["scale_factor"].append(float(fit.scale_factor[i]))
        got["chi2_red"].append(_num(d["chi2_red"]))
        want["chi2_red"].append(float(fit.chi2_red[i]))
        got["p_value"].append(_num(d["p_value"]))
        want["p_value"].append(float(fit.p_value[i]))
    got["lot chi2_red"], want["lot chi2_red"] = [_num(report["chi2_red"])], [float(fit.chi2_red_total)]
    got["lot p_value"], want["lot p_value"] = [_num(report["p_value"])], [float(fit.p_value_total)]
    out = {}
    for k in got:
        a, b = np.asarray(got[k]), np.asarray(want[k])
        same = (a == b) | (np.isnan(a) & np.isnan(b))
        rel = np.abs(a - b) / np.maximum(np.abs(b), np.finfo(float).tiny)
        out[k] = {"compared": int(a.size), "bit_for_bit": int(same.sum()),
                  "max_rel_diff": float(np.nanmax(np.where(same, 0.0, rel))) if a.size else 0.0}
    out["status"] = {"compared": len(fit.status), "bit_for_bit": sum(
        d["status"] == s for d, s in zip(report["devices"], fit.status)), "max_rel_diff": None}
    out["device order"] = [d["device"] for d in report["devices"]] == list(fit.devices)
    out["unidentifiable"] = report["unidentifiable"] == [p for u in fit.unidentifiable for p in u.parameters]
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--devices", type=int, default=2000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--chunks", default="16,64")
    parser.add_argument("--json")
    args = parser.parse_args()

    import gyrojax as gj
    from gyrojax._distributed import DistributedSolve, identify_lot

    record = {"devices": args.devices, "workers": args.workers, "load": os.getloadavg(), "runs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "lot.csv")
        t = time.perf_counter()
        gj.write_table(gj.simulate_table(gj.paper_qmg(), devices=args.devices, sweeps=("rate_table",), seed=39,
                                         progress=False), path)
        record["simulate_s"] = time.perf_counter() - t
        t = time.perf_counter()
        fit = gj.identify("paper-qmg", gj.read_table(path), progress=False)
        record["single_process_s"] = time.perf_counter() - t
        print(f"{args.devices} devices simulated in {record['simulate_s']:.0f} s; one process fitted them in "
              f"{record['single_process_s']:.0f} s", flush=True)
        for chunk in (int(c) for c in args.chunks.split(",")):
            out = os.path.join(tmp, f"out{chunk}.json")
            t = time.perf_counter()
            report = identify_lot("paper-qmg", path, out, DistributedSolve(workers=args.workers, chunk=chunk),
                                  progress=False)
            seconds = time.perf_counter() - t
            result = compare(fit, report)
            record["runs"][chunk] = {"seconds": seconds, "failed": len(report["failed"]), "comparison": result}
            print(f"{args.workers} workers, chunks of {chunk}: {seconds:.0f} s, {len(report['failed'])} failed; "
                  f"device order {'same' if result['device order'] else 'DIFFERS'}, unidentifiable "
                  f"{'same' if result['unidentifiable'] else 'DIFFERS'}", flush=True)
            for k, v in result.items():
                if isinstance(v, dict):
                    print(f"  {k}: {v['bit_for_bit']}/{v['compared']} bit for bit"
                          + (f", largest relative difference {v['max_rel_diff']:.3g}" if v["max_rel_diff"] else ""),
                          flush=True)
            if args.json:
                with open(args.json, "w") as f:
                    json.dump(record, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
