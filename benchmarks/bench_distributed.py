#!/usr/bin/env python
"""A lot beyond one process: `gyrojax.identify_lot` on a local Dask cluster of 1 and 2 worker processes against
the single-process `identify` (`VmapSolve`), and the engines' own costs (a script, not a test).

    python benchmarks/bench_distributed.py [--sizes 256,2000,10000] [--workers 1,2] [--chunk 16] [--json PATH]
    python benchmarks/bench_distributed.py --engines-only    # the Dask / Ray measurement alone (~40 s)

**Engines.** A local cluster of 2 worker processes (one thread each) of Dask distributed and, where installed,
of Ray: the time to start it (and run one task), then 200 no-op tasks 3 times (the last round's time per task:
the engine's overhead per chunk), then its shutdown.

**Lots** ("compact data"): `paper_qmg()` lots of 256 simulated devices (default process spread, the rate table
only, one run, noise on), repeated with new device names up to each size (the fit of a copy costs what its
original does). Per size: the single-process `identify` (`VmapSolve`, chunks of 16 on a CPU) twice (the first
with tracing and compiling), then `identify_lot` with each number of workers from a fresh results folder (its
wall time includes starting the cluster and each worker's tracing and compiling, from the persistent cache once
it holds the program): devices/s, each worker's peak resident memory (from the chunk reports), and the fit time
of a chunk inside its worker (mean, median, longest: a worker's first chunk traces and compiles). `--json` is
rewritten after every measurement.
"""

import argparse
import json
import os
import platform
import resource
import shutil
import sys
import tempfile
import time


def _noop(x):
    return x


def engines() -> dict:
    out = {}
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=40) as cluster, Client(cluster) as client:
        client.submit(_noop, 0).result()
        t1 = time.perf_counter()
        for _ in range(3):
            ta = time.perf_counter()
            client.gather(client.map(_noop, range(200), pure=False))
            tb = time.perf_counter()
        t2 = time.perf_counter()
    out["dask"] = {"startup_s": t1 - t0, "per_task_ms": (tb - ta) / 200 * 1e3, "shutdown_s": time.perf_counter() - t2}
    try:
        import ray
    except ImportError:
        out["ray"] = None
        return out
    t0 = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(_noop)
    ray.get(remote.remote(0))
    t1 = time.perf_counter()
    for _ in range(3):
        ta = time.perf_counter()
        ray.get([remote.remote(i) for i in range(200)])
        tb = time.perf_counter()
    t2 = time.perf_counter()
    ray.shutdown()
    out["ray"] = {"startup_s": t1 - t0, "per_task_ms": (tb - ta) / 200 * 1e3, "shutdown_s": time.perf_counter() - t2}
    return out


def _lot(n: int, base):
    """`base` (a Table of distinct devices) repeated with new device names up to `n` devices."""
    import numpy as np

    import gyrojax as gj

    names = list(dict.fromkeys(base["device"].tolist()))
    cols = {k: [] for k in base.column_names}
    for copy in range(-(-n // len(names))):
        keep = names[:min(len(names), n - copy * len(names))]
        rows = np.flatnonzero(np.isin(base["device"], keep))
        for k in base.column_names:
            v = base[k][rows]
            cols[k].append(np.char.add(v.astype(str), f"-c{copy:03d}") if k == "device" else v)
    return gj.Table({k: np.concatenate(v) for k, v in cols.items()}, source=f"lot of {n}")


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10


def lots(sizes, workers, chunk, record, save):
    import gyrojax as gj
    from gyrojax._distributed import DistributedSolve, identify_lot

    base = gj.simulate_table(gj.paper_qmg(), devices=256, sweeps=("rate_table",), seed=11, progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = os.path.join(tmp, f"lot{n}.csv")
            table = _lot(n, base)
            gj.write_table(table, path)
            table = gj.read_table(path)
            entry = {"devices": n, "rows": len(table), "file_mb": os.path.getsize(path) / 2**20}
            times = []
            for _ in range(2):
                t = time.perf_counter()
                gj.identify("paper-qmg", table, progress=False)
                times.append(time.perf_counter() - t)
            entry["single_process"] = {"first_s": times[0], "second_s": times[1], "devices_per_s": n / times[1],
                                       "peak_rss_mb": _peak_mb()}
            print(f"{n} devices: single process {times[1]:.1f} s ({n / times[1]:.1f} devices/s; first call "
                  f"{times[0]:.1f} s), peak {_peak_mb():.0f} MB", flush=True)
            for w in workers:
                out = os.path.join(tmp, f"out{n}-{w}.json")
                t = time.perf_counter()
                report = identify_lot("paper-qmg", path, out, DistributedSolve(workers=w, chunk=chunk), progress=False)
                wall = time.perf_counter() - t
                chunks = []
                for name in sorted(os.listdir(out + ".parts")):
                    if name.startswith("chunk-") and name.endswith(".json") and "failed" not in name:
                        with open(os.path.join(out + ".parts", name)) as f:
                            r = json.load(f)
                        chunks.append((r["seconds"], r["worker"]["pid"], r["worker"]["peak_rss_mb"]))
                peak = {}
                for _, pid, mb in chunks:
                    peak[pid] = max(peak.get(pid, 0.0), mb)
                fit_s = sum(c[0] for c in chunks)
                entry[f"workers_{w}"] = {
                    "wall_s": wall, "devices_per_s": n / wall, "failed": len(report["failed"]),
                    "chunks": len(chunks), "chunk_fit_mean_s": fit_s / max(len(chunks), 1),
                    "chunk_fit_first_s": max((c[0] for c in chunks), default=None),
                    # without each worker's first chunk (tracing, and compiling or loading the program)
                    "chunk_fit_median_s": sorted(c[0] for c in chunks)[len(chunks) // 2] if chunks else None,
                    "worker_peak_rss_mb": sorted(peak.values()),
                    # wall x workers not spent inside a chunk's fit: cluster start, imports, waiting, the engine
                    "outside_fits_per_chunk_s": (wall * w - fit_s) / max(len(chunks), 1)}
                print(f"  {w} worker(s): {wall:.1f} s ({n / wall:.1f} devices/s), {len(chunks)} chunks, chunk fit mean "
                      f"{fit_s / max(len(chunks), 1):.2f} s, median {entry[f'workers_{w}']['chunk_fit_median_s']:.2f} "
                      f"s, longest {entry[f'workers_{w}']['chunk_fit_first_s']:.1f} s, worker peaks "
                      f"{[round(v) for v in sorted(peak.values())]} MB", flush=True)
                shutil.rmtree(out + ".parts")
            record["lots"].append(entry)
            save()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="256,2000,10000")
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--chunk", type=int, default=16)
    parser.add_argument("--engines-only", action="store_true")
    parser.add_argument("--json")
    args = parser.parse_args()
    import importlib.metadata as md

    record = {"machine": f"{platform.platform()}, {os.cpu_count()} CPUs", "load": os.getloadavg(),
              "versions": {p: md.version(p) for p in ("jax", "distributed") if _has(p)}, "lots": []}
    print(record, flush=True)

    def save():
        if args.json:
            from gyrojax._data.io import atomic_write_json

            atomic_write_json(record, args.json)

    record["engines"] = engines()
    print("engines:", record["engines"], flush=True)
    save()
    if not args.engines_only:
        lots([int(s) for s in args.sizes.split(",")], [int(w) for w in args.workers.split(",")], args.chunk, record,
             save)


def _has(package: str) -> bool:
    import importlib.metadata as md

    try:
        md.version(package)
        return True
    except md.PackageNotFoundError:
        return False


if __name__ == "__main__":
    sys.exit(main())
