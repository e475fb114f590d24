"""Blind effects: a fifth set of hidden effects for the discovery benchmark (`discovery_benchmark.py --effects blind`).

Twelve effects outside gyrojax's library (`gyrojax.EFFECTS`), each a physical mechanism of a MEMS Coriolis
vibratory gyroscope or of its test benches, and each of a kind the other four sets (`HIDDEN`, `HELD_OUT`,
`FRESH`, `UNSEEN` in `_discovery_lot.py`) do not hold: a memory of the hottest temperature reached, a heating
that depends on the order of the set points, a coarse quantisation of the virtual-Coriolis amplitude, a scallop
periodic in the temperature, a segment-gain error of the DAC's low bits, a gain change of the DAC bench between
runs, a relaxation in the first power-on only, a bias of the rate's sign growing with the temperature, a ripple
of the rate gain along the drive frequency, a relaxation with its own time constant per device, a few bursts of
interference and a bias while the chamber cools only.

This set was written blind: without reading the diagnosis's code (`gyrojax/_diagnose/`) or its tests, from the
generator's conventions and the description of the formula dictionary in `docs/diagnosis.md` alone. Each
effect's `fn(lot)` returns the output change per row at unit size (the benchmark scales it to the target visible
chi2); `formula` names the dictionary's canonical terms that express it (any one of them), or None where no term
does. Plain NumPy; nothing of gyrojax's physics is imported. Importing this module adds the set to
`_discovery_lot.EFFECTS`, so `discovery_lot(name, ...)` generates its lots.
"""

import _discovery_lot
import numpy as np
from _discovery_lot import DWELL_S, OMEGA_FS_DPS, RV, _blocks, _dT, _h, _mask, _n_dev, _sf_rate, _t, _x


def _thermal_ratchet(lot):
    """Die-attach ratcheting: the adhesive yields at the hottest temperature the die has reached since power-on,
    and the stress it then holds (and the zero-rate output it gives) grows with how far the die has cooled from
    that peak: c (T_peak so far - T), zero while the die warms to new peaks."""
    temp = _dT(lot)
    out = np.zeros_like(temp)
    for i in _blocks(lot, *RV):
        out[i] = np.maximum.accumulate(temp[i]) - temp[i]
    return _sf_rate(lot) * out


FIXTURE_TAU_S = 600.0  # the rate-table fixture's thermal time constant


def _fixture_heating(lot):
    """The rate table's motor dissipates ~ rate^2; the fixture stores the heat with a time constant of 10 min and
    the gradient it puts across the package gives a bias: a first-order lag of (rate / full scale)^2 over the set
    points in the order they were visited (the fixture starts cold), read at the middle of each dwell."""
    x = _x(lot)
    out = np.zeros_like(x)
    half, full = np.exp(-0.5 * DWELL_S / FIXTURE_TAU_S), np.exp(-DWELL_S / FIXTURE_TAU_S)
    for i in _blocks(lot, "rate_table"):
        heat = 0.0
        for k in i:
            p = (x[k] / OMEGA_FS_DPS) ** 2
            out[k] = p + (heat - p) * half
            heat = p + (heat - p) * full
    return _sf_rate(lot) * out * _mask(lot, "rate_table")


VCF_AMPLITUDE_STEPS = 127  # the self-test amplitude DAC: sign and 7 bits of magnitude over 2 V


def _vcf_quantization(lot):
    """The virtual-Coriolis AC amplitude comes from the ASIC's coarse self-test DAC (sign and 7 bits over 2 V):
    the electrode gets the set amplitude rounded to a step of 2 V / 127, not the amplitude the bench records (the
    smallest set points round to zero); the change is G (round(V / q) q - V) on the VCF rows."""
    x = _x(lot)
    q = 2.0 / VCF_AMPLITUDE_STEPS
    return np.where(_mask(lot, "vcf_static"), lot.sf * (np.round(x / q) * q - x), 0.0)


TRIM_KNOT_K = 2.0  # the ASIC's bias-trim table: a knot every 2 K from 25 C


def _trim_scallop(lot):
    """The ASIC trims the bias by linear interpolation in a temperature table with a knot every 2 K; the curved
    true bias leaves a scallop between knots: 4 u (1 - u) - 2/3 with u the position between knots (1 peak to
    peak, mean zero), periodic in the temperature."""
    u = np.mod(_dT(lot) / TRIM_KNOT_K, 1.0)
    return _sf_rate(lot) * (4.0 * u * (1.0 - u) - 2.0 / 3.0) * _mask(lot, *RV)


LSB_SEGMENT_BITS = 12


def _dac_lsb_segment(lot):
    """A segmented DAC: the 12 low bits come from a binary-weighted ladder whose gain is 1 + c of the unary
    high segment's; the error is c g sign(w) (|w| mod 2^12)."""
    x = _x(lot)
    low = np.mod(np.abs(x), 2.0**LSB_SEGMENT_BITS)
    return np.where(_mask(lot, "dac"), lot.sf * np.sign(x) * low, 0.0)


def _first_run_relax(lot):
    """The first power-on after storage: charge the dielectrics took up in storage leaks off, a bias relaxing as
    exp(-t / 20 min), in run 0 of every device only (the later power-ons start preconditioned)."""
    first = np.asarray(lot.columns["run"]) == 0
    return _sf_rate(lot) * np.exp(-_t(lot) / 1200.0) * first * _mask(lot, *RV)


def _sign_rate_tempco(lot):
    """Each sign of the rebalance force uses its own electrode, selected by a switch whose charge injection grows
    with the temperature: a bias +-c (T - 25) with the sign of the rate (of the VCF input too: its force is
    balanced by the same electrodes)."""
    return _sf_rate(lot) * np.sign(_x(lot)) * _dT(lot) * _mask(lot, *RV)


DDS_PERIOD_HZ = 0.4


def _drive_ripple(lot):
    """The drive's DDS truncates its phase word: the synthesized amplitude that the AGC's reference is sampled
    through ripples with the drive frequency, period 0.4 Hz of the frequency itself; the drive amplitude, and with
    it the Coriolis force (not the virtual-Coriolis force), ripples: a rate gain sin(2 pi f / 0.4 Hz)."""
    f = np.nan_to_num(np.asarray(lot.columns["drive_freq_hz"], dtype=float))
    return lot.clean * np.sin(2 * np.pi * f / DDS_PERIOD_HZ) * _mask(lot, "rate_table")


def _vcf_relax_per_device(lot):
    """The VCF forcer electrode's dielectric charges after power-on with a time constant of its own per device
    (log-uniform, 5 to 40 min: the oxide thickness and its traps vary): a bias exp(-t / tau_d) on the VCF rows."""
    n = _n_dev(lot)
    tau = 300.0 * 2.0 ** (3.0 * np.random.default_rng(4000 + 7 * n).uniform(size=n))
    return _sf_rate(lot) * np.exp(-_t(lot) / tau[lot.dev]) * _mask(lot, "vcf_static")


def _emi_bursts(lot):
    """Interference through the rate table's slip rings (a welder next door): bursts of about four minutes, each
    on two consecutive set points of one run of three devices (at times of their own), a bias of its own sign and
    size (0.6 to 1.4) per burst; the VCF and DAC sweeps use no slip ring."""
    n = _n_dev(lot)
    n_runs = int(np.max(lot.columns["run"])) + 1
    rng = np.random.default_rng(5000 + 7 * n)
    hit = rng.choice(n, size=min(3, n), replace=False)
    runs = rng.integers(0, n_runs, size=hit.size)
    sizes = rng.choice([-1.0, 1.0], size=hit.size) * rng.uniform(0.6, 1.4, size=hit.size)
    starts = rng.uniform(size=hit.size)
    out = np.zeros(lot.dev.size)
    run = np.asarray(lot.columns["run"])
    for i in _blocks(lot, "rate_table"):
        d, r = lot.dev[i[0]], run[i[0]]
        for k in np.flatnonzero((hit == d) & (runs == r)):
            j = int(starts[k] * (i.size - 1))  # the burst's first point in this block's time order
            out[i[j:j + 2]] += sizes[k]
    return _sf_rate(lot) * out


BLIND_LIST = [
    _h("zro_thermal_ratchet", RV, "temperature_c", None, None, "deg/s per K below the peak",
       "die-attach ratcheting: a zero-rate output c (T_peak so far - T), zero while the die warms to new peaks "
       "(a memory of the hottest temperature since power-on)")(_thermal_ratchet),
    _h("rate_fixture_heating", ("rate_table",), "input", None, None, "deg/s at a settled full-scale rate",
       "the rate table's motor heats the fixture ~ rate^2: a bias following a 10-min lag of (rate / FS)^2 over "
       "the set points in the order visited")(_fixture_heating),
    _h("vcf_amplitude_quantization", ("vcf_static",), "input", None, None, "share of the 8-bit rounding",
       "the VCF amplitude from the ASIC's coarse self-test DAC: the electrode gets V rounded to 2 V / 127 (the "
       "smallest set points to zero)")(_vcf_quantization),
    _h("zro_trim_scallop", RV, "temperature_c", None, None, "deg/s peak to peak",
       "the ASIC's bias trim interpolates a table with knots every 2 K: a scallop 4 u (1 - u) - 2/3 between "
       "knots, periodic in the die temperature")(_trim_scallop),
    _h("dac_lsb_segment_gain", ("dac",), "input", None, None, "relative gain of the 12 low bits",
       "a segmented DAC whose binary-weighted 12-bit low segment has its own gain: c g sign(w) (|w| mod 2^12)")(
        _dac_lsb_segment),
    _h("dac_gain_run_cal", ("dac",), "run", None, ("per_run(1)*model", "lin(run)*model"), "relative gain",
       "the bench voltmeter's self-calibration between the runs: the DAC bench reads 1 + c of the voltage in "
       "run 1 on every device")(lambda lot: lot.clean * (np.asarray(lot.columns["run"]) == 1) * _mask(lot, "dac")),
    _h("bias_relax_first_run", RV, "time_s", None, ("relax(time_s)",), "deg/s at power-on",
       "the first power-on after storage: a bias relaxing exp(-t / 20 min) in run 0 of every device only")(
        _first_run_relax),
    _h("zro_sign_rate_tempco", RV, "temperature_c", None, ("lin(temperature_c)*sign(input)",), "deg/s per K",
       "charge injection of the electrode-selection switch: a bias +-c (T - 25) with the sign of the rate")(
        _sign_rate_tempco),
    _h("rate_gain_drive_ripple", ("rate_table",), "drive_freq_hz", None, None, "relative gain amplitude",
       "the drive DDS's phase truncation: the drive amplitude and the rate gain ripple sin(2 pi f / 0.4 Hz) "
       "along the drive frequency itself (the VCF force does not involve the drive)")(_drive_ripple),
    _h("vcf_bias_relax_device_tau", ("vcf_static",), "time_s", None, ("relax(time_s)",), "deg/s at power-on",
       "the VCF electrode's dielectric charging: a bias exp(-t / tau_d) on the VCF rows, tau_d 5 to 40 min of "
       "its own per device")(_vcf_relax_per_device),
    _h("rate_emi_bursts", ("rate_table",), "time_s", None, None, "deg/s",
       "interference through the table's slip rings: three bursts of two consecutive set points (one run of "
       "three devices), each a bias of its own sign and size")(_emi_bursts),
    _h("bias_cooling_vibration", RV, "dtemperature_dt", None, ("abs(dtemperature_dt)",), "deg/s per (K/min)",
       "the chamber's compressor runs only while it cools, and its vibration rectifies: a bias c max(-dT/dt, 0), "
       "zero while warming ((|dT/dt| - dT/dt) / 2: the abs term is its own)")(
        lambda lot: _sf_rate(lot) * 60.0 * np.maximum(-lot.dtdt, 0.0) * _mask(lot, *RV)),
]
BLIND = {h.name: h for h in BLIND_LIST}
assert len(BLIND) == len(BLIND_LIST) == 12
# no name of another set (a re-import of this module may find its own names registered: those it replaces)
_CLASH = sorted(k for k in BLIND if k in _discovery_lot.EFFECTS
                and getattr(_discovery_lot.EFFECTS[k].fn, "__module__", None) != __name__)
assert not _CLASH, f"blind effect names already taken: {_CLASH}"
assert all(h.library is None and h.sweeps <= set(_discovery_lot.SWEEPS) for h in BLIND_LIST)
_discovery_lot.EFFECTS.update(BLIND)
