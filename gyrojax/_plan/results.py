"""The results of `plan`: `Plan`, a `CandidatePlan` per candidate effect with its `Recommendation`s, and
the scale factor's `ScaleFactorDesign`; their summaries and JSON."""

import math
from collections.abc import Sequence
from typing import ClassVar, overload

import equinox as eqx
import numpy as np

from .._data.table import Table
from .._gyroscope import Gyroscope
from .._identify import Fit
from .._identify.spec import default_free
from .._numerics.testability import MIN_TYPICAL_CHI2
from .._sweeps.rate_table import RateTable
from .experiment import (
    CandidateExperiment,
)
from .simulate import simulate_runs


class Recommendation(eqx.Module):
    """Runs of one experiment in a recommended set: how many, their minutes, and the expected chi2 and power
    of the effect's test with only these runs added to the data given."""

    experiment: CandidateExperiment
    runs: int = eqx.field(static=True)
    expected_chi2: float = eqx.field(static=True)
    power: float = eqx.field(static=True)

    @property
    def minutes(self) -> float:
        return self.runs * self.experiment.minutes

    def to_json(self) -> dict:
        return {"sweep": self.experiment.name, "kind": self.experiment.kind,
                "settings": dict(self.experiment.settings), "runs": self.runs, "minutes": self.minutes,
                "expected_chi2": self.expected_chi2, "power": self.power}


class ExperimentGain(eqx.Module):
    """What one run of one experiment adds to a candidate's test (a record of `CandidatePlan.per_experiment`): the
    experiment's `name`, its `minutes`, the expected chi2 of a typical-size effect with the run added to the data
    given, and the test's power there."""

    name: str = eqx.field(static=True)
    minutes: float = eqx.field(static=True)
    expected_chi2: float = eqx.field(static=True)
    power: float = eqx.field(static=True)


class CandidatePlan(eqx.Module):
    """What one candidate effect needs: its test on the data given, what one run of each experiment adds,
    and the cheapest set of runs with which its test reaches the target power.

    `testable` is `gyrojax._numerics.testability`'s rule, the diagnosis's own: a typical size leaves an expected chi2
    of at least `MIN_TYPICAL_CHI2` on the data given. `detected` is the stronger demand the plan works to: the
    test's power at the typical size reaches `target_power`; runs are recommended until it does."""

    effect: str = eqx.field(static=True)
    df: int = eqx.field(static=True)
    expected_chi2: float = eqx.field(static=True)  # on the data given
    power: float = eqx.field(static=True)
    testable: bool = eqx.field(static=True)
    ambiguous_with: tuple[str, ...] = eqx.field(static=True)
    per_experiment: tuple[ExperimentGain, ...] = eqx.field(static=True)  # one run of each experiment
    recommended: tuple[Recommendation, ...] = eqx.field(static=True)  # per experiment of the cheapest set
    recommended_chi2: float = eqx.field(static=True)
    recommended_power: float = eqx.field(static=True)
    reason: str = eqx.field(static=True)
    detected: bool = eqx.field(static=True, default=False)  # power at the typical size reaches the target

    @property
    def minutes(self) -> float:
        return float(sum(r.minutes for r in self.recommended))

    def to_json(self) -> dict:
        return {"testable": self.testable, "detected": self.detected, "df": self.df,
                "expected_chi2": self.expected_chi2, "power": self.power,
                "ambiguous_with": list(self.ambiguous_with),
                "experiments": {g.name: {"minutes": g.minutes, "expected_chi2": g.expected_chi2, "power": g.power,
                                         "chi2_per_minute": (g.expected_chi2 - self.expected_chi2) / g.minutes}
                                for g in self.per_experiment},
                "recommended": [r.to_json() for r in self.recommended],
                "recommended_minutes": self.minutes, "recommended_expected_chi2": self.recommended_chi2,
                "recommended_power": self.recommended_power, "reason": self.reason}


class ScaleFactorDesign(eqx.Module):
    """The campaign within `budget_min` that minimises the scale factor's standard error, and seed 000's
    protocol at equal time (both predicted for the baseline model, per device; mean over the lot in
    `summary`)."""

    budget_min: float = eqx.field(static=True)
    rates_dps: tuple[float, ...] = eqx.field(static=True)
    rate_runs: int = eqx.field(static=True)
    vcf_rates_dps: tuple[float, ...] = eqx.field(static=True)
    vcf_runs: int = eqx.field(static=True)
    minutes: float = eqx.field(static=True)
    stderr: tuple[float, ...] = eqx.field(static=True)  # per device, LSB per deg/s
    seed000_runs: int = eqx.field(static=True)
    seed000_minutes: float = eqx.field(static=True)
    seed000_stderr: tuple[float, ...] = eqx.field(static=True)
    # on the data given (NaN where identify does not determine it)
    data_stderr: tuple[float, ...] = eqx.field(static=True)
    scale_factor: tuple[float, ...] = eqx.field(static=True)
    # identification's reason, per device, where the data given do not determine the scale factor ("" where
    # they do)
    data_not_determined: tuple[str, ...] = eqx.field(static=True, default=())

    @property
    def ratio(self) -> float:
        """The design's stderr over seed 000's, mean over devices (below 1: the design is better)."""
        return float(np.mean(np.asarray(self.stderr) / np.asarray(self.seed000_stderr)))

    def rate_table(self) -> RateTable:
        """The design's rate table, `gyrojax.sweeps.RateTable` at its rates (simulate it with `runs=rate_runs`)."""
        return RateTable(rates_dps=self.rates_dps)

    def to_json(self) -> dict:
        return {"budget_min": self.budget_min, "rates_dps": list(self.rates_dps), "rate_runs": self.rate_runs,
                "vcf_rates_dps": list(self.vcf_rates_dps), "vcf_runs": self.vcf_runs, "minutes": self.minutes,
                "stderr": list(self.stderr), "seed000": {"rates_dps": "seed 000's 22", "runs": self.seed000_runs,
                                                         "minutes": self.seed000_minutes,
                                                         "stderr": list(self.seed000_stderr)},
                "ratio": self.ratio, "data_stderr": list(self.data_stderr),
                "data_not_determined": [w or None for w in self.data_not_determined],
                "scale_factor": [math.nan if w else v for v, w in
                                 zip(self.scale_factor, self.data_not_determined or ("",) * len(self.scale_factor))],
                "unit": "LSB/(deg/s)"}


class Plan(eqx.Module):
    """The solution of `plan`: per candidate effect a `CandidatePlan`, the scale-factor design, the
    experiments considered, the baseline fit, and how the search was made."""

    candidates: tuple[CandidatePlan, ...]
    scale_factor: ScaleFactorDesign | None  # None when plan was told not to design it
    experiments: tuple[CandidateExperiment, ...]
    baseline: Fit  # the fit whose Jacobians the plan used (with every candidate at zero)
    alpha: float = eqx.field(static=True)
    target_power: float = eqx.field(static=True)
    max_repeats: int = eqx.field(static=True)
    devices: tuple[str, ...] = eqx.field(static=True)
    search: str = eqx.field(static=True, default="exact")
    warnings: tuple[str, ...] = eqx.field(static=True, default=())  # what the reader must know before acting on it

    def candidate(self, name: str) -> CandidatePlan:
        for c in self.candidates:
            if c.effect == name:
                return c
        raise ValueError(f"no candidate {name!r} in this plan; it has {', '.join(c.effect for c in self.candidates)}.")

    def runs(self) -> dict:
        """The runs to add: the union of the experiments recommended for the candidates whose test does not
        reach the target power on the data given, per experiment name `(experiment, runs, candidates)`: the
        most runs any candidate asks for, and the candidates asking (in the plan's order)."""
        out = {}
        for c in self.candidates:
            for r in c.recommended:
                e, k, who = out.get(r.experiment.name, (r.experiment, 0, ()))
                out[r.experiment.name] = (e, max(k, r.runs), who + (c.effect,))
        return out

    def free(self, free: Sequence[str] | None = None) -> tuple:
        """The `free` argument of `gyrojax.diagnose` (or `identify`) for the data given plus `runs()`: `free`
        (None: `gyrojax.identification.default_free` of the data given, as `diagnose`'s default) and the
        parameters those runs read on the plan's device (`AbstractSweep.reads_on`), as the plan's expected chi2
        assumes."""
        device = self.baseline.model.device
        read = (p for e, _, _ in self.runs().values() for p in e.sweep.reads_on(device))
        given = default_free(device, self.baseline.data) if free is None else tuple(free)
        return tuple(dict.fromkeys(given + tuple(read)))

    def simulate(self, gyro: Gyroscope, table: Table | None = None, *, devices: int = 1, runs: int = 1, seed: int = 0,
                 noise_seed: int = 1000) -> Table:
        """A simulation study's next step: `runs()` simulated for the lot that `gyrojax.simulate_table(gyro,
        devices=devices, runs=runs, seed=seed)` drew (`gyrojax.campaign_lot`), each device on its own with
        noise seed `seed + noise_seed + i` (a draw independent of the data's), labelled as that table's
        devices and numbered after its `runs` runs. An experiment at a warmer chamber (`<kind>_hot`) runs
        with the die's ambient (a `ConstantTemperature`) at its chamber's temperature. Returns `table` (the
        data given) with these runs appended (a column missing on either side is NaN there), or the runs
        alone when `table` is None; diagnose it with `free=self.free(...)`. Raises a `ValueError` when
        nothing is recommended."""
        return simulate_runs(self.runs(), gyro, table, devices=devices, runs_given=runs, seed=seed,
                             noise_seed=noise_seed)

    kind: ClassVar[str] = "plan"

    def to_json(self) -> dict:
        """The plan as JSON (numbers that are not finite, e.g. an undetermined stderr, are null)."""
        return _finite({"candidates": {c.effect: c.to_json() for c in self.candidates},
                "scale_factor": None if self.scale_factor is None else self.scale_factor.to_json(),
                "experiments": {e.name: e.to_json() for e in self.experiments},
                "alpha": self.alpha, "target_power": self.target_power, "max_repeats": self.max_repeats,
                "search": self.search, "warnings": list(self.warnings), "min_typical_chi2": MIN_TYPICAL_CHI2,
                "devices": list(self.devices)})

    def summary(self) -> str:
        lines = [f"warning: {w}" for w in self.warnings]
        lines += [f"candidate effects (expected chi2 of a typical-size effect: testable at >= {MIN_TYPICAL_CHI2:g}, "
                  f"as diagnose rules; detected at power {self.target_power:g}, alpha = {self.alpha:g}; "
                  f"{len(self.devices)} device(s)):"]
        for c in self.candidates:
            amb = f", ambiguous with {', '.join(c.ambiguous_with)}" if c.ambiguous_with else ""
            state = (" -> detected" if c.detected else " -> testable, below the target power" if c.testable
                     else " -> not testable")
            lines.append(f"  {c.effect:<20} now: chi2 {c.expected_chi2:10.3g}, power {c.power:.2f}{amb}{state}")
            if c.detected:
                continue
            best = max(c.per_experiment, key=lambda g: (g.expected_chi2 - c.expected_chi2) / g.minutes)
            lines.append(f"  {'':<20} best per minute: {best.name} "
                         f"(+{(best.expected_chi2 - c.expected_chi2) / best.minutes:.3g} "
                         "chi2/min)")
            if c.recommended:
                what = " + ".join(f"{r.runs} x {r.experiment.name}" for r in c.recommended)
                lines.append(f"  {'':<20} add {what} ({c.minutes:.0f} min): chi2 {c.recommended_chi2:.3g}, power "
                             f"{c.recommended_power:.2f}")
            else:
                lines.append(f"  {'':<20} {c.reason}")
        s = self.scale_factor
        if s is None:
            return "\n".join(lines)
        mean = float(np.mean(s.stderr))
        ref = float(np.mean(s.seed000_stderr))
        lines += [f"scale factor in {s.budget_min:g} min (per device, LSB per deg/s, mean over the lot; point "
                  "noise at the data's output_sigma, neighbours sharing the bias wander):",
                  "  on the data given: " + _data_sf_text(s, self.devices),
                  f"  seed 000's 22 rates x {s.seed000_runs} run(s) ({s.seed000_minutes:.0f} min): stderr {ref:.4g}",
                  f"  design: rates {list(s.rates_dps)} x {s.rate_runs} run(s)"
                  + (f" + VCF at {list(s.vcf_rates_dps)} deg/s x {s.vcf_runs} run(s)" if s.vcf_runs else "")
                  + f" ({s.minutes:.0f} min): stderr {mean:.4g}, {s.ratio:.3g} x seed 000's"]
        return "\n".join(lines)


def _data_sf_text(s: ScaleFactorDesign, devices) -> str:
    """The scale factor on the data given, in identification's terms: its stderr where the data determine
    it, else that they do not, and why (identify's reason)."""
    undetermined = [(d, w) for d, w in zip(devices, s.data_not_determined) if w]
    ok = [k for k, w in enumerate(s.data_not_determined or ("",) * len(devices)) if not w]
    text = ""
    if ok:
        se, sf = np.mean([s.data_stderr[k] for k in ok]), np.mean([s.scale_factor[k] for k in ok])
        some = f", {len(ok)} of {len(devices)} devices" if undetermined else ""
        text = f"stderr {se:.4g} (SF {sf:.6g}{some})"
    if undetermined:
        d, why = undetermined[0]
        text += ("; " if text else "") + (f"SF not determined by the data on {len(undetermined)} of {len(devices)} "
                                          f"device(s), as identify rules (e.g. {d}: {why})")
    return text


@overload
def _finite(obj: dict) -> dict: ...


@overload
def _finite(obj: object) -> object: ...


def _finite(obj: object) -> object:
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj
