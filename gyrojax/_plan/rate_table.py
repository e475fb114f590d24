"""How many devices of a lot to put on the rate table (`gyrojax.rate_table_plan`): the others' scale factors are
then predicted by a population fit (`gyrojax.PopulationSolve`), and the width of their prediction intervals falls
with the number K of rate-tabled devices.

With the lot's relative spread s of what the rate table alone sees (for the open-loop batch calibration the rate
path G K_yi Ag a, the random effect Ag; `PopulationFit.parameters[j].relative_spread` of a previous lot, or an
assumption) and a predicted device's own relative uncertainty u from the sweeps it does have, the prediction from
K devices that fix their own rate path precisely is the lot mean, off the device's value by its draw from the lot
and the mean's error: relative variance s^2 (1 + 1/K) + u^2, with s^2 known from K - 1 degrees of freedom, so
the 95 % interval's half-width is t_{K-1} sqrt(s^2 (1 + 1/K) + u^2) (the population fit's own interval, see
docs/population.md). K = 1 gives no interval (a spread needs two devices).

Which devices: the prediction assumes the rate-tabled devices are a random sample of the lot (every device of
the lot is drawn from one distribution); take them at random over the lot, not the first ones off a line nor one
region of a wafer, whose rate path may differ from the lot's.
"""

import json
import math
from typing import ClassVar

import equinox as eqx
import numpy as np

from .._identify.population import t_quantile


class RateTablePlan(eqx.Module):
    """The result of `gyrojax.rate_table_plan`: per number of rate-tabled devices `counts`, the predicted
    devices' expected 95 % half-width (`halfwidth`, relative) and its parts; `recommended` (the fewest devices that
    reach `target`, or None where none of `counts` does)."""

    counts: np.ndarray
    halfwidth: np.ndarray
    dof: np.ndarray
    spread: float
    own: float
    target: float
    devices: int
    recommended: int | None

    kind: ClassVar[str] = "rate_table_plan"

    def to_json(self) -> dict:
        """The plan as JSON (what `gyrojax plan --rate-table-target ... --json` writes)."""
        return self.report()

    def report(self) -> dict:
        return {"spread": self.spread, "own": self.own, "target": self.target, "devices": self.devices,
                "recommended": self.recommended,
                "rows": [{"rate_devices": int(k), "halfwidth_95": float(h), "dof": float(d)}
                         for k, h, d in zip(self.counts, self.halfwidth, self.dof)]}

    def summary(self) -> str:
        lines = [f"rate-table devices for a 95 % prediction interval of +/- {self.target * 100:.3g} % (lot spread "
                 f"{self.spread * 100:.3g} %, own uncertainty {self.own * 100:.3g} %, {self.devices} devices):"]
        shown = {2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, self.recommended}
        for k, h in zip(self.counts, self.halfwidth):
            if int(k) not in shown:
                continue
            mark = "  <- fewest that reach the target" if k == self.recommended else ""
            lines.append(f"  {int(k):4d} rate-tabled: the other {self.devices - int(k)} predicted +/- {h * 100:.3g} %"
                         f"{mark}")
        if self.recommended is None:
            floor = Z95_FLOOR * math.sqrt(self.spread**2 + self.own**2)
            lines.append(f"  no count reaches it: even all-but-one rate-tabled leave +/- {floor * 100:.3g} % (the "
                         "lot spread itself); measure the rate path per device, or lower the spread")
        lines.append("  take the rate-tabled devices at random over the lot (the prediction assumes they are a random "
                     "sample of it)")
        return "\n".join(lines)


Z95_FLOOR = 1.959963984540054
"""The normal 95 % point: the half-width with the lot spread known exactly."""


def rate_table_plan(spread: float, target: float, *, devices: int = 64, own: float = 0.0) -> RateTablePlan:
    """How many of `devices` to put on the rate table so that the others' predicted scale factors have 95 %
    intervals within +/- `target` (relative, e.g. 0.002 for 0.2 %).

    **Arguments:**

    - `spread`: the lot's relative spread (1 sigma) of what only the rate table sees (see the module docstring).
    - `target`: the wanted half-width of the predictions' 95 % intervals, relative.
    - `devices`: the lot size.
    - `own`: a predicted device's relative standard uncertainty from its own sweeps (default 0).

    **Returns:** a `RateTablePlan` (counts 2 .. devices - 1).
    """
    for name, value in (("spread", spread), ("target", target)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"rate_table_plan: {name} must be a positive relative number (e.g. 0.001 for 0.1 %), "
                             f"got {value!r}.")
    if not (isinstance(own, (int, float)) and math.isfinite(own) and own >= 0):
        raise ValueError(f"rate_table_plan: own must be >= 0 (relative), got {own!r}.")
    if not (isinstance(devices, int) and devices >= 3):
        raise ValueError(f"rate_table_plan: devices must be an integer >= 3 (two rate-tabled and one predicted), got "
                         f"{devices!r}.")
    counts = np.arange(2, devices)
    dof = (counts - 1).astype(float)
    half = t_quantile(0.975, dof) * np.sqrt(spread**2 * (1.0 + 1.0 / counts) + own**2)
    ok = np.flatnonzero(half <= target)
    return RateTablePlan(counts=counts, halfwidth=half, dof=dof, spread=float(spread), own=float(own),
                         target=float(target), devices=devices, recommended=int(counts[ok[0]]) if ok.size else None)


def lot_spread_from_report(path: str, name: str | None = None) -> tuple[float, int, str]:
    """The lot's relative spread of a random parameter from an identify report with a population section
    (`gyrojax identify DATA --population ... --json FILE`): (spread, number of devices, parameter name). `name`
    picks the parameter where the fit had several random ones (default: the only one). Raises `ValueError`
    naming the file and what is missing."""
    try:
        with open(path, encoding="utf-8") as f:
            report = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a readable JSON report ({e})") from None
    pop = report.get("population") if isinstance(report, dict) else None
    if not isinstance(pop, dict) or not pop.get("parameters"):
        raise ValueError(f"{path}: no 'population' section with parameters: write it with `gyrojax identify DATA "
                         "--population NAME --json FILE`")
    params = {p.get("name"): p for p in pop["parameters"]}
    if name is None:
        if len(params) != 1:
            raise ValueError(f"{path}: the population has several random parameters ({', '.join(params)}); name the "
                             "one only the rate table sees (--random NAME)")
        (name,) = params
    if name not in params:
        raise ValueError(f"{path}: no random parameter {name!r} in its population (it has {', '.join(params)})")
    spread = params[name].get("relative_spread")
    if not (isinstance(spread, (int, float)) and math.isfinite(spread) and spread > 0):
        raise ValueError(f"{path}: the population's {name} has no relative spread (a parameter on a log scale has "
                         f"one; got {spread!r})")
    if not params[name].get("spread_resolved", True):
        raise ValueError(f"{path}: the lot spread of {name} is not resolved from zero in that fit: a plan on it "
                         "would rest on noise; fit a lot with more devices first, or give --lot-spread")
    return float(spread), len(pop.get("devices") or ()), str(name)
