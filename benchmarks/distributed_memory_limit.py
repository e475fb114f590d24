#!/usr/bin/env python
"""A lot file larger than the memory the process may use, fitted by `gyrojax identify --workers` (issue 39; a
script, not a test: it writes a file of over 2 GB).

    python benchmarks/distributed_memory_limit.py [--limit-gib 2] [--devices 256] [--runs 4] [--workers 2] [--chunk 4]
                                                 [--keep DIR]

Writes a simulated `paper_qmg()` rate-table lot (`--devices` x `--runs` runs of 22 points) as a CSV whose rows
each carry a `note` column long enough that the file is 5 % larger than the limit (at most 100 kB: a CSV field
is read up to 128 kB), so that the fit stays small: this measures the reading, not the fit. Then, each in a
subprocess whose address space is limited to `--limit-gib` GiB (`RLIMIT_AS`, as `ulimit -v`; inherited by the
cluster's workers): `read_table` of the whole file (expected to fail), and `gyrojax identify FILE --workers N
--chunk C --json OUT` (a worker holds a chunk's rows, their text columns as numpy strings of 4 bytes a
character: 4 devices of 88 rows of 100 kB notes are 140 MB). Prints the file's size, each one's exit code and
wall time, the peak resident memory, and the devices fitted.
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time


def _limited(gib: float):
    def set_limit():
        limit = int(gib * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return set_limit


def _run(argv, gib, cwd):
    t = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, preexec_fn=_limited(gib))
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return done, time.perf_counter() - t, (peak if peak > before else None)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--limit-gib", type=float, default=2.0)
    parser.add_argument("--devices", type=int, default=256)
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--chunk", type=int, default=4)
    parser.add_argument("--keep", help="write the files in this folder (kept) instead of a temporary one")
    args = parser.parse_args()

    import numpy as np

    import gyrojax as gj

    tmp = args.keep or tempfile.mkdtemp()
    os.makedirs(tmp, exist_ok=True)
    try:
        table = gj.simulate_table(gj.paper_qmg(), devices=args.devices, runs=args.runs, sweeps=("rate_table",),
                                  seed=39,
                                  progress=False)
        small = os.path.join(tmp, "small.csv")
        gj.write_table(table, small)
        with open(small) as f:
            header, *rows = f.read().splitlines()
        target = 1.05 * args.limit_gib * 2**30
        note = int((target - os.path.getsize(small)) / len(rows)) + 1
        if note > 100_000:
            raise SystemExit(f"{len(rows)} rows would need notes of {note / 1e3:.0f} kB (at most 100 kB): give more "
                             "--devices or --runs.")
        path = os.path.join(tmp, "big.csv")
        filler = "x" * note
        with open(path, "w") as f:
            f.write(header + ",note\n")
            for row in rows:
                f.write(f"{row},{filler}\n")
        size = os.path.getsize(path)
        print(f"{path}: {size / 1e9:.2f} GB ({args.devices} devices, {len(rows)} rows of {note / 1e3:.0f} kB notes); "
              f"address space limit {args.limit_gib} GiB = {args.limit_gib * 2**30 / 1e9:.2f} GB", flush=True)
        code = f"import gyrojax as gj; t = gj.read_table({path!r}); print(len(t))"
        whole, seconds, peak = _run([sys.executable, "-c", code], args.limit_gib, tmp)
        print(f"read_table of the whole file: exit {whole.returncode} in {seconds:.0f} s ("
              + (whole.stderr.strip().splitlines() or ["no message"])[-1][:200] + ")", flush=True)
        out = os.path.join(tmp, "big.json")
        shutil.rmtree(out + ".parts", ignore_errors=True)
        lot, seconds, peak = _run([sys.executable, "-m", "gyrojax.cli", "identify", path, "--workers",
                                   str(args.workers), "--chunk", str(args.chunk), "--json", out], args.limit_gib, tmp)
        print(f"gyrojax identify --workers {args.workers} --chunk {args.chunk}: exit {lot.returncode} in "
              f"{seconds:.0f} s", flush=True)
        if lot.returncode not in (0, 3, 4):
            print(lot.stderr[-3000:])
            return 1
        with open(out) as f:
            report = json.load(f)
        statuses = {}
        for d in report["devices"]:
            statuses[d["status"]] = statuses.get(d["status"], 0) + 1
        workers = {}
        parts = out + ".parts"
        for name in os.listdir(parts):
            if name.startswith("chunk-") and name.endswith(".json") and "failed" not in name:
                with open(os.path.join(parts, name)) as f:
                    w = json.load(f)["worker"]
                workers[w["pid"]] = max(workers.get(w["pid"], 0.0), w["peak_rss_mb"])
        print(f"  devices: {statuses}, failed {sum(len(f['devices']) for f in report['failed'])}; peak resident "
              f"memory of the children (command or a worker, the largest) {peak / 2**10 if peak else float('nan'):.0f}"
              f" MB; workers {sorted(round(v) for v in workers.values())} MB; the lot's devices "
              f"{'all' if len(report['devices']) == args.devices else 'NOT all'} fitted once", flush=True)
        assert np.isfinite(report["chi2_red"])
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
