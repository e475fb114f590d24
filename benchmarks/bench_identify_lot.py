#!/usr/bin/env python
"""Lot identification: gyrojax.identify (one vmapped, compiled Levenberg-Marquardt over the lot, Jacobians
by forward-mode autodiff through the steady state) against the same problem solved device by device with
scipy.optimize.least_squares and a finite-difference Jacobian (a script, not a test).

    python benchmarks/bench_identify_lot.py [--sizes 1,16,256,1024] [--scipy-devices 16] [--json PATH]

The problem: `paper_qmg()` lots (default process spread) measured with seed 000's rate table, the static
virtual-Coriolis sweep and the DAC sweep, one run each, noise on; the default free parameters. Both sides
evaluate the *same* compiled residual function (gyrojax's standardised residuals of one device, with the
run biases projected out), so the comparison is of what each does around it: scipy's MINPACK LM
(`method="lm"`, `jac="2-point"`) calls it once per parameter per Jacobian from a Python loop over devices;
gyrojax differentiates it and solves all devices in one call.

Equal accuracy: each scipy fit must end within 0.05 standard errors (gyrojax's reported ones) of gyrojax's
solution on every free parameter; the script prints the worst deviation and fails loudly if it is larger.

scipy is timed on the first `--scipy-devices` devices of each lot and scaled by N / that count: the
devices are independent and solved one after another, so its time is linear in N (printed as "scaled").
gyrojax is timed twice per size: the first call (compile included, reported as compile time = first -
second) and the second call. Peak resident memory of the process is printed after each size, and on an
accelerator the device's peak memory in use too.

On a machine with an accelerator gyrojax runs on JAX's default backend (the GPU) while scipy's residual is
compiled for and run on the host CPU (`--scipy-backend cpu`, the default): scipy is a CPU tool, and a
GPU round trip per finite-difference evaluation would only slow it down. `--json` is rewritten after every
size, so a run cut short keeps the sizes it finished.
"""

import argparse
import os
import platform
import resource
import sys
import time

import numpy as np


def _versions():
    import importlib.metadata as md

    return {p: md.version(p) for p in ("jax", "jaxlib", "equinox", "optimistix", "lineax", "scipy", "numpy")}


def _problems(fit, preset):
    """The per-device residual problems identify solves (same construction as identify's)."""
    import equinox as eqx
    import jax.numpy as jnp

    from gyrojax import Steady
    from gyrojax._identify.problem import Problem
    from gyrojax._model.parameters import as_model, batched, read_values

    n = len(fit.devices)
    model = batched(as_model(preset), n)
    start = eqx.filter_vmap(lambda m: read_values(m, fit.entries))(model)
    data = fit.data.unlabelled()
    n_dev = len(fit.names)
    mask = jnp.broadcast_to(jnp.asarray(np.asarray(fit.free, dtype=float)), (n, n_dev))
    empty = jnp.zeros((n, 0))
    return Problem(model, start, data, mask, n_dev, fit.entries, Steady(), jnp.zeros((n, 0), dtype=int), empty,
                    jnp.ones((n, 0)), sf_temperature=jnp.full((n,), 25.0))


def _device_peak_gb():
    """Peak memory in use on the default JAX device (GB), where the backend reports it (GPU), else None."""
    import jax

    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else peak / 1e9


def run(sizes, scipy_devices, seed=0, preset="paper-qmg", chunk=None, scipy_backend="cpu", on_row=None):
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    from scipy.optimize import least_squares

    import gyrojax as gj

    scipy_device = jax.devices(scipy_backend)[0] if scipy_backend else jax.devices()[0]
    residual = eqx.filter_jit(lambda p, u: p.residuals(u, jnp.zeros(0, device=scipy_device)))
    rows = []
    for n in sizes:
        t0 = time.perf_counter()
        table = gj.simulate_table(gj.preset(preset), devices=n, runs=1, seed=seed,
                                  sweeps=("rate_table", "vcf_static", "dac"))
        t_sim = time.perf_counter() - t0
        t0 = time.perf_counter()
        lot_chunk = "auto" if chunk is None else (chunk if n > chunk else None)
        fit = gj.identify(preset, table, lot_solve=gj.VmapSolve(chunk=lot_chunk))
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        fit = gj.identify(preset, table, lot_solve=gj.VmapSolve(chunk=lot_chunk))
        t_gj = time.perf_counter() - t0
        rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        device_gb = _device_peak_gb()
        free = np.flatnonzero(np.asarray(fit.free))
        u_gj = np.asarray(fit.u)[:, free]
        se = np.sqrt(np.einsum("dii->di", np.asarray(fit.covariance)))[:, free]

        problems = jax.tree.map(lambda x: jax.device_put(x, scipy_device) if eqx.is_array(x) else x,
                                _problems(fit, preset))
        m = min(n, scipy_devices)
        worst, t_sp, nfev = 0.0, 0.0, 0
        for d in range(m):
            p = jax.tree.map(lambda x: x[d] if eqx.is_array(x) else x, problems)
            full = np.zeros(len(fit.names))

            def fun(x, p=p, full=full):
                full[free] = x
                return np.asarray(residual(p, jax.device_put(full, scipy_device)))

            fun(np.zeros(len(free)))  # compile (once) before timing
            t0 = time.perf_counter()
            sol = least_squares(fun, np.zeros(len(free)), method="lm", jac="2-point", xtol=1e-10, ftol=1e-10,
                                gtol=1e-10)
            t_sp += time.perf_counter() - t0
            nfev += sol.nfev
            worst = max(worst, float(np.max(np.abs(sol.x - u_gj[d]) / se[d])))
        t_sp_n = t_sp * n / m
        row = {"devices": n, "lot_chunk": lot_chunk, "points_per_device": int(np.asarray(fit.residual_vector).shape[1]),
               "free_parameters": len(free), "simulate_s": t_sim, "gyrojax_first_call_s": t_first,
               "gyrojax_compile_s": t_first - t_gj, "gyrojax_s": t_gj, "gyrojax_per_device_ms": 1e3 * t_gj / n,
               "gyrojax_converged": int(np.sum(np.asarray(fit.converged))), "gyrojax_steps_max":
               int(np.max(np.asarray(fit.num_steps))), "gyrojax_steps_mean": float(np.mean(np.asarray(fit.num_steps))),
               "scipy_devices_timed": m, "scipy_s": t_sp_n,
               "scipy_scaled": m < n, "scipy_per_device_ms": 1e3 * t_sp / m, "scipy_nfev_per_device": nfev / m,
               "speedup": t_sp_n / t_gj, "worst_deviation_in_stderr": worst, "peak_rss_gb": rss_gb,
               "device_peak_gb": device_gb, "gyrojax_backend": jax.default_backend(),
               "scipy_backend": scipy_device.platform}
        rows.append(row)
        print(f"N={n:5d}  gyrojax {t_gj:8.2f} s ({1e3 * t_gj / n:7.1f} ms/device, compile {t_first - t_gj:6.1f} s, "
              f"converged {row['gyrojax_converged']}/{n}, LM steps max {row['gyrojax_steps_max']})  "
              f"scipy {t_sp_n:9.2f} s{' (scaled)' if m < n else ''} "
              f"({1e3 * t_sp / m:7.1f} ms/device, {nfev / m:.0f} evaluations)  speed-up {t_sp_n / t_gj:6.1f}x  "
              f"worst |du| {worst:.3f} sigma  peak RSS {rss_gb:.2f} GB"
              + ("" if device_gb is None else f", device peak {device_gb:.2f} GB"), flush=True)
        if on_row is not None:
            on_row(rows)
        if worst > 0.05:
            raise SystemExit(f"scipy and gyrojax disagree by {worst:.3f} standard errors at N={n}: not equal "
                             "accuracy; the ratio would mean nothing.")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1,16,256,1024")
    ap.add_argument("--scipy-devices", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--chunk", type=int, help="identify(lot_solve=VmapSolve(chunk=...)) for lots larger than "
                    "this (default: VmapSolve's 'auto', 16 on a CPU)")
    ap.add_argument("--scipy-backend", default="cpu", help="JAX backend of scipy's residual (default: cpu)")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    import jax

    import gyrojax  # noqa: F401  (float64 from here on)

    machine = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax_devices": [str(d) for d in jax.devices()],
               "device_kind": jax.devices()[0].device_kind}
    print(f"versions {_versions()}; {machine}; load {os.getloadavg()}", flush=True)

    def write(rows):
        if args.json:
            from gyrojax._data.io import atomic_write_json

            atomic_write_json({"versions": _versions(), "machine": machine, "rows": rows}, args.json)

    rows = run([int(s) for s in args.sizes.split(",")], args.scipy_devices, args.seed, chunk=args.chunk,
               scipy_backend=args.scipy_backend, on_row=write)
    print(f"load at end {os.getloadavg()}")
    if len(rows) > 1:
        per = [r["gyrojax_per_device_ms"] for r in rows if r["devices"] >= 16]
        if per:
            print(f"gyrojax per-device time from 16 up: max/min = {max(per) / min(per):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
