"""Sealed effects: a sixth set of hidden effects for the discovery benchmark (`--effects sealed`).

Twelve effects outside gyrojax's library (`gyrojax.EFFECTS`), each a physical mechanism of a MEMS Coriolis
vibratory gyroscope or of its test benches, and each of a kind the other five sets (`HIDDEN`, `HELD_OUT`,
`FRESH`, `UNSEEN` in `_discovery_lot.py`, `BLIND` in `_discovery_blind.py`) do not hold: a virtual-Coriolis gain
that grows with the dose of AC field applied so far, a thermal-EMF offset on one device's DAC-bench channel, a
centripetal bias whose g-sensitivity grows with the temperature, a bias latched by a package lid that snaps
through with hysteresis in the temperature, the cubic residual of a quadratic bias trim, a rate gain that follows
the temperature through the drive pick-off while the drive frequency does not (the library's thermal drift without
its fingerprint on the resonance), a fixed charge injection of the VCF polarity switch, encoder interference at a
few table rates whose harmonics fall near the drive frequency, a cubic nonlinearity of the bench voltmeter (a DAC
INL's shape on the DAC bench alone), a feedback compression in the first run only (a sagging supply), a bias
creeping at a thermally activated rate, and a V^2 leak of one device's demodulator growing after power-on.

This set was written sealed: without reading the diagnosis's code (`gyrojax/_diagnose/`, `gyrojax/_locate*`,
`gyrojax/_probes.py`, `gyrojax/_compare.py`) or its tests, from the generator's conventions, the other sets and
the description of the formula dictionary in `docs/diagnosis.md` alone. Each effect's `fn(lot)` returns the
output change per row at unit size (the benchmark scales it to the target visible chi2); `formula` names the
dictionary's canonical terms that express it (any one of them), or None where no term does. Plain NumPy; nothing
of gyrojax's physics is imported. Importing this module adds the set to `_discovery_lot.EFFECTS`, so
`discovery_lot(name, ...)` generates its lots.
"""

import _discovery_lot
import numpy as np
from _discovery_lot import OMEGA_FS_DPS, RV, _blocks, _dT, _h, _mask, _s, _sf_rate, _t, _x


VCF_FS_V = 2.0  # the largest virtual-Coriolis amplitude of the sweep


def _vcf_charge_dose(lot):
    """Field-driven charge injection into the VCF electrode's oxide: charge is trapped at a rate ~ V_ac^2 and kept
    for the rest of the power-on; it adds to the carrier V_fc, so the virtual-Coriolis gain grows with the dose
    sum (V_k / 2 V)^2 over the dwells applied so far (the current one's first half included), in full-scale
    dwells."""
    x = _x(lot)
    out = np.zeros_like(x)
    for i in _blocks(lot, "vcf_static"):
        p = (x[i] / VCF_FS_V) ** 2
        out[i] = np.cumsum(p) - 0.5 * p
    return lot.clean * out * _mask(lot, "vcf_static")


def _lid_snap(lot):
    """A bistable package lid: thermal stress makes it snap through when the die passes 29 C warming, and it snaps
    back only below 27 C; while it is buckled its stress on the die gives a bias (a hysteresis loop in the
    temperature; a run that never reaches 29 C never sees it)."""
    temp = _dT(lot)
    out = np.zeros_like(temp)
    for i in _blocks(lot, *RV):
        state = 0.0
        for k in i:
            if temp[k] >= 4.0:
                state = 1.0
            elif temp[k] < 2.0:
                state = 0.0
            out[k] = state
    return _sf_rate(lot) * out


ENCODER_LINES = 81920  # the rate table's optical encoder (20 x 2^12 lines per revolution)
SENSE_BAND_REL = 0.02  # the sense loop's half bandwidth around the drive frequency, relative


def _encoder_interference(lot):
    """The table's encoder lines pass at f_enc = N |rate| / 360 deg; its first four harmonics couple into the
    sense pick-off and are rectified by the demodulator when one falls within the sense band around the drive
    frequency: a bias sum_k (1/k) / (1 + ((k f_enc - f_d) / (0.02 f_d))^2), even in the rate, at the few set
    points that hit (|rate| 5, 10, 20 deg/s on design a), its size per device set by its own drive frequency."""
    rate = _mask(lot, "rate_table")
    f_enc = ENCODER_LINES * np.abs(_x(lot)[rate]) / 360.0
    f_d = np.asarray(lot.columns["drive_freq_hz"], dtype=float)[rate]
    out = np.zeros(lot.dev.size)
    for k in range(1, 5):
        out[rate] += (1.0 / k) / (1.0 + ((k * f_enc - f_d) / (SENSE_BAND_REL * f_d)) ** 2)
    return _sf_rate(lot) * out


VOLTMETER_RANGE_V = 2.0


def _voltmeter_cubic(lot):
    """The bench voltmeter's own ADC nonlinearity on its 2 V range: it reads v + c V_r (v / V_r)^3. Only the DAC
    bench is read through it; the rebalance words of the rate and VCF sweeps are not, so they keep their shape
    (a DAC INL's fingerprint on one sweep of the three)."""
    v = lot.clean
    return np.where(_mask(lot, "dac"), VOLTMETER_RANGE_V * (v / VOLTMETER_RANGE_V) ** 3, 0.0)


ACTIVATION_K = 2.0 / np.log(2.0)  # the leak doubles every 2 K


def _activated_creep(lot):
    """Charge leaking onto the sense electrode through a thermally activated path, its rate doubling every 2 K:
    a bias that creeps as the integral since power-on of exp((T - 25) / 2.885 K) (in hours at 25 C), fast while
    the die is warm and slow while it is cool, so the creep's curve follows each run's chamber cycle."""
    temp = _dT(lot)
    t = _t(lot)
    out = np.zeros_like(temp)
    for i in _blocks(lot, *RV):
        rate = np.exp(temp[i] / ACTIVATION_K)
        steps = np.diff(t[i]) * 0.5 * (rate[1:] + rate[:-1])  # trapezoids between the dwells' middles
        out[i] = (t[i][0] * rate[0] + np.concatenate(([0.0], np.cumsum(steps)))) / 3600.0
    return _sf_rate(lot) * out


SEALED_LIST = [
    _h("vcf_gain_charge_dose", ("vcf_static",), "input", None, None, "relative gain per full-scale dwell",
       "field-driven charging of the VCF electrode's oxide: the virtual-Coriolis gain grows with the dose "
       "sum (V / 2 V)^2 of the set points applied so far in the power-on (their order matters)")(_vcf_charge_dose),
    _h("dac_scanner_emf_one_device", ("dac",), "device", None, None, "fraction of full scale",
       "a thermal EMF at the bench scanner's relay contacts of the first device's channel: a constant offset on "
       "its DAC readings in every run, none on the other devices")(
        lambda lot: lot.full_scale * (lot.dev == 0) * _mask(lot, "dac")),
    _h("rate_centripetal_tempco", ("rate_table",), "temperature_c", None, ("lin(temperature_c)*sq(input)",),
       "deg/s per K at the full-scale rate",
       "an off-axis mount's centripetal acceleration r Omega^2 through a g-sensitivity nulled at 25 C that grows "
       "with the mode split's drift: a bias c (T - 25)(rate / FS)^2 on the rate rows")(
        lambda lot: _sf_rate(lot) * _dT(lot) * (_x(lot) / OMEGA_FS_DPS) ** 2 * _mask(lot, "rate_table")),
    _h("zro_lid_snap_hysteresis", RV, "temperature_c", None, None, "deg/s",
       "a bistable package lid snapping through at 29 C warming and back below 27 C cooling: a bias while it is "
       "buckled (a hysteresis loop in the temperature, absent from runs that stay below 29 C)")(_lid_snap),
    _h("zro_trim_cubic_residual", RV, "temperature_c", None, ("cube(temperature_c)",), "deg/s per K^3",
       "the ASIC trims the zero-rate output's temperature curve with a quadratic: the curve's cubic term is "
       "left, a bias c (T - 25)^3 on the rate and VCF rows")(
        lambda lot: _sf_rate(lot) * _dT(lot) ** 3 * _mask(lot, *RV)),
    _h("rate_gain_pickoff_tempco", ("rate_table",), "temperature_c", None,
       ("lin(temperature_c)*model", "lin(temperature_c)*lin(input)"), "1/K",
       "the AGC holds the drive pick-off signal, whose gap expands with the temperature: the drive amplitude and "
       "the rate gain follow (1 + c (T - 25)) while the resonance, its frequency reading and the VCF force do not")(
        lambda lot: lot.clean * _dT(lot) * _mask(lot, "rate_table")),
    _h("vcf_polarity_injection", ("vcf_static",), "input", None, ("sign(input)", "step(input)"), "deg/s",
       "the switch that reverses the VCF polarity injects a fixed charge each carrier cycle: a bias +-c with the "
       "sign of the set amplitude, whatever its size")(
        lambda lot: _sf_rate(lot) * np.sign(_x(lot)) * _mask(lot, "vcf_static")),
    _h("rate_encoder_interference", ("rate_table",), "input", None, None, "deg/s at a centred hit",
       "the table encoder's line frequency N |rate| / 360 (N = 81920) and its harmonics rectified where one falls "
       "within 2 % of the drive frequency: a bias at a few set points only, of a size per device")(
        _encoder_interference),
    _h("dac_voltmeter_cubic", ("dac",), "input", None, ("cube(input)", "cube(model)"),
       "fraction of the 2 V range at 2 V",
       "the bench voltmeter's own cubic nonlinearity, v + c V_r (v / V_r)^3: a DAC INL's shape on the DAC bench "
       "alone (the rebalance words are not read through the voltmeter)")(_voltmeter_cubic),
    _h("compression_first_run_supply", RV, "input", None, None, "fraction of full scale at full scale",
       "the ASIC's supply sagged in run 0 (a bench supply without its sense leads, fixed before run 1): the "
       "feedback amplifier compresses, -c W s^3, in run 0 only")(
        lambda lot: -lot.fs_rate * _s(lot) ** 3 * (np.asarray(lot.columns["run"]) == 0) * _mask(lot, *RV)),
    _h("bias_activated_creep", RV, "time_s", None, None, "deg/s per h at 25 C",
       "charge leaking through a thermally activated path (rate doubling every 2 K): a bias creeping as the "
       "integral of exp((T - 25) / 2.885 K) since power-on, its curve set by each run's chamber cycle")(
        _activated_creep),
    _h("vcf_demod_duty_one_device", ("vcf_static",), "time_s", None, ("lin(time_s)*sq(input)",),
       "deg/s per h at 2 V",
       "the last device's demodulator has a duty-cycle error that lets the V_ac^2 force through, growing as its "
       "ASIC warms after power-on: a bias c (t / 1 h)(V / 2 V)^2 on its VCF rows")(
        lambda lot: _sf_rate(lot) * _t(lot) / 3600.0 * (_x(lot) / VCF_FS_V) ** 2 * (lot.dev == lot.dev.max())
        * _mask(lot, "vcf_static")),
]
SEALED = {h.name: h for h in SEALED_LIST}
assert len(SEALED) == len(SEALED_LIST) == 12
# no name of another set (a re-import of this module may find its own names registered: those it replaces)
_CLASH = sorted(k for k in SEALED if k in _discovery_lot.EFFECTS
                and getattr(_discovery_lot.EFFECTS[k].fn, "__module__", None) != __name__)
assert not _CLASH, f"sealed effect names already taken: {_CLASH}"
assert all(h.library is None and h.sweeps <= set(_discovery_lot.SWEEPS) for h in SEALED_LIST)
_discovery_lot.EFFECTS.update(SEALED)
