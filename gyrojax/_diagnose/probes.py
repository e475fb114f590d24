r"""Shape probes: generic terms, scored like the candidate effects, that say where an unexplained misfit lives.

The library of physical effects will never hold every effect a real device has. A probe is a small generic
basis of what a missing term could add to the predictions - a bias or a gain linear in the die temperature or
in the time since power-on, a gain per run, an odd cubic of the force path after the DAC or of the DAC itself,
an even bow, a gain that differs for positive and negative inputs - with its coefficient in physical units.
Each is scored from the baseline fit with the same score (Lagrange-multiplier) test as the effects: what the
fit's free parameters and run biases could already absorb is projected out, and

    S = r^T G' (G'^T G')^+ G'^T r ~ chi2(rank G')

is the chi2 the probe would remove, where G' is the probe's design (its effect on the standardised residuals
per unit coefficient) after the projection. Its share of the chi2 in excess of the degrees of freedom says
how much of the misfit has that shape, and the fitted coefficient G'^+ r says how large the missing term is.

A probe's design is computed from the fit alone (its predictions, scale factor and the data's coordinates),
so probes cost no compile and no refit.
"""

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import numpy as np

from .._identify import Fit
from .._numerics.stats import score_p_value


# Which sweep kinds a probe acts on, from what the kind reads (`AbstractSweep`'s class attributes), so that a
# new kind is probed by what it is, not by its name.
def rate_sweeps(kind) -> bool:
    """Read from the rate output, with a turn-on bias per run (rate table, static VCF)."""
    return kind.rate_output and kind.biased


def gain_sweeps(kind) -> bool:
    """The output scales with the gain of the rate path (rate table, static and dynamic VCF)."""
    return kind.rate_output


def gain_and_dac_sweeps(kind) -> bool:
    return kind.rate_output or kind.word_input


def rate_and_dac_sweeps(kind) -> bool:
    return rate_sweeps(kind) or kind.word_input


def unbiased_sweeps(kind) -> bool:
    """Read without a turn-on bias (dynamic VCF as a lock-in amplitude, the DAC sweep, bench readings)."""
    return not kind.biased


class AbstractProbe(eqx.Module):
    """A generic shape a missing term could add to the predictions.

    **Class attributes:** `name`, `coordinate` (the data column it runs along, or `"order"`, `"run"`),
    `shape` (in words), `unit` (of its coefficient), `sweeps` (a predicate on a sweep kind, an
    `AbstractSweep`: whether the probe acts on it).
    """

    name: ClassVar[str]
    coordinate: ClassVar[str]
    shape: ClassVar[str]
    unit: ClassVar[str]
    sweeps: ClassVar  # (AbstractSweep) -> bool

    def acts_on(self, fit: Fit, sweep: str) -> bool:
        """Whether the probe acts on the data's sweep `sweep`."""
        return sweep in fit.data.blocks and type(self).sweeps(fit.data.kind(sweep))

    @abc.abstractmethod
    def changes(self, fit: Fit, sweep: str) -> np.ndarray | None:
        """The change of the predictions of `sweep` per unit coefficient, shape (device, run, point, k) in the
        sweep's output unit; None when the probe does not act on this sweep or the data lack its
        coordinate."""


def _coordinate(block, field):
    values = getattr(block, field, None)
    if values is None:
        return None
    values = np.asarray(values, float)
    mask = np.asarray(block.mask)
    if not mask.any() or not np.all(np.isfinite(values[mask])):
        return None
    return np.where(mask, values, 0.0)


def _sf(fit):
    """Each device's scale factor, LSB per deg/s (device, 1, 1)."""
    return np.asarray(fit.scale_factor, float)[:, None, None]


def _full_scale_word(fit):
    """The full-scale rebalance word (LSB) of a closed-loop device, else None."""
    device = fit.model.device
    if device.excitation is None:
        return None
    return 2.0 ** (device.excitation.dac.word_bits - 1)


class _AbstractLinear(AbstractProbe):
    """A bias (deg/s of equivalent rate, through each device's scale factor) or a relative gain (ppm) linear
    in a coordinate of the data."""

    gain: ClassVar[bool]  # a gain (ppm of the prediction) rather than a bias (deg/s)
    field: ClassVar[str]  # the SweepArrays field of the coordinate
    per: ClassVar[float]  # coordinate units per unit of the coefficient
    origin: ClassVar[float | None]  # where the term is zero; None: the device's mean

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        c = _coordinate(fit.data.blocks[sweep], self.field)
        if c is None:
            return None
        origin = self.origin
        if origin is None:  # the device's mean of the coordinate (e.g. the drive frequency)
            mask = np.asarray(fit.data.blocks[sweep].mask)
            origin = np.sum(np.where(mask, c, 0.0), axis=(1, 2), keepdims=True) / np.maximum(
                mask.sum(axis=(1, 2), keepdims=True), 1)
        scale = np.asarray(fit.predictions[sweep]) * 1e-6 if self.gain else _sf(fit)
        return (scale * (c - origin) / self.per)[..., None]


class BiasVsTemperature(_AbstractLinear):
    name = "bias_vs_temperature"
    coordinate = "temperature_c"
    shape = "a bias linear in die temperature"
    unit = "(deg/s)/K"
    sweeps = rate_sweeps
    gain, field, per, origin = False, "temperatures", 1.0, 25.0


class GainVsTemperature(_AbstractLinear):
    name = "gain_vs_temperature"
    coordinate = "temperature_c"
    shape = "a gain linear in die temperature"
    unit = "ppm/K"
    sweeps = gain_sweeps
    gain, field, per, origin = True, "temperatures", 1.0, 25.0


class BiasVsTime(_AbstractLinear):
    name = "bias_vs_time"
    coordinate = "time_s"
    shape = "a bias linear in time since power-on"
    unit = "(deg/s)/h"
    sweeps = rate_sweeps
    gain, field, per, origin = False, "times", 3600.0, 0.0


class GainVsTime(_AbstractLinear):
    name = "gain_vs_time"
    coordinate = "time_s"
    shape = "a gain linear in time since power-on"
    unit = "ppm/h"
    sweeps = gain_sweeps
    gain, field, per, origin = True, "times", 3600.0, 0.0


class GainVsDriveFrequency(_AbstractLinear):
    name = "gain_vs_drive_frequency"
    coordinate = "drive_freq_hz"
    shape = "a gain linear in the drive frequency (beyond the model's own)"
    unit = "ppm/Hz"
    sweeps = rate_sweeps
    gain, field, per, origin = True, "drive_freqs", 1.0, None


class GainPerRun(AbstractProbe):
    name = "gain_per_run"
    coordinate = "run"
    shape = "a gain that changes from run to run"
    unit = "ppm"
    sweeps = gain_and_dac_sweeps

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        f = np.asarray(fit.predictions[sweep]) * 1e-6
        runs = f.shape[1]
        if runs < 2:
            return None
        return f[..., None] * np.eye(runs)[None, :, None, :]


class BiasPerRun(AbstractProbe):
    name = "bias_per_run"
    coordinate = "run"
    shape = "an offset that changes from run to run (sweeps read without a turn-on bias)"
    unit = "output unit"
    sweeps = unbiased_sweeps

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        mask = np.asarray(fit.data.blocks[sweep].mask)
        runs = mask.shape[1]
        if runs < 2:
            return None
        return np.broadcast_to(np.eye(runs)[None, :, None, :], mask.shape + (runs,)).astype(float)


class CubicAfterDac(AbstractProbe):
    """Closed loop: an odd cubic of the force path after the DAC (amplifier, electrodes) compresses the
    feedback force, so the loop raises the word: the rate output grows by +c (w/W)^3 W (W the full-scale
    word); the DAC sweep, read before it, does not move. Open loop: an odd cubic of the readout."""

    name = "cubic_after_dac"
    coordinate = "input"
    shape = "an odd cubic of the force path after the DAC (or of an open-loop readout), not seen by the DAC sweep"
    unit = "ppm of full scale"
    sweeps = rate_sweeps

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        f = np.asarray(fit.predictions[sweep])
        w = _full_scale_word(fit)
        if w is None:  # open loop: relative to the largest rate-table output of the device
            table = next((s for s in fit.predictions if fit.data.kind(s).rate_input), sweep)
            ref, mask = fit.predictions[table], fit.data.blocks[table].mask
            w = np.max(np.where(np.asarray(mask), np.abs(np.asarray(ref)), 0.0), axis=(1, 2), keepdims=True)
            w = np.where(w > 0, w, 1.0)
        return (f * (f / w) ** 2 * 1e-6)[..., None]


class CubicOfDac(AbstractProbe):
    """Closed loop: an odd cubic of the DAC's own transfer v = k (w + c w^3 / W^2): the DAC sweep reads it
    directly, and the loop answers it with the opposite sign, -c (w/W)^3 W, on the rate output."""

    name = "cubic_of_dac"
    coordinate = "input"
    shape = "an odd cubic of the DAC itself (rate output and DAC sweep, with opposite signs)"
    unit = "ppm of full scale"
    sweeps = rate_and_dac_sweeps

    def changes(self, fit, sweep):
        w = _full_scale_word(fit)
        if w is None or not self.acts_on(fit, sweep):
            return None
        f = np.asarray(fit.predictions[sweep])
        if fit.data.kind(sweep).word_input:
            words = np.asarray(fit.data.blocks[sweep].inputs)
            return (f * (words / w) ** 2 * 1e-6)[..., None]
        return (-f * (f / w) ** 2 * 1e-6)[..., None]


class EvenBow(AbstractProbe):
    name = "even_bow"
    coordinate = "input"
    shape = "an even bow in the input"
    unit = "ppm of full scale"
    sweeps = rate_sweeps

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        block = fit.data.blocks[sweep]
        mask = np.asarray(block.mask)
        x = np.asarray(block.inputs)
        f = np.asarray(fit.predictions[sweep])
        span = np.max(np.where(mask, np.abs(x), 0.0), axis=(1, 2), keepdims=True)
        top = np.max(np.where(mask, np.abs(f), 0.0), axis=(1, 2), keepdims=True)
        return (top * (x / np.where(span > 0, span, 1.0)) ** 2 * 1e-6)[..., None]


class SignGain(AbstractProbe):
    name = "sign_gain"
    coordinate = "input"
    shape = "a gain that differs for positive and negative inputs (K+ vs K-)"
    unit = "ppm"
    sweeps = rate_sweeps

    def changes(self, fit, sweep):
        if not self.acts_on(fit, sweep):
            return None
        x = np.asarray(fit.data.blocks[sweep].inputs)
        return (np.asarray(fit.predictions[sweep]) * (x > 0) * 1e-6)[..., None]


PROBES: tuple[AbstractProbe, ...] = (
    BiasVsTemperature(), GainVsTemperature(), BiasVsTime(), GainVsTime(), GainVsDriveFrequency(),
    GainPerRun(), BiasPerRun(), CubicAfterDac(), CubicOfDac(), EvenBow(), SignGain(),
)
"""The generic shapes every diagnosis scores beside the candidate effects."""


def standardised(fit, sweep, g):
    """A change of the predictions (device, run, point, k) as columns of the standardised residuals (what
    the data carry beyond the model per unit coefficient), with each run's bias projected out as the fit
    does for biased sweeps."""
    block = fit.data.blocks[sweep]
    mask = np.asarray(block.mask)[..., None]
    sig = np.asarray(block.sigmas)[..., None]
    g = np.where(mask, np.nan_to_num(np.asarray(g, float)), 0.0)
    if fit.data.kind(sweep).biased:
        w = np.where(mask, 1.0 / sig**2, 0.0)
        g = g - np.sum(w * g, axis=2, keepdims=True) / np.maximum(np.sum(w, axis=2, keepdims=True), 1e-300)
    return np.where(mask, g / sig, 0.0)


def design(fit, probe: AbstractProbe) -> np.ndarray:
    """The probe's columns in the fit's residual layout (device, residual, k): each sweep's (run, point)
    block in the order of `fit.data.sweeps`, then zeros for the prior rows."""
    n = len(fit.devices)
    parts, k = [], None
    for sweep in fit.data.sweeps:
        block = fit.data.blocks[sweep]
        rows = int(np.prod(np.shape(block.inputs)[1:]))
        g = probe.changes(fit, sweep)
        if g is None:
            parts.append(None)
            continue
        cols = standardised(fit, sweep, g)
        k = cols.shape[-1] if k is None else k
        parts.append(cols.reshape(n, rows, -1))
    total = np.asarray(fit.residual_vector).shape[1]
    if k is None:
        return np.zeros((n, total, 0))
    out = np.zeros((n, total, k))
    row = 0
    for sweep, part in zip(fit.data.sweeps, parts):
        rows = int(np.prod(np.shape(fit.data.blocks[sweep].inputs)[1:]))
        if part is not None:
            out[:, row:row + rows, :part.shape[-1]] = part
        row += rows
    return out


@dataclasses.dataclass(frozen=True)
class Projected:
    """A block of columns scored against a fit: its score S, degrees of freedom, p-value, fingerprint (the
    residual change it would explain, (device, residual)), fitted coefficients (device, k) and the largest
    eigenvalue of its projected information (summed over devices)."""

    statistic: float
    df: int
    p_value: float
    fingerprint: np.ndarray
    coefficients: np.ndarray
    information: float


# Directions of the projected columns kept by the score test: information above this share of the columns' own
# (before projection). Not a significance level: it separates a column that lies in the span up to round-off and
# the Jacobian's curvature (a library effect's own generic shape: ~1e-14 of its information left) from one that
# differs from the span on some rows the data barely measure (a cubic after the DAC against the DAC's INL, on a
# DAC sweep to a third of full scale: ~3e-4 left). Relative, so that a probe's unit does not decide it.
RELATIVE_RANK_TOL = 1e-10


def project_out(cols, against):
    """`cols` (rows, k) with the span of `against` (rows, m) removed. The span is taken from the SVD, keeping
    singular values above 1e-12 of the largest: a column at round-off (an effect term the data do not see) adds
    no direction, and cannot take part of the real columns' span with it (as an unpivoted QR's arbitrary
    direction there would)."""
    u = span_basis(against)
    return cols - u @ (u.T @ cols)


def span_basis(against):
    """An orthonormal basis (rows, r) of the span of `against` (rows, m), as `project_out` takes it."""
    if against.shape[1] == 0:
        return np.zeros((against.shape[0], 0))
    u, s, _ = np.linalg.svd(against, full_matrices=False)
    return u[:, s > 1e-12 * max(float(s[0]), 1e-300)]


class Beyond:
    """The scatter the residuals keep beyond a column block on the rows it touches, summed over devices: their
    chi2 beyond the absorbable span and its degrees of freedom (rows less their leverage), for
    `score_p_value`'s reading of the block's statistic against it."""

    def __init__(self):
        self.chi2, self.dof = 0.0, 0.0

    def add(self, cols, residual, u):
        touched = np.any(cols != 0, axis=1)
        if touched.any():
            rb = residual - u @ (u.T @ residual)
            self.chi2 += float(np.sum(rb[touched] ** 2))
            self.dof += float(np.sum(1.0 - np.sum(u[touched] ** 2, axis=1)))

    def p_value(self, stat, df):
        return score_p_value(stat, df, self.chi2 - stat, self.dof - df)


def score_columns(base, cols, residuals, *, rank_tol: float = 0.0,
                  relative_rank_tol: float = RELATIVE_RANK_TOL) -> Projected:
    """Score test of the columns `cols` (device, residual, k) against residuals (device, residual) after
    projecting out `base` (device, residual, m): the chi2 they would remove, and their fingerprint.

    A direction of the projected columns counts (one degree of freedom) when its information exceeds both
    `rank_tol` (absolute: for candidate effects, whose columns are per typical size, the chi2 a typical size
    would change) and `relative_rank_tol` times the columns' own largest information before projection."""
    stat, df, info = 0.0, 0, 0.0
    n, rows, k = cols.shape
    fingerprint = np.zeros((n, rows))
    coef = np.zeros((n, k))
    beyond = Beyond()
    for d in range(n):
        own = float(np.linalg.norm(cols[d], 2)) ** 2 if k else 0.0  # the columns' largest information
        floor = max(rank_tol, relative_rank_tol * own)
        u = span_basis(base[d])
        je = cols[d] - u @ (u.T @ cols[d])
        beyond.add(cols[d], residuals[d], u)
        evals, evecs = np.linalg.eigh(je.T @ je)
        info += max(float(evals[-1]), 0.0) if evals.size else 0.0
        keep = evals > floor
        if not keep.any():
            continue
        inv = (evecs[:, keep] / evals[keep]) @ evecs[:, keep].T
        s = je.T @ residuals[d]
        stat += float(s @ inv @ s)
        df += int(keep.sum())
        coef[d] = inv @ s
        fingerprint[d] = je @ coef[d]
    return Projected(stat, df, beyond.p_value(stat, df), fingerprint, coef, info)
