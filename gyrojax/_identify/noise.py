"""The noise of data without `output_sigma`: estimated per sweep and device from the residuals of a first fit
(contrasts that cancel the model's misfit, solved by the method of moments; optionally pooled over the lot's
devices where they agree), with the chi2's null distribution under that estimate; the data are then re-weighted
by it and fitted again (`identify`)."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import betainc

from .._model.fitdata import FitData
from .._numerics.stats import chi2_sf
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

_REPEATS = "differences between runs at equal inputs"

# Where runs repeat inputs, the differences between runs are the estimate unless they exceed the local
# contrasts' estimate with an F-test p below this: then a misfit that differs from run to run (a drift in time
# on runs swept in opposite directions, a gain that changes at power-on) has reached them, and the local
# contrasts, which cancel what is smooth along the input within a run, measure the noise.
REPEATS_ALPHA = 0.01


def contrasts(x, mask, family="repeats"):
    """Contrasts of one device's sweep block (`x`, `mask` of shape (run, point)) whose mean square measures
    the noise while a misfit of the model barely reaches it: rows over the block's flattened (run, point)
    positions, and how they were made.

    - `family="repeats"`: where two runs repeat an input, the difference of their residuals there: any misfit
      that repeats from run to run (every error of the model that depends on the input) cancels exactly.
    - Else (or with `family="local"`), within each run in input order, the combination of every
      `_LOCAL_DEGREE` + 2 neighbouring residuals that cancels a polynomial of degree `_LOCAL_DEGREE` through
      them: a misfit smooth over a few neighbouring inputs barely enters, however widely they are spaced."""
    if family not in ("repeats", "local"):
        raise ValueError(f"contrasts: family must be 'repeats' or 'local', got {family!r}")
    n_run, n_pt = x.shape
    runs = [k for k in range(n_run) if mask[k].any()]
    tol = _SAME_INPUT_RTOL * max(float(np.max(np.abs(x[mask]))) if mask.any() else 0.0, np.finfo(float).tiny)
    rows = []
    for a, b in zip(runs, runs[1:]) if family == "repeats" else ():
        left = list(np.flatnonzero(mask[a]))
        for j in np.flatnonzero(mask[b]):
            same = [i for i in left if abs(x[a, i] - x[b, j]) <= tol]
            if same:
                left.remove(same[0])
                row = np.zeros(n_run * n_pt)
                row[b * n_pt + j], row[a * n_pt + same[0]] = 1.0, -1.0
                rows.append(row)
    if rows:
        return np.asarray(rows), _REPEATS
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


def noise_scales(residual, jac, blocks, *, draws=0, rng=None, fixed=None):
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

    Where runs repeat inputs, the differences between them are the contrasts unless their estimate exceeds
    the local contrasts' (`_exceeds`, at `REPEATS_ALPHA`): a misfit that differs from run to run has then
    reached them (measured on two runs swept up then down under a bias drift of 4.2 sigma per run: median
    kappa 0.96 after the choice; the differences alone 4.4: the drift adds 3.4x the noise variance to them,
    0.002x to the local ones), and the local ones are taken.

    With `draws` > 0, also the chi2 the data give in units of their estimated noise, sum_t |r_t|^2 / kappa_t,
    and `draws` samples of it under white noise of the estimated kappa (the same estimator applied to M e for
    Gaussian e, with `rng`, the choice of contrasts made again in each draw): its null distribution. The chi2
    and the noise estimate share the residuals, so chi2 / dof is not F-distributed (on a 22-point rate table
    its 1 % point is 2.8, F's 4.9); the draws are.

    `fixed`: `(kappa, nu, how)` per sweep, NaN where the sweep's own estimate stands: a noise estimated
    elsewhere (the lot's pooled one, `estimated_noise`), taken as it is, its estimate drawn in the null as a
    scaled chi2 with `nu` degrees of freedom independent of this device's residuals (they are part of it:
    conservative).

    **Returns:** `(kappa, nu, methods, null)`: kappa per sweep (NaN where a sweep has no contrast: too few
    points), the effective degrees of freedom of each estimate (Satterthwaite: tr(S)^2 / tr(S^2) with S the
    covariance of the contrasts), how each was made, and `(chi2, chi2 draws)` or None."""
    offsets, idx, pos, resid_maker = _residual_maker(jac, blocks)
    fam = _Families(np.asarray(residual, dtype=float)[idx], resid_maker, blocks, offsets, pos)
    use_local, test = fam.choice()
    _, has, kappa = fam.solve(use_local)
    nu, weights = fam.effective_dof(use_local, kappa, has)
    methods = [fam.family(t, u)[3] for t, u in enumerate(use_local)]
    if test is not None:
        for t in np.flatnonzero(fam.two & use_local):
            methods[t] += (f": the {_REPEATS} estimate {test[0][t] / test[1][t]:.3g} times more (F-test p < "
                           f"{REPEATS_ALPHA:g}), a misfit that differs from run to run")
    given = np.zeros(len(blocks), bool)
    if fixed is not None:
        given = np.isfinite(np.asarray(fixed[0], dtype=float)) & has
        kappa = np.where(given, np.asarray(fixed[0], dtype=float), kappa)
        nu = np.where(given, np.asarray(fixed[1], dtype=float), nu)
        methods = [f"{m}; {fixed[2][t]}" if given[t] else m for t, m in enumerate(methods)]
        weights = fam.weights(kappa)
    null = None
    if draws and np.all(np.isfinite(kappa[has])) and np.all(kappa[has] > 0) and has.any():
        null = fam.null(kappa, nu, weights, has, use_local, test, given, draws, rng or np.random.default_rng(0))
    return kappa, nu, methods, null


class _Families:
    """One device's contrasts of each sweep in both families (`contrasts`), over its real points, with the
    residuals `r` and the residual maker M: the moment equations, their solution for a choice of family per
    sweep, and the null draws."""

    def __init__(self, r, resid_maker, blocks, offsets, pos):
        self.r, self.resid_maker, self.n = r, resid_maker, r.size
        self.sel = [pos[offsets[t]:offsets[t + 1]][pos[offsets[t]:offsets[t + 1]] >= 0] for t in range(len(blocks))]

        def family(s, name):
            # (C M, |C r|^2, |C|^2, how they were made) of sweep s's contrasts mapped onto the real points
            x, mask = np.asarray(blocks[s][0], dtype=float), np.asarray(blocks[s][1], dtype=bool)
            rows, method = contrasts(x, mask, name)
            c = np.zeros((rows.shape[0], self.n))
            c[:, self.sel[s]] = rows[:, pos[offsets[s]:offsets[s + 1]] >= 0]
            return c @ resid_maker, float(np.sum((c @ r) ** 2)), float(np.sum(c**2)), method

        self.local = [family(s, "local") for s in range(len(blocks))]
        self.repeats = [family(s, "repeats") for s in range(len(blocks))]
        # where a sweep's runs repeat no input, both families are its local contrasts
        self.two = np.array([rep[3] == _REPEATS for rep in self.repeats])
        self.rows = {u: [_moment_row(f, self.sel, t) for t, f in enumerate(self.local if u else self.repeats)]
                     for u in (False, True)}

    def family(self, t, use_local):
        return (self.local if use_local else self.repeats)[t]

    def solve(self, use_local, q=None):
        """(a, has, kappa) with each sweep's local contrasts where `use_local`, else its differences between
        runs; `q` (sweep, draws) in place of the data's."""
        a = np.array([self.rows[bool(u)][t][0] for t, u in enumerate(use_local)])
        has = np.array([self.rows[bool(u)][t][1] for t, u in enumerate(use_local)])
        q = np.array([self.family(t, u)[1] for t, u in enumerate(use_local)]) if q is None else q
        return a, has, _solve_kappa(a, q, has)

    def weights(self, kappa):
        """kappa on each real point (0 where not finite)."""
        w = np.zeros(self.n)
        for t, st in enumerate(self.sel):
            w[st] = kappa[t] if np.isfinite(kappa[t]) else 0.0
        return w

    def effective_dof(self, use_local, kappa, has):
        """Satterthwaite's degrees of freedom of each sweep's estimate, and the weights they assume."""
        weights = self.weights(kappa)
        nu = np.full(len(self.sel), np.nan)
        for t, u in enumerate(use_local):
            if has[t]:
                cm = self.family(t, u)[0]
                cov = (cm * weights) @ cm.T
                tr2 = float(np.sum(cov * cov))
                nu[t] = float(np.trace(cov)) ** 2 / tr2 if tr2 > 0 else np.nan
        return nu, weights

    def choice(self):
        """Which family each sweep takes (True: local), and `(kappa, nu)` of both for the test, or None."""
        if not self.two.any():
            return ~self.two, None
        both = []
        for use_local in (~self.two, np.ones(len(self.sel), bool)):
            _, has, k = self.solve(use_local)
            both += [k, self.effective_dof(use_local, k, has)[0]]
        k_rep, nu_rep, k_loc, nu_loc = both
        return ~self.two | (self.two & _exceeds(k_rep, nu_rep, k_loc, nu_loc)), (k_rep, k_loc, nu_rep, nu_loc)

    def null(self, kappa, nu, weights, has, use_local, test, given, draws, rng):
        """`(chi2, chi2 draws)`: the data's chi2 in units of kappa and its null distribution (see
        `noise_scales`); the choice of family made again in each draw, the `given` sweeps' kappa drawn as a
        scaled chi2 of `nu`."""
        sel, n_sweeps = self.sel, len(self.sel)
        chi2 = sum(float(np.sum(self.r[sel[t]] ** 2)) / kappa[t] for t in range(n_sweeps) if has[t])
        e = np.sqrt(weights)[:, None] * rng.normal(size=(self.n, draws))
        q_of = {u: np.stack([np.sum((self.family(t, u)[0] @ e) ** 2, axis=0) for t in range(n_sweeps)])
                for u in (False, True)}

        def pick(pattern):
            return np.where(np.asarray(pattern)[:, None], q_of[True], q_of[False])

        if test is None:
            k_draws = self.solve(use_local, pick(use_local))[2]
        else:
            _, _, nu_rep, nu_loc = test
            kr = self.solve(~self.two, pick(~self.two))[2]
            kl = self.solve(np.ones(n_sweeps, bool), q_of[True])[2]
            chosen = ~self.two[:, None] | (self.two[:, None] & _exceeds(kr, nu_rep[:, None], kl, nu_loc[:, None]))
            k_draws = np.full((n_sweeps, draws), np.nan)  # every draw's pattern below
            for pattern in np.unique(chosen.T, axis=0):
                cols = np.all(chosen.T == pattern, axis=1)
                k_draws[:, cols] = self.solve(pattern, pick(pattern)[:, cols])[2]
        for t in np.flatnonzero(given):
            k_draws[t] = kappa[t] * rng.chisquare(nu[t], size=draws) / nu[t]
        keep = [t for t in range(n_sweeps) if has[t]]
        rr = self.resid_maker[np.concatenate([sel[t] for t in keep])] @ e
        bounds = np.cumsum([0] + [sel[t].size for t in keep])
        chi2_draws = sum(np.sum(rr[lo:hi] ** 2, axis=0) / k_draws[t]
                         for lo, hi, t in zip(bounds[:-1], bounds[1:], keep))
        return chi2, chi2_draws


def _moment_row(family, sel, s):
    """Sweep s's row of the moment equations from its contrasts `family` ((C M, |C r|^2, |C|^2, method);
    `sel` the sweeps' real points): `(a_s, has_s)`, E |C_s r|^2 = sum_t a_st kappa_t, and whether its
    contrasts see noise."""
    a = np.array([float(np.sum(family[0][:, st] ** 2)) for st in sel])
    # A sweep whose contrasts the fit absorbs entirely (as many parameters as points) measures nothing; the
    # cut is far above round-off of M (~1e-15) and far below any contrast that sees noise.
    return a, bool(a[s] > 1e-9 * family[2])


def _exceeds(k_rep, nu_rep, k_loc, nu_loc):
    """Where the differences between runs estimate a variance above the local contrasts' with an F-test p
    below `REPEATS_ALPHA` (each estimate scaled chi2 with its effective degrees of freedom; they share the
    residuals, so the test is conservative). Elementwise over arrays."""
    k_rep, nu_rep, k_loc, nu_loc = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                                         (k_rep, nu_rep, k_loc, nu_loc)))
    ok = np.isfinite(k_rep) & np.isfinite(k_loc) & (k_loc > 0) & (k_rep > 0) & (nu_rep > 0) & (nu_loc > 0)
    ratio = np.where(ok, k_rep / np.where(ok, k_loc, 1.0), 1.0)
    nr, nl = np.where(ok, nu_rep, 1.0), np.where(ok, nu_loc, 1.0)
    p = np.asarray(betainc(nl / 2.0, nr / 2.0, nl / (nl + nr * ratio)))
    return ok & (p < REPEATS_ALPHA)


# Draws of the chi2's null distribution per device: the rejection at reject_alpha = 0.01 is then decided to
# +/-0.0016 (the binomial error of a p-value near 0.01).
_NULL_DRAWS = 4000


def estimated_noise(fit: Fit, seed: int, first_device: int = 0, *, pool: bool = False):
    """Per device, the noise of each sweep estimated from `fit` (`noise_scales`): `(kappa (device, sweep),
    (noise_dof (device,), warnings per device, determined per device, null draws per device))`, the draws of the
    chi2 in units of the estimated noise under its null distribution (None where not tested; `null_p_values`
    reads the refit's chi2 against them), drawn per device with `seed` and its position in the lot
    (`first_device` + its index: a chunk of a lot draws what the whole lot draws for the same devices).

    With `pool`, each sweep's noise is one for the lot where the devices' estimates agree (`_pooled`): each
    device's estimate from ~20 degrees of freedom scatters +/-30 % in variance, and a device whose noise came
    out low carries residuals that look like structure to every scan that reads them. A chunk of a lot then
    pools over its own devices only."""
    data = fit.data
    sweeps = data.sweeps
    rows = sum(int(np.prod(data.blocks[s].inputs.shape[1:])) for s in sweeps)
    free = np.asarray(fit.free)
    dof = np.asarray(fit.dof)
    n = len(data.device_names())
    # Without output_sigma the first fit's sigmas are a scale (`first_fit_scale`): the noise is kappa times it.
    base = np.array([[1.0 if data.weighted else float(np.max(np.where(np.asarray(data.blocks[s].mask[d]),
                                                                       np.asarray(data.blocks[s].fit_sigmas()[d]),
                                                                       0.0)))
                      for s in sweeps] for d in range(n)])

    def device(d, fixed=None):
        blocks = [(np.asarray(data.blocks[s].inputs[d]), np.asarray(data.blocks[s].mask[d]),
                   1.0 / np.asarray(data.blocks[s].fit_sigmas()[d]), data.kind(s).biased) for s in sweeps]
        res = np.asarray(fit.residual_vector[d])[:rows]
        jac = np.asarray(fit.jacobian[d])[:rows][:, free]
        points = np.array([int(np.sum(b[1])) for b in blocks], dtype=float)
        if not (np.all(np.isfinite(res)) and np.all(np.isfinite(jac))):
            return np.full(len(sweeps), np.nan), np.full(len(sweeps), np.nan), [""] * len(sweeps), None, points
        out = noise_scales(res, jac, blocks, draws=_NULL_DRAWS if fixed is not None or not pool else 0,
                           rng=np.random.default_rng([seed, first_device + d]), fixed=fixed)
        return (*out, points)

    per_device = [device(d) for d in range(n)]
    if pool:
        fixed = _pooled(np.array([r[0] for r in per_device]), np.array([r[1] for r in per_device]), base)
        per_device = [device(d, fixed=tuple(f[d] for f in fixed)) for d in range(n)]
    kappa = np.ones((n, len(sweeps)))
    noise_dof = np.full(n, np.inf)
    notes, determined, draws = [], [], []
    unit = "x the given output_sigma" if data.weighted else "output units"
    for d, (k, nu, methods, null, points) in enumerate(per_device):
        present = points > 0
        ok = present & np.isfinite(k) & (k > 0) & np.isfinite(nu)
        kappa[d] = np.where(ok, k, 1.0)
        noise_dof[d] = pooled_dof(np.where(ok, nu, 0.0)[present], points[present])
        draws.append(null[1] if null is not None and ok[present].all() and dof[d] > 0 else None)
        parts = [f"{s} {math.sqrt(k[i]) * base[d, i]:.3g} {unit} from {nu[i]:.3g} effective degrees of freedom "
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


# A sweep's noise estimates are pooled over the lot's devices unless Bartlett's test of their equality has p below
# this: devices of one design on one bench share their noise, and a test at 1 % keeps a real difference apart.
POOL_ALPHA = 0.01


def _pooled(kappa, nu, base):
    """For each sweep (columns of `kappa`, `nu` (device, sweep)), the lot's pooled estimate where the devices'
    variances (kappa x `base`^2, in output units) pass Bartlett's test at `POOL_ALPHA`: `(kappa, nu, how)`, each
    (device, sweep), NaN (and "") where a sweep is not pooled; row d is what `noise_scales(fixed=...)` takes for
    device d."""
    fixed_k, fixed_nu = np.full(kappa.shape, np.nan), np.full(kappa.shape, np.nan)
    how = np.full(kappa.shape, "", dtype=object)
    n_sweeps = kappa.shape[1]
    for s in range(n_sweeps):
        ok = np.isfinite(kappa[:, s]) & (kappa[:, s] > 0) & np.isfinite(nu[:, s]) & (nu[:, s] > 0)
        if ok.sum() < 2:
            continue
        v, f = kappa[ok, s] * base[ok, s] ** 2, nu[ok, s]
        total = float(f.sum())
        pooled = float(np.sum(f * v) / total)
        k = int(ok.sum())
        stat = (total * math.log(pooled) - float(np.sum(f * np.log(v)))) / (
            1.0 + (float(np.sum(1.0 / f)) - 1.0 / total) / (3.0 * (k - 1)))
        p = chi2_sf(stat, k - 1)
        if p < POOL_ALPHA:
            continue
        fixed_k[ok, s] = pooled / base[ok, s] ** 2
        fixed_nu[ok, s] = total
        how[ok, s] = f"pooled over {k} devices, whose estimates agree (Bartlett p = {p:.2g})"
    return fixed_k, fixed_nu, how


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
