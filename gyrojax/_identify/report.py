"""What `gyrojax identify` reports: a `Fit` with where the model fails (`fit_report`, `IdentifyReport`)."""

from typing import Any, ClassVar

import equinox as eqx

from . import Fit, PopulationFit


def fit_report(fit: Fit) -> dict:
    """The identify report: `Fit.to_json()` (its keys documented there) and `compare`, where the model fails
    (`gyrojax.compare`)."""
    from .._diagnose.compare import compare

    return {**fit.to_json(), "compare": compare(fit).to_json()}


class IdentifyReport(eqx.Module):
    """What `gyrojax identify` prints and writes: the fit, where the model fails (`gyrojax.compare`), and the
    population fit where there is one (its JSON `population` section)."""

    fit: Fit
    population: PopulationFit | None = None

    kind: ClassVar[str] = "identify"

    def to_json(self) -> dict[str, Any]:
        report = fit_report(self.fit)
        if self.population is not None:
            report["population"] = self.population.report()
        return report

    def summary(self) -> str:
        from .._diagnose.compare import compare

        parts = [self.fit.summary(), compare(self.fit).summary()]
        if self.population is not None:
            parts.append(self.population.summary())
        return "\n".join(parts)
