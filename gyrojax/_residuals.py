"""Standardised residuals of a model against `FitData`, for one device, with the run biases projected out.

The turn-on bias of each run of a biased sweep (rate table, static VCF) is a free parameter that enters
linearly, so it is eliminated exactly (variable projection): for any physical parameters the best bias is
the weighted mean of the run's raw residuals, and the residual that remains is

    r = (y - f - b_run) / sigma,   b_run = sum(w (y - f)) / sum(w),  w = 1 / sigma^2 on real points.

The projection does not depend on the parameters, so Jacobians of r are the projected Jacobians of f and
chi2, covariance and score tests are those of the full model with the biases free.
"""

import jax
import jax.numpy as jnp

from ._fitdata import BIASED_SWEEPS, FitData, SweepBlock
from ._gyroscope import Gyroscope
from ._observe import dac_points, rate_table_points, vcf_dynamic_points, vcf_static_points
from ._simulate.tiers import Steady
from ._solution import RESULTS


def predict_block(gyro: Gyroscope, sweep: str, block: SweepBlock, tier=Steady()):
    """Noise-free, bias-free predictions of one device's sweep block, shape (run, point), and a flag of
    points that did not settle."""
    shape = block.inputs.shape
    x, temps = jnp.ravel(block.inputs), jnp.ravel(block.temperatures)
    times = None if block.times is None else jnp.ravel(block.times)
    if sweep == "rate_table":
        s = rate_table_points(gyro, x, temps, tier, times=times)
        pred, bad = s.rate, s.result != RESULTS.successful
    elif sweep == "vcf_static":
        s = vcf_static_points(gyro, x, temps, tier, times=times)
        pred, bad = s.rate, s.result != RESULTS.successful
    elif sweep == "vcf_dynamic":
        # Each point at its own die temperature, as measured and simulated: one mean temperature per sweep
        # left ~1e-5 of amplitude, 10x the noise.
        pred, _ = vcf_dynamic_points(gyro, x, temps)
        bad = ~jnp.isfinite(pred)
    elif sweep == "dac":
        pred = dac_points(gyro, x)
        bad = ~jnp.isfinite(pred)
    else:
        raise ValueError(f"unknown sweep {sweep!r}.")
    bad = bad & jnp.ravel(block.mask)
    return jnp.reshape(pred, shape), jnp.reshape(bad, shape)


def run_biases(sweep: str, block: SweepBlock, pred):
    """Best bias per run (weighted mean of the raw residuals), shape (run,); zero for unbiased sweeps."""
    if sweep not in BIASED_SWEEPS:
        return jnp.zeros(block.inputs.shape[0])
    w = jnp.where(block.mask, 1.0 / block.sigmas**2, 0.0)
    raw = jnp.where(block.mask, block.outputs - pred, 0.0)
    return jnp.sum(w * raw, axis=-1) / jnp.maximum(jnp.sum(w, axis=-1), jnp.finfo(float).tiny)


def block_residuals(sweep: str, block: SweepBlock, pred):
    """Standardised residuals (run, point) after the run biases; zero on padding."""
    b = run_biases(sweep, block, pred)
    r = (block.outputs - pred - b[:, None]) / block.sigmas
    return jnp.where(block.mask, r, 0.0)


def device_residuals(gyro: Gyroscope, data: FitData, tier=Steady()):
    """All standardised residuals of one device (data without the device axis), flattened in the order of
    `data.sweeps`, the number of points that did not settle, and the predictions per sweep (run, point)."""
    parts, preds, failed = [], {}, jnp.zeros((), dtype=int)
    for sweep in data.sweeps:
        block = data.blocks[sweep]
        pred, bad = predict_block(gyro, sweep, block, tier)
        parts.append(jnp.ravel(block_residuals(sweep, block, pred)))
        preds[sweep] = pred
        failed = failed + jnp.sum(bad)
    return jnp.concatenate(parts), failed, preds


def num_biases(data: FitData):
    """Run biases per device (real runs of biased sweeps), shape (device,)."""
    total = 0
    for sweep in data.sweeps:
        if sweep in BIASED_SWEEPS:
            total = total + jnp.sum(jnp.any(data.blocks[sweep].mask, axis=-1), axis=-1)
    return jnp.asarray(total)


def num_points(data: FitData):
    """Real points per device, shape (device,)."""
    return sum(jnp.sum(b.mask, axis=(-2, -1)) for b in data.blocks.values())


def unbatch(tree):
    """Drop a leading axis of size 1 (a one-device slice)."""
    return jax.tree.map(lambda x: x[0], tree)
