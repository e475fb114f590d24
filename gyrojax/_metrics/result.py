"""`MetricsReport`, what `metrics_report` returns: the report's dict with a summary for a terminal."""

from typing import Any, ClassVar

from .._sweeps.registry import sweep_kind
from .._text import safe_name


def _na(value, spec: str, reason: str | None = None, unit: str = "") -> str:
    """`value` formatted with `spec` and followed by `unit`, or "n/a" (with the reason) when it is None."""
    if value is None:
        return "n/a" + (f" ({reason})" if reason else "")
    return format(value, spec) + unit


class MetricsReport(dict[str, Any]):
    """The metrics report (keys in `metrics_report`): a dict, so that it is read as one (`report["points"]`) and is
    its own JSON form, with the `kind`, `to_json()` and `summary()` of every gyrojax result."""

    kind: ClassVar[str] = "metrics"

    def to_json(self) -> dict[str, Any]:
        return dict(self)

    def summary(self) -> str:
        """Per device, run and sweep its scale factor and nonlinearity (a bandwidth for a dynamic sweep), "n/a"
        with the reason where there is none; per device with several runs its repeatability. Device names are
        shown with their control characters escaped."""
        lines = []
        for p in self["points"]:
            why = p.get("not_applicable", {})
            head = f"{safe_name(p['device']):>16} run {p['run']:<3} {p['sweep']:<11}"
            kind = sweep_kind(p["sweep"])
            if not kind.straight_line:
                lines.append(f"{head} bandwidth {_na(p.get('bandwidth_hz'), '.4g', why.get('bandwidth_hz'), ' Hz')}")
                continue
            unit = kind.scale_factor_unit
            sf = _na(p["scale_factor"], ".6g", why.get("scale_factor"), f" {unit}" if unit else "")
            if p["nonlinearity_max_ppm"] is None:
                lines.append(f"{head} SF {sf}  NL n/a ({why.get('nonlinearity_max_ppm', 'not determined')})")
            else:
                lines.append(f"{head} SF {sf}  NL max {p['nonlinearity_max_ppm']:.1f} ppm  "
                             f"rms {_na(p['nonlinearity_rms_ppm'], '.1f', why.get('nonlinearity_rms_ppm'), ' ppm')}")
        for d in self["devices"]:
            if d["n_runs"] > 1:
                rep = _na(d["repeatability_ppm"], ".2f", d.get("not_applicable", {}).get("repeatability_ppm"), " ppm")
                lines.append(f"{safe_name(d['device']):>16} {d['sweep']:<11} repeatability {rep} over {d['n_runs']} "
                             "runs")
        return "\n".join(lines)

    def undetermined(self) -> int:
        """How many sweeps with a straight-line fit gave no figure that applies to their kind."""
        return sum(1 for p in self["points"] if sweep_kind(p["sweep"]).straight_line and p["undetermined"])
