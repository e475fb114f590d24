#!/usr/bin/env python
"""Time to first result: trace, lower, compile and run time of gyrojax's entry points on the demo lot, with an
empty persistent compilation cache (cold) and with the cache the cold run filled (warm), each in a fresh
process (a script, not a test).

    python benchmarks/bench_compile.py [--quick] [--entries simulate_table,identify,...] [--json PATH]

Entry points, all on the demo's data (`gyrojax._cli.demo_job.DEMO_LOT`: 3 paper-qmg devices x 2 runs, rate table +
static virtual-Coriolis + DAC sweeps, with the demo's hidden `dac_inl`):

- `simulate_table`: `gj.simulate_table(gj.add_effect(gj.paper_qmg(), "dac_inl"), **DEMO_LOT)` (it also writes
  the table the others read, outside the timed part);
- `identify`: `gj.identify("paper-qmg", table)`;
- `diagnose`: `gj.diagnose("paper-qmg", table)` (every candidate effect and probe);
- `compensate`: `gj.compensate(table, method="model")` (the model-based compensator, the one that compiles);
- `demo`: what `gyrojax demo` runs (`run_demo(folder)`, without the full-waveform tier, as the command's
  default);
- `simulate_revealing`: `gj.simulate_table` of paper-qmg with the steady and AGC set-point kinds
  (`REVEALING_SWEEPS`: rate table, static VCF, quadrature injection, drive amplitude, drive frequency,
  set-point zero rate), the demo's devices and runs, noise-free: all of them settle in one program.

For each entry point and each state (cold, warm) a subprocess imports gyrojax with `GYROJAX_CACHE_DIR`
pointing at a folder of its own (JAX's own cache variables removed) and runs the entry point once. JAX's
monitoring events split its wall time: **trace** (jaxpr tracing of top-level jits), **lower** (jaxpr to
StableHLO), **compile** (XLA backend compile, or loading the executable from the persistent cache on a hit),
and **other** = wall - trace - lower - compile: running the programs, Python, equinox's own work around its
jits. A third process (`sizes`, warm) dumps every program JAX compiles (`JAX_DUMP_IR_TO`, debug info off)
and counts its StableHLO operations. `--quick` runs only `simulate_table` and `identify`.

The results are printed as a table and written to `--json` (default `bench_compile.json` in the current
folder) atomically after each entry point, so a run cut short keeps what it finished.
"""

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time


ENTRIES = ("simulate_table", "identify", "diagnose", "compensate", "demo", "simulate_revealing")
REVEALING_SWEEPS = ("rate_table", "vcf_static", "quadrature_injection", "drive_amplitude", "drive_frequency",
                    "setpoint_zero_rate")
QUICK_ENTRIES = ("simulate_table", "identify")
STAGES = {"trace": "/jax/core/compile/jaxpr_trace_duration",
          "lower": "/jax/core/compile/jaxpr_to_mlir_module_duration",
          "compile": "/jax/core/compile/backend_compile_duration"}


# --- the worker: one entry point in this process ---------------------------------------------------------

def _worker(entry, data_path, out_path):
    import jax

    record = {"on": False, "seconds": {k: 0.0 for k in STAGES}, "programs": [], "traces": [], "counts": {}}
    names = {v: k for k, v in STAGES.items()}

    def duration(event, secs, **kw):
        if record["on"] and event in names:
            record["seconds"][names[event]] += secs
            if names[event] in ("compile", "trace"):
                record["programs" if names[event] == "compile" else "traces"].append((kw.get("fun_name", "?"), secs))

    def count(event, **kw):
        if record["on"]:
            record["counts"][event] = record["counts"].get(event, 0) + 1

    jax.monitoring.register_event_duration_secs_listener(duration)
    jax.monitoring.register_event_listener(count)

    t = time.perf_counter()
    import gyrojax as gj
    from gyrojax._cli.demo_job import DEMO_LOT, HIDDEN_EFFECT, run_demo
    import_s = time.perf_counter() - t

    table = None if entry == "simulate_table" else gj.read_table(data_path)
    with tempfile.TemporaryDirectory() as scratch:
        record["on"] = True
        t = time.perf_counter()
        if entry == "simulate_table":
            table = gj.simulate_table(gj.add_effect(gj.paper_qmg(), HIDDEN_EFFECT), **DEMO_LOT)
        elif entry == "identify":
            gj.identify("paper-qmg", table)
        elif entry == "diagnose":
            gj.diagnose("paper-qmg", table)
        elif entry == "compensate":
            gj.compensate(table, method="model")
        elif entry == "demo":
            run_demo(scratch, full_tier=False, log=lambda *a: None)
        elif entry == "simulate_revealing":
            lot = {k: v for k, v in DEMO_LOT.items() if k in ("devices", "runs", "seed")}
            gj.simulate_table(gj.paper_qmg(), sweeps=REVEALING_SWEEPS, noise_free=True, progress=False, **lot)
        else:
            raise ValueError(f"entry must be one of {', '.join(ENTRIES)}, got {entry!r}.")
        wall = time.perf_counter() - t
        record["on"] = False
    if entry == "simulate_table":
        gj.write_table(table, data_path)

    s = record["seconds"]
    programs = sorted(record["programs"], key=lambda p: -p[1])
    traces = sorted(record["traces"], key=lambda p: -p[1])
    c = record["counts"]
    result = {"import_s": import_s, "wall_s": wall, **{f"{k}_s": v for k, v in s.items()},
              "other_s": wall - sum(s.values()), "programs": len(programs),
              "cache_hits": c.get("/jax/compilation_cache/cache_hits", 0),
              "cache_writes": c.get("/jax/compilation_cache/cache_misses", 0),
              "slowest_programs": [{"name": n, "compile_s": round(v, 3)} for n, v in programs[:5]],
              "slowest_traces": [{"name": n, "trace_s": round(v, 3)} for n, v in traces[:5]],
              "cache_dir": gj.io.compilation_cache(), "load_average": os.getloadavg()}
    with open(out_path, "w") as f:
        json.dump(result, f)


# --- the driver -------------------------------------------------------------------------------------------

_OP = re.compile(r"\bstablehlo\.[a-z_]+")


def _sizes(dump_dir):
    """StableHLO operations and characters of every program dumped into `dump_dir`, largest first."""
    out = []
    for name in sorted(os.listdir(dump_dir)):
        if name.endswith(".mlir"):
            with open(os.path.join(dump_dir, name)) as f:
                text = f.read()
            module = re.sub(r"^jax_ir\d+_|_compile\.mlir$", "", name)
            out.append({"name": module, "ops": len(_OP.findall(text)), "chars": len(text)})
    return sorted(out, key=lambda p: -p["ops"])


def _folder_size(path):
    files = [os.path.join(path, n) for n in os.listdir(path)] if os.path.isdir(path) else []
    files = [p for p in files if p.endswith("-cache")]
    return len(files), sum(os.path.getsize(p) for p in files)


def _run_worker(entry, data_path, cache_dir, dump_dir=None):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE", "JAX_ENABLE_COMPILATION_CACHE",
                                "JAX_DUMP_IR", "GYROJAX_CACHE_DIR"))}
    env["GYROJAX_CACHE_DIR"] = cache_dir
    if dump_dir is not None:
        env.update(JAX_DUMP_IR_TO=dump_dir, JAX_INCLUDE_DEBUG_INFO_IN_DUMPS="false")
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out_path = f.name
    try:
        t = time.perf_counter()
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", entry, "--data", data_path,
                               "--result", out_path], env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"{entry}: worker failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}")
        with open(out_path) as f:
            result = json.load(f)
        result["process_s"] = time.perf_counter() - t
        return result
    finally:
        os.remove(out_path)


def _write_json(path, payload):
    from gyrojax._data.io import atomic_write_json

    atomic_write_json(payload, path)


def _fmt(x, nd=1):
    return "" if x is None else f"{x:.{nd}f}"


def _print_table(results):
    head = ("| entry | state | wall (s) | trace | lower | compile | other | programs | cache hits | "
            "cache files / MB | StableHLO ops (all / largest) |")
    print(head)
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for entry, r in results.items():
        for state in ("cold", "warm"):
            x = r.get(state)
            if x is None:
                continue
            files = f"{x['cache_files']} / {x['cache_bytes'] / 1e6:.1f}" if state == "cold" else ""
            sizes = ""
            if state == "cold" and r.get("sizes"):
                s = r["sizes"]
                sizes = f"{s['ops_total']:,} / {s['largest'][0]['ops']:,} ({s['largest'][0]['name']})"
            print(f"| {entry} | {state} | {_fmt(x['wall_s'])} | {_fmt(x['trace_s'])} | {_fmt(x['lower_s'])} | "
                  f"{_fmt(x['compile_s'])} | {_fmt(x['other_s'])} | {x['programs']} | {x['cache_hits']} | {files} | "
                  f"{sizes} |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="only simulate_table and identify")
    parser.add_argument("--entries", help=f"comma-separated subset of {','.join(ENTRIES)}")
    parser.add_argument("--json", default="bench_compile.json", metavar="PATH", help="where to write the results")
    parser.add_argument("--no-sizes", action="store_true", help="skip the third (program-size) process")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--data", help=argparse.SUPPRESS)
    parser.add_argument("--result", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return _worker(args.worker, args.data, args.result)

    entries = QUICK_ENTRIES if args.quick else ENTRIES
    if args.entries:
        entries = tuple(e.strip() for e in args.entries.split(",") if e.strip())
        bad = [e for e in entries if e not in ENTRIES]
        if bad:
            parser.error(f"--entries: unknown {', '.join(bad)} (choose from {', '.join(ENTRIES)})")
    import importlib.metadata as md

    payload = {"mode": "quick" if args.quick else "full", "entries": {},
               "versions": {p: md.version(p) for p in ("jax", "jaxlib", "equinox", "diffrax", "optimistix")},
               "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                           "load_average_at_start": os.getloadavg()}}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as work:
        data_path = os.path.join(work, "demo_lot.csv")
        # simulate_table writes the table the others read: it always runs first (its figures are kept only if
        # it was asked for).
        order = ("simulate_table",) + tuple(e for e in entries if e != "simulate_table")
        for entry in order:
            cache = os.path.join(work, f"cache-{entry}")
            r = {"cold": _run_worker(entry, data_path, cache)}
            r["cold"]["cache_files"], r["cold"]["cache_bytes"] = _folder_size(cache)
            if entry not in entries:
                continue
            r["warm"] = _run_worker(entry, data_path, cache)
            if not args.no_sizes:
                dump = os.path.join(work, f"dump-{entry}")
                _run_worker(entry, data_path, cache, dump_dir=dump)
                programs = _sizes(dump)
                r["sizes"] = {"programs": len(programs), "ops_total": sum(p["ops"] for p in programs),
                              "chars_total": sum(p["chars"] for p in programs), "largest": programs[:5]}
                shutil.rmtree(dump)
            payload["entries"][entry] = r
            payload["wall_s"] = time.perf_counter() - t0
            _write_json(args.json, payload)
            print(f"{entry}: cold {r['cold']['wall_s']:.1f} s, warm {r['warm']['wall_s']:.1f} s", flush=True)
    payload["machine"]["load_average_at_end"] = os.getloadavg()
    payload["wall_s"] = time.perf_counter() - t0
    _write_json(args.json, payload)
    print(f"\n{platform.platform()}, {os.cpu_count()} CPUs, jax {payload['versions']['jax']}; load average "
          f"{payload['machine']['load_average_at_start']} at start, {payload['machine']['load_average_at_end']} "
          f"at end; {payload['wall_s']:.0f} s in all. Seconds; 'other' = running the programs + Python.\n")
    _print_table(payload["entries"])
    print(f"\nwritten to {args.json}")


if __name__ == "__main__":
    sys.exit(main())
