"""A closed-loop gyro lot generated outside gyrojax's models: plain NumPy, its own closed-form output.

Per point (one device, one run, one table rate Omega, averaged over its dwell):

    y = SF(T) * (Omega + delta(Omega)) + b_run + noise,   SF(T) = SF0 * (1 + tcf * (T - 25 C)),
    delta(Omega) = OMEGA_FS * (a3 * s**3 + a5 * s**5),    s = Omega / OMEGA_FS,

with delta the odd S-curve that a feedback DAC's integral nonlinearity leaves on the rebalance word, T the
die temperature of a first-order warm-up T(t) = 25 C + rise * (1 - exp(-t / tau)) averaged over the point's
dwell, and the drive frequency reading f = F0 * (1 + tcf * (T - 25 C)) + reading noise (the resonance
tracks the same silicon TCF as the scale factor). Nothing here calls a gyrojax model: the package only
receives the finished table, as it would receive a file from a test lab.

Run as a script to write the lot as CSV: `python tests/_foreign_lot.py lot.csv`.
"""

import sys

import numpy as np

import gyrojax as gj


RATES_DPS = np.asarray(gj.sweeps.DING_ZHOU_2025_RATES_DPS)  # the 22 table rates, -200 ... 200 deg/s, in sweep order
OMEGA_FS_DPS = 200.0  # the protocol's largest rate: the INL coefficients are given relative to it

WARMUP_S = 60.0  # seed 000 §5: 1 min of settling after the table starts, before the first point
DWELL_S = 120.0  # seed 000 §5: 2 min per rate
OUTPUT_RATE_HZ = 100.0  # ASSUMPTION: decimated output word rate; n_samples = DWELL_S * OUTPUT_RATE_HZ = 12000

SF0_LSB_PER_DPS = 13700.0  # ASSUMPTION: 200 deg/s fills a third of a 24-bit word (2.7e6 of 8.4e6 LSB), the
#                            headroom a force-to-rebalance loop keeps for shock and quadrature
SF0_SPREAD_REL = 0.02  # ASSUMPTION: 2 % (1 sigma) device-to-device SF spread from mass, gap and gain tolerances
TCF_PER_K = -30e-6  # silicon resonance TCF (Young's modulus -60 ppm/K, f ~ sqrt(E)): about -30 ppm/K
TCF_SPREAD_PER_K = 1e-6  # ASSUMPTION: 1 ppm/K spread from doping and package stress between dies
F0_HZ = 4634.0  # ASSUMPTION: a 4.6 kHz drive mode, the band of the seed paper's gyro
F0_SPREAD_REL = 0.005  # ASSUMPTION: 0.5 % resonance spread from lithography (width^2 / length^3 scaling)
FREQ_READING_SIGMA_HZ = 1e-4  # ASSUMPTION: PLL frequency word averaged over a 2-min dwell resolves ~0.1 mHz

# The DAC INL's odd terms as a fraction of full-scale rate at full scale: a 16-bit DAC's INL of a few LSB on a
# +-2^15 code range seen through the carrier amplitude gives tens to hundreds of ppm of SF nonlinearity.
INL_A3 = -400e-6  # ASSUMPTION: the cubic compresses the large rates ...
INL_A5 = 250e-6  # ASSUMPTION: ... and the quintic partly undoes it at the ends: an S-curve with an inflection
INL_SPREAD_REL = 0.25  # ASSUMPTION: 25 % (1 sigma) part-to-part spread of each INL coefficient

RISE_K = (10.0, 2.0, 2.0)  # the lot's story: run 0 starts cold (10 K of self-heating), runs 1-2 start warm
TAU_S = 600.0  # ASSUMPTION: die + package + fixture time constant of ~10 min, a third of the 45-min sweep
AMBIENT_C = 25.0  # ASSUMPTION: lab ambient; the TCF is referred to 25 C

NOISE_DENSITY_DPS_RTHZ = 0.005  # ASSUMPTION: rate noise density 0.005 deg/s/rtHz (ARW 0.3 deg/rt h), white
TURN_ON_BIAS_SIGMA_DPS = 0.05  # ASSUMPTION: 0.05 deg/s (180 deg/h) run-to-run turn-on bias, 1 sigma
DEVICE_BIAS_SIGMA_DPS = 0.5  # ASSUMPTION: 0.5 deg/s device-to-device untrimmed bias, 1 sigma


def _dwell_mean_temperature(rise, tau, t0, t1):
    """Mean of 25 C + rise (1 - exp(-t / tau)) over [t0, t1] (closed form): the output is a dwell average."""
    return AMBIENT_C + rise * (1.0 - tau * (np.exp(-t0 / tau) - np.exp(-t1 / tau)) / (t1 - t0))


def foreign_lot(n_devices: int = 6, n_runs: int = 3, *, seed: int = 0, rise_k=RISE_K, tau_s: float = TAU_S,
                inl_scale: float = 1.0, noise_scale: float = 1.0, prefix: str = "foreign",
                source: str = "foreign-lot.csv") -> gj.Table:
    """The lot as a tidy `gyrojax.Table` (rate_table rows of every device and run, in sweep order).

    **Arguments:**

    - `n_devices`, `n_runs`: lot size; run r warms up by `rise_k[r]` K (the last entry repeats for more runs).
    - `seed`: NumPy seed of the device spread and the noise.
    - `rise_k`, `tau_s`: warm-up rise per run (K) and its time constant (s).
    - `inl_scale`, `noise_scale`: multiply the INL coefficients, and the output and drive-frequency reading
      noise (0: a noise-free, linear lot whose `output_sigma` is 0).
    - `prefix`: device names are `{prefix}-00`, `{prefix}-01`, ...
    - `source`: the table's source name (shown in messages).

    **Returns:** a `gyrojax.Table` with columns device, run, sweep, input, output, output_sigma,
    temperature_c, drive_freq_hz, n_samples.
    """
    rng = np.random.default_rng(seed)
    n_samples = DWELL_S * OUTPUT_RATE_HZ
    # white rate noise of density N sampled at OUTPUT_RATE_HZ has sigma N sqrt(rate / 2) per sample; a dwell
    # average of n_samples independent samples divides it by sqrt(n_samples)
    sigma_dps = noise_scale * NOISE_DENSITY_DPS_RTHZ * np.sqrt(OUTPUT_RATE_HZ / 2.0) / np.sqrt(n_samples)
    t0 = WARMUP_S + DWELL_S * np.arange(RATES_DPS.size)
    s = RATES_DPS / OMEGA_FS_DPS
    cols = {k: [] for k in ("device", "run", "sweep", "input", "output", "output_sigma", "temperature_c",
                            "drive_freq_hz", "n_samples")}
    for d in range(n_devices):
        sf0 = SF0_LSB_PER_DPS * (1.0 + SF0_SPREAD_REL * rng.normal())
        tcf = TCF_PER_K + TCF_SPREAD_PER_K * rng.normal()
        f0 = F0_HZ * (1.0 + F0_SPREAD_REL * rng.normal())
        a3 = inl_scale * INL_A3 * (1.0 + INL_SPREAD_REL * rng.normal())
        a5 = inl_scale * INL_A5 * (1.0 + INL_SPREAD_REL * rng.normal())
        bias_dev = DEVICE_BIAS_SIGMA_DPS * rng.normal()
        for r in range(n_runs):
            rise = rise_k[min(r, len(rise_k) - 1)]
            temp = _dwell_mean_temperature(rise, tau_s, t0, t0 + DWELL_S)
            sf = sf0 * (1.0 + tcf * (temp - AMBIENT_C))
            delta = OMEGA_FS_DPS * (a3 * s**3 + a5 * s**5)
            bias = sf0 * (bias_dev + TURN_ON_BIAS_SIGMA_DPS * rng.normal())
            sigma_lsb = sf0 * sigma_dps
            y = sf * (RATES_DPS + delta) + bias + sigma_lsb * rng.normal(size=RATES_DPS.size)
            f = (f0 * (1.0 + tcf * (temp - AMBIENT_C))
                 + noise_scale * FREQ_READING_SIGMA_HZ * rng.normal(size=RATES_DPS.size))
            n = RATES_DPS.size
            cols["device"] += [f"{prefix}-{d:02d}"] * n
            cols["run"] += [r] * n
            cols["sweep"] += ["rate_table"] * n
            cols["input"] += list(RATES_DPS)
            cols["output"] += list(y)
            cols["output_sigma"] += [sigma_lsb] * n
            cols["temperature_c"] += list(temp)
            cols["drive_freq_hz"] += list(f)
            cols["n_samples"] += [n_samples] * n
    return gj.Table.from_columns({k: np.asarray(v) for k, v in cols.items()}, source=source)


if __name__ == "__main__":
    gj.write_table(foreign_lot(), sys.argv[1])
    print(f"wrote {sys.argv[1]}")
