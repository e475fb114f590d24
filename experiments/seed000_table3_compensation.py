"""Seed 000's Table 3 on a simulated paper-like device: uncompensated, traditional, composite, model-based.

Run: python experiments/seed000_table3_compensation.py [--out DIR] [--inl-scale S] [--warmup-rise K] [--seed N]

The device is `paper_qmg()` with the typical FTR-DAC INL (`dac_inl`) and silicon's TCF; three rate-table runs
(seed 000 §5: power-on, 1 min warm-up, 22 rates, 2 min each), each self-heating by the same rise, the first one
slowly, so that it sweeps through its warm-up ("the longer time required for temperature stabilization during
the first set", §5) while the next two settle within their first points. Every compensator is judged on held-out data
only: leave-one-out, run k is compensated by a compensator fitted on the other two runs. Per method the table gives
the worst nonlinearity of each run (max residual / full scale) and the repeatability (sample std of the three
runs' scale factors over their mean), seed 000's definitions.

Writes into --out: `data.csv` (the simulated runs, tidy format), `table3.md`, `table3.json` and
`fig10.png` (residual curves per method, as seed 000 Fig. 10).
"""

import argparse
import io
import os
import sys

import numpy as np

import gyrojax as gj


# Seed 000 Table 3 (worst nonlinearity per group, ppm; scale factor, LSB/(deg/s); repeatability, ppm).
SEED000_TABLE3 = {
    "uncompensated": {"runs_ppm": [1832.803, 2083.751, 2232.039], "scale_factor": 13709.853,
                      "repeatability_ppm": 1230.656},
    "polynomial": {"runs_ppm": [435.907, 429.962, 429.962], "scale_factor": -13694.696,
                   "repeatability_ppm": 163.253},
    "composite": {"runs_ppm": [99.085, 91.828, 91.525], "scale_factor": 13719.534, "repeatability_ppm": 93.534},
}

INL_SCALE = 1.0  # the typical dac_inl: ~460 ppm alone, seed 000 §3.3's DAC share (Table 2's measured DAC)
WARMUP_RISE_K = 15.0  # ASSUMPTION: self-heating of die + FPGA/analog boards in a closed housing (seed 000 gives
#                       no figure); larger than gyrojax's default 2 K so the thermal part of Table 3 shows
FIRST_RUN_TIME_CONSTANT_S = 900.0  # ASSUMPTION: run 1 starts with fixture and table cold and is still warming
#                                    through its 46-min sweep (seed 000 §5: "the longer time required for
#                                    temperature stabilization during the first set")
RUN_TIME_CONSTANT_S = 120.0  # ASSUMPTION: runs 2-3 start with a warm fixture: settled after the first points
N_RUNS = 3  # seed 000 §5: three repeated experiments

METHODS = ("uncompensated", "polynomial", "composite", "model")
LABELS = {"uncompensated": "Origin", "polynomial": "Tra method", "composite": "Composite (seed 000)",
          "model": "Model-based"}


def protocol(rise: float) -> gj.Protocol:
    """Seed 000 §5's rate-table timing (1 min warm-up, 2 min per rate) with a warm-up of `rise` K per run,
    the first run slower."""
    return gj.Protocol(warmup=gj.sweeps.RunWarmup(
        rise_k=rise, time_constant_s=RUN_TIME_CONSTANT_S, first_rise_k=rise,
        first_time_constant_s=FIRST_RUN_TIME_CONSTANT_S))


def simulate_runs(*, inl_scale: float, rise: float, seed: int, rates_dps) -> gj.Table:
    """Three runs of the paper-like device as one tidy table (runs 0, 1, 2; each its own power-on)."""
    gyro = gj.add_effect(gj.paper_qmg(), "dac_inl", inl_scale)
    return gj.simulate_table(gyro, runs=N_RUNS, seed=seed, rates_dps=rates_dps, protocol=protocol(rise))


def leave_one_out(table: gj.Table, method) -> dict:
    """Each run judged by a compensator fitted on the other runs."""
    worst, sf, curves = [], [], []
    for k in range(N_RUNS):
        res = gj.compensate(table, method=method, train_runs=[j for j in range(N_RUNS) if j != k])
        rec = next(r for r in res.runs if r.run == k)
        assert not rec.used_for_training
        if not rec.converged:  # a figure the method did not produce is not reported
            raise RuntimeError(f"{method} compensation of run {k} did not converge: {res.devices[0].message}")
        worst.append(rec.nonlinearity_max_ppm_after)
        sf.append(rec.scale_factor_after)
        curves.append(list(rec.residuals_ppm_after or ()))
    return {"runs_ppm": worst, "scale_factor": float(np.mean(sf)),
            "repeatability_ppm": float(gj.metrics.repeatability(np.asarray(sf))), "residuals_ppm": curves,
            "compensator": res.devices[0].compensator}


def uncompensated(table: gj.Table) -> dict:
    fits = []
    for k in range(N_RUNS):
        sel = (table["run"] == k) & (table["sweep"] == "rate_table")
        fits.append(gj.fit_scale_factor(table["input"][sel], table["output"][sel]))
    sf = np.asarray([float(f.scale_factor) for f in fits])
    return {"runs_ppm": [float(f.nonlinearity_max_ppm) for f in fits], "scale_factor": float(np.mean(sf)),
            "repeatability_ppm": float(gj.metrics.repeatability(sf)),
            "residuals_ppm": [(1e6 * f.residuals / f.full_scale).tolist() for f in fits]}


def format_table(results: dict) -> str:
    names = ("One", "Two", "Three")
    head = "| Group | " + " | ".join(LABELS[m] for m in METHODS) + " |"
    lines = [head, "|" + "---|" * (len(METHODS) + 1)]
    for k in range(N_RUNS):
        lines.append(f"| {names[k]} (ppm) | " + " | ".join(f"{results[m]['runs_ppm'][k]:.2f}" for m in METHODS)
                     + " |")
    lines.append("| SF | " + " | ".join(
        f"{results[m]['scale_factor']:,.3f} LSB/(°/s)" if m == "uncompensated"
        else f"{results[m]['scale_factor']:.6f} (°/s)/(°/s)" for m in METHODS) + " |")
    lines.append("| Repetitive error (ppm) | " + " | ".join(f"{results[m]['repeatability_ppm']:.2f}"
                                                         for m in METHODS) + " |")
    lines.append("| *seed 000: worst / repeat. (ppm)* | " + " | ".join(
        f"*{max(SEED000_TABLE3[m]['runs_ppm']):.1f} / {SEED000_TABLE3[m]['repeatability_ppm']:.1f}*"
        if m in SEED000_TABLE3 else "-" for m in METHODS) + " |")
    return "\n".join(lines)


def plot(results: dict, rates, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True)
    for ax, m, tag in zip(axes.ravel(), METHODS, "abcd"):
        for k, curve in enumerate(results[m]["residuals_ppm"]):
            ax.plot(rates, curve, marker="o", ms=3, label=f"run {k + 1}")
        ax.set_xscale("symlog", linthresh=1.0)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(f"({tag}) {LABELS[m]}: worst {max(results[m]['runs_ppm']):.1f} ppm, "
                     f"repeat. {results[m]['repeatability_ppm']:.1f} ppm", fontsize=9)
        ax.set_ylabel("nonlinearity (ppm of full scale)")
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("input rate (°/s)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Seed 000 Fig. 10 on the simulated paper-like QMG (each run held out)", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    gj.io.atomic_write_bytes(path, buf.getvalue())


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="seed000-table3", help="output folder (default ./seed000-table3)")
    ap.add_argument("--inl-scale", type=float, default=INL_SCALE,
                    help=f"dac_inl size, times typical (default {INL_SCALE}; 4 gives Table 3's uncompensated size)")
    ap.add_argument("--warmup-rise", type=float, default=WARMUP_RISE_K,
                    help=f"self-heating rise, K (default {WARMUP_RISE_K})")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    ap.add_argument("--rates", default=None, help="comma-separated table rates, deg/s (default seed 000's 22)")
    ap.add_argument("--quick", action="store_true", help="skip the sensitivity rows (for tests)")
    args = ap.parse_args(argv)
    rates = gj.sweeps.DING_ZHOU_2025_RATES_DPS if args.rates is None else tuple(float(r) for r in args.rates.split(","))
    os.makedirs(args.out, exist_ok=True)

    table = simulate_runs(inl_scale=args.inl_scale, rise=args.warmup_rise, seed=args.seed, rates_dps=rates)
    gj.write_table(table, os.path.join(args.out, "data.csv"))
    results = {"uncompensated": uncompensated(table)}
    for m in ("polynomial", "composite", "model"):
        results[m] = leave_one_out(table, m)
    extras = {} if args.quick else {
        "polynomial order 5": leave_one_out(table, gj.compensation.PolynomialCompensator(order=5)),
        "composite, straight line per segment": leave_one_out(
            table, gj.compensation.CompositeCompensator(segment_degree=1)),
        "model, frequency exponent identified": leave_one_out(
            table, gj.compensation.ModelCompensator(frequency_exponent=None)),
    }
    worst = {m: max(results[m]["runs_ppm"]) for m in METHODS}
    gain_nl = worst["composite"] / worst["model"]
    gain_rep = results["composite"]["repeatability_ppm"] / results["model"]["repeatability_ppm"]
    ordered = worst["uncompensated"] > worst["polynomial"] > worst["composite"] > worst["model"]

    text = format_table(results)
    rt = table["sweep"] == "rate_table"
    floor_ppm = float(1e6 * np.median(table["output_sigma"][rt]) / (abs(results["uncompensated"]["scale_factor"])
                                                                   * np.max(np.abs(table["input"][rt]))))
    temps = [float(table["temperature_c"][table["run"] == k].min()) for k in range(N_RUNS)]
    temps_hi = [float(table["temperature_c"][table["run"] == k].max()) for k in range(N_RUNS)]
    print("Seed 000 Table 3 on the simulated paper-like QMG (each run judged by a compensator fitted on the "
          "other two)")
    print(f"  dac_inl x {args.inl_scale}, warm-up rise {args.warmup_rise} K (tau {FIRST_RUN_TIME_CONSTANT_S:.0f} s "
          f"for run 1, {RUN_TIME_CONSTANT_S:.0f} s after); die "
          "temperature per run: " + ", ".join(f"{a:.1f}-{b:.1f} °C" for a, b in zip(temps, temps_hi)))
    print(text)
    print("  ordering uncompensated > traditional > composite > model-based: "
          f"{'REPRODUCED' if ordered else 'NOT reproduced'}")
    rep_c, rep_m = results["composite"]["repeatability_ppm"], results["model"]["repeatability_ppm"]
    print(f"  model-based vs composite on held-out runs: worst nonlinearity {worst['composite']:.2f} -> "
          f"{worst['model']:.2f} ppm ({gain_nl:.1f}x {'better' if gain_nl > 1 else 'WORSE'}); repeatability "
          f"{rep_c:.2f} -> {rep_m:.2f} ppm (both take the thermal state out of the scale factor)")
    print(f"  noise floor: one point's output_sigma is {floor_ppm:.2f} ppm of full scale, so ~{2.5 * floor_ppm:.1f} "
          "ppm is the worst residual to expect from noise alone over 22 points")
    for name, r in extras.items():
        print(f"  sensitivity: {name}: worst {max(r['runs_ppm']):.2f} ppm, repeatability "
              f"{r['repeatability_ppm']:.2f} ppm")
    p = results["model"]["compensator"]["parameters"]
    print(f"  model (fitted with run Three held out): INL u^3 {p['inl_u3_lsb']['value']:.1f} LSB, u^5 "
          f"{p['inl_u5_lsb']['value']:.1f} LSB (true {-1063.6 * args.inl_scale:.1f}, {3418.6 * args.inl_scale:.1f}; "
          "the unmodelled 10 deg/s quadrature word lifts the u^3 fit by ~1.5 LSB per unit scale); "
          f"TCF {p['tcf_ppm_per_k']['value']:.2f} ppm/K (true -30)")

    summary = {"settings": {"inl_scale": args.inl_scale, "warmup_rise_k": args.warmup_rise,
                            "first_run_time_constant_s": FIRST_RUN_TIME_CONSTANT_S,
                            "run_time_constant_s": RUN_TIME_CONSTANT_S, "seed": args.seed,
                            "rates_dps": list(rates), "protocol": "leave-one-out: each run compensated by a "
                                                                  "compensator fitted on the other runs"},
               "results": {m: {k: v for k, v in results[m].items() if k != "residuals_ppm"} for m in METHODS},
               "sensitivity": {k: {kk: vv for kk, vv in v.items() if kk != "residuals_ppm"}
                               for k, v in extras.items()},
               "seed000_table3": SEED000_TABLE3, "ordering_reproduced": ordered,
               "model_over_composite_worst_nonlinearity": gain_nl,
               "model_over_composite_repeatability": gain_rep, "noise_floor_ppm_per_point": floor_ppm,
               "table_markdown": text}
    gj.io.atomic_write_json(summary, os.path.join(args.out, "table3.json"))
    gj.io.atomic_write_bytes(os.path.join(args.out, "table3.md"), (text + "\n").encode())
    plot(results, np.asarray(rates), os.path.join(args.out, "fig10.png"))
    print(f"  wrote data.csv, table3.md, table3.json, fig10.png to {args.out}")
    return summary


if __name__ == "__main__":
    main(sys.argv[1:])
