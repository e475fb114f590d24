"""`MetricsReport`, what `metrics_report` returns, and its records: `SweepMetrics` per (device, run, sweep) with its
`RateLineMetrics` and `BandwidthMetrics`, `DeviceMetrics` per (device, sweep), and the `MetricsConventions`."""

from typing import Any, ClassVar

import equinox as eqx

from .._sweeps.registry import sweep_kind
from .._text import safe_name


def _na(value, spec: str, reason: str | None = None, unit: str = "") -> str:
    """`value` formatted with `spec` and followed by `unit`, or "n/a" (with the reason) when it is None."""
    if value is None:
        return "n/a" + (f" ({reason})" if reason else "")
    return format(value, spec) + unit


class RateLineMetrics(eqx.Module):
    """A sweep's straight line against the rate its input stands for (`rate_dps`: a `dac` sweep's word), its JSON
    keys `scale_factor_vs_rate`, `bias_vs_rate`, `nonlinearity_max_ppm_vs_rate`, `nonlinearity_rms_ppm_vs_rate`
    (None: not determined, or no measurement on the kind; the record's `not_applicable` says which)."""

    scale_factor: float | None
    bias: float | None
    nonlinearity_max_ppm: float | None
    nonlinearity_rms_ppm: float | None

    def to_json(self) -> dict[str, Any]:
        return {"scale_factor_vs_rate": self.scale_factor, "bias_vs_rate": self.bias,
                "nonlinearity_max_ppm_vs_rate": self.nonlinearity_max_ppm,
                "nonlinearity_rms_ppm_vs_rate": self.nonlinearity_rms_ppm}


class BandwidthMetrics(eqx.Module):
    """A dynamic sweep's rate bandwidth (`bandwidth_hz`), the phase there (`phase_deg_at_bandwidth`: None without a
    `phase_deg` on every point) and its low-frequency gain."""

    bandwidth_hz: float | None
    phase_deg_at_bandwidth: float | None
    low_frequency_gain: float | None

    def to_json(self) -> dict[str, Any]:
        return {"bandwidth_hz": self.bandwidth_hz, "phase_deg_at_bandwidth": self.phase_deg_at_bandwidth,
                "low_frequency_gain": self.low_frequency_gain}


class SweepMetrics(eqx.Module):
    """One (device, run, sweep) of `metrics_report` (a record of `MetricsReport.points`): the straight-line
    figures (None on a dynamic sweep), `vs_rate` where the kind is also fitted against `rate_dps` and the data
    give it, `bandwidth` on a dynamic sweep; `undetermined`: the keys of figures that apply to the kind but that
    the points did not give; `not_applicable`: the reason, by JSON key, for each figure that is None."""

    device: str
    run: int
    sweep: str
    n_points: int
    scale_factor: float | None
    bias: float | None
    nonlinearity_max_ppm: float | None
    nonlinearity_rms_ppm: float | None
    asymmetry_ppm: float | None
    vs_rate: RateLineMetrics | None
    bandwidth: BandwidthMetrics | None
    undetermined: tuple[str, ...]
    not_applicable: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        """The record's JSON (docs/cli.md): the `vs_rate` and `bandwidth` figures under their own keys."""
        return {"device": self.device, "run": self.run, "sweep": self.sweep, "n_points": self.n_points,
                "scale_factor": self.scale_factor, "bias": self.bias,
                "nonlinearity_max_ppm": self.nonlinearity_max_ppm, "nonlinearity_rms_ppm": self.nonlinearity_rms_ppm,
                "asymmetry_ppm": self.asymmetry_ppm,
                **(self.vs_rate.to_json() if self.vs_rate is not None else {}),
                **(self.bandwidth.to_json() if self.bandwidth is not None else {}),
                "undetermined": list(self.undetermined), "not_applicable": dict(self.not_applicable)}


class DeviceMetrics(eqx.Module):
    """One (device, sweep) with a straight-line fit (a record of `MetricsReport.devices`): its runs, their mean
    scale factor and repeatability (None with a single run, or a mean scale factor of 0), and the reason, by JSON
    key, for each figure that is None."""

    device: str
    sweep: str
    n_runs: int
    scale_factor_mean: float | None
    repeatability_ppm: float | None
    not_applicable: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        return {"device": self.device, "sweep": self.sweep, "n_runs": self.n_runs,
                "scale_factor_mean": self.scale_factor_mean, "repeatability_ppm": self.repeatability_ppm,
                "not_applicable": dict(self.not_applicable)}


class MetricsConventions(eqx.Module):
    """The choices behind a metrics report: the nonlinearity's full scale, weighting, the asymmetry model, the
    repeatability's ddof, the RMS convention, and the unit of `scale_factor` per sweep kind."""

    full_scale: str
    weighted: bool
    asymmetry: str
    repeatability_ddof: int
    nonlinearity_rms: str
    scale_factor_units: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        return {"full_scale": self.full_scale, "weighted": self.weighted, "asymmetry": self.asymmetry,
                "repeatability_ddof": self.repeatability_ddof, "nonlinearity_rms": self.nonlinearity_rms,
                "scale_factor_units": dict(self.scale_factor_units)}


class MetricsReport(eqx.Module):
    """The metrics report of a table (what `metrics_report` returns): `points` (a `SweepMetrics` per device, run
    and sweep, in order of first appearance), `devices` (a `DeviceMetrics` per device and sweep with a straight-line
    fit) and `conventions`; its JSON (`to_json()`, the `metrics` JSON of docs/cli.md) and a `summary()`."""

    points: tuple[SweepMetrics, ...]
    devices: tuple[DeviceMetrics, ...]
    conventions: MetricsConventions

    kind: ClassVar[str] = "metrics"

    def to_json(self) -> dict[str, Any]:
        return {"points": [p.to_json() for p in self.points], "devices": [d.to_json() for d in self.devices],
                "conventions": self.conventions.to_json()}

    def summary(self) -> str:
        """Per device, run and sweep its scale factor and nonlinearity (a bandwidth for a dynamic sweep), "n/a"
        with the reason where there is none; per device with several runs its repeatability. Device names are
        shown with their control characters escaped."""
        lines = []
        for p in self.points:
            why = p.not_applicable
            head = f"{safe_name(p.device):>16} run {p.run:<3} {p.sweep:<11}"
            kind = sweep_kind(p.sweep)
            if not kind.straight_line:
                bandwidth = p.bandwidth.bandwidth_hz if p.bandwidth is not None else None
                lines.append(f"{head} bandwidth {_na(bandwidth, '.4g', why.get('bandwidth_hz'), ' Hz')}")
                continue
            unit = kind.scale_factor_unit
            sf = _na(p.scale_factor, ".6g", why.get("scale_factor"), f" {unit}" if unit else "")
            if p.nonlinearity_max_ppm is None:
                lines.append(f"{head} SF {sf}  NL n/a ({why.get('nonlinearity_max_ppm', 'not determined')})")
            else:
                lines.append(f"{head} SF {sf}  NL max {p.nonlinearity_max_ppm:.1f} ppm  "
                             f"rms {_na(p.nonlinearity_rms_ppm, '.1f', why.get('nonlinearity_rms_ppm'), ' ppm')}")
        for d in self.devices:
            if d.n_runs > 1:
                rep = _na(d.repeatability_ppm, ".2f", d.not_applicable.get("repeatability_ppm"), " ppm")
                lines.append(f"{safe_name(d.device):>16} {d.sweep:<11} repeatability {rep} over {d.n_runs} runs")
        return "\n".join(lines)

    def undetermined(self) -> int:
        """How many sweeps with a straight-line fit gave no figure that applies to their kind."""
        return sum(1 for p in self.points if sweep_kind(p.sweep).straight_line and p.undetermined)
