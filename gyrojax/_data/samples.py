"""Raw sample streams -> settled points: the mean of a point and its batch-means standard error."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from jaxtyping import ArrayLike, Float

from .._sweeps.registry import sweep_kind
from .cells import DataError, Where, parse_dac_word, parse_float, parse_int, parse_str, parse_sweep


def aggregate_samples(device: str, run: int, sweep: str, input: Any, samples: Float[ArrayLike, " sample"], *,
                      sample_rate_hz: float, discard_s: float = 0.0, n_batches: int = 20) -> dict[str, Any]:
    """Reduce one raw output stream of one settled point to a row of the tidy table.

    The mean is over every sample left after the settling time is discarded. Its standard error is estimated by
    **batch means**: the kept samples are cut into `n_batches` consecutive batches of equal length
    m = N // n_batches (a remainder of fewer than `n_batches` samples, at the end, counts in the mean but not in
    the error estimate), and

        output_sigma = std(batch means, ddof=1) / sqrt(n_batches).

    Why not std(samples)/sqrt(N): gyro output noise is correlated (loop filters, 1/f, quantization
    shaping), and the naive formula then understates the error, by sqrt((1+phi)/(1-phi)) for AR(1) noise with
    coefficient phi (6x for phi = 0.95). Batch means are unbiased for any noise whose correlation time is short
    compared with a batch (T / n_batches); for white noise they agree with the naive formula on average, with a
    relative scatter of about 1/sqrt(2 (n_batches - 1)) (16% for 20 batches). The batch-means variance is the
    ordinary variance of adjacent block averages; for white noise it equals the Allan variance at
    tau = T / n_batches. For flicker noise no standard error of a mean exists; the estimate then describes the
    noise at the batch time scale, and a longer record will not shrink it as 1/sqrt(T).

    **Arguments:**

    - `device`, `run`, `sweep`, `input`: the point's identity, as in the table (`input` of a `dac` sweep may be
      an integer or a hex word).
    - `samples`: 1-D array of output samples, in time order, all finite.
    - `sample_rate_hz`: sampling rate.
    - `discard_s`: settling time at the start to drop; ceil(discard_s * sample_rate_hz) samples are dropped.
    - `n_batches`: number of batches for the error estimate; at least 2 samples per batch are required.

    **Returns:**

    A dict with `device`, `run`, `sweep`, `input`, `output` (mean), `output_sigma` (batch-means standard error)
    and `n_samples` (samples in the mean), ready for `Table.from_records`.
    """
    label = f"aggregate_samples(device={device!r}, run={run!r}, sweep={sweep!r}, input={input!r})"
    where = Where(label, None)
    device = parse_str(device, where, 0, "device")
    run = parse_int(run, where, 0, "run")
    sweep = parse_sweep(sweep, where, 0, "sweep")
    if sweep_kind(sweep).word_input:
        value = parse_dac_word(input, where, 0, "input")[0]
    else:
        value = parse_float(input, where, 0, "input")
    if not (isinstance(sample_rate_hz, (int, float, np.number)) and sample_rate_hz > 0
            and math.isfinite(sample_rate_hz)):
        raise ValueError(f"{label}: sample_rate_hz must be a positive finite number, got {sample_rate_hz!r}.")
    if not (discard_s >= 0 and math.isfinite(discard_s)):
        raise ValueError(f"{label}: discard_s must be >= 0, got {discard_s!r}.")
    if not (isinstance(n_batches, (int, np.integer)) and n_batches >= 2):
        raise ValueError(f"{label}: n_batches must be an integer >= 2, got {n_batches!r}.")
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1:
        raise DataError(f"{label}: samples must be one-dimensional, got shape {x.shape}.", source=label)
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise DataError(f"{label}: sample {bad[0]} (0-based) is {float(x[bad[0]])!r}; every sample must be finite "
                        f"({bad.size} are not).", source=label)
    drop = math.ceil(discard_s * sample_rate_hz - 1e-9)
    kept = x[drop:]
    if kept.size < 2 * n_batches:
        raise DataError(f"{label}: {kept.size} samples left after discarding {drop} ({discard_s} s at "
                        f"{sample_rate_hz} Hz); need at least {2 * n_batches} for {n_batches} batches.",
                        source=label)
    m = kept.size // n_batches
    batch_means = kept[: m * n_batches].reshape(n_batches, m).mean(axis=1)
    sigma = float(np.std(batch_means, ddof=1) / math.sqrt(n_batches))
    return {"device": device, "run": run, "sweep": sweep, "input": value, "output": float(np.mean(kept)),
            "output_sigma": sigma, "n_samples": int(kept.size)}
