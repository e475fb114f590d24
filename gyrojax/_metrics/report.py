"""The `metrics` report of a table (`metrics_report`): every metric per (device, run, sweep) and per device, each
None that is no measurement or was not determined with its reason, and the conventions used."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np

from .._data.cells import DataError
from .._data.table import Table, padded_columns
from .._data.validate import check_outputs_change
from .._sweeps.base import AbstractSweep
from .._sweeps.registry import SWEEP_KINDS
from .asymmetry import asymmetry
from .bandwidth import MIN_POINTS_BANDWIDTH, rate_bandwidth
from .repeatability import repeatability
from .result import (
    BandwidthMetrics,
    DeviceMetrics,
    MetricsConventions,
    MetricsReport,
    RateLineMetrics,
    SweepMetrics,
)
from .scale_factor import FULL_SCALE_CONVENTIONS, MIN_POINTS_LINEAR, fit_scale_factor


def scale_factor_units() -> dict[str, str]:
    """The unit of `scale_factor` per sweep kind with a straight-line fit (output unit per input unit), and
    `{name}_vs_rate` for the kinds also fitted against `rate_dps`."""
    units = {}
    for cls in SWEEP_KINDS.values():
        kind = cls()
        if kind.straight_line:
            units[kind.name] = kind.scale_factor_unit
    for cls in SWEEP_KINDS.values():
        if cls.fit_against_rate:
            units[f"{cls.name}_vs_rate"] = f"{cls.output_unit}/(deg/s)"
    return units


def _num(x) -> float | None:
    v = float(np.asarray(x))
    return None if math.isnan(v) else v


_FLAT = "the outputs do not change with the input (scale factor 0)"

# The figures a sweep should give where they apply: one of them None is a number the data did not determine.
_DETERMINED = ("scale_factor", "bias", "nonlinearity_max_ppm", "nonlinearity_rms_ppm", "bandwidth_hz")

# The report's keys of each metric an `AbstractSweep.applicable_metrics` names.
_METRIC_KEYS = {
    "scale_factor": ("scale_factor", "scale_factor_vs_rate", "scale_factor_mean"),
    "bias": ("bias", "bias_vs_rate"),
    "nonlinearity": ("nonlinearity_max_ppm", "nonlinearity_rms_ppm", "nonlinearity_max_ppm_vs_rate",
                     "nonlinearity_rms_ppm_vs_rate"),
    "asymmetry": ("asymmetry_ppm",),
    "repeatability": ("repeatability_ppm",),
    "bandwidth": ("bandwidth_hz", "phase_deg_at_bandwidth", "low_frequency_gain"),
}


def _drop_inapplicable(rec: dict[str, Any], kind: AbstractSweep, brief: bool = False) -> dict[str, str]:
    """Set to None the numbers of `rec` that are no measurement on its sweep `kind` (its `applicable_metrics`);
    returns the reason for each (`brief`: the kind's reason in full for the first key only, the others refer to
    it, so that a line of text says it once)."""
    applies = kind.applicable_metrics()
    reasons = {}
    for metric, keys in _METRIC_KEYS.items():
        if metric in applies:
            continue
        for key in keys:
            if key in rec:
                rec[key] = None
                first = next(iter(reasons), None)
                reasons[key] = (f"not a measurement on a {kind.name} sweep (see {first})" if brief and first
                                else kind.metric_not_applicable(metric))
    return reasons


def _why_not(rec: dict[str, Any], outputs: np.ndarray, inputs: np.ndarray, kind: AbstractSweep) -> dict[str, str]:
    """The reason for each None among a point record's numbers (see `metrics_report`); `kind` is its sweep's."""
    flat = bool(np.all(outputs == outputs[0]))
    reasons = {}
    for key, value in rec.items():
        if value is not None or key in ("device", "run", "sweep", "n_points"):
            continue
        if not kind.straight_line:
            why = ("no phase_deg was given for every point of this sweep" if key == "phase_deg_at_bandwidth"
                   else f"a {rec['sweep']} sweep gives a bandwidth, not a straight-line fit")
        elif flat and key.startswith("nonlinearity"):
            why = f"{_FLAT}: there is no full scale to divide the residuals by"
        elif flat and key == "asymmetry_ppm":
            why = f"{_FLAT}: there are no slopes to compare"
        elif key == "asymmetry_ppm" and not (np.any(inputs > 0) and np.any(inputs < 0)):
            why = "the sweep lacks positive or negative inputs; an asymmetry needs both signs"
        elif key.startswith("scale_factor") or key.startswith("bias"):
            why = "fewer than two distinct inputs: no slope can be fitted"
        else:
            why = "not determined by these points"
        reasons[key] = why
    return reasons


def metrics_report(table: Table, *, full_scale: str = "half_range", weighted: bool = False,
                   common_bias: bool = True, ddof: int = 1) -> MetricsReport:
    """The `metrics` JSON of docs/cli.md for a table: per-sweep metrics and per-device repeatability.

    **Arguments:**

    - `table`: a [`gyrojax.Table`][].
    - `full_scale`: nonlinearity full scale, see [`gyrojax.fit_scale_factor`][].
    - `weighted`: weight fits by `1/output_sigma**2` (the table must give `output_sigma` for every point of
      the sweeps with a linear fit); default unweighted, as the standards do.
    - `common_bias`: asymmetry model, see [`gyrojax.metrics.asymmetry`][].
    - `ddof`: repeatability standard deviation, see [`gyrojax.metrics.repeatability`][].

    **Returns:**

    A `MetricsReport` with the `summary()` the command line prints; its fields are typed records, its `to_json()`
    the JSON below (Python numbers, None for "not applicable"):

    - `points`: one record per (device, run, sweep) (`SweepMetrics`; `vs_rate` and `bandwidth` hold the figures
      below that only some kinds give), in order of first appearance in the table: `device`,
      `run`, `sweep`, `n_points`, `scale_factor`, `bias`, `nonlinearity_max_ppm`, `nonlinearity_rms_ppm`,
      `asymmetry_ppm` (None when the sweep lacks positive or negative inputs). For `dac` sweeps with a
      `rate_dps` column also `scale_factor_vs_rate`, `bias_vs_rate`, `nonlinearity_max_ppm_vs_rate`,
      `nonlinearity_rms_ppm_vs_rate` (output against the rate the word stands for). For `vcf_dynamic` sweeps
      the linear keys are None and `bandwidth_hz`, `phase_deg_at_bandwidth`, `low_frequency_gain` are given.
      A metric that is no measurement on the sweep's kind (`AbstractSweep.applicable_metrics`: e.g. none on
      `drive_frequency`) is None. A sweep whose outputs are all equal has `scale_factor` 0 and None
      nonlinearities and asymmetry (a kind whose slope's sign a convention sets refuses it: see below).
      `not_applicable` maps each key that is None to the reason, in words; `undetermined` lists the keys of
      metrics that apply to the kind but that the points did not give.
    - `devices`: one record per (device, sweep) with a linear fit (`DeviceMetrics`): `device`, `sweep`, `n_runs`,
      `scale_factor_mean`, `repeatability_ppm` (None with a single run, or when the mean scale factor is 0),
      and `not_applicable` as above.
    - `conventions`: the choices above and the unit of `scale_factor` per sweep kind (`MetricsConventions`).

    Raises [`gyrojax.DataError`][] naming the device, run, sweep and rows when a run of a rate-table, VCF, DAC or
    drive-amplitude sweep has outputs that are all equal (a dead output, refused as `compensate` refuses it),
    when a sweep has too few points
    (3 for a linear fit, 2 for a bandwidth), when `rate_dps` is given for some but not all points of a `dac`
    sweep, when a weighted fit lacks a positive `output_sigma`, or when a dynamic sweep never reaches -3 dB.
    """
    if not isinstance(table, Table):
        raise TypeError(f"metrics_report expects a gyrojax.Table, got {type(table).__name__}.")
    if full_scale not in FULL_SCALE_CONVENTIONS:
        raise ValueError(f"full_scale must be one of {', '.join(FULL_SCALE_CONVENTIONS)}, got {full_scale!r}.")
    groups = table.groups()
    _check_groups(table, groups, weighted)
    check_outputs_change(table, groups)

    records: dict[tuple, dict[str, Any]] = {}
    device_records: list[dict[str, Any]] = []
    for sweep in table.kinds():
        arr = SimpleNamespace(**padded_columns(table, sweep))  # NumPy: no compilation for a report
        if not arr.kind.straight_line:
            records.update(_bandwidth_records(table, groups, arr, sweep))
            continue
        sig = arr.sigmas if weighted else None
        fit = fit_scale_factor(arr.inputs, arr.outputs, mask=arr.mask, sigmas=sig, full_scale=full_scale)
        records.update(_linear_records(arr, sweep, fit, sig, full_scale, common_bias))
        device_records.extend(_device_records(arr, sweep, fit, ddof))
    order = {}
    for dev, _, sweep in groups:
        order.setdefault((dev, sweep), len(order))
    device_records.sort(key=lambda rec: order[(rec["device"], rec["sweep"])])
    conventions = MetricsConventions(full_scale=full_scale, weighted=weighted,
                                     asymmetry="common_bias" if common_bias else "separate_fits",
                                     repeatability_ddof=ddof,
                                     nonlinearity_rms="population RMS of residuals (divided by n)",
                                     scale_factor_units=scale_factor_units())
    return MetricsReport(points=tuple(_sweep_metrics(records[key]) for key in groups),
                         devices=tuple(_device_metrics(rec) for rec in device_records), conventions=conventions)


def _sweep_metrics(rec: dict[str, Any]) -> SweepMetrics:
    """A point record (built as a dict, its keys those of the JSON) as the report's typed record."""
    vs_rate = None if "scale_factor_vs_rate" not in rec else RateLineMetrics(
        scale_factor=rec["scale_factor_vs_rate"], bias=rec["bias_vs_rate"],
        nonlinearity_max_ppm=rec["nonlinearity_max_ppm_vs_rate"],
        nonlinearity_rms_ppm=rec["nonlinearity_rms_ppm_vs_rate"])
    bandwidth = None if "bandwidth_hz" not in rec else BandwidthMetrics(
        bandwidth_hz=rec["bandwidth_hz"], phase_deg_at_bandwidth=rec["phase_deg_at_bandwidth"],
        low_frequency_gain=rec["low_frequency_gain"])
    return SweepMetrics(device=rec["device"], run=rec["run"], sweep=rec["sweep"], n_points=rec["n_points"],
                        scale_factor=rec["scale_factor"], bias=rec["bias"],
                        nonlinearity_max_ppm=rec["nonlinearity_max_ppm"],
                        nonlinearity_rms_ppm=rec["nonlinearity_rms_ppm"], asymmetry_ppm=rec["asymmetry_ppm"],
                        vs_rate=vs_rate, bandwidth=bandwidth, undetermined=tuple(rec["undetermined"]),
                        not_applicable=dict(rec["not_applicable"]))


def _device_metrics(rec: dict[str, Any]) -> DeviceMetrics:
    return DeviceMetrics(device=rec["device"], sweep=rec["sweep"], n_runs=rec["n_runs"],
                         scale_factor_mean=rec["scale_factor_mean"], repeatability_ppm=rec["repeatability_ppm"],
                         not_applicable=dict(rec["not_applicable"]))


def _group_name(table: Table, key, rows) -> str:
    """A (device, run, sweep) group of `table` in words, with the rows it spans."""
    dev, run, sweep = key
    first = table.locate(int(rows[0]), with_source=False)
    last = table.locate(int(rows[-1]), with_source=False)
    span = first if len(rows) == 1 else f"{first} to {last}"
    return f"device {dev!r}, run {run}, sweep {sweep!r} ({span})"


def _check_groups(table: Table, groups, weighted: bool) -> None:
    """Checks with names, before any arithmetic: enough points per group, a positive `output_sigma` on every
    point of a weighted fit, `rate_dps` on all or none of a group's points where the kind is fitted against it."""
    kinds = table.kinds()
    for key, rows in groups.items():
        kind = kinds[key[2]]
        line = kind.straight_line
        need = MIN_POINTS_LINEAR if line else MIN_POINTS_BANDWIDTH
        what = "a scale factor with a nonlinearity" if line else "a rate bandwidth"
        if len(rows) < need:
            raise DataError(f"{table.source}: {_group_name(table, key, rows)} has {len(rows)} "
                            f"point{'s' * (len(rows) != 1)}; {what} needs at least {need}.",
                            source=table.source, row=int(rows[0]) + 1)
        if weighted and line:
            sig = table["output_sigma"] if "output_sigma" in table else None
            bad = rows if sig is None else rows[~(sig[rows] > 0)]
            if bad.size:
                raise DataError(f"{table.locate(int(bad[0]), 'output_sigma')}: weighted=True needs a positive "
                                f"output_sigma on every point; {_group_name(table, key, rows)} lacks one.",
                                source=table.source, row=int(bad[0]) + 1, column="output_sigma")
        if kind.fit_against_rate and "rate_dps" in table:
            given = ~np.isnan(table["rate_dps"][rows])
            if given.any() and not given.all():
                r = int(rows[~given][0])
                raise DataError(f"{table.locate(r, 'rate_dps')}: rate_dps is given for some points of "
                                f"{_group_name(table, key, rows)} but not this one; give it for all or none.",
                                source=table.source, row=r + 1, column="rate_dps")


def _run_index(arr) -> dict:
    """(device, run) -> (its index on the device axis, on the run axis) of a sweep's padded arrays."""
    return {(dev, r): (d, k) for d, dev in enumerate(arr.devices) for k, r in enumerate(arr.runs[d])}


def _bandwidth_records(table: Table, groups, arr, sweep: str) -> dict:
    """The point records of a dynamic sweep: its rate bandwidth, phase there and low-frequency gain per run."""
    phase = arr.aux.get("phase_deg")
    if phase is not None:
        phase = np.where(np.isnan(phase), 0.0, phase)
    try:
        bw = rate_bandwidth(arr.inputs, arr.outputs, mask=arr.mask, phase_deg=phase)
    except DataError as e:
        key = _first_failing_bandwidth(arr, table, groups)
        raise DataError(f"{table.source}: {_group_name(table, key, groups[key])}: {e}",
                        source=table.source) from None
    records = {}
    for (dev, r), (d, k) in _run_index(arr).items():
        has_phase = phase is not None and not np.isnan(arr.aux["phase_deg"][d, k][arr.mask[d, k]]).any()
        records[(dev, r, sweep)] = {
            "device": dev, "run": r, "sweep": sweep, "n_points": int(arr.mask[d, k].sum()),
            "scale_factor": None, "bias": None, "nonlinearity_max_ppm": None,
            "nonlinearity_rms_ppm": None, "asymmetry_ppm": None,
            "bandwidth_hz": _num(bw.bandwidth_hz[d, k]),
            "phase_deg_at_bandwidth": _num(bw.phase_deg[d, k]) if has_phase else None,
            "low_frequency_gain": _num(bw.low_frequency_gain[d, k])}
        sel = arr.mask[d, k]
        why = _why_not(records[(dev, r, sweep)], arr.outputs[d, k][sel], arr.inputs[d, k][sel], arr.kind)
        records[(dev, r, sweep)]["undetermined"] = [key for key in why if key in _DETERMINED]
        records[(dev, r, sweep)]["not_applicable"] = why
    return records


def _linear_records(arr, sweep: str, fit, sig, full_scale: str, common_bias: bool) -> dict:
    """The point records of a sweep with a linear fit (`fit`): scale factor, bias, nonlinearity and asymmetry
    per run, and against `rate_dps` where the kind is fitted against it and the data give it."""
    asym = asymmetry(arr.inputs, arr.outputs, mask=arr.mask, sigmas=sig, common_bias=common_bias)
    vs_rate = None
    if arr.kind.fit_against_rate and "rate_dps" in arr.aux:
        rate = arr.aux["rate_dps"]
        has = arr.mask & ~np.isnan(rate)
        vs_rate = fit_scale_factor(np.where(has, rate, 0.0), arr.outputs, mask=has, sigmas=sig,
                                   full_scale=full_scale)
    records = {}
    for (dev, r), (d, k) in _run_index(arr).items():
        rec = {"device": dev, "run": r, "sweep": sweep, "n_points": int(arr.mask[d, k].sum()),
               "scale_factor": _num(fit.scale_factor[d, k]), "bias": _num(fit.bias[d, k]),
               "nonlinearity_max_ppm": _num(fit.nonlinearity_max_ppm[d, k]),
               "nonlinearity_rms_ppm": _num(fit.nonlinearity_rms_ppm[d, k]),
               "asymmetry_ppm": _num(asym[d, k])}
        if vs_rate is not None and _num(vs_rate.n_points[d, k]):
            rec.update({"scale_factor_vs_rate": _num(vs_rate.scale_factor[d, k]),
                        "bias_vs_rate": _num(vs_rate.bias[d, k]),
                        "nonlinearity_max_ppm_vs_rate": _num(vs_rate.nonlinearity_max_ppm[d, k]),
                        "nonlinearity_rms_ppm_vs_rate": _num(vs_rate.nonlinearity_rms_ppm[d, k])})
        sel = arr.mask[d, k]
        kind_reasons = _drop_inapplicable(rec, arr.kind, brief=True)
        why = _why_not({key: v for key, v in rec.items() if key not in kind_reasons}, arr.outputs[d, k][sel],
                       arr.inputs[d, k][sel], arr.kind)
        rec["undetermined"] = [key for key in why if key in _DETERMINED]
        rec["not_applicable"] = {**why, **kind_reasons}
        records[(dev, r, sweep)] = rec
    return records


def _device_records(arr, sweep: str, fit, ddof: int) -> list:
    """The device records of a sweep with a linear fit: mean scale factor and repeatability over its runs."""
    out = []
    run_mask = arr.mask.any(axis=-1)
    rep = repeatability(np.where(run_mask, fit.scale_factor, 0.0), mask=run_mask, ddof=ddof)
    n_runs = run_mask.sum(axis=-1)
    for d, dev in enumerate(arr.devices):
        sf = fit.scale_factor[d][run_mask[d]]
        rec = {"device": dev, "sweep": sweep, "n_runs": int(n_runs[d]),
               "scale_factor_mean": _num(np.mean(sf)), "repeatability_ppm": _num(rep[d])}
        rec["not_applicable"] = _drop_inapplicable(rec, arr.kind)
        if rec["repeatability_ppm"] is None and "repeatability_ppm" not in rec["not_applicable"]:
            rec["not_applicable"]["repeatability_ppm"] = (
                f"{int(n_runs[d])} run{'s' * (int(n_runs[d]) != 1)}: a repeatability needs at least {ddof + 1}"
                if int(n_runs[d]) <= ddof else "the mean scale factor is 0: there is nothing to be relative to")
        out.append(rec)
    return out


def _first_failing_bandwidth(arr, table, groups):
    """The (device, run, sweep) key of the first dynamic sweep that rate_bandwidth refuses."""
    for d, dev in enumerate(arr.devices):
        for k, r in enumerate(arr.runs[d]):
            try:
                rate_bandwidth(arr.inputs[d, k], arr.outputs[d, k], mask=arr.mask[d, k])
            except DataError:
                return (dev, r, arr.sweep)
    return next(iter(groups))
