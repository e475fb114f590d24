"""Plausibility: data no fit could mean anything with are refused before fitting (an output absurdly far from the
rest of its run; outputs that run against the input with the opposite sign of the model's), and fitted physical
parameters far outside `Parameter.plausible` of their design values are flagged with a likely cause."""

import math

import numpy as np

from .._model.fitdata import FitData
from .._model.parameters import PARAMETERS


# A reading this many times the largest other reading of its run is refused: a 24-bit readout spans 1.7e7
# levels, so no genuine reading exceeds another of the same run by 1e8.
ABSURD_RATIO = 1e8


def check_absurd_outputs(data: FitData):
    """Raise a ValueError naming each device, run and input whose output is absurdly far from the rest of its
    run (`ABSURD_RATIO`): one such point decides every fit it enters (its chi2 alone can overflow), so no fit
    is attempted."""
    bad = []
    for s in data.sweeps:
        block = data.blocks[s]
        y, x, m = (np.asarray(a) for a in (block.outputs, block.inputs, block.mask))
        runs = data.run_ids(s)
        for d, k in np.ndindex(m.shape[:2]):
            idx = np.flatnonzero(m[d, k])
            if idx.size < 2:
                continue
            mag = np.abs(y[d, k, idx])
            top = np.argsort(mag)[-2:]  # the largest other than the largest is the second largest
            for j, i in enumerate(idx):
                others = mag[top[0]] if j == top[1] else mag[top[1]]
                if others > 0 and mag[j] > ABSURD_RATIO * others:
                    bad.append(f"sweep {s!r}, device {data.device_names()[d]!r}, run {runs[d][k]}, "
                               f"input {x[d, k, i]:.6g}: "
                               f"output {y[d, k, i]:.6g} is {mag[j] / others:.2g} times the largest other output "
                               f"of its run ({others:.6g})")
    if bad:
        raise ValueError(f"identify: {data.source}: {len(bad)} output(s) are no reading on the scale of the rest "
                         f"of their run (more than {ABSURD_RATIO:.0e} times the largest other): " + "; ".join(bad[:5])
                         + ("; ..." if len(bad) > 5 else "") + ". A typo or a failed acquisition? Fix or remove "
                         "these rows; no fit is made with them.")


# The data's slope must have the model's sign at 5 standard errors before it counts as flipped: a right table
# reads the wrong sign that clearly once in ~3.5 million runs.
_FLIP_SIGMAS = 5.0



def _slope(x, y, w):
    """Weighted least-squares slope of y on (1, x), its standard error from the given weights (`known`) and
    from the scatter about the line (NaN with fewer than 3 points)."""
    sw = np.sum(w)
    xm = np.sum(w * x) / sw
    sxx = np.sum(w * (x - xm) ** 2)
    if sxx <= 0:
        return np.nan, np.nan, np.nan
    b = np.sum(w * (x - xm) * y) / sxx
    resid = y - np.sum(w * y) / sw - b * (x - xm)
    scatter = np.sqrt(np.sum(w * resid**2) / (x.size - 2) / sxx) if x.size > 2 else np.nan
    return b, np.sqrt(1.0 / sxx), scatter


def check_signs(data: FitData, predictions, model_name: str):
    """Raise a ValueError naming each device and run whose outputs run against the input with the opposite
    sign of the start model's predictions, both slopes at more than `_FLIP_SIGMAS` standard errors of the
    data's slope from zero: a sign convention of the data (output, or
    input) flipped against the model's, which no positive gain or factor of the model can fit. Only sweeps of a
    kind whose slope's sign a convention sets (`AbstractSweep.sign_definite`) are checked."""
    bad = []
    for s in data.sweeps:
        # A straight-line sweep's output runs with its input with the sign the model predicts where a convention
        # sets that sign; where an effect's sign sets it (the drive frequency against the set-point: a cubic
        # spring hardens or softens), a library effect at its typical size turns the model's slope over.
        kind = data.kind(s)
        if not (kind.straight_line and kind.sign_definite) or s not in predictions:
            continue
        block = data.blocks[s]
        x, y, m, sig = (np.asarray(a) for a in (block.inputs, block.outputs, block.mask, block.sigmas))
        pred = np.asarray(predictions[s])
        runs = data.run_ids(s)
        for d, k in np.ndindex(m.shape[:2]):
            sel = m[d, k] & np.isfinite(pred[d, k])
            if sel.sum() < 2:
                continue
            w = 1.0 / sig[d, k][sel] ** 2
            b, known, scatter = _slope(x[d, k][sel], y[d, k][sel], w)
            b_model, _, _ = _slope(x[d, k][sel], pred[d, k][sel], w)
            se = known if data.weighted else scatter
            # Both slopes clear of zero: a model that predicts (almost) no slope, like the drive frequency
            # against the AGC set-point of a device without a cubic spring, cannot say which sign is right;
            # there the data's slope is the effect to be found, not a flipped convention.
            if (np.isfinite(b) and np.isfinite(b_model) and np.isfinite(se) and se > 0 and b * b_model < 0
                    and abs(b) > _FLIP_SIGMAS * se and abs(b_model) > _FLIP_SIGMAS * se):
                bad.append(f"sweep {s!r}, device {data.device_names()[d]!r}, run {runs[d][k]}: "
                           f"slope {b:.6g} +/- {se:.2g} "
                           f"per input unit, the model's {b_model:.6g}")
    if bad:
        raise ValueError(f"identify: {data.source}: the outputs change with the input with the opposite sign of "
                         f"the model {model_name!r} (by more than {_FLIP_SIGMAS:g} standard errors) in {len(bad)} "
                         "run(s): " + "; ".join(bad[:5]) + ("; ..." if len(bad) > 5 else "") + ". The data's sign "
                         "convention is flipped against the model's (the output's, or the input's: a rate table "
                         "turning the other way): negate the output (or input) column of these runs, or use a model "
                         "of this device's polarity. No fit is made: no positive gain of the model can fit them.")


def _power_hint(ratio: float) -> str:
    """What a ratio of a fitted value to its design value near a power of 10 or of 2 suggests."""
    # Within 5 %: a unit or word-width error is exact up to the device's own deviation from design, a few
    # percent at most (the lot spread of a scale factor is about 1 %).
    hints = []
    k10 = round(math.log10(ratio))
    if k10 != 0 and abs(math.log(ratio / 10.0**k10)) < math.log(1.05):
        hints.append(f"10^{k10}")
    k2 = round(math.log2(ratio))
    if abs(k2) >= 1 and abs(math.log(ratio / 2.0**k2)) < math.log(1.05):
        hints.append(f"2^{k2}")
    if not hints:
        return "the preset may not describe this device (or the data's units differ from the preset's)"
    return (f"the ratio is within 5 % of {' = '.join(hints)}: a unit or scaling error in the data is likely "
            "(outputs or inputs in other units, or another word width, than the preset's); else the preset does "
            "not describe this device")


def implausible_values(entries, start, values, lot_values, free, n):
    """Per device, sentences for each fitted physical parameter outside `Parameter.plausible` of its start
    (design) value."""
    out = [[] for _ in range(n)]
    k_dev = k_lot = 0
    for e, p0 in zip(entries, start):
        k = k_lot if e.shared else k_dev
        if e.shared:
            k_lot += e.size
        else:
            k_dev += e.size
        par = PARAMETERS.get(e.label) if e.effect_index is None else None
        if par is None or par.plausible is None or (not e.shared and not free[k]):
            continue
        p0 = np.reshape(np.asarray(p0), (-1,))
        for d in range(n):
            v = float(lot_values[k]) if e.shared else float(values[d, k])
            ref = float(p0[d] if p0.size == n else p0[0])
            unit = f" {par.unit}" if par.unit else ""
            if e.transform == "log":
                ratio = v / ref if ref != 0 else np.inf
                if ratio > 0 and 1.0 / par.plausible <= ratio <= par.plausible:
                    continue
                hint = _power_hint(ratio) if ratio > 0 and math.isfinite(ratio) else "the fit ran off"
                out[d].append(f"{e.label} = {v:.4g}{unit} is {ratio:.3g} x its design value {ref:.4g}{unit}, "
                              f"outside the plausible factor of {par.plausible:g} ({par.plausible_why}): {hint}")
            elif abs(v - ref) > par.plausible:
                out[d].append(f"{e.label} = {v:.4g}{unit} is {v - ref:+.3g}{unit} from its design value "
                              f"{ref:.4g}{unit}, beyond the plausible {par.plausible:g}{unit} ({par.plausible_why}): "
                              "the preset may not describe this device, or the data's units differ from its")
    return out


# A fit whose chi2_red passes this misses every point by ~1000 standard errors: whatever stopped its steps, it
# is no fit of the data (a unit or scale error of the outputs or of their sigmas, or another device).
ASTRONOMICAL_CHI2_RED = 1e6


def output_scale_ratio(data: FitData, predictions) -> np.ndarray:
    """(device, sweep): how many times the model's the data's outputs are, as the ratio of their spreads about
    each run's mean (a turn-on bias changes neither), over the valid points; NaN where either spread is 0 or not
    finite (a sweep without `predictions`, a single point per run)."""
    out = np.full((len(data.device_names()), len(data.sweeps)), np.nan)
    for i, s in enumerate(data.sweeps):
        if s not in predictions:
            continue
        block = data.blocks[s]
        y, m = np.asarray(block.outputs, dtype=float), np.asarray(block.mask, dtype=bool)
        p = np.asarray(predictions[s], dtype=float)
        m = m & np.isfinite(p)
        count = np.maximum(m.sum(axis=-1, keepdims=True), 1)

        def spread(v):
            centred = np.where(m, v - np.sum(np.where(m, v, 0.0), axis=-1, keepdims=True) / count, 0.0)
            return np.sqrt(np.sum(centred**2, axis=(1, 2)))

        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = spread(y) / spread(p)
        out[:, i] = np.where(np.isfinite(ratio) & (ratio > 0), ratio, np.nan)
    return out


def scale_hint(data: FitData, predictions, d: int) -> str:
    """For device `d` of a fit that misses its data by far: which sweeps' outputs are on another scale than the
    model's ("outputs are ~1000x the model's: check the unit of output / output_sigma"), or "" if none is."""
    ratio = output_scale_ratio(data, predictions)[d]
    off = [(s, r) for s, r in zip(data.sweeps, ratio) if np.isfinite(r) and not 1 / 3 <= r <= 3]
    if not off:
        return ""
    return ("; ".join(f"the {s} outputs are ~{r:.3g}x the model's" for s, r in off)
            + ": check the unit of output and output_sigma (or use a model of this device)")


def temperature_hint(gyro, data: FitData, d: int) -> str:
    """For device `d` of a fit the data reject: the sweeps of the rate channel with no `temperature_c` on any of
    the device's points, whose points the model then holds at the device's power-on die temperature (`gyro`, the
    model's device, batched over the lot or not), or "" if every sweep records it."""
    def unrecorded(block):
        mask = np.asarray(block.mask[d])
        return mask.any() and (block.temperatures is None
                               or not np.isfinite(np.asarray(block.temperatures[d])[mask]).any())

    # the rate channel's sweeps: a bench reading of the DAC does not follow the die temperature
    missing = [s for s in data.sweeps if data.kind(s).rate_output and unrecorded(data.blocks[s])]
    if not missing:
        return ""
    own = np.ravel(np.asarray(gyro.temperature(0.0), dtype=float))
    at = own[d] if own.size > d else own[0]
    return (f"the data give no temperature_c for {', '.join(missing)}: the model holds every point of it at the "
            f"device's power-on die temperature ({at:.4g} C); a die that warms or is cycled during the runs leaves "
            "a misfit that follows the time since power-on or the drive frequency (a thermometer through the "
            "resonator's frequency tempco). Record temperature_c (deg C) if the setup reads it")
