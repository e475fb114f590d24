"""Figures of merit of a rate sensor: the scale factor fit with its nonlinearity (`fit_scale_factor`,
`FULL_SCALE_CONVENTIONS`), asymmetry, repeatability, rate bandwidth, the whole-lot `metrics_report` (a
`MetricsReport`), and the nonlinearity budget over a device's effects.

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._metrics import (
    FULL_SCALE_CONVENTIONS as FULL_SCALE_CONVENTIONS,
    BandwidthMetrics as BandwidthMetrics,
    DeviceMetrics as DeviceMetrics,
    MetricsConventions as MetricsConventions,
    MetricsReport as MetricsReport,
    RateBandwidth as RateBandwidth,
    RateLineMetrics as RateLineMetrics,
    ScaleFactorFit as ScaleFactorFit,
    SweepMetrics as SweepMetrics,
    asymmetry as asymmetry,
    fit_scale_factor as fit_scale_factor,
    metrics_report as metrics_report,
    rate_bandwidth as rate_bandwidth,
    repeatability as repeatability,
)
from ._sensitivity import (
    EffectContribution as EffectContribution,
    NonlinearityBudget as NonlinearityBudget,
    nonlinearity_budget as nonlinearity_budget,
)


__all__ = [
    "BandwidthMetrics",
    "DeviceMetrics",
    "EffectContribution",
    "FULL_SCALE_CONVENTIONS",
    "MetricsConventions",
    "MetricsReport",
    "NonlinearityBudget",
    "RateBandwidth",
    "RateLineMetrics",
    "ScaleFactorFit",
    "SweepMetrics",
    "asymmetry",
    "fit_scale_factor",
    "metrics_report",
    "nonlinearity_budget",
    "rate_bandwidth",
    "repeatability",
]
