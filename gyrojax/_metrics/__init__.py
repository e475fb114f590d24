"""Scale-factor metrics: scale factor, bias, nonlinearity, asymmetry, repeatability and rate bandwidth.

Every function takes NumPy or JAX arrays whose *last* axis runs over the points of one sweep; leading axes are
batch axes, so the padded `(device, run, point)` arrays of [`gyrojax.io.SweepArrays`][] go straight in with their
`mask`. They are pure functions written once for both array libraries: given any JAX array (or tracer) they
run in `jax.numpy` and are safe under `jit`, `vmap` and `grad` (masked entries never reach a division or a log);
given only NumPy arrays they run in NumPy, which spares a host-side report the seconds of first-call
compilation. Results come back in the library that went in.

**Too few points.** A sweep with some but too few valid points is an error: a [`gyrojax.DataError`][] when the
mask is concrete, an `eqx.error_if` runtime error under `jit`. A *fully* masked sweep is padding and gives NaN.
[`gyrojax.metrics.metrics_report`][] checks the counts first and names the offending device, run and sweep.

**Sources.** Terms follow IEEE Std 528 (inertial sensor terminology) and the rate-table practice of
IEEE Std 952-1997 (single-axis FOG test procedure), which seed 000 (Ding & Zhou, Micromachines 16, 851, 2025)
follows for its closed-loop MEMS gyro. Where a definition leaves a choice open (which "full scale", which
standard deviation), the choice is gyrojax's and is written down here. (The wording of the standards is from
memory of their definitions, not checked against their text here.)

One concept per file: `arrays.py` (what every metric shares), `scale_factor.py`, `asymmetry.py`,
`repeatability.py`, `bandwidth.py`, `report.py` (`metrics_report` over a table) and `result.py` (`MetricsReport`,
what it returns, and its records).
"""

from .asymmetry import asymmetry as asymmetry
from .bandwidth import RateBandwidth as RateBandwidth, rate_bandwidth as rate_bandwidth
from .repeatability import repeatability as repeatability
from .report import metrics_report as metrics_report, scale_factor_units as scale_factor_units
from .result import (
    BandwidthMetrics as BandwidthMetrics,
    DeviceMetrics as DeviceMetrics,
    MetricsConventions as MetricsConventions,
    MetricsReport as MetricsReport,
    RateLineMetrics as RateLineMetrics,
    SweepMetrics as SweepMetrics,
)
from .scale_factor import (
    FULL_SCALE_CONVENTIONS as FULL_SCALE_CONVENTIONS,
    MIN_POINTS_LINEAR as MIN_POINTS_LINEAR,
    ScaleFactorFit as ScaleFactorFit,
    fit_scale_factor as fit_scale_factor,
)
