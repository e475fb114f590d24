"""Settled-point lots with one hidden effect, generated outside gyrojax's models: plain NumPy, own closed forms.

The discovery benchmark's generator (`experiments/discovery_benchmark.py`). Per device d, run r, point i:

    rate_table:  y = SF_d (1 + TCF (T - 25 C)) Omega + b_drs + noise    (Omega in deg/s, y in LSB)
    vcf_static:  y = G_d V + b_drs + noise                              (V in volts, y in LSB)
    dac:         v = g_d w + voltmeter noise                            (w a DAC word, v in volts)

The rate output is the rebalance word, proportional to the Coriolis force 2 m A omega_d Omega: the AGC holds the
drive amplitude A, so the scale factor follows the drive frequency and its silicon TCF. The virtual-Coriolis force
K V_fc V_ac (seed 003 Eq. 7) does not involve the drive motion, so the VCF gain G_d has no TCF; the voltages stand
for the rates through Omega_eq = K V_fc V_ac / (2 m A omega_d), so a design with twice the drive frequency has
half the equivalent rate per volt. The DAC is measured alone on the bench: no bias, no temperature, no time
(seed 000 Table 2). Each (device, run, sweep) is its own power-on with its own turn-on bias b_drs.

Temperature: each run is a chamber cycle T(t) = 25 C + dT_r sin(pi t / t_end), warming then cooling, so that
temperature and time since power-on are not confounded. The drive-frequency reading is
f = F0_d (1 + TCF (T - 25 C)) + reading noise.

A hidden effect (`HIDDEN`) is a function added to these outputs, linear in its size; its size at each SNR level
is the one whose chi2 beyond what the baseline's free gains and biases can take up (a linear projection,
`visible_chi2`) is 30, 300 or 3000 over the lot. Nothing here calls a gyrojax model: gyrojax only packages the
finished columns into a `Table` (`Table.from_columns`), as it would read a file from a test lab.
"""

import dataclasses
from collections.abc import Callable

import numpy as np

from gyrojax import Table


RATES_DPS = np.array([-200.0, -100.0, -50.0, -20.0, -10.0, -5.0, -2.0, -1.0, -0.5, -0.2, -0.1,
                      0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0])  # seed 000 §5, sweep order
OMEGA_FS_DPS = 200.0  # the protocol's largest rate
WARMUP_S = 60.0  # seed 000 §5: 1 min of settling before the first point
DWELL_S = 120.0  # seed 000 §5: 2 min per point
OUTPUT_RATE_HZ = 100.0  # seed 000 §5: sampled at 100 Hz; n_samples = 12000 per point
TCF_PER_K = -30e-6  # silicon resonance TCF: Young's modulus -60 ppm/K and f ~ sqrt(E)
AMBIENT_C = 25.0  # the TCF and every temperature coefficient are referred to 25 C

VCF_CARRIER_V = 1.0  # seed 003 §3: V_fc = 1 V
VCF_AMPLITUDES_V = RATES_DPS / 100.0  # ASSUMPTION: the electrode is sized so that 2 V stands for 200 deg/s
VCF_GAIN_SPREAD_REL = 0.01  # ASSUMPTION: 1 % electrode-gap tolerance on the virtual-Coriolis gain
DAC_V_PER_WORD = 1.637 / 2745157.0  # seed 000 Table 2: word 0x29E345 (2745157) reads 1.637 V
DAC_GAIN_SPREAD_REL = 1e-3  # ASSUMPTION: 0.1 % reference and resistor tolerance
VOLTMETER_SIGMA_V = 2e-5  # ASSUMPTION: a 6.5-digit AC voltmeter's reading noise on a 2 V range

NOISE_DENSITY_DPS_RTHZ = 0.005  # ASSUMPTION: white rate noise 0.005 deg/s/rtHz (ARW 0.3 deg/rt h)
TURN_ON_BIAS_SIGMA_DPS = 0.05  # ASSUMPTION: 0.05 deg/s run-to-run turn-on bias, 1 sigma
DEVICE_BIAS_SIGMA_DPS = 0.5  # ASSUMPTION: 0.5 deg/s device-to-device untrimmed bias, 1 sigma
SF_SPREAD_REL = 0.02  # ASSUMPTION: 2 % device-to-device scale-factor spread (mass, gap, gain tolerances)
F0_SPREAD_REL = 0.005  # ASSUMPTION: 0.5 % resonance spread from lithography
FREQ_READING_SIGMA_HZ = 1e-4  # ASSUMPTION: the PLL word averaged over a 2-min dwell resolves ~0.1 mHz
STEP_TAU_S = 900.0  # ASSUMPTION: a packaged die follows a chamber step with a 15-minute time constant
CYCLE_K = (6.0, 3.0)  # ASSUMPTION: chamber cycle amplitude of run 0, run 1 (the last repeats for more runs)


@dataclasses.dataclass(frozen=True)
class Design:
    """A device design: nominal scale factor (LSB per deg/s), drive frequency (Hz) and VCF equivalent rate per
    volt (deg/s per V at V_fc = 1 V), and the protocol it is measured with: `"cycle"` (the rates in sweep order
    while the chamber runs one half-sine cycle per run) or `"shuffled-ramp"` (the rates in a random order per
    run while the chamber steps, up on even runs and down on odd ones, and the die follows it with the time
    constant `STEP_TAU_S`)."""

    name: str
    sf_lsb_per_dps: float
    f0_hz: float
    vcf_dps_per_v: float
    protocol: str = "cycle"


DESIGNS = {
    # paper-qmg-like: 200 deg/s fills a third of a 24-bit word (seed 000 Table 2: 2745157 at 200 deg/s)
    "a": Design("a", 13700.0, 4634.0, 100.0),
    # far apart: twice the drive frequency (stiffer springs) and 0.6x the scale factor; Omega_eq ~ 1/omega_d
    "b": Design("b", 0.6 * 13700.0, 2.0 * 4634.0, 50.0),
    # design a on another protocol: the input order no longer follows the time, nor dT/dt its sign
    "c": Design("c", 13700.0, 4634.0, 100.0, protocol="shuffled-ramp"),
}

SWEEPS = ("rate_table", "vcf_static", "dac")
TARGET_CHI2 = {"low": 30.0, "mid": 300.0, "high": 3000.0}


@dataclasses.dataclass
class Lot:
    """Everything the generator knows about a lot, one entry per row: the clean parts of the output and the
    coordinates the hidden effects act on."""

    design: Design
    columns: dict  # device, run, sweep, input, output, output_sigma, temperature_c, time_s, drive_freq_hz, n_samples
    dev: np.ndarray  # device index per row
    sf: np.ndarray  # the row's local gain: LSB per deg/s (rate), LSB per V (vcf), V per word (dac)
    full_scale: np.ndarray  # the row's output at full-scale input (LSB or V), per device
    fs_rate: np.ndarray  # the device's rate output at the full-scale rate (LSB): the word range of the force path
    dtdt: np.ndarray  # dT/dt, K/s (0 for the DAC)
    phase: np.ndarray  # the drive-frequency deviation from the device's own F0, relative
    clean: np.ndarray  # the noise-free output without bias or hidden effect


def _rows(design, n_devices, n_runs, rng):
    """The clean lot (no noise, no hidden effect): per-row arrays."""
    n = RATES_DPS.size
    t = WARMUP_S + DWELL_S * (np.arange(n) + 0.5)  # the middle of each dwell
    t_end = WARMUP_S + DWELL_S * n
    out = {k: [] for k in ("device", "run", "sweep", "input", "clean", "bias", "sigma", "temperature_c", "time_s",
                           "drive_freq_hz", "n_samples", "dev", "sf", "full_scale", "fs_rate", "dtdt", "phase")}
    sigma_dps = NOISE_DENSITY_DPS_RTHZ * np.sqrt(OUTPUT_RATE_HZ / 2.0) / np.sqrt(DWELL_S * OUTPUT_RATE_HZ)

    def add(**kw):
        for k, v in kw.items():
            out[k].append(np.broadcast_to(np.asarray(v), (n,)).copy() if k not in ("device", "sweep")
                          else np.array([v] * n))

    for d in range(n_devices):
        sf = design.sf_lsb_per_dps * (1.0 + SF_SPREAD_REL * rng.normal())
        g_vcf = sf * design.vcf_dps_per_v * (1.0 + VCF_GAIN_SPREAD_REL * rng.normal())
        g_dac = DAC_V_PER_WORD * (1.0 + DAC_GAIN_SPREAD_REL * rng.normal())
        f0 = design.f0_hz * (1.0 + F0_SPREAD_REL * rng.normal())
        bias_dev = DEVICE_BIAS_SIGMA_DPS * rng.normal()
        name = f"disc-{design.name}-{d:02d}"
        for r in range(n_runs):
            amp = CYCLE_K[min(r, len(CYCLE_K) - 1)]
            temp, dtdt = _chamber(design, r, amp, t, t_end)
            order = rng.permutation(n) if design.protocol == "shuffled-ramp" else np.arange(n)
            rel = TCF_PER_K * (temp - AMBIENT_C)
            rate_gain = sf * (1.0 + rel)  # the Coriolis force follows omega_d; the VCF force does not
            for sweep, x, gain in (("rate_table", RATES_DPS[order], rate_gain),
                                   ("vcf_static", VCF_AMPLITUDES_V[order], g_vcf)):
                f = f0 * (1.0 + rel) + FREQ_READING_SIGMA_HZ * rng.normal(size=n)
                b = sf * (bias_dev + TURN_ON_BIAS_SIGMA_DPS * rng.normal())
                add(device=name, run=r, sweep=sweep, input=x, clean=gain * x, bias=b, sigma=sf * sigma_dps,
                    temperature_c=temp, time_s=t, drive_freq_hz=f, n_samples=DWELL_S * OUTPUT_RATE_HZ, dev=d,
                    sf=gain, full_scale=np.abs(gain * x).max(), fs_rate=sf * OMEGA_FS_DPS, dtdt=dtdt,
                    phase=f / f0 - 1.0)
            # the DAC bench sweep: seed 000 Table 2's words for the protocol's rates, word = -SF x rate
            words = np.round(-RATES_DPS * design.sf_lsb_per_dps)
            add(device=name, run=r, sweep="dac", input=words, clean=g_dac * words, bias=0.0, sigma=VOLTMETER_SIGMA_V,
                temperature_c=np.nan, time_s=np.nan, drive_freq_hz=np.nan, n_samples=np.nan, dev=d, sf=g_dac,
                full_scale=np.abs(g_dac * words).max(), fs_rate=sf * OMEGA_FS_DPS, dtdt=0.0, phase=0.0)
    return {k: np.concatenate(v) for k, v in out.items()}


# ----------------------------------------------------------------------------------------------------------------
# Hidden effects. Each returns the change of the output per row at unit size (zero on the rows it leaves alone);
# `lot` holds the clean rows. Sizes are in the unit the `unit` field names.

def _chamber(design, run, amp, t, t_end):
    """The die temperature and dT/dt at the dwell times `t` of run `run` (chamber amplitude `amp`, K)."""
    if design.protocol == "shuffled-ramp":
        sign = 1.0 if run % 2 == 0 else -1.0
        settled = np.exp(-t / STEP_TAU_S)  # the share of the step still to come
        temp = AMBIENT_C + amp * (1.0 - settled if sign > 0 else settled)
        return temp, sign * amp / STEP_TAU_S * settled
    return AMBIENT_C + amp * np.sin(np.pi * t / t_end), amp * np.pi / t_end * np.cos(np.pi * t / t_end)


def _mask(lot, *sweeps):
    return np.isin(lot.columns["sweep"], sweeps)


def _x(lot):
    return np.asarray(lot.columns["input"], dtype=float)


def _s(lot):
    """Where a row sits in the force path's word range, -1 to 1: the DAC word over its largest on the DAC bench;
    on rate and VCF rows the output over the device's rate output at the full-scale rate (a VCF sweep whose
    electrode stands for fewer deg/s per volt than the table reaches uses less of the range, and a nonlinearity
    of the words sees it there)."""
    x = _x(lot)
    out = np.zeros_like(x)
    dac = _mask(lot, "dac")
    out[dac] = x[dac] / np.abs(x[dac]).max()
    rv = _mask(lot, *RV)
    out[rv] = lot.clean[rv] / lot.fs_rate[rv]
    return out


def _dT(lot):
    return np.nan_to_num(lot.columns["temperature_c"] - AMBIENT_C)


def _t(lot):
    return np.nan_to_num(lot.columns["time_s"])


def _sf_rate(lot):
    """The device's rate scale factor (LSB per deg/s), on every row: a deg/s of bias in output units."""
    return lot.fs_rate / OMEGA_FS_DPS


def _n_dev(lot):
    return int(lot.dev.max()) + 1


def _blocks(lot, *sweeps):
    """Row indices of each (device, run, sweep) block of `sweeps`, in time order (each block is a power-on)."""
    c = lot.columns
    run = np.asarray(c["run"])
    sweep = np.asarray(c["sweep"])
    t = _t(lot)
    for sw in sweeps:
        for d in np.unique(lot.dev):
            for r in np.unique(run):
                i = np.flatnonzero((lot.dev == d) & (run == r) & (sweep == sw))
                if i.size:
                    yield i[np.argsort(t[i], kind="stable")]


def _device_spread(lot, seed_offset, rel):
    """A per-device multiplier 1 + rel N(0, 1), drawn from the lot's own devices (reproducible per lot)."""
    n = int(lot.dev.max()) + 1
    k = np.random.default_rng(1000 + seed_offset + 7 * n).normal(size=n)
    return (1.0 + rel * k)[lot.dev]


def _device_sign(lot, seed_offset):
    n = int(lot.dev.max()) + 1
    k = np.random.default_rng(2000 + seed_offset + 7 * n).normal(size=n)
    return k[lot.dev]


def _inl(lot, a3, a5):
    """An odd S-curve of the DAC's transfer: the DAC reads w + W (a3 s^3 + a5 s^5); the rebalance word that makes
    a given force is then smaller by the same amount (to first order), so rate and VCF rows move the other way."""
    s = _s(lot)
    shape = a3 * s**3 + a5 * s**5
    dac = _mask(lot, "dac")
    return np.where(dac, lot.full_scale * shape, -lot.fs_rate * shape * _mask(lot, "rate_table", "vcf_static"))


def _compression(lot, per_device=1.0):
    s = _s(lot)
    return -per_device * lot.fs_rate * s**3 * _mask(lot, "rate_table", "vcf_static")


def _zro(lot, per_device=1.0):
    # a zero-rate output in deg/s per K, read through the device's rate scale factor
    sf_rate = lot.fs_rate / OMEGA_FS_DPS  # on VCF rows too: the loop balances it like a rate
    return per_device * sf_rate * _dT(lot) * _mask(lot, "rate_table", "vcf_static")


@dataclasses.dataclass(frozen=True)
class Hidden:
    """A hidden effect and its expected answer.

    - `sweeps`: the sweep kinds whose outputs it changes; `coordinate`: the recorded column it varies with
      (`input`, `temperature_c`, `time_s`, `drive_freq_hz`, `run`, `device`, or `model` for a pure gain);
      `library`: the gyrojax effect it is, or None; `formula`: canonical terms that express it (None: no simple
      term does); `unit`: the unit of its size; `fn(lot)`: the output change per row at unit size;
      `drive_shift(lot)`: the relative change of the drive-frequency reading per row at unit size (None: the
      effect leaves the drive resonance alone)."""

    name: str
    sweeps: frozenset
    coordinate: str
    library: str | None
    formula: frozenset | None
    unit: str
    fn: Callable
    description: str
    drive_shift: Callable | None = None


def _h(name, sweeps, coordinate, library, formula, unit, description, drive_shift=None):
    def wrap(fn):
        return Hidden(name, frozenset(sweeps), coordinate, library, None if formula is None else frozenset(formula),
                      unit, fn, description, drive_shift)
    return wrap


RV = ("rate_table", "vcf_static")
GAIN_T = ("lin(temperature_c)*model", "lin(temperature_c)*lin(input)")
HIDDEN_LIST = [
    # --- twelve cases of the five library effects that leave a fingerprint on settled rate/VCF/DAC data ----------
    _h("dac_inl_s_curve", SWEEPS, "input", "dac_inl", ("cube(input)",), "fraction of full scale at full scale",
       "DAC INL odd S-curve a3 s^3 + a5 s^5 (a5 = -0.6 a3), on the DAC bench and the rebalance words")(
        lambda lot: _inl(lot, 1.0, -0.6)),
    _h("dac_inl_cubic", SWEEPS, "input", "dac_inl", ("cube(input)",), "fraction of full scale at full scale",
       "DAC INL pure cubic, expansive")(lambda lot: _inl(lot, -1.0, 0.0)),
    _h("dac_inl_spread", SWEEPS, "input", "dac_inl", ("cube(input)",), "fraction of full scale at full scale",
       "DAC INL cubic, 40 % part-to-part spread")(
        lambda lot: _inl(lot, 1.0, 0.0) * _device_spread(lot, 1, 0.4)),
    _h("feedback_compression", RV, "input", "feedback_compression", ("cube(input)",),
       "fraction of full scale at full scale", "feedback amplifier cubic compression y -> y - c W s^3")(
        lambda lot: _compression(lot)),
    _h("feedback_expansion", RV, "input", "feedback_compression", ("cube(input)",),
       "fraction of full scale at full scale", "feedback amplifier cubic expansion (negative compression)")(
        lambda lot: -_compression(lot)),
    _h("feedback_compression_spread", RV, "input", "feedback_compression", ("cube(input)",),
       "fraction of full scale at full scale", "feedback compression with 40 % part-to-part spread")(
        lambda lot: _compression(lot, _device_spread(lot, 2, 0.4))),
    _h("zro_tempco", RV, "temperature_c", "zro_tempco", ("lin(temperature_c)",), "deg/s per K",
       "zero-rate output linear in the die temperature, same on every device")(lambda lot: _zro(lot)),
    _h("zro_tempco_spread", RV, "temperature_c", "zro_tempco", ("lin(temperature_c)",), "deg/s per K",
       "zero-rate output tempco of random sign and size per device")(lambda lot: _zro(lot, _device_sign(lot, 3))),
    _h("vref_drift", RV, "temperature_c", "vref_drift", GAIN_T, "1/K",
       "feedback reference drift: rate and VCF gain (1 + a (T - 25))")(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, *RV)),
    _h("vref_drift_spread", RV, "temperature_c", "vref_drift", GAIN_T, "1/K",
       "feedback reference drift, 50 % part-to-part spread")(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, *RV) * _device_spread(lot, 4, 0.5)),
    # closed loop, SF ~ omega_d: the extra TCF moves the rate gain and every drive-frequency reading alike (the
    # VCF rows' too: the resonance does not know which sweep runs)
    _h("thermal_drift", ("rate_table",), "temperature_c", "thermal_drift", GAIN_T, "1/K",
       "extra drive-resonance TCF: the rate scale factor (and the drive-frequency reading) follow it",
       drive_shift=_dT)(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, "rate_table")),
    _h("thermal_drift_spread", ("rate_table",), "temperature_c", "thermal_drift", GAIN_T, "1/K",
       "extra drive-resonance TCF of 50 % part-to-part spread",
       drive_shift=lambda lot: _dT(lot) * _device_spread(lot, 5, 0.5))(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, "rate_table") * _device_spread(lot, 5, 0.5)),
    # --- outside the library ----------------------------------------------------------------------------------
    _h("vcf_gain_tempco", ("vcf_static",), "temperature_c", None, GAIN_T, "1/K",
       "virtual-Coriolis gain (1 + c (T - 25)) on the VCF rows only (electrode gap thermal expansion)")(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, "vcf_static")),
    _h("gain_hysteresis", RV, "dtemperature_dt", None, None, "relative gain",
       "thermal hysteresis: the gain is 1 + c warming and 1 - c cooling (package stress lags the die)")(
        lambda lot: lot.clean * np.sign(lot.dtdt) * _mask(lot, *RV)),
    _h("bias_dTdt", RV, "dtemperature_dt", None, ("lin(dtemperature_dt)",), "deg/s per (K/min)",
       "a zero-rate output proportional to dT/dt (a thermal gradient across the die)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * 60.0 * lot.dtdt * _mask(lot, *RV)),
    _h("rate_saturation", ("rate_table",), "input", None, ("hinge(input)",), "relative gain above 100 deg/s",
       "table-rate saturation: the output loses c of each deg/s above 100 deg/s")(
        lambda lot: -lot.sf * np.sign(_x(lot)) * np.clip(np.abs(_x(lot)) - 100.0, 0, None)
        * _mask(lot, "rate_table")),
    _h("temp_x_abs_input", RV, "temperature_c", None,
       ("lin(temperature_c)*abs(input)", "lin(temperature_c)*abs(model)"), "fraction of FS per K",
       "an even gain that grows with temperature: c (T - 25) |s| W")(
        lambda lot: lot.fs_rate * _dT(lot) * np.abs(_s(lot)) * _mask(lot, *RV)),
    _h("dac_periodic", ("dac",), "input", None, ("periodic(input)",), "fraction of full scale",
       "a code-dependent error of the DAC's amplitude register, periodic in the word (period 2^18 codes)")(
        lambda lot: lot.full_scale * np.sin(2 * np.pi * _x(lot) / 2.0**18) * _mask(lot, "dac")),
    _h("dac_missing_code", ("dac",), "input", None, ("step(input)",), "fraction of full scale",
       "a missing-code step at the word 2^20: every word above reads c W higher")(
        lambda lot: lot.full_scale * (_x(lot) >= 2.0**20) * _mask(lot, "dac")),
    _h("bias_step", ("rate_table",), "time_s", None, ("step(time_s)",), "deg/s",
       "a bias jump at t = 1500 s in run 0 of the first device's rate table (a charging event)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * (_t(lot) > 1500.0)
        * _mask(lot, "rate_table") * (lot.dev == 0) * (lot.columns["run"] == 0)),
    _h("bias_relaxation", RV, "time_s", None, ("relax(time_s)",), "deg/s",
       "a bias relaxing exp(-t / 600 s) after power-on (dielectric charging)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * np.exp(-_t(lot) / 600.0) * _mask(lot, *RV)),
    _h("even_gain_vcf", ("vcf_static",), "input", None, ("abs(input)",), "fraction of full scale",
       "an even |V| term on the VCF rows (electrode asymmetry, V_ac^2-like)")(
        lambda lot: lot.fs_rate * np.abs(_s(lot)) * _mask(lot, "vcf_static")),
    _h("sign_gain_rate", ("rate_table",), "input", None, ("abs(input)", "sign(input)*lin(input)"),
       "relative gain", "a gain 1 + c for positive table rates only (K+ != K-)")(
        lambda lot: lot.clean * (_x(lot) > 0) * _mask(lot, "rate_table")),
    # with two runs a gain linear in the run index and a gain of the second run are one function
    _h("per_run_gain", RV, "run", None, ("lin(run)*model", "per_run(1)*model"), "relative gain",
       "a gain that changes from power-on to power-on: 1 + c (run - mean) on each device")(
        lambda lot: lot.clean * (lot.columns["run"] - 0.5) * _mask(lot, *RV) * _device_sign(lot, 6)),
    _h("drive_freq_gain", ("rate_table",), "drive_freq_hz", None, ("lin(drive_freq_hz)*model",), "1/ppm",
       "a rate gain proportional to the drive-frequency reading's deviation (ppm) from the device's own F0")(
        lambda lot: lot.clean * lot.phase * 1e6 * _mask(lot, "rate_table")),
    _h("time_quadratic", RV, "time_s", None, ("sq(time_s)",), "deg/s at t = 1 h",
       "a bias growing as (t / 1 h)^2 since power-on")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * (_t(lot) / 3600.0) ** 2 * _mask(lot, *RV)),
]
HIDDEN = {h.name: h for h in HIDDEN_LIST}


def _settling_memory(lot):
    """The dwell before each point did not settle: the point keeps a share of the step from the previous set
    point, gain x (previous input - input), each (device, run, sweep) starting from rest."""
    c = lot.columns
    x = _x(lot)
    prev = np.zeros_like(x)
    keys = np.char.add(np.char.add(np.asarray(c["device"]).astype(str), "|"),
                       np.char.add(np.asarray(c["run"]).astype(str), np.asarray(c["sweep"]).astype(str)))
    for k in np.unique(keys):
        i = np.flatnonzero(keys == k)  # rows of a block are in time order
        prev[i[1:]] = x[i[:-1]]
    return lot.sf * (prev - x) * _mask(lot, *RV)


def _zro_per_run(lot):
    # a zero-rate output tempco that differs from power-on to power-on: +1 in run 0, -0.5 in run 1, per device sign
    per_run = np.where(np.asarray(lot.columns["run"]) % 2 == 0, 1.0, -0.5)
    return _zro(lot, _device_sign(lot, 7) * per_run)


# Held-out effects: written after the benchmark's guards were tuned and never used to tune them; a measure of how
# the diagnosis fares on shapes nobody designed it for (`discovery_benchmark.py --effects held-out`). All outside
# the library.
HELD_OUT_LIST = [
    _h("gain_time_drift", RV, "time_s", None, ("lin(time_s)*model", "lin(time_s)*lin(input)"), "relative gain per h",
       "a gain drifting linearly since power-on (charging of the feedback electrodes)")(
        lambda lot: lot.clean * _t(lot) / 3600.0 * _mask(lot, *RV)),
    _h("bias_periodic_time", RV, "time_s", None, ("periodic(time_s)",), "deg/s",
       "a bias oscillating with the lab's air conditioning, period 20 min, phase locked to power-on")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * np.sin(2 * np.pi * _t(lot) / 1200.0) * _mask(lot, *RV)),
    _h("dead_band", ("rate_table",), "input", None, None, "share of the rate lost",
       "a dead band of the rate loop: the output loses c of the input for |rate| <= 0.5 deg/s")(
        lambda lot: -lot.sf * _x(lot) * (np.abs(_x(lot)) <= 0.5) * _mask(lot, "rate_table")),
    _h("even_quadratic_rate", ("rate_table",), "input", None, ("sq(input)", "sq(model)"), "fraction of FS",
       "an even quadratic of the table rate on the rate rows only (centripetal pick-up of an off-axis mount)")(
        lambda lot: lot.fs_rate * (_x(lot) / OMEGA_FS_DPS) ** 2 * _mask(lot, "rate_table")),
    _h("temp_step_bias", RV, "temperature_c", None, ("step(temperature_c)",), "deg/s",
       "a bias that jumps when the die passes 28 C (a mode hop of a parasitic resonance)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * (_dT(lot) > 3.0) * _mask(lot, *RV)),
    _h("vcf_cubic_only", ("vcf_static",), "input", None, ("cube(input)", "cube(model)"), "fraction of FS",
       "a cubic of the virtual-Coriolis electrode alone (gap nonlinearity of the forcer), not of the rate path")(
        lambda lot: -lot.fs_rate * _s(lot) ** 3 * _mask(lot, "vcf_static")),
    _h("zro_per_run", RV, "temperature_c", None, None, "deg/s per K",
       "a zero-rate-output tempco that differs from power-on to power-on (+1, -0.5 of it, sign per device)")(
        _zro_per_run),
    _h("gain_quadratic_temp", RV, "temperature_c", None, ("sq(temperature_c)*model",), "1/K^2",
       "a rate and VCF gain quadratic in the die temperature (a reference with a parabolic tempco)")(
        lambda lot: lot.clean * _dT(lot) ** 2 * _mask(lot, *RV)),
    _h("dac_sign_gain", ("dac",), "input", None, ("abs(input)", "sign(input)*lin(input)"), "relative gain",
       "a bipolar DAC whose negative half has its own gain (c of the word for negative words)")(
        lambda lot: lot.sf * _x(lot) * (_x(lot) < 0) * _mask(lot, "dac")),
    _h("vcf_bias_tempco", ("vcf_static",), "temperature_c", None, ("lin(temperature_c)",), "deg/s per K",
       "a bias linear in the die temperature on the VCF rows only (the forcer's DC offset follows temperature)")(
        lambda lot: _zro(lot) * _mask(lot, "vcf_static")),
    _h("settling_memory", RV, "input", None, None, "share of the previous step",
       "incomplete settling: each point keeps c of the step from the previous set point")(_settling_memory),
    _h("gain_step_device", RV, "time_s", None, ("step(time_s)*model",), "relative gain",
       "a gain that switches at t = 1500 s in every run of the first device (a range relay)")(
        lambda lot: lot.clean * (_t(lot) > 1500.0) * (lot.dev == 0) * _mask(lot, *RV)),
]
HELD_OUT = {h.name: h for h in HELD_OUT_LIST}


def _bit(lot, k):
    """Bit `k` of the DAC word's magnitude, with the word's sign (a bit-weight error of a sign-magnitude DAC)."""
    x = _x(lot)
    return np.sign(x) * ((np.abs(x).astype(np.int64) >> k) & 1)


def _bias_steps(lot):
    # a bias jump in run 1 of two devices, each at its own time (two charging events)
    t, run = _t(lot), np.asarray(lot.columns["run"])
    at = np.where(lot.dev == 1, 900.0, 2100.0)
    hit = ((lot.dev == 1) | (lot.dev == 3)) & (run == 1) & (t > at)
    return lot.fs_rate / OMEGA_FS_DPS * hit * _mask(lot, *RV)


# Fresh effects: a third set, written after the threshold scans and measured before any change made for them;
# no issue names them (`discovery_benchmark.py --effects fresh`). All outside the library.
FRESH_LIST = [
    _h("bias_log_time", RV, "time_s", None, None, "deg/s per e-fold",
       "a bias creeping logarithmically since power-on, ln(1 + t / 300 s) (dielectric absorption)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * np.log1p(_t(lot) / 300.0) * _mask(lot, *RV)),
    _h("gain_tempco_one_device", RV, "temperature_c", None, GAIN_T, "1/K",
       "one device (the third) whose rate and VCF gain follow the die temperature (a cracked die attach)")(
        lambda lot: lot.clean * _dT(lot) * (lot.dev == 2) * _mask(lot, *RV)),
    _h("vcf_gain_per_run", ("vcf_static",), "run", None, ("lin(run)*model", "per_run(1)*model"), "relative gain",
       "a virtual-Coriolis gain that changes from power-on to power-on (the carrier amplitude is reset), sign "
       "per device")(
        lambda lot: lot.clean * (lot.columns["run"] - 0.5) * _mask(lot, "vcf_static") * _device_sign(lot, 8)),
    _h("bias_sign_dtdt", RV, "dtemperature_dt", None, ("sign(dtemperature_dt)",), "deg/s",
       "a bias that differs warming and cooling (+c warming, -c cooling: a stress gradient of the package)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * np.sign(lot.dtdt) * _mask(lot, *RV)),
    _h("rate_quintic_only", ("rate_table",), "input", None, None, "fraction of FS at full scale",
       "a quintic of the table rate on the rate rows only (a mechanical stop stiffening at large deflection)")(
        lambda lot: -lot.fs_rate * (_x(lot) / OMEGA_FS_DPS) ** 5 * _mask(lot, "rate_table")),
    _h("dac_bit_error", ("dac",), "input", None, None, "fraction of full scale",
       "a bit-weight error of the DAC: every word with bit 19 set reads c W further from zero")(
        lambda lot: lot.full_scale * _bit(lot, 19) * _mask(lot, "dac")),
    _h("asym_clip", ("rate_table",), "input", None, None, "relative gain above +120 deg/s",
       "a one-sided limit: the output loses c of each deg/s above +120 deg/s (positive rates only)")(
        lambda lot: -lot.sf * np.clip(_x(lot) - 120.0, 0, None) * _mask(lot, "rate_table")),
    _h("bias_sq_temp_spread", RV, "temperature_c", None, ("sq(temperature_c)",), "deg/s per K^2",
       "a zero-rate output quadratic in the die temperature, of random sign and size per device")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * _dT(lot) ** 2 * _device_sign(lot, 11) * _mask(lot, *RV)),
    _h("gain_dtdt", RV, "dtemperature_dt", None, ("lin(dtemperature_dt)*model",), "relative gain per (K/min)",
       "a rate and VCF gain proportional to dT/dt (thermal strain of the electrodes while the die heats)")(
        lambda lot: lot.clean * 60.0 * lot.dtdt * _mask(lot, *RV)),
    _h("gain_sqrt_time", RV, "time_s", None, None, "relative gain at t = 1 h",
       "a gain creeping as sqrt(t / 1 h) since power-on (diffusion-limited charging)")(
        lambda lot: lot.clean * np.sqrt(_t(lot) / 3600.0) * _mask(lot, *RV)),
    _h("bias_steps_two_devices", RV, "time_s", None, None, "deg/s",
       "a bias jump in run 1 of two devices, at 900 s in one and 2100 s in the other")(_bias_steps),
    _h("vcf_range_gain", ("vcf_static",), "input", None, None, "relative gain",
       "the VCF drive amplifier's range switch: a gain 1 + c for |V| > 1 V")(
        lambda lot: lot.clean * (np.abs(_x(lot)) > 1.0) * _mask(lot, "vcf_static")),
]
FRESH = {h.name: h for h in FRESH_LIST}


def _inl_even(lot):
    """An even DAC INL: the DAC reads w + W s^2; the rebalance word for a given force is smaller by the same
    amount, so rate and VCF rows move the other way (as `_inl`)."""
    s2 = _s(lot) ** 2
    dac = _mask(lot, "dac")
    return np.where(dac, lot.full_scale * s2, -lot.fs_rate * s2 * _mask(lot, *RV))


def _bias_wander(lot):
    """A bias following an unrecorded environment (pressure, humidity): per (device, run) two slow sinusoids of
    their own periods (1500-5000 s) and phases, unit RMS on average."""
    run = np.asarray(lot.columns["run"])
    t = _t(lot)
    out = np.zeros_like(t)
    rng = np.random.default_rng(3000 + 7 * (int(lot.dev.max()) + 1))
    for d in range(int(lot.dev.max()) + 1):
        for r in range(int(run.max()) + 1):
            p1, p2 = rng.uniform(1500.0, 5000.0, size=2)
            f1, f2 = rng.uniform(0.0, 2 * np.pi, size=2)
            m = (lot.dev == d) & (run == r)
            out[m] = np.sin(2 * np.pi * t[m] / p1 + f1) + 0.6 * np.sin(2 * np.pi * t[m] / p2 + f2)
    return lot.fs_rate / OMEGA_FS_DPS * out / np.sqrt(0.68) * _mask(lot, *RV)


# Unseen effects: a fourth set, written on 2026-12-02 after every change of the fresh set and measured before any
# change made for them (`discovery_benchmark.py --effects unseen`). All outside the library; several near a
# library effect's shape (an even DAC INL beside the odd one, a kinked ZRO tempco, a compression that grows with
# the temperature, a concave rate gain), the others sweep-, device- or run-specific versions of drifts.
UNSEEN_LIST = [
    _h("gain_relax_time", RV, "time_s", None, ("relax(time_s)*model",), "relative gain at power-on",
       "a rate and VCF gain relaxing exp(-t / 900 s) after power-on (the drive amplitude's slow settling)")(
        lambda lot: lot.clean * np.exp(-_t(lot) / 900.0) * _mask(lot, *RV)),
    _h("dac_even_inl", SWEEPS, "input", None, ("sq(input)", "sq(model)"), "fraction of full scale at full scale",
       "an even DAC INL s^2 (a bow of the transfer), on the DAC bench and, reversed, the rebalance words")(_inl_even),
    _h("bias_env_wander", RV, "time_s", None, None, "deg/s RMS",
       "a bias following an unrecorded environment: two slow sinusoids of their own period and phase per run")(
        _bias_wander),
    _h("temp_x_cube_input", RV, "temperature_c", None, ("lin(temperature_c)*cube(input)",), "fraction of FS per K",
       "a cubic compression that grows with the die temperature: -c (T - 25) s^3 W")(
        lambda lot: -lot.fs_rate * _dT(lot) * _s(lot) ** 3 * _mask(lot, *RV)),
    _h("rate_gain_time_drift", ("rate_table",), "time_s", None, ("lin(time_s)*model", "lin(time_s)*lin(input)"),
       "relative gain per h", "a rate gain drifting linearly since power-on, on the rate rows only (the table's "
       "own encoder reference drifts)")(lambda lot: lot.clean * _t(lot) / 3600.0 * _mask(lot, "rate_table")),
    _h("gain_run_one_device", RV, "run", None, ("per_run(1)*model", "lin(run)*model"), "relative gain",
       "the last device's rate and VCF gain 1 + c in its second run only (a connector reseated)")(
        lambda lot: lot.clean * (np.asarray(lot.columns["run"]) == 1) * (lot.dev == lot.dev.max()) * _mask(lot, *RV)),
    _h("vcf_gain_sq_temp", ("vcf_static",), "temperature_c", None, ("sq(temperature_c)*model",), "1/K^2",
       "a virtual-Coriolis gain quadratic in the die temperature, on the VCF rows only")(
        lambda lot: lot.clean * _dT(lot) ** 2 * _mask(lot, "vcf_static")),
    _h("dac_code_pattern", ("dac",), "input", None, None, "fraction of full scale",
       "a short-period code-dependent DAC error, sin(2 pi w / 2^13 + 0.7): aliased to a fixed pattern at the "
       "bench's words")(
        lambda lot: lot.full_scale * np.sin(2 * np.pi * _x(lot) / 2.0**13 + 0.7) * _mask(lot, "dac")),
    _h("zro_kink", RV, "temperature_c", None, None, "deg/s per K above 27.5 C",
       "a zero-rate output that sets in above 27.5 C, c max(T - 27.5, 0) (a leakage path that opens when warm)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * np.maximum(_dT(lot) - 2.5, 0.0) * _mask(lot, *RV)),
    _h("vcf_bias_time_drift", ("vcf_static",), "time_s", None, ("lin(time_s)",), "deg/s per h",
       "a bias drifting linearly since power-on on the VCF rows only (the forcer's DC offset charging)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * _t(lot) / 3600.0 * _mask(lot, "vcf_static")),
    _h("rate_gain_log_abs", ("rate_table",), "input", None, None, "relative gain per e-fold",
       "a rate gain growing as ln(1 + |rate| / 10 deg/s), on the rate rows only (a rate-dependent damping)")(
        lambda lot: lot.clean * np.log1p(np.abs(_x(lot)) / 10.0) * _mask(lot, "rate_table")),
    _h("bias_time_slope_device", RV, "time_s", None, ("lin(time_s)",), "deg/s per h",
       "a bias drifting linearly since power-on at a rate of random sign and size per device (aging)")(
        lambda lot: lot.fs_rate / OMEGA_FS_DPS * _t(lot) / 3600.0 * _device_sign(lot, 12) * _mask(lot, *RV)),
]
UNSEEN = {h.name: h for h in UNSEEN_LIST}
EFFECTS = {**HIDDEN, **HELD_OUT, **FRESH, **UNSEEN}  # every effect the generator can hide


def _baseline_columns(lot: Lot, m: np.ndarray) -> list:
    """The baseline's free columns on the rows `m` (of one device): per sweep a gain (the rate gain follows the
    TCF: `lot.clean`) and, on rate and VCF rows, a bias per run (each (device, run, sweep) is its own power-on)."""
    c = lot.columns
    cols = []
    for sw in SWEEPS:
        ms = m & (c["sweep"] == sw)
        if not ms.any():
            continue
        cols.append(np.where(ms, lot.clean, 0.0))
        if sw != "dac":
            cols += [(ms & (c["run"] == r)).astype(float) for r in np.unique(c["run"][ms])]
    return cols


def _beyond(delta: np.ndarray, sigma: np.ndarray, m: np.ndarray, cols: list) -> float:
    """The chi2 of `delta` on the rows `m` beyond the span of `cols` (full-length columns), noise-free."""
    a = np.stack([col[m] for col in cols], axis=1) / sigma[m, None]
    z = delta[m] / sigma[m]
    coef = np.linalg.lstsq(a, z, rcond=None)[0]
    return float(np.sum((z - a @ coef) ** 2))


def visible_chi2(lot: Lot, delta: np.ndarray, sigma: np.ndarray) -> tuple[float, dict]:
    """The chi2 of an output change `delta` beyond what the baseline's free parameters take up, by a linear
    projection: per (device, run, sweep) a bias (rate and VCF), per device a gain on each sweep (the rate gain
    follows the TCF: it is `lot.clean`). Returns the total and the share of each sweep."""
    shares = {}
    for sw in SWEEPS:
        shares[sw] = 0.0
        for d in np.unique(lot.dev):
            m = (lot.columns["sweep"] == sw) & (lot.dev == d)
            if m.any():
                shares[sw] += _beyond(delta, sigma, m, _baseline_columns(lot, m))
    total = sum(shares.values())
    return total, {k: (v / total if total > 0 else 0.0) for k, v in shares.items()}


def look_alike_chi2(lot: Lot, delta: np.ndarray, sigma: np.ndarray, library: str | None = None) -> dict:
    """How far the data put an output change `delta` from each library effect, as this generator writes it: per
    library effect (other than `library`), the chi2 of `delta` beyond the baseline's free columns and that
    effect's own, per device (each device its own coefficient on every case of it in `HIDDEN`, a spread case
    included): the noise-free separation, the best any method could see. Below ~9 (3 sigma) no method can tell the
    two apart on this lot. The drive-frequency readings an effect also moves are left out (output rows only)."""
    out = {}
    for lib in sorted({h.library for h in HIDDEN.values() if h.library and h.library != library}):
        shapes = [h.fn(lot) for h in HIDDEN.values() if h.library == lib]
        out[lib] = sum(_beyond(delta, sigma, m, _baseline_columns(lot, m) + shapes)
                       for m in (lot.dev == d for d in np.unique(lot.dev)))
    return out


COORDINATE_KNOTS = 6  # as many knots per device as the diagnosis's own curves along a coordinate


def _coordinate_values(lot: Lot) -> dict:
    """The coordinates a misfit may be located along, per row (NaN where a sweep does not record it): the
    recorded columns, the input, dT/dt and the point's order in its run (the rank of its time)."""
    c = lot.columns
    order = np.full(lot.dev.size, np.nan)
    for key in {(d, r, s) for d, r, s in zip(lot.dev, c["run"], c["sweep"])}:
        m = (lot.dev == key[0]) & (c["run"] == key[1]) & (c["sweep"] == key[2])
        t = c["time_s"][m]
        if np.all(np.isfinite(t)):
            order[m] = np.argsort(np.argsort(t, kind="stable"), kind="stable")
    return {"input": _x(lot), "temperature_c": c["temperature_c"], "dtemperature_dt": lot.dtdt,
            "time_s": c["time_s"], "order": order, "drive_freq_hz": c["drive_freq_hz"]}


def _hats(x: np.ndarray, m: np.ndarray) -> list:
    """Piecewise-linear hats of `x` on `COORDINATE_KNOTS` knots at its quantiles over the rows `m` (full-length
    columns); none where `x` is not recorded there or takes one value."""
    xs = np.asarray(x, float)
    u = np.unique(xs[m][np.isfinite(xs[m])])
    if u.size < 2 or not np.all(np.isfinite(xs[m])):
        return []
    knots = np.unique(np.quantile(u, np.linspace(0.0, 1.0, min(COORDINATE_KNOTS, u.size))))
    return [np.where(m, np.interp(np.nan_to_num(xs), knots, np.eye(knots.size)[j]), 0.0) for j in range(knots.size)]


def coordinate_chi2(lot: Lot, delta: np.ndarray, sigma: np.ndarray) -> dict:
    """How far the data put an output change `delta` from a curve along each coordinate: per coordinate, the chi2
    of `delta` beyond the baseline's free columns and a piecewise-linear curve along it (`COORDINATE_KNOTS` knots
    at its quantiles in each device and sweep, shared by the device's runs), as an offset or as a gain (the
    smaller). Below ~9 a curve along that coordinate takes the effect up as well as one along its own: with
    curves of equal freedom the data cannot tell the two coordinates apart."""
    groups = [m for d in np.unique(lot.dev) for sw in SWEEPS
              if (m := (lot.dev == d) & (lot.columns["sweep"] == sw)).any()]
    out = {}
    for name, x in _coordinate_values(lot).items():
        chi2 = {"offset": 0.0, "gain": 0.0}
        for m in groups:
            base, hats = _baseline_columns(lot, m), _hats(x, m)
            chi2["offset"] += _beyond(delta, sigma, m, base + hats)
            chi2["gain"] += _beyond(delta, sigma, m, base + [h * lot.clean for h in hats])
        out[name] = min(chi2.values())
    return out


def discovery_lot(hidden: str | None = None, *, snr: str = "mid", design: str = "a", n_devices: int = 6,
                  n_runs: int = 2, seed: int = 0) -> tuple[Table, dict]:
    """A lot with at most one hidden effect.

    **Arguments:**

    - `hidden`: a name of `HIDDEN`, or None for a null lot.
    - `snr`: `low`, `mid` or `high`: the effect's visible chi2 is 30, 300 or 3000 (`TARGET_CHI2`).
    - `design`: `a` (paper-qmg-like) or `b` (2x drive frequency, 0.6x scale factor) (`DESIGNS`).
    - `n_devices`, `n_runs`: lot size (each device runs every sweep `n_runs` times).
    - `seed`: NumPy seed of the devices and the noise.

    **Returns:** the `gyrojax.Table` and a dict of what was hidden: name, size, unit, visible chi2 and its share per
    sweep (`visible_sweeps`: those with a share >= 0.2), and the expected answer.
    """
    if design not in DESIGNS:
        raise ValueError(f"design must be one of {sorted(DESIGNS)}, got {design!r}.")
    if snr not in TARGET_CHI2:
        raise ValueError(f"snr must be one of {sorted(TARGET_CHI2)}, got {snr!r}.")
    if hidden is not None and hidden not in EFFECTS:
        raise ValueError(f"unknown hidden effect {hidden!r}; expected one of {', '.join(EFFECTS)} or None.")
    if n_devices < 1 or n_runs < 1:
        raise ValueError(f"n_devices and n_runs must be >= 1, got {n_devices}, {n_runs}.")
    rng = np.random.default_rng(seed)
    rows = _rows(DESIGNS[design], n_devices, n_runs, rng)
    columns = {k: rows[k] for k in ("device", "run", "sweep", "input", "temperature_c", "time_s", "drive_freq_hz",
                                    "n_samples")}
    columns["output_sigma"] = rows["sigma"]
    lot = Lot(DESIGNS[design], columns, rows["dev"], rows["sf"], rows["full_scale"], rows["fs_rate"], rows["dtdt"],
              rows["phase"], rows["clean"])
    info = {"hidden": hidden, "snr": snr, "design": design, "seed": seed, "devices": n_devices, "runs": n_runs}
    delta = np.zeros_like(rows["clean"])
    if hidden is not None:
        h = EFFECTS[hidden]
        unit_delta = h.fn(lot)
        chi2_unit, shares = visible_chi2(lot, unit_delta, rows["sigma"])
        if chi2_unit <= 1e-12 * float(np.sum((unit_delta / rows["sigma"]) ** 2)):
            raise ValueError(f"hidden effect {hidden!r} leaves no chi2 beyond the baseline's free gains and biases "
                             f"on design {design!r} (on this protocol it is a bias or gain per run).")
        size = float(np.sqrt(TARGET_CHI2[snr] / chi2_unit))
        delta = size * unit_delta
        info.update(size=size, unit=h.unit, visible_chi2=TARGET_CHI2[snr], sweep_shares=shares,
                    look_alike_chi2=look_alike_chi2(lot, delta, rows["sigma"], h.library),
                    coordinate_chi2=coordinate_chi2(lot, delta, rows["sigma"]),
                    visible_sweeps=sorted(s for s, v in shares.items() if v >= 0.2),
                    sweeps=sorted(h.sweeps), coordinate=h.coordinate, library=h.library,
                    formula=None if h.formula is None else sorted(h.formula), description=h.description)
        if h.drive_shift is not None:  # the effect moves the drive resonance: the frequency readings follow it
            columns["drive_freq_hz"] = columns["drive_freq_hz"] * (1.0 + size * h.drive_shift(lot))
    noise = rows["sigma"] * rng.normal(size=rows["sigma"].size)
    columns["output"] = rows["clean"] + rows["bias"] + delta + noise
    table = Table.from_columns({k: np.asarray(v) for k, v in columns.items()},
                               source=f"<discovery lot {hidden or 'null'} {snr} design {design} seed {seed}>")
    return table, info


def noise_free(design: str, seed: int, n_devices: int, n_runs: int) -> tuple[np.ndarray, np.ndarray]:
    """The noise-free output of a null lot of `seed` (biases included) and the stated sigma, per row."""
    rows = _rows(DESIGNS[design], n_devices, n_runs, np.random.default_rng(seed))
    return rows["clean"] + rows["bias"], rows["sigma"]


def truth_chi2(table: Table, n_devices: int, n_runs: int, seed: int, design: str = "a") -> tuple[float, int]:
    """The chi2 of a null lot's outputs against the generator's own noise-free truth (biases included), and the
    number of points: the documented noise level makes it ~ n."""
    truth, sigma = noise_free(design, seed, n_devices, n_runs)
    z = (np.asarray(table.columns["output"], dtype=float) - truth) / sigma
    return float(np.sum(z**2)), int(z.size)


if __name__ == "__main__":
    import sys

    from gyrojax import write_table

    name = sys.argv[2] if len(sys.argv) > 2 else None
    tab, meta = discovery_lot(name)
    write_table(tab, sys.argv[1])
    print(f"wrote {sys.argv[1]}: {meta}")
