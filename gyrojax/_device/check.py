"""The checked start of a fit: the device (a file or a preset) against what the data reveal without a fit.

Three numbers need no model to be read from the data:

- the drive resonance: the PLL's frequency (`drive_freq_hz`), which the drive loop locks to the resonance;
- the DAC's full scale: the slope of the DAC sweep (volts per word) over the ideal volts per word of a DAC of
  that width and the hold's gain;
- the scale factor's size: the slope of the rate table, LSB per deg/s.

A design far from them is a start a fit may not recover from (the drive resonance is not among the parameters a
fit frees by default; the gains a fit frees are judged implausible beyond a factor 2 of their start). Each is
compared in turn on the device with the ones before moved to the data, so that a drive resonance 2x off is not
reported again as a scale factor 2x off. `start_from_data` moves the leaves each number determines.
"""

import dataclasses
import math
import sys
from typing import TextIO

import equinox as eqx
import numpy as np

from .._data.table import Table
from .._gyroscope import Gyroscope, closed_loop_parts
from .._units import DEG, rad_s_to_hz


DRIVE_TOLERANCE = 0.02
"""Relative: a lot spreads its resonances by ~0.3 % and 100 K of temperature moves them by 0.3 %; a drive
resonance 2 % from the PLL's reading is another design."""

DAC_TOLERANCE = 0.05
"""Relative: a DAC's gain error, reference included, stays below 1 % for any data-sheet grade (5 % is the
plausible bound of `dac_gain_error`)."""

SCALE_FACTOR_FACTOR = 2.0
"""A factor: the plausible range of the gains a fit frees for the scale factor (`k_vf`, `sense_gain`)."""


@dataclasses.dataclass(frozen=True)
class StartReading:
    """One number read from the data and the device's value of it (with the readings before it moved to the
    data's): `quantity`, `unit`, `file_value`, `data_value`, `far` (outside its tolerance), `leaves` (what
    `start_from_data` moves), `text` (one line with the numbers)."""

    quantity: str
    unit: str
    file_value: float
    data_value: float
    far: bool
    leaves: tuple[str, ...]
    text: str


def _median(x) -> float | None:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else None


def _slopes(table, sweep) -> list[float]:
    """The least-squares slope of output on input of each (device, run) of a sweep (3 points or more)."""
    out = []
    for (_, _, _), rows in table.groups(sweep).items():
        x = np.asarray(table["input"][rows], dtype=float)
        y = np.asarray(table["output"][rows], dtype=float)
        if x.size >= 3 and np.ptp(x) > 0:
            out.append(float(np.polyfit(x, y, 1)[0]))
    return out


def _f(x) -> float:
    return float(np.asarray(x, dtype=float))


def _file_drive_hz(gyro, temperature) -> float:
    omega, _, _, _ = gyro.resonator.at_temperature(temperature)
    return rad_s_to_hz(_f(omega))


def _dac_volts_per_word(gyro) -> float:
    dac = gyro.excitation.dac
    hold_gain, _ = dac.hold(gyro.resonator.omega_x)
    return _f(dac.volts_per_word_lsb * (1.0 + dac.gain_error) * hold_gain)


def model_scale_factor(gyro) -> float:
    """|scale factor| of one device, LSB per deg/s, from its linear chain at its reference temperature: seed
    000 Eq. (2) in closed loop; in open loop the sense response at the drive frequency, |G_s| Ag a /
    |g_y - j d_y| (g_y = w_y / (2 Q_y), d_y = (w_y^2 - w^2) / (2 w)), the demodulation taken in phase."""
    if gyro.closed_loop:
        return abs(_f(gyro.ideal_scale_factor())) * DEG
    r = gyro.resonator
    w, wy, qy = _f(r.omega_x), _f(r.omega_y), _f(r.q_y)
    a = _f(gyro.drive_amplitude(w))
    g_s = abs(complex(np.asarray(gyro.sense_frontend.phasor_gain(w))))
    return g_s * _f(r.angular_gain) * a / math.hypot(wy / (2.0 * qy), (wy**2 - w**2) / (2.0 * w)) * DEG


def _move_drive(gyro, ratio):
    """The device with both resonances and the PLL's centre frequency times `ratio`; the rebalance carrier's
    phase follows if it is the DAC hold's delay at the old resonance (the design's rule)."""
    r = gyro.resonator
    leaves = [lambda g: g.resonator.omega_x, lambda g: g.resonator.omega_y, lambda g: g.drive_loop.center_frequency]
    values = [r.omega_x * ratio, r.omega_y * ratio, gyro.drive_loop.center_frequency * ratio]
    names = ["resonator.omega_x", "resonator.omega_y", "drive_loop.center_frequency"]
    if gyro.closed_loop:
        _, delay = gyro.excitation.dac.hold(r.omega_x)
        if math.isclose(_f(gyro.rebalance_loop.carrier_phase), _f(delay), rel_tol=1e-9, abs_tol=1e-15):
            leaves.append(lambda g: g.rebalance_loop.carrier_phase)
            values.append(gyro.excitation.dac.hold(r.omega_x * ratio)[1])
            names.append("rebalance_loop.carrier_phase")
    return eqx.tree_at(lambda g: [f(g) for f in leaves], gyro, values), tuple(names)


def _move_scale_factor(gyro, ratio):
    """The device with the gain a fit frees for the scale factor moved so that it reads `ratio` times more."""
    if gyro.closed_loop:  # SF is inversely proportional to K_vf
        return (eqx.tree_at(lambda g: g.feedback_electrode.k_vf, gyro, gyro.feedback_electrode.k_vf / ratio),
                ("feedback_electrode.k_vf",))
    return (eqx.tree_at(lambda g: g.sense_frontend.gain, gyro, gyro.sense_frontend.gain * ratio),
            ("sense_frontend.gain",))


def _ratio_text(file_value, data_value) -> str:
    if not file_value:
        return "the file's is zero"
    ratio = data_value / file_value
    return f"{ratio:.3f}x the file's" if 0.1 <= abs(ratio) < 10 else f"{ratio:.3g}x the file's"


def check_start(gyro: Gyroscope, table: Table) -> tuple[tuple[StartReading, ...], Gyroscope]:
    """Compare one device with what `table` reveals directly; returns `(readings, moved)`: one `StartReading` per
    number the data give (a sweep the data lack gives none) and the device with every far reading moved to the
    data's (`start_from_data`'s result)."""
    if np.ndim(gyro.resonator.mass) > 0:
        raise ValueError("check_start: the device is a lot; give one device (the design the fit starts from).")
    readings, moved = [], gyro
    sweeps = set(np.asarray(table["sweep"]).tolist())
    if "dac" in sweeps and not gyro.closed_loop:
        readings.append(StartReading(
            "loop", "", 0.0, 1.0, True, (),
            "the data have a dac sweep (the DAC of a force-to-rebalance loop): a closed-loop device; the file's "
            "device is open loop (it has [readout], not [rebalance_loop]): start from a closed-loop design"))
    # 1. the drive resonance, read by the PLL
    f_data = _median(table["drive_freq_hz"]) if "drive_freq_hz" in table else None
    if f_data is not None:
        temp = _median(table["temperature_c"]) if "temperature_c" in table else None
        temp = _f(gyro.resonator.t_ref) if temp is None else temp
        f_file = _file_drive_hz(gyro, temp)
        far = abs(f_data / f_file - 1.0) > DRIVE_TOLERANCE
        names = ()
        if far:
            moved, names = _move_drive(moved, f_data / f_file)
        readings.append(StartReading(
            "drive resonance", "Hz", f_file, f_data, far, names,
            f"the file's drive resonance {f_file:.5g} Hz, the data's {f_data:.5g} Hz (the PLL's drive_freq_hz, "
            f"median at {temp:.3g} degC): {_ratio_text(f_file, f_data)}"))
    # 2. the DAC's full scale, from the DAC sweep
    slopes = _slopes(table, "dac") if moved.closed_loop else []
    if slopes:
        per_word = _dac_volts_per_word(moved)
        dac = closed_loop_parts(moved, "the DAC sweep's check").excitation.dac
        fs_file = _f(dac.full_scale)
        fs_data = fs_file * float(np.median(slopes)) / per_word
        far = not abs(fs_data / fs_file - 1.0) <= DAC_TOLERANCE
        names = ()
        if far and fs_data > 0:
            moved = eqx.tree_at(lambda g: g.excitation.dac.full_scale, moved,
                                dac.full_scale * (fs_data / fs_file))
            names = ("excitation.dac.full_scale",)
        readings.append(StartReading(
            "DAC full scale", "V", fs_file, fs_data, far, names,
            f"the file's DAC full scale {fs_file:.4g} V, the data's {fs_data:.4g} V (the DAC sweep's "
            f"{float(np.median(slopes)):.4g} V per word over {per_word / fs_file:.4g} per volt of full scale for "
            f"{dac.bits} bits fed from {dac.word_bits}): "
            f"{_ratio_text(fs_file, fs_data)}"))
    # 3. the scale factor's size, from the rate table
    slopes = _slopes(table, "rate_table")
    if slopes:
        sf_as_is = model_scale_factor(gyro)
        sf_file = model_scale_factor(moved)
        sf_data = float(np.median(np.abs(slopes)))
        ratio = sf_data / sf_file if sf_file > 0 else math.inf
        far = not (1.0 / SCALE_FACTOR_FACTOR <= ratio <= SCALE_FACTOR_FACTOR)
        names = ()
        if far and math.isfinite(ratio) and ratio > 0:
            moved, names = _move_scale_factor(moved, ratio)
        with_moves = f" ({sf_file:.5g} with the numbers above moved to the data's)" if moved is not gyro and \
            not math.isclose(sf_file, sf_as_is, rel_tol=1e-9) else ""
        readings.append(StartReading(
            "scale factor", "LSB/(deg/s)", sf_file, sf_data, far, names,
            f"the file's scale factor {sf_as_is:.5g} LSB/(deg/s){with_moves}, the data's {sf_data:.5g} "
            f"LSB/(deg/s) (the rate table's slope, median of {len(slopes)} run(s)): {_ratio_text(sf_file, sf_data)}"))
    return tuple(readings), moved


def start_lines(readings, *, moved: bool, label: str) -> list[str]:
    """The lines identify prints: each far reading, with what `--start-from-data` moves (or moved)."""
    lines = []
    for r in readings:
        if not r.far:
            continue
        if moved and r.leaves:
            lines.append(f"{label}: {r.text}; moved {', '.join(r.leaves)} to the data's before the fit")
        elif r.leaves:
            lines.append(f"{label}: {r.text}; far from the data: --start-from-data moves {', '.join(r.leaves)} there "
                         "before the fit")
        else:
            lines.append(f"{label}: {r.text}; far from the data")
    return lines


def checked_start(gyro: Gyroscope, table: Table, *, move: bool, label: str, file: TextIO | None = None) -> Gyroscope:
    """identify's checked start: compare the device with what `table` reveals (`check_start`), print each far
    reading on `file` (standard error by default) as `label: warning: ...`, and return the device, with the far
    readings' leaves moved to the data's when `move` (`--start-from-data`)."""
    readings, moved = check_start(gyro, table)
    for line in start_lines(readings, moved=move, label=label):
        print(line if move else line.replace(f"{label}: ", f"{label}: warning: ", 1), file=file or sys.stderr)
    return moved if move else gyro
