"""A coverage audit of a fit's intervals (`gyrojax.coverage`): the fitted lot simulated with the data's noise
`draws` times, every draw refitted, and the share of the 95 % intervals that cover the values the draws were
made from, per free parameter and for the scale factor.

The draws are made from the fit itself (a parametric bootstrap): each point's output is the fitted model's
prediction plus its run's fitted bias plus Gaussian noise of the point's sigma (the data's `output_sigma`, or the
noise the fit estimated). All draws of all devices are refitted in one vmapped `identify` (the lot repeated
`draws` times as more devices), starting from the fit's values, with the data's sigmas as they are
(`estimate_noise=False`). A parameter whose Wald interval covers less than 93 % (effects near zero, bounded or
log-transformed parameters with large relative errors) is flagged: its intervals under-cover.
"""

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .fit import Fit


Z95 = 1.959963984540054


class Coverage(eqx.Module):
    """The result of `gyrojax.coverage`.

    **Fields:** `names` (the fit's free per-device parameters, then `"scale_factor"`); `coverage` (share of the
    95 % intervals that cover the truth, per name); `count` (intervals per name: devices x draws, the refits that
    converged); `z_rms` (RMS of (refit - truth) / stderr per name; 1 where the standard errors are right);
    `draws`; `failed` (refits that did not converge, left out); `undercovered` (names below `low`).
    """

    names: tuple[str, ...]
    coverage: np.ndarray
    count: np.ndarray
    z_rms: np.ndarray
    draws: int
    failed: int
    low: float

    @property
    def undercovered(self) -> tuple[str, ...]:
        return tuple(n for n, c in zip(self.names, self.coverage) if c < self.low)

    def report(self) -> dict:
        return {"draws": self.draws, "failed": self.failed, "low": self.low,
                "intervals": {n: {"coverage_95": float(c), "count": int(k), "z_rms": float(z)}
                              for n, c, k, z in zip(self.names, self.coverage, self.count, self.z_rms)},
                "undercovered": list(self.undercovered)}

    def summary(self) -> str:
        se = [math.sqrt(0.95 * 0.05 / max(int(k), 1)) for k in self.count]
        lines = [f"coverage of the 95 % intervals over {self.draws} draws ({self.failed} refits not converged, left "
                 "out):"]
        for n, c, k, z, s in zip(self.names, self.coverage, self.count, self.z_rms, se):
            flag = "  UNDER-COVERS" if c < self.low else ""
            lines.append(f"  {n}: {c * 100:.1f} % (+/- {s * 100:.1f} %) of {int(k)}, z RMS {z:.2f}{flag}")
        return "\n".join(lines)


def _tile(x, draws):
    return jnp.concatenate([x] * draws, axis=0) if eqx.is_array(x) and jnp.ndim(x) > 0 else x


def simulated_data(fit: Fit, draws: int, key):
    """The fit's data repeated `draws` times along the device axis, its outputs replaced by the fitted
    predictions plus the fitted run biases plus Gaussian noise of each point's sigma."""
    blocks = {}
    names = tuple(f"{d}#{j}" for j in range(draws) for d in fit.devices)
    for i, (sweep, b) in enumerate(fit.data.blocks.items()):
        pred = np.asarray(fit.predictions[sweep])
        bias = np.asarray(fit.biases[sweep])
        mean = pred + bias[..., None]
        sig = np.asarray(b.sigmas)
        noise = np.asarray(jax.random.normal(jax.random.fold_in(key, i), (draws,) + mean.shape))
        out = (mean[None] + noise * sig[None]).reshape((-1,) + mean.shape[1:])
        mask = np.tile(np.asarray(b.mask), (draws, 1, 1))
        tiled = jax.tree.map(lambda x: np.concatenate([np.asarray(x)] * draws, axis=0), b)
        blocks[sweep] = dataclasses.replace(tiled, outputs=jnp.asarray(np.where(mask, out, 0.0)), devices=names,
                                            runs=tuple(b.runs) * draws if b.runs is not None else None)
    return dataclasses.replace(fit.data, blocks=blocks, source=f"{fit.data.source} (coverage draws)")


def coverage(fit: Fit, draws: int = 50, *, seed: int = 0, low: float = 0.93, **identify_options: Any) -> Coverage:
    """Audit the coverage of `fit`'s 95 % intervals: simulate the fitted lot with the data's noise `draws` times,
    refit every draw (one vmapped `identify`), and report per free parameter and for the scale factor the share
    of intervals that cover the values the draws were made from.

    **Arguments:**

    - `fit`: a `Fit` of `identify` without shared parameters (a joint fit's draws would share them).
    - `draws`: simulated lots.
    - `seed`: the noise's PRNG seed.
    - `low`: coverage below this flags a parameter (`Coverage.undercovered`).
    - `identify_options`: what the fit was made with besides its free parameters (`priors`, `tier`, `hold`, ...);
      `free` defaults to the fit's parameters.

    **Returns:** a `Coverage`.
    """
    from .identify import identify

    if not isinstance(fit, Fit):
        raise TypeError(f"coverage needs a gyrojax.Fit, got {type(fit).__name__}.")
    if fit.lot_names:
        raise ValueError(f"coverage: the fit has lot-shared parameters ({', '.join(fit.lot_names)}): its draws "
                         "would share them in one refit; audit a fit without shared=... .")
    if not (isinstance(draws, int) and draws >= 2):
        raise ValueError(f"coverage: draws must be an integer >= 2, got {draws!r}.")
    data = simulated_data(fit, draws, jax.random.PRNGKey(seed))
    model = jax.tree.map(lambda x: _tile(x, draws), fit.model)
    free = identify_options.pop("free", tuple(e.label for e in fit.entries if not e.shared and e.effect_index is None))
    refit = identify(model, data, free=free, estimate_noise=False, progress=False, **identify_options)
    if not isinstance(refit, Fit):
        raise ValueError("coverage: the refit is a population fit (lot_solve=PopulationSolve(...)); audit a fit of "
                         "independent or joint solves.")
    truth = np.tile(np.asarray(fit.values), (draws, 1))
    ok = np.asarray(refit.converged)
    names, cov, count, zrms = [], [], [], []
    for k, nm in enumerate(fit.names):
        if not fit.free[k] or nm not in refit.names or not refit.free[refit.names.index(nm)]:
            continue
        j = refit.names.index(nm)
        z = (np.asarray(refit.values[:, j]) - truth[:, k]) / np.asarray(refit.stderr[:, j])
        z = z[ok & np.isfinite(z)]
        names.append(nm)
        cov.append(float(np.mean(np.abs(z) < Z95)) if z.size else math.nan)
        count.append(z.size)
        zrms.append(float(np.sqrt(np.mean(z**2))) if z.size else math.nan)
    sf_truth = np.tile(np.asarray(fit.scale_factor), draws)
    z = (np.asarray(refit.scale_factor) - sf_truth) / np.asarray(refit.scale_factor_stderr)
    z = z[ok & np.isfinite(z)]
    names.append("scale_factor")
    cov.append(float(np.mean(np.abs(z) < Z95)) if z.size else math.nan)
    count.append(z.size)
    zrms.append(float(np.sqrt(np.mean(z**2))) if z.size else math.nan)
    return Coverage(tuple(names), np.asarray(cov), np.asarray(count), np.asarray(zrms), draws,
                    int(np.sum(~ok)), float(low))
