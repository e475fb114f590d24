"""The results of a population fit: `PopulationParameter` (the lot distribution of one quantity) and
`PopulationFit` (the lot, its devices' shrunken estimates and scale factors with their intervals)."""

import math
from typing import Any, ClassVar

import equinox as eqx
import numpy as np

from ..fit import Fit
from .intervals import t_quantile


class PopulationParameter(eqx.Module):
    """The lot distribution of one quantity: `mean` (for a `"log"` parameter the geometric mean, exp(mu)) with
    `mean_stderr`, `spread` (the lot's 1-sigma spread in the quantity's unit; for a `"log"` parameter mean x s)
    with `spread_stderr`, `relative_spread` (s for a `"log"` parameter) and whether the data resolve the spread
    from zero (`resolved`: spread > 2 spread_stderr)."""

    name: str
    unit: str
    mean: float
    mean_stderr: float
    spread: float
    spread_stderr: float
    relative_spread: float
    resolved: bool

    def report(self) -> dict:
        return {"name": self.name, "unit": self.unit, "mean": self.mean, "mean_stderr": self.mean_stderr,
                "spread": self.spread, "spread_stderr": self.spread_stderr,
                "relative_spread": self.relative_spread, "spread_resolved": self.resolved}


class PopulationFit(eqx.Module):
    """The solution of `identify(..., lot_solve=PopulationSolve(...))`.

    **Fields:**

    - `fit`: the last fit of the lot, every device conditioned on the population (a Gaussian prior at the lot
      mean and spread on its random parameters): its values are the shrunken estimates.
    - `random`: the random parameters' names; `parameters`: their `PopulationParameter`s; `scale_factor`: the
      lot distribution of the zero-rate scale factor (moments of the devices' posteriors, see `population_fit`).
    - `estimates`, `estimates_stderr`: (device, random) each device's shrunken estimate and its standard error
      (the posterior's, plus the uncertainty of the lot mean and spread).
    - `sf`, `sf_stderr`: (device,) each device's scale factor (LSB per deg/s) and its standard error likewise;
      for a device whose data miss the sweeps that fix it, a prediction from the lot.
    - `sf_dof`: (device,) the degrees of freedom of each scale factor's interval (Student-t; infinite where the
      lot spread does not enter, see `population_fit`).
    - `missing`: per device the sweeps of the data it has no points in.
    - `hyper`, `hyper_covariance`: (mu, log s) in the fit's coordinates and their covariance.
    - `converged`, `refits`, `warnings` (sentences: non-convergence with what to try, unresolved spreads).
    """

    fit: Fit
    random: tuple[str, ...]
    parameters: tuple[PopulationParameter, ...]
    scale_factor: PopulationParameter
    estimates: np.ndarray
    estimates_stderr: np.ndarray
    sf: np.ndarray
    sf_stderr: np.ndarray
    sf_dof: np.ndarray
    missing: tuple[tuple[str, ...], ...]
    hyper: np.ndarray
    hyper_covariance: np.ndarray
    converged: bool
    refits: int
    warnings: tuple[str, ...]

    kind: ClassVar[str] = "population_fit"

    @property
    def devices(self) -> tuple[str, ...]:
        return self.fit.devices

    def interval(self, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) per device: the scale factor's `level` interval (a prediction interval where sweeps are
        missing), Student-t with `sf_dof` degrees of freedom."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1), got {level!r}.")
        t = t_quantile(0.5 + level / 2.0, self.sf_dof)
        return self.sf - t * self.sf_stderr, self.sf + t * self.sf_stderr

    @property
    def exit_status(self) -> int:
        """The fit's exit status; 1 (a failed computation) where the population did not converge."""
        return self.fit.exit_status if self.converged else max(self.fit.exit_status, 1)

    def report(self) -> dict:
        """The JSON `population` section (keys in docs/population.md)."""
        low, high = self.interval()
        devices = []
        for i, d in enumerate(self.fit.devices):
            devices.append({
                "device": d, "missing_sweeps": list(self.missing[i]),
                "estimates": {nm: {"value": _num(self.estimates[i, k]), "stderr": _num(self.estimates_stderr[i, k])}
                              for k, nm in enumerate(self.random)},
                "scale_factor_lsb_per_dps": _num(self.sf[i]), "scale_factor_stderr": _num(self.sf_stderr[i]),
                "scale_factor_interval_95": [_num(low[i]), _num(high[i])], "interval_dof": _num(self.sf_dof[i]),
                "prediction": bool(self.missing[i]),
            })
        return {"random": list(self.random), "parameters": [p.report() for p in self.parameters],
                "scale_factor": self.scale_factor.report(), "devices": devices, "converged": self.converged,
                "refits": self.refits, "warnings": list(self.warnings)}

    def to_json(self) -> dict[str, Any]:
        """The fit's JSON (`Fit.to_json()`) with the `population` section (`report()`)."""
        return {**self.fit.to_json(), "population": self.report()}

    def summary(self) -> str:
        lines = [f"population fit of {len(self.fit.devices)} device(s), random: {', '.join(self.random)} "
                 f"({'converged' if self.converged else 'NOT CONVERGED'} after {self.refits} refit(s))"]
        for p in self.parameters + (self.scale_factor,):
            rel = f" ({p.relative_spread * 100:.3g} %)" if math.isfinite(p.relative_spread) else ""
            lines.append(f"  lot {p.name}: mean {p.mean:.6g} +/- {p.mean_stderr:.2g}, spread {p.spread:.3g}{rel} "
                         f"+/- {p.spread_stderr:.2g} {p.unit}" + ("" if p.resolved else " (not resolved from zero)"))
        low, high = self.interval()
        for i, d in enumerate(self.fit.devices):
            what = f"predicted (no {', '.join(self.missing[i])})" if self.missing[i] else "shrunken"
            dof = f" (t, {self.sf_dof[i]:.3g} dof)" if self.sf_dof[i] < 1e6 else ""
            if not math.isfinite(self.sf[i]):
                lines.append(f"  {d}: SF not determined, {what} (see the warning)")
                continue
            lines.append(f"  {d}: SF {self.sf[i]:.6f} +/- {self.sf_stderr[i]:.2g} LSB/(deg/s) {what}, 95 % "
                         f"[{low[i]:.6f}, {high[i]:.6f}]{dof}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None
