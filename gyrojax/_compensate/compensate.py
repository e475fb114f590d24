"""`compensate`: fit a compensator on training runs, judge it on held-out runs (seed 000's metrics)."""

import dataclasses
import math
import warnings
from collections.abc import Callable, Iterable, Sequence
from typing import Any, ClassVar

import equinox as eqx
import numpy as np

from .._data.cells import DataError
from .._data.table import Table, device_runs
from .._data.validate import check_outputs_change
from .._metrics import (
    FULL_SCALE_CONVENTIONS,
    MIN_POINTS_LINEAR,
    fit_scale_factor,
    repeatability,
)
from .._runtime.progress import ProgressArg, as_progress
from .._text import safe_name
from .base import AbstractCompensation, AbstractCompensator
from .composite import CompositeCompensator
from .model import ModelCompensator
from .points import RatePoints
from .polynomial import PolynomialCompensator


# Callable: each is a concrete compensator class whose fields all have defaults.
COMPENSATORS: dict[str, Callable[[], AbstractCompensator]] = {
    cls.name: cls for cls in (PolynomialCompensator, CompositeCompensator, ModelCompensator)}
"""Compensation methods by name, each at its default settings."""


def rate_points(table: Table, device: str) -> RatePoints:
    """The `rate_table` points of one device of `table` as [`gyrojax.compensation.RatePoints`][], in file order."""
    rows = np.flatnonzero((table["device"] == device) & (table["sweep"] == "rate_table"))
    if rows.size == 0:
        raise DataError(f"{table.source}: no rate_table rows for device {device!r}.", source=table.source)

    def col(name):
        return table[name][rows] if name in table else None

    return RatePoints(table["input"][rows], table["output"][rows], drive_freq_hz=col("drive_freq_hz"),
                      temperature_c=col("temperature_c"), output_sigma=col("output_sigma"), run=table["run"][rows])


class CompensatedRun(eqx.Module):
    """One (device, run) of [`gyrojax.compensate`][] judged before and after (a record of
    `CompensationResult.runs`): seed 000's figures on the output (`_before`, LSB per deg/s) and on the compensated
    rate (`_after`, compensated deg/s per table deg/s), None where one is not determined (every `_after` figure of a
    device whose fit did not converge), and the curve: `rates_dps` and the residuals from the run's own straight
    line over its full scale (ppm, signed: the worst |.| is the max nonlinearity)."""

    device: str
    run: int
    used_for_training: bool
    n_points: int
    converged: bool  # the device's fit
    scale_factor_before: float | None
    scale_factor_after: float | None
    nonlinearity_max_ppm_before: float | None
    nonlinearity_max_ppm_after: float | None
    nonlinearity_rms_ppm_before: float | None
    nonlinearity_rms_ppm_after: float | None
    rates_dps: tuple[float, ...]
    residuals_ppm_before: tuple[float | None, ...] | None
    residuals_ppm_after: tuple[float | None, ...] | None

    def to_json(self) -> dict[str, Any]:
        return _record_json(self)


class CompensatedDevice(eqx.Module):
    """One device of [`gyrojax.compensate`][] (a record of `CompensationResult.devices`): its training and held-out
    runs, the repeatability before and after over all its runs and over the held-out runs only (`..._held_out`,
    None with fewer than two), the worst held-out nonlinearity before and after, the fitted coefficients
    (`compensator`, method-specific: `AbstractCompensation.summary()`), and whether the fit converged (`message`:
    empty when it did; else what did not converge and what to try)."""

    device: str
    method: str
    train_runs: tuple[int, ...]
    held_out_runs: tuple[int, ...]
    n_runs: int
    repeatability_ppm_before: float | None
    repeatability_ppm_after: float | None
    repeatability_ppm_before_held_out: float | None
    repeatability_ppm_after_held_out: float | None
    worst_nonlinearity_max_ppm_held_out_before: float | None
    worst_nonlinearity_max_ppm_held_out_after: float | None
    compensator: dict[str, Any]  # JSON-ready coefficients, method-specific
    converged: bool
    message: str

    def to_json(self) -> dict[str, Any]:
        return _record_json(self)


def _record_json(record: eqx.Module) -> dict[str, Any]:
    """A record's fields in order, tuples as lists (its JSON form)."""
    return {f.name: list(v) if isinstance(v := getattr(record, f.name), tuple) else v
            for f in dataclasses.fields(record)}


class CompensationResult(eqx.Module):
    """What [`gyrojax.compensate`][] returns.

    **Fields:**

    - `method`: the method's name.
    - `runs`: a [`gyrojax.compensation.CompensatedRun`][] per (device, run): the run before and after.
    - `devices`: a [`gyrojax.compensation.CompensatedDevice`][] per device: repeatability before and after, the
      fitted coefficients, convergence.
    - `solutions`: the fitted compensators by device, to apply to new data
      (`solution.rate(output, drive_freq_hz=...)`); for a device whose fit did not converge, its best fit.
    - `full_scale`: the nonlinearity full-scale convention (see [`gyrojax.fit_scale_factor`][]).

    Every `_after` figure of a device whose fit did not converge is None: the figures of a compensator that
    is not the method's result are not reported as the method's.
    """

    method: str = eqx.field(static=True)
    runs: tuple[CompensatedRun, ...]
    devices: tuple[CompensatedDevice, ...]
    solutions: dict[str, AbstractCompensation]
    full_scale: str = eqx.field(static=True, default="half_range")

    kind: ClassVar[str] = "compensation"

    def summary(self) -> str:
        """Per run the worst nonlinearity before and after ("n/a" with the reason where there is none), and per
        device with several runs the repeatability before and after."""
        lines = [f"{'device':>16} {'run':>4} {'use':>8}  worst nonlinearity before -> after (ppm)"]
        for r in self.runs:
            before, after = r.nonlinearity_max_ppm_before, r.nonlinearity_max_ppm_after
            use = "train" if r.used_for_training else "held-out"
            lines.append(f"{safe_name(r.device):>16} {r.run:>4} {use:>8}  "
                         f"{_na(before, '10.2f', _why_na(r, 'before'))} -> {_na(after, '.2f', _why_na(r, 'after'))}")
        for d in self.devices:
            if d.n_runs < 2:
                continue
            before, after = d.repeatability_ppm_before, d.repeatability_ppm_after
            lines.append(f"{safe_name(d.device):>16} repeatability over {d.n_runs} runs: "
                         f"{_na(before, '.2f', 'not determined', ' ppm')} -> "
                         f"{_na(after, '.2f', 'not determined', ' ppm')} ({self.method}, trained on runs "
                         f"{', '.join(map(str, d.train_runs))})")
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """The `compensate` JSON of docs/cli.md (Python numbers, None for "not applicable")."""
        return {"method": self.method, "runs": [r.to_json() for r in self.runs],
                "devices": [d.to_json() for d in self.devices],
                "conventions": {
                    "full_scale": self.full_scale,
                    "nonlinearity": "residual from each run's own least-squares line over its full scale (ppm)",
                    "repeatability": "sample std (ddof=1) of the runs' scale factors over their mean (ppm), "
                                     "seed 000 §5",
                    "scale_factor_after_units": "compensated deg/s per table deg/s"}}


def _na(value, spec: str, reason: str | None = None, unit: str = "") -> str:
    """`value` formatted with `spec` and followed by `unit`, or "n/a" (with the reason) when it is None."""
    if value is None:
        return "n/a" + (f" ({reason})" if reason else "")
    return format(value, spec) + unit


def _why_na(run: CompensatedRun, when: str) -> str:
    """Why a run's nonlinearity before/after compensation is None."""
    if when == "after" and not run.converged:
        return "the compensation did not converge for this device (see its message)"
    if getattr(run, f"scale_factor_{when}") == 0:
        return ("the outputs do not change with the input" if when == "before"
                else "the compensated rates do not change with the input")
    return "not determined"


def _num(v) -> float | None:
    v = float(v)
    return None if math.isnan(v) else v


def _resolve_method(method) -> AbstractCompensator:
    if isinstance(method, AbstractCompensator):
        return method
    if isinstance(method, str) and method in COMPENSATORS:
        return COMPENSATORS[method]()
    raise ValueError(f"method must be one of {', '.join(COMPENSATORS)} (or a gyrojax compensator), got {method!r}.")


def _resolve_train_runs(train_runs: object, devices, runs_of) -> dict[str, tuple[int, ...]]:
    if train_runs is None:
        return {d: (runs_of[d][0],) for d in devices}
    if isinstance(train_runs, (int, np.integer)) and not isinstance(train_runs, bool):
        train_runs = (train_runs,)
    try:
        items = list(train_runs) if isinstance(train_runs, Iterable) else []
    except TypeError:
        items = []
    if not items or any(isinstance(r, bool) or not isinstance(r, (int, np.integer)) for r in items):
        raise ValueError(f"train_runs must be a non-empty list of run ids (integers), got {train_runs!r}.")
    wanted = tuple(dict.fromkeys(int(r) for r in items))
    out = {}
    for d in devices:
        missing = [r for r in wanted if r not in runs_of[d]]
        if missing:
            raise DataError(f"train_runs names run {missing[0]}, which device {d!r} does not have (its rate_table "
                            f"runs: {', '.join(map(str, runs_of[d]))}).")
        out[d] = wanted
    return out


def _ppm_list(fit):
    """A run's residuals in ppm of full scale, None where a value is not finite (JSON has no NaN)."""
    full = float(fit.full_scale)
    if not (math.isfinite(full) and full > 0):
        return None
    return tuple(_num(v) for v in 1e6 * np.asarray(fit.residuals) / full)


def _worst(values):
    """The largest value, or None when there is none or one is not a number (max() with NaN depends on order)."""
    if not values or not all(math.isfinite(v) for v in values):
        return None
    return max(values)


def _check_rate_tables(table: Table, compensator) -> tuple[list[str], dict[str, list[int]]]:
    """The devices with rate_table rows (in order of appearance) and each one's runs, after checking that there
    are such rows, that each run has enough points whose outputs change, and that every point has the columns
    the compensator requires."""
    groups = table.groups("rate_table")
    if not groups:
        present = sorted(set(table["sweep"].tolist()))
        raise DataError(f"{table.source}: no rate_table rows to compensate; the table has {', '.join(present)}.",
                        source=table.source, column="sweep")
    devices, runs_of = device_runs(groups)
    for (dev, run, _), rows in groups.items():
        if len(rows) < MIN_POINTS_LINEAR:
            raise DataError(f"{table.locate(int(rows[0]))}: device {dev!r}, run {run} has {len(rows)} rate_table "
                            f"point(s); judging a compensation needs at least {MIN_POINTS_LINEAR}.",
                            source=table.source, row=int(rows[0]) + 1)
    check_outputs_change(table, groups)
    for (dev, run, _), rows in groups.items():
        for name in compensator.requires:
            values = table[name][rows] if name in table else np.full(len(rows), np.nan)
            bad = rows[~np.isfinite(values)]
            if bad.size:
                raise DataError(f"{table.locate(int(bad[0]), name)}: {compensator.name} compensation needs "
                                f"{name} on every rate_table point; device {dev!r}, run {run} lacks it.",
                                source=table.source, row=int(bad[0]) + 1, column=name)
    return devices, runs_of


def _repeatability_or_none(sf, mask=None):
    """The repeatability of the scale factors `sf` (of the runs of `mask`), None with fewer than 2 runs or a NaN
    (a fit that did not converge)."""
    if mask is not None and mask.sum() < 2 or not np.all(np.isfinite(sf)):  # NaN: fit not converged
        return None
    return _num(repeatability(sf if mask is None else sf[mask]))


def _judge(dev, pts, compensator, solution, runs, train, full_scale):
    """One device's compensation judged run by run, before and after, and over its held-out runs: (run
    records, the device record)."""
    converged, message = solution.status()
    estimate = (np.asarray(solution.rate(pts.output, drive_freq_hz=pts.drive_freq_hz,
                                         temperature_c=pts.temperature_c)) if converged else None)
    run_records = []
    sf_before, sf_after, held = [], [], []
    worst_before, worst_after = [], []
    for run in runs:
        sel = pts.run == run
        x = pts.rate_dps[sel]
        before = fit_scale_factor(x, pts.output[sel], full_scale=full_scale)
        after = fit_scale_factor(x, estimate[sel], full_scale=full_scale) if estimate is not None else None
        trained = run in train
        sf_before.append(float(before.scale_factor))
        sf_after.append(float(after.scale_factor) if after is not None else math.nan)
        held.append(not trained)
        if not trained:
            worst_before.append(float(before.nonlinearity_max_ppm))
            if after is not None:
                worst_after.append(float(after.nonlinearity_max_ppm))

        def post(name):
            return _num(getattr(after, name)) if after is not None else None

        run_records.append(CompensatedRun(
            device=dev, run=int(run), used_for_training=bool(trained), n_points=int(sel.sum()), converged=converged,
            scale_factor_before=_num(before.scale_factor), scale_factor_after=post("scale_factor"),
            nonlinearity_max_ppm_before=_num(before.nonlinearity_max_ppm),
            nonlinearity_max_ppm_after=post("nonlinearity_max_ppm"),
            nonlinearity_rms_ppm_before=_num(before.nonlinearity_rms_ppm),
            nonlinearity_rms_ppm_after=post("nonlinearity_rms_ppm"),
            rates_dps=tuple(float(v) for v in x),
            residuals_ppm_before=_ppm_list(before),
            residuals_ppm_after=_ppm_list(after) if after is not None else None,
        ))
    sf_before, sf_after, held = np.asarray(sf_before), np.asarray(sf_after), np.asarray(held)
    rep = _repeatability_or_none
    device = CompensatedDevice(
        device=dev, method=compensator.name, train_runs=tuple(int(r) for r in train),
        held_out_runs=tuple(int(r) for r, h in zip(runs, held) if h), n_runs=len(runs),
        repeatability_ppm_before=rep(sf_before), repeatability_ppm_after=rep(sf_after),
        repeatability_ppm_before_held_out=rep(sf_before, held),
        repeatability_ppm_after_held_out=rep(sf_after, held),
        worst_nonlinearity_max_ppm_held_out_before=_worst(worst_before),
        worst_nonlinearity_max_ppm_held_out_after=_worst(worst_after),
        compensator=solution.summary(), converged=converged, message=message,
    )
    return run_records, device


def compensate(table: Table, *, method: str | AbstractCompensator = "composite",
               train_runs: int | Sequence[int] | None = None, full_scale: str = "half_range",
               progress: ProgressArg = True) -> CompensationResult:
    """Fit a scale-factor compensator on each device's training runs and judge it on its held-out runs.

    Only the `rate_table` rows are used. For each device the compensator is fitted on the points of its
    training runs and applied to every run; every run is then judged by seed 000's metrics on the
    compensated output against the table rate: the worst nonlinearity (max residual from the run's own
    straight line over full scale) and, per device, the repeatability (std of the runs' scale factors over
    their mean). Runs used for training are flagged: only the held-out ones say how the compensation does
    on new data.

    **Arguments:**

    - `table`: a [`gyrojax.Table`][] with `rate_table` rows; `composite` and `model` need `drive_freq_hz`
      on every rate_table row; `model` uses `temperature_c` (for the TCF) and `output_sigma` (weights) when
      given.
    - `method`: `"polynomial"`, `"composite"` (default, seed 000's method) or `"model"`, at their default
      settings, or a configured compensator (e.g. `gj.compensation.PolynomialCompensator(order=5)`).
    - `train_runs`: run ids to fit on, the same for every device (default: each device's first run, as a
      factory calibration followed by use). Every device must have them.
    - `full_scale`: nonlinearity full-scale convention of [`gyrojax.fit_scale_factor`][].
    - `progress`: `True` (default) reports each device on standard error, `False` is silent, a callable gets
      the messages.

    **Returns:** a [`gyrojax.CompensationResult`][]. A device whose fit does not converge (an iterative
    method, `model`) does not stop the others: its record says so (`converged`, `message`, no `_after`
    figures) and a `RuntimeWarning` carries the message.

    Raises [`gyrojax.DataError`][] naming the device, run and row where the data cannot support the method
    (no rate_table rows, a run with fewer than 3 points, a training run the device lacks, a missing
    `drive_freq_hz`), `ValueError` for a bad argument.
    """
    if not isinstance(table, Table):
        raise TypeError(f"compensate expects a gyrojax.Table, got {type(table).__name__}.")
    if full_scale not in FULL_SCALE_CONVENTIONS:
        raise ValueError(f"full_scale must be one of {', '.join(FULL_SCALE_CONVENTIONS)}, got {full_scale!r}.")
    compensator = _resolve_method(method)
    devices, runs_of = _check_rate_tables(table, compensator)
    train = _resolve_train_runs(train_runs, devices, runs_of)

    run_records, device_records, solutions = [], [], {}
    say = as_progress(progress, "gyrojax.compensate")
    for k, dev in enumerate(devices, 1):
        say(f"device {k}/{len(devices)} ({dev}): fitting the {compensator.name} compensator on runs "
            f"{', '.join(map(str, train[dev]))}")
        pts = rate_points(table, dev)
        is_train = np.isin(pts.run, train[dev])
        try:
            solution = compensator.fit(pts.select(is_train))
        except ValueError as e:
            raise ValueError(f"device {dev!r}, training runs {list(train[dev])}: {e}") from None
        solutions[dev] = solution
        converged, message = solution.status()
        if not converged:
            warnings.warn(f"device {dev!r}, training runs {list(train[dev])}: {message}", RuntimeWarning,
                          stacklevel=2)
        runs, device = _judge(dev, pts, compensator, solution, runs_of[dev], train[dev], full_scale)
        run_records += runs
        device_records.append(device)
    return CompensationResult(method=compensator.name, runs=tuple(run_records), devices=tuple(device_records),
                              solutions=solutions, full_scale=full_scale)
