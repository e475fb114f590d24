"""The noise of data without `output_sigma`: estimated per sweep and device from the residuals of a first fit
(contrasts that cancel the model's misfit, solved by the method of moments), with the chi2's null distribution
under that estimate; the data are then re-weighted by it and fitted again (`identify`)."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._model.fitdata import FitData
from .covariance import mc_p_value, pooled_dof
from .fit import Fit
from .plausibility import output_scale_ratio


# Inputs of two runs closer than this (relative to the sweep's largest |input|) are the same setting.
_SAME_INPUT_RTOL = 1e-9


# Within a run, each contrast spans this degree + 2 neighbouring inputs and cancels polynomials of this degree.
# On seed 000's 22-point rate table (log-spaced, +/-0.1 to 200 deg/s) the estimate then takes up 1/299 of a
# cubic misfit's share of the residual (1/1190 of a tanh, 1/76 of x^5), against 1/5 with degree 1 and 1/1.3
# with plain neighbour differences; its effective degrees of freedom fall only from 10.7 (degree 1) to 8.8.
_LOCAL_DEGREE = 2


def contrasts(x, mask):
    """Contrasts of one device's sweep block (`x`, `mask` of shape (run, point)) whose mean square measures
    the noise while a misfit of the model barely reaches it: rows over the block's flattened (run, point)
    positions, and how they were made.

    - Where two runs repeat an input, the difference of their residuals there: any misfit that repeats from
      run to run (every error of the model that depends on the input) cancels exactly.
    - Else, within each run in input order, the combination of every `_LOCAL_DEGREE` + 2 neighbouring
      residuals that cancels a polynomial of degree `_LOCAL_DEGREE` through them: a misfit smooth over a few
      neighbouring inputs barely enters, however widely they are spaced."""
    n_run, n_pt = x.shape
    runs = [k for k in range(n_run) if mask[k].any()]
    tol = _SAME_INPUT_RTOL * max(float(np.max(np.abs(x[mask]))) if mask.any() else 0.0, np.finfo(float).tiny)
    rows = []
    for a, b in zip(runs, runs[1:]):
        left = list(np.flatnonzero(mask[a]))
        for j in np.flatnonzero(mask[b]):
            same = [i for i in left if abs(x[a, i] - x[b, j]) <= tol]
            if same:
                left.remove(same[0])
                row = np.zeros(n_run * n_pt)
                row[b * n_pt + j], row[a * n_pt + same[0]] = 1.0, -1.0
                rows.append(row)
    if rows:
        return np.asarray(rows), "differences between runs at equal inputs"
    width = _LOCAL_DEGREE + 2
    for k in runs:
        idx = np.flatnonzero(mask[k])
        idx = idx[np.argsort(x[k, idx], kind="stable")]
        for i in range(idx.size - width + 1):
            window = idx[i:i + width]
            xs = x[k, window] - np.mean(x[k, window])
            span = np.max(np.abs(xs))
            # the null vector of the window's Vandermonde rows: sum_i c_i p(x_i) = 0 for every p of the degree
            _, _, vt = np.linalg.svd(np.vander(xs / span if span > 0 else xs, _LOCAL_DEGREE + 1, increasing=True).T)
            row = np.zeros(n_run * n_pt)
            row[k * n_pt + window] = vt[-1]
            rows.append(row)
    return (np.asarray(rows).reshape(-1, n_run * n_pt),
            f"combinations of {width} neighbouring inputs within each run that cancel a local polynomial of degree "
            f"{_LOCAL_DEGREE}")


def _solve_kappa(a, q, has):
    """kappa from the moment equations a kappa = q over the sweeps `has` (q may carry draws on a second axis):
    the joint solution, or where it is not positive, each sweep on its own (ignoring what leaks in from the
    others' noise: an overestimate)."""
    q = np.asarray(q, dtype=float)
    kappa = np.full(q.shape, np.nan)
    if not has.any():
        return kappa
    sub = np.ix_(has, has)
    try:
        kappa[has] = np.linalg.solve(a[sub], q[has])
    except np.linalg.LinAlgError:
        kappa[has] = np.nan
    alone = q[has] / np.diag(a)[has].reshape((-1,) + (1,) * (q.ndim - 1))
    bad = ~np.all(np.isfinite(kappa[has]) & (kappa[has] > 0), axis=0)
    kappa[has] = np.where(bad, alone, kappa[has])
    return kappa


def _residual_maker(jac, blocks):
    """M = P_b - J J^+ over the real points of `blocks` (see `noise_scales`): the projector that removes each
    biased run's bias and what the free parameters (`jac`) absorb. Returns (each block's first flattened
    position, the real points' flattened positions, each flattened position's index among the real points or
    -1, M)."""
    sizes = [b[0].size for b in blocks]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    real = np.concatenate([np.ravel(b[1]) for b in blocks]).astype(bool)
    idx = np.flatnonzero(real)
    pos = np.full(real.size, -1)
    pos[idx] = np.arange(idx.size)
    n = idx.size
    proj = np.eye(n)
    for s, (x, mask, inv_sigma, biased) in enumerate(blocks):
        if not biased:
            continue
        for k in range(x.shape[0]):
            local = pos[offsets[s] + k * x.shape[1] + np.flatnonzero(mask[k])]
            if local.size:
                w = np.ravel(inv_sigma[k][mask[k]])
                proj[np.ix_(local, local)] -= np.outer(w, w) / (w @ w)
    j = np.asarray(jac, dtype=float)[idx]
    if j.size and np.all(np.isfinite(j)):
        u, sv, _ = np.linalg.svd(j, full_matrices=False)
        u = u[:, sv > sv[:1] * max(j.shape) * np.finfo(float).eps] if sv.size else u[:, :0]
        return offsets, idx, pos, proj - u @ u.T
    return offsets, idx, pos, proj


def noise_scales(residual, jac, blocks, *, draws=0, rng=None):
    """Per sweep of one device, the factor kappa by which the variance of its standardised residuals exceeds
    1 (for unit weights: the noise variance in output units), unbiased for white noise.

    `residual` (rows,) are the standardised residuals of a fit, `jac` (rows, free) their Jacobian (data rows
    only, free parameters only), both over the concatenated blocks' flattened (run, point) positions; `blocks`
    a list of `(x, mask, inv_sigma, biased)` per sweep, each (run, point). Near the solution r = M e, with e
    the standardised noise and M = P_b - J J^+ the projector that removes the run biases (P_b) and what the
    free parameters absorb. For contrasts C_s of sweep s (`contrasts`), E |C_s r|^2 = sum_t kappa_t
    tr(C_s M E_t M C_s^T), E_t selecting sweep t's rows: the method of moments solves these equations for
    kappa, exactly unbiased for the linearised fit (prior rows are left out of M: a prior holds the fit back
    a little, which can only raise the estimate).

    With `draws` > 0, also the chi2 the data give in units of their estimated noise, sum_t |r_t|^2 / kappa_t,
    and `draws` samples of it under white noise of the estimated kappa (the same estimator applied to M e for
    Gaussian e, with `rng`): its null distribution. The chi2 and the noise estimate share the residuals, so
    chi2 / dof is not F-distributed (on a 22-point rate table its 1 % point is 2.8, F's 4.9); the draws are.

    **Returns:** `(kappa, nu, methods, null)`: kappa per sweep (NaN where a sweep has no contrast: too few
    points), the effective degrees of freedom of each estimate (Satterthwaite: tr(S)^2 / tr(S^2) with S the
    covariance of the contrasts), how each was made, and `(chi2, chi2 draws)` or None."""
    offsets, idx, pos, resid_maker = _residual_maker(jac, blocks)
    n = idx.size
    r = np.asarray(residual, dtype=float)[idx]
    selects = [(pos[offsets[s]:offsets[s + 1]] >= 0) for s in range(len(blocks))]
    cm, q, methods, size = [], [], [], []
    for s, (x, mask, _, _) in enumerate(blocks):
        rows, method = contrasts(np.asarray(x, dtype=float), np.asarray(mask, dtype=bool))
        c = np.zeros((rows.shape[0], n))
        c[:, pos[offsets[s]:offsets[s + 1]][selects[s]]] = rows[:, selects[s]]
        cm.append(c @ resid_maker)
        q.append(float(np.sum((c @ r) ** 2)))
        methods.append(method)
        size.append(float(np.sum(c**2)))
    sel = [pos[offsets[t]:offsets[t + 1]][selects[t]] for t in range(len(blocks))]
    a = np.array([[float(np.sum(cm[s][:, sel[t]] ** 2)) for t in range(len(blocks))] for s in range(len(blocks))])
    # A sweep whose contrasts the fit absorbs entirely (as many parameters as points) measures nothing; the
    # cut is far above round-off of M (~1e-15) and far below any contrast that sees noise.
    has = np.diag(a) > 1e-9 * np.asarray(size)
    kappa = _solve_kappa(a, np.asarray(q), has)
    nu = np.full(len(blocks), np.nan)
    weights = np.zeros(n)
    for t in range(len(blocks)):
        weights[sel[t]] = kappa[t] if np.isfinite(kappa[t]) else 0.0
    for s in range(len(blocks)):
        if has[s]:
            cov = (cm[s] * weights) @ cm[s].T
            tr2 = float(np.sum(cov * cov))
            nu[s] = float(np.trace(cov)) ** 2 / tr2 if tr2 > 0 else np.nan
    null = None
    if draws and np.all(np.isfinite(kappa[has])) and np.all(kappa[has] > 0) and has.any():
        keep = np.concatenate([sel[t] for t in range(len(blocks)) if has[t]])
        chi2 = sum(float(np.sum(r[sel[t]] ** 2)) / kappa[t] for t in range(len(blocks)) if has[t])
        e = np.sqrt(weights)[:, None] * (rng or np.random.default_rng(0)).normal(size=(n, draws))
        rr = resid_maker[keep] @ e
        q_draws = np.stack([np.sum((cm[s] @ e) ** 2, axis=0) if has[s] else np.zeros(draws)
                            for s in range(len(blocks))])
        k_draws = _solve_kappa(a, q_draws, has)
        offsets_keep = np.cumsum([0] + [sel[t].size for t in range(len(blocks)) if has[t]])
        parts = [np.sum(rr[lo:hi] ** 2, axis=0) for lo, hi in zip(offsets_keep[:-1], offsets_keep[1:])]
        chi2_draws = sum(part / k_draws[t] for part, t in zip(parts, np.flatnonzero(has)))
        null = (chi2, chi2_draws)
    return kappa, nu, methods, null


# Draws of the chi2's null distribution per device: the rejection at reject_alpha = 0.01 is then decided to
# +/-0.0016 (the binomial error of a p-value near 0.01).
_NULL_DRAWS = 4000


def estimated_noise(fit: Fit, seed: int, first_device: int = 0):
    """Per device, the noise of each sweep estimated from `fit` (`noise_scales`): `(kappa (device, sweep),
    (noise_dof (device,), warnings per device, determined per device, null draws per device))`, the draws of the
    chi2 in units of the estimated noise under its null distribution (None where not tested; `null_p_values`
    reads the refit's chi2 against them), drawn per device with `seed` and its position in the lot
    (`first_device` + its index: a chunk of a lot draws what the whole lot draws for the same devices)."""
    data = fit.data
    sweeps = data.sweeps
    rows = sum(int(np.prod(data.blocks[s].inputs.shape[1:])) for s in sweeps)
    free = np.asarray(fit.free)
    dof = np.asarray(fit.dof)
    n = len(data.device_names())
    kappa = np.ones((n, len(sweeps)))
    noise_dof = np.full(n, np.inf)
    notes, determined, draws = [], [], []
    for d in range(n):
        blocks = [(np.asarray(data.blocks[s].inputs[d]), np.asarray(data.blocks[s].mask[d]),
                   1.0 / np.asarray(data.blocks[s].fit_sigmas()[d]), data.kind(s).biased) for s in sweeps]
        res = np.asarray(fit.residual_vector[d])[:rows]
        jac = np.asarray(fit.jacobian[d])[:rows][:, free]
        if not (np.all(np.isfinite(res)) and np.all(np.isfinite(jac))):
            k, nu, methods, null = np.full(len(sweeps), np.nan), np.full(len(sweeps), np.nan), [""] * len(sweeps), None
        else:
            k, nu, methods, null = noise_scales(res, jac, blocks, draws=_NULL_DRAWS,
                                                 rng=np.random.default_rng([seed, first_device + d]))
        points = np.array([int(np.sum(b[1])) for b in blocks], dtype=float)
        present = points > 0
        ok = present & np.isfinite(k) & (k > 0) & np.isfinite(nu)
        kappa[d] = np.where(ok, k, 1.0)
        noise_dof[d] = pooled_dof(np.where(ok, nu, 0.0)[present], points[present])
        draws.append(null[1] if null is not None and ok[present].all() and dof[d] > 0 else None)
        unit = "x the given output_sigma" if data.weighted else "output units"
        # Without output_sigma the first fit's sigmas are a scale (`first_fit_scale`): the noise is k times it.
        base = [1.0 if data.weighted else float(np.max(np.where(np.asarray(data.blocks[s].mask[d]),
                                                                 np.asarray(data.blocks[s].fit_sigmas()[d]), 0.0)))
                for s in sweeps]
        parts = [f"{s} {math.sqrt(k[i]) * base[i]:.3g} {unit} from {nu[i]:.3g} effective degrees of freedom "
                 f"({methods[i]})" for i, s in enumerate(sweeps) if ok[i]]
        bad = [s for i, s in enumerate(sweeps) if present[i] and not ok[i]]
        text = []
        if parts:
            what = "no output_sigma" if not data.weighted else "estimate_noise=True"
            text.append(f"{what}: the noise was estimated from the residuals of a first fit: " + "; ".join(parts)
                        + "; the points were weighted by it and fitted again, and the chi2 is tested against its "
                        "distribution under white noise of that size (Monte Carlo of the linearised fit)")
        if bad:
            text.append(f"no output_sigma, and the data leave nothing to estimate the noise of {', '.join(bad)} "
                        "from (too few points, or a first fit that failed): the uncertainties are not determined")
        notes.append(tuple(text))
        determined.append(not bad)
    return kappa, (noise_dof, notes, determined, tuple(draws))


def null_p_values(chi2, dof, noise_dof, draws) -> tuple[np.ndarray, float]:
    """The p-values of the refit's chi2 per device over its data rows, `chi2` (device,), in units of the estimated
    noise (the refit's sigmas are it), against the null `draws` of `estimated_noise` (None where a device was not
    tested), and the lot's. The refit's chi2, not the first fit's: the first fit, weighted by a unit guess, may
    leave a misfit the contrasts cancel (a sweep in volts beside one in LSB) that the refit removes."""
    n = len(draws)
    p_value = np.full(n, np.nan)
    for d in range(n):
        if draws[d] is not None:
            p_value[d] = mc_p_value(float(chi2[d]), draws[d], dof[d], noise_dof[d])
    # The lot: the devices' chi2 draws are independent, so their sums sample the lot's null distribution.
    tested = [d for d in range(n) if draws[d] is not None]
    p_lot = (mc_p_value(float(sum(chi2[d] for d in tested)), sum(draws[d] for d in tested),
                        int(np.asarray(dof)[tested].sum()), pooled_dof(np.asarray(noise_dof)[tested],
                                                                       np.asarray(dof)[tested]))
             if tested else float("nan"))
    return p_value, p_lot


def first_fit_scale(data: FitData, predictions) -> FitData:
    """The data of the first fit of data without `output_sigma`: each device's unit sigmas times the power of 10
    nearest the ratio of its outputs to the model's predictions at the start (`predictions`; the median over its
    sweeps, `output_scale_ratio`), so that the fit, the noise estimated from it and the p-value do not depend on
    the unit of the outputs. 1 (the unit weights) for outputs in the model's units."""
    ratio = output_scale_ratio(data, predictions)
    n = len(data.device_names())
    scale = np.ones(n)
    for d in range(n):
        r = ratio[d][np.isfinite(ratio[d])]
        if r.size:
            scale[d] = 10.0 ** round(math.log10(float(np.median(r))))
    if np.all(scale == 1.0):
        return data
    return reweighted(data, np.repeat(scale[:, None] ** 2, len(data.sweeps), axis=1))


def reweighted(data: FitData, kappa) -> FitData:
    """`data` with each device's sigmas of each sweep multiplied by sqrt(kappa) (device, sweep)."""
    sweeps = data.sweeps
    new = []
    for i, s in enumerate(sweeps):
        block = data.blocks[s]
        scale = jnp.sqrt(jnp.asarray(kappa[:, i]))[:, None, None]
        sigmas = block.fit_sigmas()
        new.append(jnp.where(block.mask, sigmas * scale, sigmas))
    return eqx.tree_at(lambda dd: [dd.blocks[s].sigmas for s in sweeps], data, new)
