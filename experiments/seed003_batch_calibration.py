"""Seed 003's batch experiment in simulation: calibrate a lot of open-loop gyros with a virtual Coriolis force.

Run: python experiments/seed003_batch_calibration.py [--devices 13] [--runs 1] [--seed 3] [--out DIR]

Seed 003 measured 13 open-loop gyros of one batch on a rate table (SF_rate) and with a virtual rate table
(SF_virtual: V_ac swept at V_fc = 1 V, converted to a virtual rate with Eq. (7) and Table 1's design values),
and found the ratio SF_rate / SF_virtual equal across the batch within 0.79 %: one rate-table calibration then
calibrates the whole batch. It also swept the virtual rate's frequency (10-500 Hz, V_ac = 20 mV) to measure
the rate bandwidth: 354.3 Hz, against 349.5 Hz simulated.

Here a lot of `--devices` vcf-2018 devices is drawn with a batch-like spread (`SEED003_SPREAD`: Q and the mode
split vary most, m_d and K_svf "very close", seed 003 §3), each simulated on seed 000's rate table, the static
virtual rate table and the dynamic virtual test (`gyrojax.simulate_table`, noise included), and per device:
the rate-table SF, the virtual SF, their ratio against the model's own physical ratio
2 Ag m a w_d / (K_svf V_fc) over the design value, and the -3 dB bandwidth of the dynamic VCF sweep
(`gyrojax.metrics.rate_bandwidth`) against the model's own rate bandwidth (`gyrojax.physics.bandwidth`).

What closes (13 devices, seed 3, default noise):
  - the ratio is nearly constant across the lot while the rate SF is not: SF_rate spreads by 8.6 %
    (max - min over mean; the open-loop SF goes as 1 / split), the ratio by 0.36 % (seed 003: 0.79 %), so
    one device's ratio calibrates every other to 0.36 %. The ratio depends only on m Ag a w_d / K_svf, never
    on Q or the split; its spread is the spread of those four (with a charge-sensing drive loop holding the
    amplitude a, the ratio tracks w_d: 0.1 % of frequency spread is 0.1 % of ratio), so how well it closes
    with the seed's 0.79 % is set by the assumed spreads of `SEED003_SPREAD`, not fitted to it. Each
    device's ratio matches 2 Ag m a w_d / (K_svf V_fc) over the design value to 61 ppm: the real rate pulls
    the drive frequency (-66 ppm over seed 000's grid on vcf-2018) and the virtual force does not.
  - the dynamic virtual-Coriolis test measures the model's own rate bandwidth (91-100 Hz across the lot)
    per device to 0.7 Hz: the test references its 10 Hz point, not DC, and interpolates on a 10 Hz grid.
What does not close:
  - the bandwidth itself: Table 2 (w_d = 11330, w_s = 11715 rad/s, Q_s = 9824) gives ~97 Hz (the response
    peaks at the 62 Hz detuning and falls 3 dB at sqrt(1 + sqrt 2) x detuning); the paper reports 354.3 Hz
    measured and 349.5 Hz simulated. Its numbers cannot all be right.
  - the absolute ratio: seed 003 measured 0.104 mV/(deg/s) on the rate table and 0.183 mV per virtual deg/s,
    a ratio of 0.568. The model built from the same design values gives 1.000: the as-built virtual force is
    1.76x what Table 1's K_svf, m_d and x w_d predict, which the paper cannot tell apart and neither can we.
"""

import argparse
import io
import math
import os
import sys

import jax
import numpy as np

import gyrojax as gj
from gyrojax import _presets as P


DEG = gj.units.DEG


SEED003_SPREAD = gj.ProcessSpread(
    omega=1e-3,  # ASSUMPTION: both modes together, 0.1 % (1.8 Hz): dies of one batch "machined almost simultaneously"
    split=1.5e-3,  # ASSUMPTION: sense against drive, 0.15 % of w_s = 2.8 Hz on the 62 Hz split (seed 003 §3:
    #                "the main errors ... are Quality factor and frequency error"); SF_rate ~ 1 / split
    q=0.15,  # ASSUMPTION: +/-15 % Q (seed 003 §3 names Q first)
    mass=1e-3,  # ASSUMPTION: m_d "very close" (seed 003 §3): 0.1 %
    angular_gain=5e-4,  # ASSUMPTION: mode shapes of one mask: 0.05 %
    electrode=2e-3,  # ASSUMPTION: drive electrode 0.2 % (sets only the drive voltage)
    vcf_electrode=1e-3,  # ASSUMPTION: K_svf "very close" (seed 003 §3): 0.1 %
)
"""Process spread of seed 003's batch; seed 003 prints none, every figure is an ASSUMPTION (see the comments)."""

PAPER = {
    "devices": 13,  # seed 003 §3, Fig. 5
    "ratio_spread_pct": 0.79,  # seed 003 §3: "biggest difference of each other was 0.79%"
    "sf_rate_mv_per_dps": 0.104,  # seed 003 §3, rate table
    "sf_virtual_mv_per_dps": 0.183,  # seed 003 §3, virtual rate table
    "bandwidth_measured_hz": 354.3,  # seed 003 abstract, §3
    "bandwidth_simulated_hz": 349.5,  # seed 003 abstract, §3
}

DESIGN_VOLTS_PER_RAD_S = 2.0 * P.VCF_MASS * P.VCF_DRIVE_VELOCITY / (P.VCF_KSVF * gj.sweeps.VCF_CARRIER_V)
"""Seed 003 Eq. (7) with Table 1's design values: the V_ac that stands for 1 rad/s of virtual rate."""


def _fit(table, sweep):
    arr = table.to_arrays(sweep)
    fit = gj.fit_scale_factor(np.asarray(arr.inputs), np.asarray(arr.outputs), mask=np.asarray(arr.mask))
    return arr, np.asarray(fit.scale_factor)


def run(devices=13, runs=1, seed=3):
    gyro = gj.vcf_2018()
    sweeps = ("rate_table", "vcf_static", "vcf_dynamic")
    table = gj.simulate_table(gyro, devices=devices, runs=runs, sweeps=sweeps, spread=SEED003_SPREAD, seed=seed,
                              device_prefix="seed003")
    lot = gj.campaign_lot(gyro, devices=devices, seed=seed, spread=SEED003_SPREAD)
    rate, sf_rate = _fit(table, "rate_table")  # LSB per deg/s, (device, run)
    _, sf_volt = _fit(table, "vcf_static")  # LSB per V
    sf_virtual = sf_volt * DESIGN_VOLTS_PER_RAD_S * DEG  # LSB per virtual deg/s (Eq. 7, design values)
    ratio = sf_rate / sf_virtual
    dyn = table.to_arrays("vcf_dynamic")
    bw = gj.metrics.rate_bandwidth(np.asarray(dyn.inputs), np.asarray(dyn.outputs), mask=np.asarray(dyn.mask),
                           phase_deg=np.asarray(dyn.aux["phase_deg"]))
    lsb_v = P.VCF_ADC_LSB  # V per output LSB (the rate output's ADC)
    records = []
    for d in range(devices):
        g = jax.tree.map(lambda x: x[d], lot)
        r = g.resonator
        temp = float(np.mean(np.asarray(rate.temperatures[d])))
        w = float(r.at_temperature(temp)[0])
        phys = (2.0 * float(r.angular_gain) * float(r.mass) * float(g.drive_amplitude(w)) * w
                / (float(g.vcf_electrode.force_per_volt2) * gj.sweeps.VCF_CARRIER_V))
        records.append({
            "device": table.to_arrays("rate_table").devices[d],
            "q_sense": float(r.q_y),
            "split_hz": float(r.omega_y - r.omega_x) / (2 * math.pi),
            "sf_rate_lsb_per_dps": float(np.mean(sf_rate[d])),
            "sf_rate_mv_per_dps": float(np.mean(sf_rate[d])) * lsb_v * 1e3,
            "sf_virtual_lsb_per_dps": float(np.mean(sf_virtual[d])),
            "ratio": float(np.mean(ratio[d])),
            "ratio_physical": phys / DESIGN_VOLTS_PER_RAD_S,
            "bandwidth_vcf_hz": float(np.mean(np.asarray(bw.bandwidth_hz[d]))),
            "phase_at_bandwidth_deg": float(np.mean(np.asarray(bw.phase_deg[d]))),
            "bandwidth_model_hz": float(gj.physics.bandwidth(g)),
        })
    ratios = np.array([rec["ratio"] for rec in records])
    sfs = np.array([rec["sf_rate_lsb_per_dps"] for rec in records])
    bw_err = np.array([rec["bandwidth_vcf_hz"] - rec["bandwidth_model_hz"] for rec in records])
    summary = {
        "devices": devices,
        "runs": runs,
        "ratio_mean": float(np.mean(ratios)),
        "ratio_spread_pct": float(np.ptp(ratios) / np.mean(ratios) * 100),
        "rate_sf_spread_pct": float(np.ptp(sfs) / np.mean(sfs) * 100),
        "single_device_calibration_error_pct": float((np.max(ratios) / np.min(ratios) - 1) * 100),
        "ratio_vs_physical_ppm_max": float(np.max(np.abs(
            ratios / np.array([rec["ratio_physical"] for rec in records]) - 1)) * 1e6),
        "bandwidth_vcf_minus_model_hz_max": float(np.max(np.abs(bw_err))),
        "bandwidth_model_mean_hz": float(np.mean([rec["bandwidth_model_hz"] for rec in records])),
        "paper_ratio": PAPER["sf_rate_mv_per_dps"] / PAPER["sf_virtual_mv_per_dps"],
        "paper_ratio_spread_pct": PAPER["ratio_spread_pct"],
        "paper_bandwidth_measured_hz": PAPER["bandwidth_measured_hz"],
        "paper_bandwidth_simulated_hz": PAPER["bandwidth_simulated_hz"],
    }
    return table, records, summary


def _plot(table, records, summary):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    k = np.arange(len(records))
    sf = np.array([r["sf_rate_lsb_per_dps"] for r in records])
    ratio = np.array([r["ratio"] for r in records])
    ax = axes[0]
    ax.bar(k - 0.2, (sf / sf.mean() - 1) * 100, width=0.4, label="rate-table SF")
    ax.bar(k + 0.2, (ratio / ratio.mean() - 1) * 100, width=0.4, label="SF_rate / SF_virtual")
    ax.set(xlabel="device", ylabel="deviation from lot mean (%)",
           title=f"spread: SF {summary['rate_sf_spread_pct']:.1f} %, ratio {summary['ratio_spread_pct']:.2f} % "
                 f"(seed 003: {PAPER['ratio_spread_pct']} %)")
    ax.legend()
    ax = axes[1]
    ax.plot(k, ratio, "o", label="measured (simulated, noisy)")
    ax.plot(k, [r["ratio_physical"] for r in records], "x", label="2 Ag m a w_d / K_svf over design")
    ax.set(xlabel="device", ylabel="SF_rate / SF_virtual",
           title=f"ratio (seed 003 measured {summary['paper_ratio']:.3f}: does not close)")
    ax.legend()
    ax = axes[2]
    dyn = table.to_arrays("vcf_dynamic")
    f = np.asarray(dyn.inputs[0, 0])
    for d in range(len(records)):
        a = np.asarray(dyn.outputs[d, 0])
        ax.semilogx(f, 20 * np.log10(a / a[0]), lw=0.8)
    ax.axhline(-3.0, color="k", ls=":", lw=0.8)
    ax.axvline(summary["bandwidth_model_mean_hz"], color="C0", ls="--", lw=0.8, label="model rate bandwidth")
    ax.axvline(PAPER["bandwidth_measured_hz"], color="C3", ls="--", lw=0.8, label="seed 003: 354.3 Hz")
    ax.set(xlabel="modulation frequency (Hz)", ylabel="VCF response re 10 Hz (dB)",
           title="dynamic virtual-Coriolis test, V_ac = 20 mV")
    ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", type=int, default=PAPER["devices"], help="lot size (seed 003: 13)")
    ap.add_argument("--runs", type=int, default=1, help="runs per device (default 1)")
    ap.add_argument("--seed", type=int, default=3, help="PRNG seed of the lot and the noise")
    ap.add_argument("--out", help="folder for seed003_batch_calibration.json and .png")
    args = ap.parse_args(argv)
    table, records, summary = run(args.devices, args.runs, args.seed)
    print(f"Seed 003 batch calibration, simulated: {args.devices} vcf-2018 devices, {args.runs} run(s) each")
    print(f"{'device':>12} {'Q_s':>7} {'split':>7} {'SF_rate':>9} {'SF_rate':>9} {'SF_virt':>9} {'ratio':>8} "
          f"{'physical':>8} {'BW_vcf':>7} {'BW_model':>8}")
    print(f"{'':>12} {'':>7} {'Hz':>7} {'LSB/dps':>9} {'mV/dps':>9} {'LSB/dps':>9} {'':>8} {'':>8} {'Hz':>7} "
          f"{'Hz':>8}")
    for r in records:
        print(f"{r['device']:>12} {r['q_sense']:7.0f} {r['split_hz']:7.2f} {r['sf_rate_lsb_per_dps']:9.4f} "
              f"{r['sf_rate_mv_per_dps']:9.5f} {r['sf_virtual_lsb_per_dps']:9.4f} {r['ratio']:8.5f} "
              f"{r['ratio_physical']:8.5f} {r['bandwidth_vcf_hz']:7.1f} {r['bandwidth_model_hz']:8.1f}")
    s = summary
    print(f"rate-table SF spread (max - min) / mean: {s['rate_sf_spread_pct']:.2f} %")
    print(f"ratio SF_rate / SF_virtual spread: {s['ratio_spread_pct']:.3f} % (seed 003: all within "
          f"{s['paper_ratio_spread_pct']} %); one device's ratio calibrates every other to "
          f"{s['single_device_calibration_error_pct']:.3f} %  -> closes")
    print(f"ratio against the physics 2 Ag m a w_d / (K_svf V_fc): within {s['ratio_vs_physical_ppm_max']:.0f} ppm "
          "(the rate's Coriolis pulling, -66 ppm, and noise)")
    print(f"ratio itself: model {s['ratio_mean']:.4f} with the design values; seed 003 measured "
          f"{PAPER['sf_rate_mv_per_dps']} / {PAPER['sf_virtual_mv_per_dps']} = {s['paper_ratio']:.3f}  -> DOES NOT "
          "CLOSE (the as-built virtual force is 1.76x the design's)")
    print(f"dynamic VCF bandwidth vs the model's own rate bandwidth: within "
          f"{s['bandwidth_vcf_minus_model_hz_max']:.2f} Hz  -> closes")
    print(f"rate bandwidth: model {s['bandwidth_model_mean_hz']:.1f} Hz; seed 003 "
          f"{s['paper_bandwidth_measured_hz']} Hz measured, {s['paper_bandwidth_simulated_hz']} Hz simulated  "
          "-> DOES NOT CLOSE")
    out = {"devices": records, "summary": summary, "paper": PAPER, "versions": {"gyrojax": gj.__version__}}
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        gj.io.atomic_write_json(out, os.path.join(args.out, "seed003_batch_calibration.json"))
        gj.io.atomic_write_bytes(os.path.join(args.out, "seed003_batch_calibration.png"),
                                 _plot(table, records, summary))
        print(f"wrote {args.out}/seed003_batch_calibration.json and .png")
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
