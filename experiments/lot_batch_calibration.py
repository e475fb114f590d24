"""Batch calibration beyond seed 003: predict every device's rate-table scale factor, with an uncertainty,
from virtual-Coriolis (VCF) sweeps on all devices and rate tables on a few.

Run: python experiments/lot_batch_calibration.py [--devices 64] [--rate-devices 4] [--seed 11] [--out DIR]

The lot: `--devices` open-loop vcf-2018 devices (seed 003's own device; see "Why vcf-2018" below) drawn with
`gyrojax.WaferProcess`: structural thickness, CD loss of the etch and local mismatch generate the mass, the
resonances, every electrode and pick-off factor and the AGC-held drive amplitude together, the way they co-vary
physically (every number an ASSUMPTION with its reason in `gyrojax/_lots/process.py`; the thickness/CD/mismatch
figures are fixed so that the seed-003 ratio spreads as seed 003 measured: 0.79 % over 13 devices). The
as-built lot also differs from the design the fits start from: its VCF force is 1.76x the design value (seed
003's measured SF_rate / SF_virtual = 0.568) and its readout's sense channel gain is 2 % low (ASSUMPTION).
Each device gets seed 003's static and dynamic VCF sweeps; only the first `--rate-devices` also get seed
000's rate table (noise on: `gyrojax.RateNoise` defaults, one run per sweep with its warm-up).

Two predictions of every other device's rate-table scale factor, both from the data only:

- seed 003's method: the mean ratio SF_rate / SF_virtual of the rate-table devices times each device's own
  SF_virtual (least-squares slopes; SF_virtual through Eq. 7 with the design values), with the ratios'
  scatter times sqrt(1 + 1/K) as its uncertainty.
- gyrojax's model-based one: one joint `gyrojax.identify` of the whole lot from the design preset, every
  device's drive resonance set from its measured drive frequency (PLL reading, referred to 25 C with
  silicon's TCF); per device free: the sense resonance and Q (the dynamic VCF sweep's shape), the VCF
  electrode factor (absorbs K_svf / m, thickness and CD), and Ag with a Gaussian prior of the assumed
  rate-path mismatch (`WaferProcess.rate_path_sigma`); lot-shared: the sense-channel gain, fitted on the
  rate-table devices. The prediction is the fit's zero-rate scale factor with its delta-method standard
  error (covariance of the joint fit: noise, the shared gain's uncertainty and the mismatch prior).

Truth: each device's zero-rate scale factor from the noise-free true model at the temperature the fit
reports (the rate-table mean die temperature for rate-table devices, 25 C for the others).

The physics that decides it: the ratio SF_rate / SF_virtual = 2 Ag m a w_d / (K_svf V_fc) carries m, a and
K_svf, which move with thickness and CD and which no VCF sweep sees: that spread is the seed method's floor.
The open-loop rate-table SF itself is G K_yi Ag a w_d / |sense dynamics|: the VCF sweeps measure the sense
dynamics (split, Q) and the drive frequency is read from the PLL; in K_yi a (sense pick-off times the
amplitude the AGC holds through the drive pick-off) thickness and CD cancel when both pick-offs are combs of
one design etched together. What is left, G Ag K_yi / K_xi, is one lot-wide readout gain (fitted on the
rate-table devices) times local mismatch of Ag and the two pick-offs: the model-based floor,
sqrt(3) x mismatch = 0.087 % at the assumed 0.05 %. Assumptions this rests on, and what breaks it: one
calibrated readout for every device (per-device electronics with 0.5 % gain tolerance would add 0.5 %);
both pick-offs of one comb design (a parallel-plate sense pick-off would leave the CD in: 2 delta / g per
unit CD); a known TCF.

Why vcf-2018 and not paper-qmg: seed 003's batch method was made for, and measured on, this open-loop device;
its rate SF spreads by ~9 % with the mode split (`experiments/seed003_batch_calibration.py`), so the VCF
sweeps have something to measure. In closed loop (FTR) the rate SF is 2 Ag m a w / K_vf: thickness no longer
cancels (m a / K_vf ~ g^2 / h), and a VCF sweep reads only K_svf / K_vf, so the floor there is the thickness
and CD spread that the ratio method already has.
"""

import argparse
import dataclasses
import importlib.metadata
import math
import os
import platform
import sys
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import gyrojax as gj


DEG = gj.units.DEG


AS_BUILT_VCF_FACTOR = 0.183 / 0.104
"""Seed 003 §3: 0.183 mV per virtual deg/s against 0.104 mV/(deg/s) on the rate table: with the design values
the model's ratio is 1.000, so the as-built virtual force is 1.76x the design's. The fit does not know it."""

AS_BUILT_SENSE_GAIN = 0.98
"""ASSUMPTION: the readout's sense channel is 2 % below its design gain (two 1 % gain stages); common to the
lot (one calibrated test readout), unknown to the fit, which must find it from the rate-table devices."""

FREE = ("sense_gain", "vcf_gain", "omega_y", "q_y", "angular_gain")
"""Per device the sense resonance, Q, VCF factor and Ag, and the lot-shared sense gain. The sense Q has a
prior (design +/- the lot's 15 %): its resonance is 0.09 Hz wide, the dynamic test's 10 Hz grid never lands
on it, so the data see Q_y only through (g_y / detuning)^2, and unregularised from a poor start it wandered
off (measured: to 1e243 in a 3-device fit, with LM reporting success). The rate SF depends on it by 1 ppm."""
SHARED = ("sense_gain",)
SWEEPS = ("rate_table", "vcf_static", "vcf_dynamic")

_SMALL_RATES = (-200.0, -100.0, -20.0, -5.0, 5.0, 20.0, 100.0, 200.0)
SMALL_SWEEPS = (gj.sweeps.RateTable(rates_dps=_SMALL_RATES), gj.sweeps.VcfStatic(virtual_rates_dps=_SMALL_RATES),
                gj.sweeps.VcfDynamic(frequencies_hz=tuple(10.0 * k for k in range(1, 21))))
"""`--points small`: 8 table and virtual rates over +/-200 deg/s and the dynamic test on a 10 Hz grid up to 200 Hz
(the vcf-2018 response peaks at the 62 Hz split and is past its -3 dB point at ~97 Hz): 36 points per device
instead of 94. The scale factor's prediction error is set by the rate-path mismatch (0.087 %), far above what
the points' noise leaves, so the coverage statistics need lots, not points."""


def as_built(design):
    """The as-built nominal device of the lot (see AS_BUILT_*)."""
    return eqx.tree_at(lambda g: (g.vcf_electrode.force_per_volt2, g.sense_frontend.gain), design,
                       (design.vcf_electrode.force_per_volt2 * AS_BUILT_VCF_FACTOR,
                        design.sense_frontend.gain * AS_BUILT_SENSE_GAIN))


@eqx.filter_jit
def _zero_rate_sf(lot, temps):
    """d(output)/d(rate) at zero rate, LSB per deg/s, per device at its temperature (deg C)."""
    def one(g, t):
        def out(rate):
            return gj.rate_table_points(g, rate[None], t[None], gj.CAMPAIGN_TIER).rate[0]

        return jax.jvp(out, (jnp.zeros(()),), (jnp.ones(()),))[1]

    return eqx.filter_vmap(one)(lot, temps)


@eqx.filter_jit
def _lot_physics(lot):
    """Per device: the seed-003 ratio 2 Ag m a w_d / K_svf and the rate-path factor Ag K_yi a (both at t_ref)."""
    def one(g):
        r = g.resonator
        a = g.drive_amplitude(r.omega_x)
        ratio = (2.0 * r.angular_gain * r.mass * a * r.omega_x
                 / (g.vcf_electrode.force_per_volt2 * gj.sweeps.VCF_CARRIER_V))
        path = r.angular_gain * g.sense_frontend.current_per_velocity * a
        return ratio, path

    return eqx.filter_vmap(one)(lot)


def _stats(err, z=None):
    err = np.asarray(err)
    out = {"rms_pct": float(np.sqrt(np.mean(err**2)) * 100), "max_pct": float(np.max(np.abs(err)) * 100),
           "mean_pct": float(np.mean(err) * 100)}
    if z is not None:
        z = np.asarray(z)
        out.update({"z_rms": float(np.sqrt(np.mean(z**2))), "z_max": float(np.max(np.abs(z)))})
    return out


def _order_by_device(table):
    """The table's rows with devices in lot order (first appearance decides identify's device order)."""
    index = np.array([int(d.rsplit("-", 1)[1]) for d in table["device"].tolist()])
    return table.select(np.argsort(index, kind="stable"))


def measured_drive_frequency(table, design):
    """Per device (lot order): the PLL's drive frequency on the static VCF sweep referred to t_ref with the
    design TCF, rad/s (the mean over the sweep's points)."""
    arr = table.to_arrays("vcf_static")
    r = design.resonator
    mask = np.asarray(arr.mask)
    w = 2 * np.pi * np.asarray(arr.drive_freqs)
    w0 = w / (1.0 + float(r.tcf) * (np.asarray(arr.temperatures) - float(r.t_ref)))
    return np.sum(np.where(mask, w0, 0.0), axis=(1, 2)) / np.sum(mask, axis=(1, 2)), arr.devices



def measured_start(table, design, names):
    """The lot's start: the design per device, each with its drive resonance at the drive frequency it reads
    (and the sense resonance at the design's split ratio)."""
    w_drive, order = measured_drive_frequency(table, design)
    assert list(order) == names, "identify's device order must be the lot order"
    start = jax.tree.map(lambda x: jnp.broadcast_to(x, (len(names),) + jnp.shape(x)), design)
    split_ratio = design.resonator.omega_y / design.resonator.omega_x
    return eqx.tree_at(lambda g: (g.resonator.omega_x, g.resonator.omega_y), start,
                       (jnp.asarray(w_drive), jnp.asarray(w_drive) * split_ratio))

def _sf_temperature(data):
    """The temperature identify reports a scale factor at: the mean rate-table die temperature, else 25 C."""
    b = data.blocks["rate_table"]
    m = np.asarray(b.mask)
    n = m.sum(axis=(1, 2))
    t = np.where(m, np.asarray(b.temperatures), 0.0).sum(axis=(1, 2))
    return np.where(n > 0, t / np.maximum(n, 1), 25.0)


def _slopes(table, sweep):
    arr = table.to_arrays(sweep)
    fit = gj.fit_scale_factor(np.asarray(arr.inputs), np.asarray(arr.outputs), mask=np.asarray(arr.mask))
    return arr.devices, np.asarray(fit.scale_factor)[:, 0]


def _slope_ratio(data, predictions, sweep):
    """Per device: least-squares slope of the measured outputs over that of the predictions (NaN without
    points)."""
    b = data.blocks[sweep]
    x, m = np.asarray(b.inputs), np.asarray(b.mask)

    def slope(y):
        n = np.maximum(m.sum(axis=(1, 2)), 1)
        xm = np.where(m, x, 0).sum(axis=(1, 2)) / n
        ym = np.where(m, y, 0).sum(axis=(1, 2)) / n
        xc = np.where(m, x - xm[:, None, None], 0)
        return (xc * (y - ym[:, None, None])).sum(axis=(1, 2)) / np.where(m.any(axis=(1, 2)),
                                                                            (xc**2).sum(axis=(1, 2)), np.nan)

    return slope(np.asarray(b.outputs)) / slope(np.asarray(predictions[sweep]))


def linear_start(start, table, options):
    """A start from the data's sense resonance and gains: the design starts 76 % off in K_svf and 2 % in the readout
    gain, and a Levenberg-Marquardt step from there can leave the region where every point settles (the steady state's
    implicit derivative is then NaN, which raises inside identify). One evaluation of the design model
    (`evaluate_only`, the fit's own compiled pass) gives per device the measured/predicted slope of the static
    VCF sweep (~ sense gain x K_svf) and, on the rate-table devices, of the rate table (~ sense gain); the
    shared sense gain starts at the rate-table devices' mean and each K_svf at what is left."""
    # The sense resonance from the dynamic test's rise below its peak: with the detuning d = (w_y^2 - w_d^2) /
    # (2 w_d) >> g_y, the demodulated response to a virtual rate at w_z is ~ C d / (d^2 - w_z^2) below the
    # peak, so 1 / A = (d^2 - w_z^2) / (C d) is a line in w_z^2 whose intercept over slope is d^2.
    d = np.empty(start.resonator.omega_x.shape)
    b = table.to_arrays("vcf_dynamic")
    for i in range(d.size):
        f, a = np.asarray(b.inputs[i, 0]), np.asarray(b.outputs[i, 0])
        below = np.asarray(b.mask[i, 0]) & (f < f[np.argmax(np.where(np.asarray(b.mask[i, 0]), a, 0))])
        slope, intercept = np.polyfit((2 * np.pi * f[below]) ** 2, 1.0 / a[below], 1)
        d[i] = math.sqrt(-intercept / slope)
    w_d = np.asarray(start.resonator.omega_x)
    start = eqx.tree_at(lambda g: g.resonator.omega_y, start, jnp.asarray(np.sqrt(w_d**2 + 2 * w_d * d)))
    probe = gj.identify(gj.Model(start), table, evaluate_only=True, **options)
    k_vcf = _slope_ratio(probe.data, probe.predictions, "vcf_static")
    k_rate = float(np.nanmean(_slope_ratio(probe.data, probe.predictions, "rate_table")))
    return eqx.tree_at(lambda g: (g.sense_frontend.gain, g.vcf_electrode.force_per_volt2), start,
                       (start.sense_frontend.gain * k_rate,
                        start.vcf_electrode.force_per_volt2 * jnp.asarray(k_vcf / k_rate)))


def _scaled(lot, leaf, factor):
    return eqx.tree_at(leaf, lot, leaf(lot) * factor)


def joint_covariance(fit, sf_log_grad):
    """Covariance of the joint fit's internal coordinates from the SVD of the whole lot's weighted Jacobian,
    and from it the relative standard error of every device's zero-rate SF and of the shared gain.

    An independent cross-check of `fit.scale_factor_stderr` / `fit.lot_stderr` (the lot column built
    analytically here). It found that identify, which then inverted J^T J with a pseudo-inverse, squared J's
    condition number: the dynamic VCF test fixes the sense resonance to 2e-11 (singular value ~5e10 in
    internal units) while the Ag prior contributes 1 / 8.7e-4 ~ 1e3, J^T J's condition passed 1e15 and the
    prior's directions were dropped (shared-gain stderr 8e-8 relative instead of ~6e-4, z = 3681). identify now
    takes the SVD of the column-scaled J as well, and the two agree to 1e-9 (tests/test_batch_calibration.py).

    The lot column needs no second evaluation: every output of the open-loop readout is proportional to the
    sense gain, so d r / d log(G) is minus the bias-projected prediction over sigma (zero on prior rows).
    `sf_log_grad` is (device, free) d ln SF / d u for the per-device free entries; d ln SF / d log G = 1."""
    n = len(fit.devices)
    free = np.asarray(fit.free)
    jac = np.asarray(fit.jacobian)[:, :, free]  # (device, rows, n_free), rows = data then priors
    rows, k = jac.shape[1], jac.shape[2]
    lot_col = np.zeros((n, rows))
    off = 0
    for sweep in fit.data.sweeps:
        b = fit.data.blocks[sweep]
        pred = np.asarray(fit.predictions[sweep])
        m, sig = np.asarray(b.mask), np.asarray(b.sigmas)
        if sweep in ("rate_table", "vcf_static"):  # the run bias absorbs the prediction's weighted mean
            w = np.where(m, 1.0 / sig**2, 0.0)
            pred = pred - (w * pred).sum(-1, keepdims=True) / np.maximum(w.sum(-1, keepdims=True), 1e-300)
        col = np.where(m, -pred / sig, 0.0).reshape(n, -1)
        lot_col[:, off:off + col.shape[1]] = col
        off += col.shape[1]
    full = np.zeros((n * rows, n * k + 1))
    for d in range(n):
        full[d * rows:(d + 1) * rows, d * k:(d + 1) * k] = jac[d]
        full[d * rows:(d + 1) * rows, -1] = lot_col[d]
    scale = np.linalg.norm(full, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    _, sv, vt = np.linalg.svd(full / scale, full_matrices=False)
    cov = (vt.T / sv**2) @ vt / np.outer(scale, scale)
    if not fit.weighted:
        cov = cov * fit.chi2_red_total
    g = np.zeros((n, n * k + 1))
    for d in range(n):
        g[d, d * k:(d + 1) * k] = sf_log_grad[d]
    g[:, -1] = 1.0
    sf_rel = np.sqrt(np.einsum("di,ij,dj->d", g, cov, g))
    return sf_rel, float(np.sqrt(cov[-1, -1])), float(sv[0] / sv[-1])


def sf_log_gradient(fit, temps):
    """(device, free) d ln SF / d u at the solution for identify's free per-device entries: Ag and the sense
    gain enter the open-loop SF as factors (1), the VCF factor not at all (0), the sense resonance and Q by
    central differences of the steady state (relative step 1e-6; SF ~ 1 / detuning, ~ -15 per unit of
    log omega_y)."""
    gyro = fit.model.gyroscope()
    out = np.zeros((len(fit.devices), int(np.sum(fit.free))))
    names = [nm for nm, f in zip(fit.names, fit.free) if f]
    for j, nm in enumerate(names):
        if nm == "angular_gain":
            out[:, j] = 1.0
        elif nm in ("omega_y", "q_y"):
            leaf = gj.PARAMETERS[nm].where
            h = 1e-6
            up = np.asarray(_zero_rate_sf(_scaled(gyro, leaf, math.exp(h)), temps))
            down = np.asarray(_zero_rate_sf(_scaled(gyro, leaf, math.exp(-h)), temps))
            out[:, j] = (np.log(up) - np.log(down)) / (2 * h)
        elif nm != "vcf_gain":
            raise ValueError(f"no SF gradient rule for {nm!r}")
    return out


def simulate_lot(devices=64, seed=11, process=None, sweeps=None):
    """The lot and its campaign, every device with its rate table: (table, true lot, design, sweep kinds);
    `sweeps` the kinds with their points (default `SWEEPS` at their defaults)."""
    process = gj.WaferProcess() if process is None else process
    design = gj.vcf_2018()
    truth_nominal = as_built(design)
    kinds = [gj.sweeps.sweep_kind(s) for s in (SWEEPS if sweeps is None else sweeps)]
    # The static VCF voltages come from the design values (what the test engineer knows), not the as-built.
    kinds = tuple(dataclasses.replace(k, amplitudes_v=tuple(k.inputs(design)))
                  if isinstance(k, gj.sweeps.VcfStatic) else k
                  for k in kinds)
    table = gj.simulate_table(truth_nominal, devices=devices, runs=1, sweeps=kinds, spread=process, seed=seed,
                              device_prefix="lot")
    lot = gj.campaign_lot(truth_nominal, devices=devices, seed=seed, spread=process)
    return table, lot, design, kinds


def with_rate_tables(table, devices, rate_devices):
    """`table` with the rate table kept on the first `rate_devices` devices only, in lot order; and the names."""
    names = [f"lot-{i:03d}" for i in range(devices)]
    rate_names = set(names[:rate_devices])
    keep = [i for i, (d, s) in enumerate(zip(table["device"].tolist(), table["sweep"].tolist()))
            if s != "rate_table" or d in rate_names]
    return _order_by_device(table.select(keep)), names, rate_names


def ratio_method(table, design):
    """Seed 003's method: (the rate-table devices' mean SF_rate / SF_virtual, its scatter x sqrt(1 + 1/K)
    relative, {device: SF_virtual})."""
    design_volts_per_rad_s = float(2.0 * design.resonator.mass * design.resonator.angular_gain
                                   * design.drive_amplitude(design.resonator.omega_x) * design.resonator.omega_x
                                   / (design.vcf_electrode.force_per_volt2 * gj.sweeps.VCF_CARRIER_V))
    rate_devs, sf_rate = _slopes(table, "rate_table")
    vcf_devs, sf_volt = _slopes(table, "vcf_static")
    sf_virtual = dict(zip(vcf_devs, sf_volt * design_volts_per_rad_s * DEG))
    ratios = np.array([sf_rate[k] / sf_virtual[d] for k, d in enumerate(rate_devs)])
    ratio_mean = float(np.mean(ratios))
    # one device has no scatter: no uncertainty (NaN)
    ratio_rel_sd = (float(np.std(ratios, ddof=1) / ratio_mean * math.sqrt(1.0 + 1.0 / len(ratios)))
                    if len(ratios) > 1 else math.nan)
    return ratio_mean, ratio_rel_sd, sf_virtual


def run(devices=64, rate_devices=4, seed=11, process=None, sweeps=None, simulated=None):
    """Simulate (or take `simulated`, `simulate_lot`'s), fit and compare; returns (records, summary, fit)."""
    if not 1 <= rate_devices < devices:
        raise ValueError(f"rate_devices must be >= 1 (the seed method's uncertainty needs 2) and < devices; got "
                         f"{rate_devices} of {devices}.")
    process = gj.WaferProcess() if process is None else process
    timings = {}
    t0 = time.perf_counter()
    table, lot, design, _ = simulate_lot(devices, seed, process, sweeps) if simulated is None else simulated
    timings["simulate_s"] = time.perf_counter() - t0
    table, names, rate_names = with_rate_tables(table, devices, rate_devices)

    # --- seed 003: a constant ratio from the rate-table devices ---------------------------------------------
    ratio_mean, ratio_rel_sd, sf_virtual = ratio_method(table, design)

    # --- gyrojax: one joint fit of the lot ----------------------------------------------------------------
    start = measured_start(table, design, names)
    # Steady at 1e-10 (CAMPAIGN_TIER): identify's default 1e-11 stalls at round-off on open-loop points at
    # high rates (see gyrojax.CAMPAIGN_TIER), and a stalled point's implicit derivative is NaN.
    options = dict(free=FREE, shared=SHARED, tier=gj.CAMPAIGN_TIER,
                   priors={"angular_gain": (float(design.resonator.angular_gain), process.rate_path_sigma),
                           "q_y": (float(design.resonator.q_y), process.q * float(design.resonator.q_y))})
    t0 = time.perf_counter()
    start = linear_start(start, table, options)
    timings["start_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = gj.identify(gj.Model(start), table, **options)
    timings["identify_s"] = time.perf_counter() - t0

    # --- truth and comparison -----------------------------------------------------------------------------
    t0 = time.perf_counter()
    t_sf = _sf_temperature(fit.data)
    sf_true = np.asarray(_zero_rate_sf(lot, jnp.asarray(t_sf)))
    ratio_true, path_true = (np.asarray(x) for x in _lot_physics(lot))
    timings["truth_s"] = time.perf_counter() - t0
    sf_model = np.asarray(fit.scale_factor)
    t0 = time.perf_counter()
    sf_rel, shared_rel, cond = joint_covariance(fit, sf_log_gradient(fit, jnp.asarray(t_sf)))
    timings["covariance_s"] = time.perf_counter() - t0
    sd_model = sf_rel * np.abs(sf_model)
    sd_identify = np.asarray(fit.scale_factor_stderr)
    records = []
    for i, d in enumerate(names):
        pred_seed = ratio_mean * sf_virtual[d]
        records.append({
            "device": d,
            "rate_table": d in rate_names,
            "temperature_c": float(t_sf[i]),
            "sf_true": float(sf_true[i]),
            "seed_prediction": float(pred_seed),
            "seed_error_pct": float((pred_seed / sf_true[i] - 1) * 100),
            "seed_z": float((pred_seed / sf_true[i] - 1) / ratio_rel_sd),
            "model_prediction": float(sf_model[i]),
            "model_stderr": float(sd_model[i]),
            "model_error_pct": float((sf_model[i] / sf_true[i] - 1) * 100),
            "model_z": float((sf_model[i] - sf_true[i]) / sd_model[i]),
            "identify_stderr": float(sd_identify[i]),
            "converged": bool(np.asarray(fit.converged)[i]),
            "chi2_red": float(np.asarray(fit.chi2_red)[i]),
        })
    held = [r for r in records if not r["rate_table"]]
    shared_truth = float(design.sense_frontend.gain * AS_BUILT_SENSE_GAIN)
    sg = float(fit.lot_values[0])
    sg_sd = shared_rel * sg
    summary = {
        "devices": devices,
        "rate_devices": rate_devices,
        "held_out": len(held),
        "seed": seed,
        "preset": "vcf-2018",
        "process": {f: float(getattr(process, f)) for f in ("thickness", "cd_loss", "beam_width", "comb_gap",
                                                            "vcf_gap", "perimeter_per_area", "mismatch", "omega",
                                                            "split", "q")},
        "as_built": {"vcf_factor": AS_BUILT_VCF_FACTOR, "sense_gain_factor": AS_BUILT_SENSE_GAIN},
        "rate_sf_spread_pct": float(np.std(sf_true) / np.mean(sf_true) * 100),
        "true_ratio_spread_pct": float(np.std(ratio_true) / np.mean(ratio_true) * 100),
        "true_rate_path_spread_pct": float(np.std(path_true) / np.mean(path_true) * 100),
        "assumed_rate_path_sigma_pct": process.rate_path_sigma * 100,
        "seed_method": _stats([r["seed_error_pct"] / 100 for r in held], [r["seed_z"] for r in held])
        | {"ratio_mean": ratio_mean, "ratio_rel_sd_pct": ratio_rel_sd * 100,
           "paper_ratio": 0.104 / 0.183},
        "model": _stats([r["model_error_pct"] / 100 for r in held], [r["model_z"] for r in held])
        | {"stderr_rms_pct": float(np.sqrt(np.mean([(r["model_stderr"] / r["model_prediction"]) ** 2
                                                    for r in held])) * 100)},
        "model_rate_devices": _stats([r["model_error_pct"] / 100 for r in records if r["rate_table"]],
                                     [r["model_z"] for r in records if r["rate_table"]]),
        "shared": {"name": "sense_gain", "value": sg, "stderr": sg_sd, "truth": shared_truth,
                   "z": (sg - shared_truth) / sg_sd, "identify_stderr": float(fit.lot_stderr[0])},
        "identify_sf_stderr_rms_pct": float(np.sqrt(np.mean((sd_identify / sf_model) ** 2)) * 100),
        "jacobian_condition": cond,
        "fit": {"chi2_red_total": float(fit.chi2_red_total), "all_converged": fit.all_converged,
                "num_steps": int(np.max(np.asarray(fit.num_steps))), "message": fit.result_message[0],
                "held": [u.held for u in fit.unidentifiable], "free": list(FREE), "shared": list(SHARED)},
        "timings": timings,
    }
    return records, summary, fit


POP_FREE = ("vcf_gain", "omega_y", "q_y", "angular_gain")
"""The population fit's per-device parameters: no lot-shared sense gain (a population fit has no shared ones); the
sense gain stays at the data-based start (`linear_start`), and the lot mean of Ag absorbs what is left of the
readout gain."""
RANDOM = ("angular_gain",)
"""The random effect: Ag, which stands for the whole rate path G K_yi Ag a that no VCF sweep sees (its lot spread is
the rate-path mismatch, `WaferProcess.rate_path_sigma`, which the population fit learns instead of assuming)."""


def run_population(devices=64, rate_devices=4, seed=11, process=None, sweeps=None, simulated=None):
    """The population fit of the lot (`gyrojax.PopulationSolve(random=RANDOM)`): every device's rate-table SF
    predicted, with its 95 % interval (Student-t, `PopulationFit.interval`); returns (records, summary, population
    fit)."""
    if not 1 <= rate_devices < devices:
        raise ValueError(f"rate_devices must be >= 1 and < devices; got {rate_devices} of {devices}.")
    process = gj.WaferProcess() if process is None else process
    table, lot, design, _ = simulate_lot(devices, seed, process, sweeps) if simulated is None else simulated
    table, names, rate_names = with_rate_tables(table, devices, rate_devices)
    start = measured_start(table, design, names)
    q_prior = {"q_y": (float(design.resonator.q_y), process.q * float(design.resonator.q_y))}
    joint_options = dict(free=FREE, shared=SHARED, tier=gj.CAMPAIGN_TIER,
                         priors={"angular_gain": (float(design.resonator.angular_gain), process.rate_path_sigma)}
                         | q_prior)
    t0 = time.perf_counter()
    start = linear_start(start, table, joint_options)
    pf = gj.identify(gj.Model(start), table, free=POP_FREE, tier=gj.CAMPAIGN_TIER, priors=q_prior,
                     lot_solve=gj.PopulationSolve(random=RANDOM))
    seconds = time.perf_counter() - t0
    t_sf = _sf_temperature(pf.fit.data)
    sf_true = np.asarray(_zero_rate_sf(lot, jnp.asarray(t_sf)))
    _, path_true = (np.asarray(x) for x in _lot_physics(lot))
    low, high = pf.interval()
    records = []
    for i, d in enumerate(names):
        z = float((pf.sf[i] - sf_true[i]) / pf.sf_stderr[i])
        records.append({"device": d, "rate_table": d in rate_names, "sf_true": float(sf_true[i]),
                        "prediction": float(pf.sf[i]), "stderr": float(pf.sf_stderr[i]),
                        "error_pct": float((pf.sf[i] / sf_true[i] - 1) * 100), "z": z, "dof": float(pf.sf_dof[i]),
                        "covered": bool(low[i] <= sf_true[i] <= high[i]), "covered_normal": abs(z) < Z95,
                        "halfwidth_pct": float((high[i] - low[i]) / 2 / pf.sf[i] * 100)})
    held = [r for r in records if not r["rate_table"]]
    (ag,) = pf.parameters
    summary = {"devices": devices, "rate_devices": rate_devices, "seed": seed, "seconds": seconds,
               "population": _stats([r["error_pct"] / 100 for r in held], [r["z"] for r in held])
               | _coverage(held),
               "angular_gain": ag.report(), "true_rate_path_spread_pct": float(np.std(path_true) / np.mean(path_true)
                                                                                 * 100),
               "converged": pf.converged, "refits": pf.refits, "warnings": list(pf.warnings)}
    return records, summary, pf


Z95 = 1.959963984540054


def _coverage(rows):
    """Coverage of the rows' 95 % intervals (`covered`), and with normal intervals (`covered_normal`), percent;
    the mean half-width; the count."""
    return {"coverage_95_pct": float(np.mean([r["covered"] for r in rows]) * 100),
            "coverage_95_normal_pct": float(np.mean([r["covered_normal"] for r in rows]) * 100),
            "halfwidth_95_pct": float(np.mean([r["halfwidth_pct"] for r in rows])), "count": len(rows)}


def _method_rows(k, seed, method, held, **extra):
    """One row of the sweep: a method's predictions of the held-out devices of one lot (errors, z, covered kept per
    prediction so that lots pool)."""
    return ({"rate_devices": k, "seed": seed, "method": method}
            | _stats([r["error_pct"] / 100 for r in held], [r["z"] for r in held]) | _coverage(held)
            | {"errors_pct": [r["error_pct"] for r in held], "z": [r["z"] for r in held],
               "covered": [bool(r["covered"]) for r in held],
               "covered_normal": [bool(r["covered_normal"]) for r in held],
               "halfwidths_pct": [r["halfwidth_pct"] for r in held]} | extra)


POPULATION = "population fit (Ag random, spread learned)"
RATIO = "seed 003 ratio"
JOINT = "joint fit, fixed Ag prior"


def sweep(devices=64, counts=(1, 2, 4, 8, 16), seeds=(11,), process=None, joint=True, sweeps=None, out=None):
    """Per lot (one per seed) and number of rate-tabled devices in `counts`: the held-out devices' prediction errors
    and 95 % coverage of the population fit, seed 003's ratio method (K >= 2) and (`joint`) the fixed-prior joint
    fit; with `out` (a folder) the rows so far are written after each method (`lot_batch_sweep.json/.md`)."""
    rows = []

    def save():
        if out:
            os.makedirs(out, exist_ok=True)
            gj.io.atomic_write_json({"rows": rows, "pooled": pooled(rows), "versions": _versions()},
                                 os.path.join(out, "lot_batch_sweep.json"))
            gj.io.atomic_write_bytes(os.path.join(out, "lot_batch_sweep.md"), sweep_markdown(rows, devices).encode())

    for seed in seeds:
        simulated = simulate_lot(devices, seed, process, sweeps)
        table_all, lot, design, _ = simulated
        for k in counts:
            recs, summary, _ = run_population(devices, k, seed, process, simulated=simulated)
            ag = summary["angular_gain"]
            rows.append(_method_rows(k, seed, POPULATION, [r for r in recs if not r["rate_table"]],
                                     seconds=summary["seconds"], converged=summary["converged"],
                                     ag_relative_spread_pct=ag["relative_spread"] * 100,
                                     ag_relative_spread_stderr_pct=ag["spread_stderr"] / ag["mean"] * 100,
                                     true_rate_path_spread_pct=summary["true_rate_path_spread_pct"],
                                     dof_median=float(np.median([r["dof"] for r in recs if not r["rate_table"]])),
                                     warnings=summary["warnings"]))
            print(f"seed {seed} K = {k}: population " + _brief(rows[-1]), flush=True)
            save()
            if k >= 2:
                table, names, rate_names = with_rate_tables(table_all, devices, k)
                ratio_mean, ratio_rel_sd, sf_virtual = ratio_method(table, design)
                sf_true = np.asarray(_zero_rate_sf(lot, jnp.full(devices, 25.0)))
                held = []
                for i, d in enumerate(names):
                    if d not in rate_names:
                        e = ratio_mean * sf_virtual[d] / sf_true[i] - 1
                        held.append({"error_pct": e * 100, "z": e / ratio_rel_sd,
                                     "covered": abs(e) < Z95 * ratio_rel_sd,
                                     "covered_normal": abs(e) < Z95 * ratio_rel_sd,
                                     "halfwidth_pct": Z95 * ratio_rel_sd * 100})
                rows.append(_method_rows(k, seed, RATIO, held))
                print(f"seed {seed} K = {k}: ratio " + _brief(rows[-1]), flush=True)
                save()
            if not joint:
                continue
            t0 = time.perf_counter()
            recs, summ, _ = run(devices, k, seed, process, simulated=simulated)
            held = [{"error_pct": r["model_error_pct"], "z": r["model_z"], "covered": abs(r["model_z"]) < Z95,
                     "covered_normal": abs(r["model_z"]) < Z95,
                     "halfwidth_pct": Z95 * r["model_stderr"] / r["model_prediction"] * 100}
                    for r in recs if not r["rate_table"]]
            rows.append(_method_rows(k, seed, JOINT, held, seconds=time.perf_counter() - t0,
                                     converged=summ["fit"]["all_converged"]))
            print(f"seed {seed} K = {k}: joint " + _brief(rows[-1]), flush=True)
            save()
    return rows


def _brief(row):
    return (f"RMS {row['rms_pct']:.3f} %, coverage {row['coverage_95_pct']:.1f} % of {row['count']} (normal "
            f"{row['coverage_95_normal_pct']:.1f} %), half-width {row['halfwidth_95_pct']:.3f} %")


def pooled(rows):
    """Per (rate-tabled count, method): every lot's predictions together (coverage, RMS, max error, z RMS), and the
    per-lot coverages."""
    out = []
    for k, method in dict.fromkeys((r["rate_devices"], r["method"]) for r in rows):
        group = [r for r in rows if r["rate_devices"] == k and r["method"] == method]
        err = np.concatenate([r["errors_pct"] for r in group])
        z = np.concatenate([r["z"] for r in group])
        cov = np.concatenate([r["covered"] for r in group])
        out.append({"rate_devices": k, "method": method, "lots": len(group), "count": int(err.size),
                    "rms_pct": float(np.sqrt(np.mean(err**2))), "max_pct": float(np.max(np.abs(err))),
                    "z_rms": float(np.sqrt(np.mean(z**2))), "coverage_95_pct": float(np.mean(cov) * 100),
                    "coverage_95_normal_pct": float(np.mean(np.concatenate([r["covered_normal"] for r in group]))
                                                    * 100),
                    "coverage_binomial_se_pct": float(math.sqrt(0.95 * 0.05 / err.size) * 100),
                    "lot_coverages_pct": [r["coverage_95_pct"] for r in group],
                    "halfwidth_95_pct": float(np.mean(np.concatenate([r["halfwidths_pct"] for r in group])))})
    return out


def sweep_markdown(rows, devices):
    seeds = sorted({r["seed"] for r in rows})
    lines = [f"| rate-tabled (of {devices}) | method | lots | predictions | RMS error (%) | max error (%) | "
             "coverage of 95 % (%) | per lot (%) | normal-interval coverage (%) | mean 95 % half-width (%) | z RMS |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(pooled(rows), key=lambda r: r["rate_devices"]):
        lots = ", ".join(f"{c:.0f}" for c in r["lot_coverages_pct"])
        lines.append(f"| {r['rate_devices']} | {r['method']} | {r['lots']} | {r['count']} | {r['rms_pct']:.3f} | "
                     f"{r['max_pct']:.3f} | {r['coverage_95_pct']:.1f} | {lots} | {r['coverage_95_normal_pct']:.1f} | "
                     f"{r['halfwidth_95_pct']:.3f} | {r['z_rms']:.2f} |")
    return f"Seeds {', '.join(map(str, seeds))}, {devices} vcf-2018 devices per lot\n\n" + "\n".join(lines) + "\n"


def _versions():
    out = {"python": platform.python_version()}
    for pkg in ("gyrojax", "jax", "jaxlib", "equinox", "optimistix", "lineax", "numpy"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def markdown(summary):
    s, m, sm = summary, summary["model"], summary["seed_method"]
    sh = s["shared"]
    lines = [
        f"# Batch calibration of {s['devices']} vcf-2018 devices ({s['rate_devices']} on a rate table, "
        f"{s['held_out']} predicted), seed {s['seed']}",
        "",
        "| method | RMS error (%) | max error (%) | mean error (%) | z RMS | max abs z |",
        "|---|---|---|---|---|---|",
        f"| seed 003: constant SF_rate / SF_virtual | {sm['rms_pct']:.3f} | {sm['max_pct']:.3f} | "
        f"{sm['mean_pct']:+.3f} | {sm['z_rms']:.2f} | {sm['z_max']:.2f} |",
        f"| gyrojax: joint identify, shared readout gain | {m['rms_pct']:.3f} | {m['max_pct']:.3f} | "
        f"{m['mean_pct']:+.3f} | {m['z_rms']:.2f} | {m['z_max']:.2f} |",
        "",
        f"- rate-table SF spread of the lot (1 sigma): {s['rate_sf_spread_pct']:.2f} %; true seed-003 ratio "
        f"spread {s['true_ratio_spread_pct']:.3f} % (the seed method's floor); true rate-path (Ag K_yi a) spread "
        f"{s['true_rate_path_spread_pct']:.3f} % (the model's floor; assumed {s['assumed_rate_path_sigma_pct']:.3f} %)",
        f"- model: predicted standard uncertainty {m['stderr_rms_pct']:.3f} % (RMS); on the rate-table devices "
        f"themselves RMS {s['model_rate_devices']['rms_pct']:.3f} %",
        f"- shared sense-channel gain: {sh['value']:.6g} +/- {sh['stderr']:.2g} against the true {sh['truth']:.6g} "
        f"(z = {sh['z']:+.2f})",
        f"- fit: chi2_red {s['fit']['chi2_red_total']:.3f}, all converged: {s['fit']['all_converged']}, "
        f"{s['fit']['num_steps']} LM steps, held: {', '.join(s['fit']['held']) or 'none'} ({s['fit']['message']})",
        f"- seed-003 ratio {sm['ratio_mean']:.4f} (paper: {sm['paper_ratio']:.3f}), its scatter "
        f"{sm['ratio_rel_sd_pct']:.3f} % x sqrt(1 + 1/K)",
        f"- uncertainties from the SVD of the lot's weighted Jacobian (condition {s['jacobian_condition']:.1e}); "
        f"identify's own: SF {s['identify_sf_stderr_rms_pct']:.3g} % RMS (all devices), shared gain "
        f"+/- {sh['identify_stderr']:.4g}",
        f"- times: simulate {s['timings']['simulate_s']:.0f} s, start {s['timings']['start_s']:.0f} s, identify "
        f"{s['timings']['identify_s']:.0f} s, truth {s['timings']['truth_s']:.0f} s, covariance "
        f"{s['timings']['covariance_s']:.0f} s",
    ]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", type=int, default=64, help="lot size (default 64)")
    ap.add_argument("--rate-devices", type=int, default=4, help="devices with a rate table (default 4)")
    ap.add_argument("--seed", type=int, default=11, help="PRNG seed of the lot and the noise")
    ap.add_argument("--mismatch", type=float, default=None,
                    help="local mismatch of WaferProcess (default its 5e-4); the model's floor is sqrt(3) x it")
    ap.add_argument("--out", help="folder for lot_batch_calibration.json and .md")
    ap.add_argument("--sweep", type=int, nargs="+", metavar="K",
                    help="instead: for each number K of rate-tabled devices, the population fit, the ratio method and "
                         "the fixed-prior joint fit (e.g. --sweep 1 2 4 8 16); writes lot_batch_sweep.json/.md")
    ap.add_argument("--no-joint", action="store_true", help="with --sweep: skip the fixed-prior joint fit")
    ap.add_argument("--lots", type=int, default=1,
                    help="with --sweep: this many lots, seeds --seed, --seed + 1, ... (coverage pools their "
                         "predictions)")
    ap.add_argument("--points", choices=("full", "small"), default="full",
                    help="the sweeps' points: seed 000/003's (full) or 8 rates and a 20-point dynamic test (small, "
                         "SMALL_SWEEPS: ~2.6x fewer points, same physics)")
    args = ap.parse_args(argv)
    process = gj.WaferProcess() if args.mismatch is None else gj.WaferProcess(mismatch=args.mismatch)
    kinds = SMALL_SWEEPS if args.points == "small" else None
    if args.sweep:
        rows = sweep(args.devices, tuple(args.sweep), tuple(range(args.seed, args.seed + args.lots)), process,
                     joint=not args.no_joint, sweeps=kinds, out=args.out)
        print(sweep_markdown(rows, args.devices))
        if args.out:
            print(f"wrote {args.out}/lot_batch_sweep.json and .md")
        return {"rows": rows, "versions": _versions(), "argv": list(argv or [])}
    records, summary, _ = run(args.devices, args.rate_devices, args.seed, process, sweeps=kinds)
    print(f"{'device':>8} {'rate':>4} {'SF true':>10} {'seed err%':>9} {'model err%':>10} {'+/- %':>7} {'z':>6}")
    for r in records:
        print(f"{r['device']:>8} {'yes' if r['rate_table'] else '':>4} {r['sf_true']:10.5f} "
              f"{r['seed_error_pct']:9.3f} {r['model_error_pct']:10.4f} "
              f"{r['model_stderr'] / r['model_prediction'] * 100:7.4f} {r['model_z']:6.2f}")
    text = markdown(summary)
    print(text)
    out = {"summary": summary, "devices": records, "versions": _versions(), "argv": list(argv or [])}
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        gj.io.atomic_write_json(out, os.path.join(args.out, "lot_batch_calibration.json"))
        gj.io.atomic_write_bytes(os.path.join(args.out, "lot_batch_calibration.md"), text.encode())
        print(f"wrote {args.out}/lot_batch_calibration.json and .md")
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
