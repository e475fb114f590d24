"""Standardised residuals of a model against `FitData`, for one device, with the run biases projected out.

The turn-on bias of each run of a biased sweep (`AbstractSweep.biased`: rate table, static VCF) is a free
parameter that enters linearly, so it is eliminated exactly (variable projection): for any physical parameters
the best bias is the weighted mean of the run's raw residuals, and the residual that remains is

    r = (y - f - b_run) / sigma,   b_run = sum(w (y - f)) / sum(w),  w = 1 / sigma^2 on real points.

The projection does not depend on the parameters, so Jacobians of r are the projected Jacobians of f and
chi2, covariance and score tests are those of the full model with the biases free.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._data.arrays import SweepArrays
from .._gyroscope import Gyroscope
from .._simulate.tiers import Steady
from .._sweeps.rate_table import RateTable
from .._sweeps.steady import AbstractSettledSweep, steady_points
from .fitdata import FitData


SF_STEP_DPS = 1.0
"""deg/s: the scale factor at zero rate is the central difference of the rate output at +/- this rate (a secant
over 2 deg/s differs from the tangent by the curvature over it: ~1e-14 relative on the presets with every
effect at its typical size), settled in the same call as the data's steady points."""


def predict_block(gyro: Gyroscope, sweep: str, block: SweepArrays, tier=Steady()):
    """Noise-free, bias-free predictions of one device's sweep block, shape (run, point), and a flag of
    points that could not be evaluated (not settled, not finite)."""
    shape = block.inputs.shape
    if block.temperatures is None:
        raise ValueError(f"sweep {sweep!r}: the data carry no temperatures (a fit file of an early format); a "
                         "prediction needs each point's die temperature.")
    pred, bad = block.kind.predict(gyro, jnp.ravel(block.inputs), jnp.ravel(block.temperatures),
                                   None if block.times is None else jnp.ravel(block.times), tier)
    return jnp.reshape(pred, shape), jnp.reshape(bad & jnp.ravel(block.mask), shape)


def _steady(gyro, blocks, tier, sf_temperature=None):
    """The steady sweeps' points (and the scale factor's two points at `sf_temperature`, if given) in one
    call of the tier: the settled points per block, and the scale factor (LSB per deg/s) or None."""
    requests = [(b.kind, jnp.ravel(b.inputs), jnp.ravel(b.temperatures),
                 None if b.times is None else jnp.ravel(b.times)) for b in blocks.values()]
    return settle_with_scale_factor(gyro, requests, tier, sf_temperature)


def settle_with_scale_factor(gyro, requests, tier, sf_temperature=None):
    """`steady_points` of `requests` and, with `sf_temperature` (deg C), the zero-rate scale factor's two
    points in the same call: the settled points per request, and the scale factor (LSB per deg/s) or None."""
    requests = list(requests)
    if sf_temperature is not None:
        requests.append((RateTable(), jnp.asarray([-SF_STEP_DPS, SF_STEP_DPS]),
                         jnp.broadcast_to(jnp.asarray(sf_temperature, dtype=float), (2,)), None))
    settled = steady_points(gyro, requests, tier)
    if sf_temperature is None:
        return settled, None
    step = settled[-1].rate
    return settled[:-1], (step[1] - step[0]) / (2.0 * SF_STEP_DPS)


def run_biases(sweep: str, block: SweepArrays, pred):
    """Best bias per run (weighted mean of the raw residuals), shape (run,); zero for unbiased sweeps."""
    if not block.kind.biased:
        return jnp.zeros(block.inputs.shape[0])
    w = jnp.where(block.mask, 1.0 / block.fit_sigmas()**2, 0.0)
    raw = jnp.where(block.mask, block.outputs - pred, 0.0)
    return jnp.sum(w * raw, axis=-1) / jnp.maximum(jnp.sum(w, axis=-1), jnp.finfo(float).tiny)


def block_residuals(sweep: str, block: SweepArrays, pred):
    """Standardised residuals (run, point) after the run biases; zero on padding."""
    b = run_biases(sweep, block, pred)
    r = (block.outputs - pred - b[:, None]) / block.fit_sigmas()
    return jnp.where(block.mask, r, 0.0)


def device_residuals(gyro: Gyroscope, data: FitData, tier=Steady(), sf_temperature=None):
    """All standardised residuals of one device (data without the device axis), flattened in the order of
    `data.sweeps`, the number of points that did not settle, the predictions per sweep (run, point), and the
    zero-rate scale factor (LSB per deg/s) at die temperature `sf_temperature` (None when not given). The
    settled sweeps (steady and set-point kinds) and the scale factor's points settle in one call (one compiled
    settle)."""
    steady = {sweep: data.blocks[sweep] for sweep in data.sweeps
              if isinstance(data.kind(sweep), AbstractSettledSweep)}
    settled, sf = _steady(gyro, steady, tier, sf_temperature) if steady or sf_temperature is not None else ((), None)
    settled = dict(zip(steady, settled))
    parts, preds, failed = [], {}, jnp.zeros((), dtype=int)
    for sweep in data.sweeps:
        block, kind = data.blocks[sweep], data.kind(sweep)
        if sweep in settled and isinstance(kind, AbstractSettledSweep):
            pred, bad = kind.read(settled[sweep])
            pred, bad = jnp.reshape(pred, block.inputs.shape), bad & jnp.ravel(block.mask)
        else:
            pred, bad = predict_block(gyro, sweep, block, tier)
        parts.append(jnp.ravel(block_residuals(sweep, block, pred)))
        preds[sweep] = pred
        failed = failed + jnp.sum(bad)
    return jnp.concatenate(parts), failed, preds, sf


def num_biases(data: FitData):
    """Run biases per device (real runs of biased sweeps), shape (device,) (numpy: counted on the host)."""
    total = np.zeros(len(data.device_names()), dtype=int)
    for sweep in data.sweeps:
        if data.kind(sweep).biased:
            total = total + np.sum(np.any(np.asarray(data.blocks[sweep].mask), axis=-1), axis=-1)
    return total


def num_points(data: FitData):
    """Real points per device, shape (device,) (numpy)."""
    return sum(np.sum(np.asarray(b.mask), axis=(-2, -1)) for b in data.blocks.values())


def unbatch(tree):
    """Drop a leading axis of size 1 (a one-device slice)."""
    return jax.tree.map(lambda x: x[0], tree)
