"""The lot as a population: chosen per-device parameters are random effects drawn from a lot distribution whose
mean and spread are estimated with them (empirical Bayes, as nlmixr2, Monolix and Pumas do for subjects).

The method (`population_fit`), in the coordinates the fit uses (theta = log p for `"log"` parameters, p / scale
for `"linear"` ones), with a diagonal lot covariance Omega = diag(s^2):

1. Every device is fitted (vmapped, `VmapSolve`) with a Gaussian prior N(mu, Omega) on its random parameters; the
   first prior is weak (`start_spread` around the start value), so that every device's fit is determined.
2. From each fit, the data's own information about the random parameters (the prior rows left out, every other
   free parameter profiled out: the Schur complement of the weighted Jacobian) J_i and gradient give a local
   Gaussian likelihood exp(-theta^T J_i theta / 2 + h_i^T theta). A device whose data do not see a parameter (a
   device without a rate table, for the parameters only the rate table fixes) has J_i = 0 there.
3. mu and s maximise the marginal likelihood prod_i integral N(theta | mu, Omega) exp(...) dtheta (closed-form EM
   iterations); then s maximises the restricted (REML) likelihood, which removes maximum likelihood's downward
   bias of a spread estimated from few devices, and mu is its generalised-least-squares estimate. Standard errors:
   mu's from its information sum_i (Omega + C_i)^-1, log s's from the restricted likelihood's observed
   information.
4. Every device is fitted again with the prior N(mu, Omega) (from where it stopped): its estimate is then the
   shrunken one (the posterior mode), its covariance the posterior's. Steps 2-4 repeat until mu and s move by
   less than `tol` of their standard errors (for a model linear in the random parameters one refit).

The standard errors of each device's estimates and scale factor add the uncertainty of mu and s (Kass and
Steffey's first-order correction): for the random parameters through the Gaussian posterior's derivative, for
the scale factor from refits with each of mu and log s moved by half its standard error. A device's scale factor
with sweeps missing (a device measured without a rate table) is then a prediction with a prediction interval.

The intervals are Student-t, not normal: the part of a scale factor's variance that the lot spread sets
(dSF/dmu_j^2 (s_j^2 + var mu_j), all of it for a prediction, ~none for a device whose own data fix it) is known
only as well as s_j, whose restricted likelihood gives var(log s_j); a variance estimated with nu degrees of
freedom has var(log s) = 1 / (2 nu), so nu_j = 1 / (2 var(log s_j)) (K - 1 for K devices that fix the parameter
precisely, which makes the prediction interval the textbook mu +/- t_{K-1} s sqrt(1 + 1/K)); the device's degrees
of freedom combine the parts by Welch-Satterthwaite. A normal interval with s from 4 devices covers ~86 %.
"""

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._model.parameters import PARAMETERS, apply_u, read_values
from .fit import Fit
from .strategies import AbstractLotSolve, VmapSolve


Z95 = 1.959963984540054
"""The two-sided 95 % point of the standard normal."""


class PopulationSolve(AbstractLotSolve):
    """A population fit of the lot: `random` per-device parameters are drawn from a lot distribution whose mean
    and spread are estimated with them; each device's estimate is shrunk toward the lot by the fit. `identify`
    then returns a `PopulationFit` (see `gyrojax/_identify/population.py` for the method).

    **Arguments:**

    - `random`: names of `gyrojax.PARAMETERS` fitted per device as random effects; `None`: every per-device
      physical parameter a first independent fit leaves free.
    - `max_refits`: most refits of the lot with the population prior (each one vmapped fit).
    - `tol`: convergence: mu and log s move by less than this many of their standard errors.
    - `start_spread`: the weak prior of the first fit, as a spread in the fit's coordinates (relative for
      `"log"` parameters, in `Parameter.scale` for `"linear"` ones).
    - `propagate`: add the uncertainty of the lot mean and spread to each device's scale factor (2 refits per
      random parameter).
    - `em_steps`: most EM iterations per estimate of mu and s.
    - `vmap`: the `VmapSolve` that solves every fit.
    """

    random: tuple[str, ...] | None = eqx.field(static=True, default=None)
    max_refits: int = eqx.field(static=True, default=8)
    tol: float = eqx.field(static=True, default=0.01)
    start_spread: float = eqx.field(static=True, default=0.3)
    propagate: bool = eqx.field(static=True, default=True)
    em_steps: int = eqx.field(static=True, default=200_000)
    vmap: VmapSolve = VmapSolve()
    joint: ClassVar[bool] = False

    def __check_init__(self):
        if self.random is not None and (isinstance(self.random, str) or not self.random
                                        or not all(isinstance(r, str) for r in self.random)):
            raise ValueError(f"PopulationSolve: random must be a non-empty tuple of parameter names or None, got "
                             f"{self.random!r}.")
        for name in self.random or ():
            if name not in PARAMETERS:
                raise ValueError(f"PopulationSolve: unknown parameter {name!r} in random; expected per-device "
                                 f"physical parameters of gyrojax.PARAMETERS ({', '.join(PARAMETERS)}).")
        if not (isinstance(self.max_refits, int) and self.max_refits >= 1):
            raise ValueError(f"PopulationSolve: max_refits must be an integer >= 1, got {self.max_refits!r}.")
        if not (isinstance(self.tol, (int, float)) and self.tol > 0):
            raise ValueError(f"PopulationSolve: tol must be > 0, got {self.tol!r}.")
        if not (isinstance(self.start_spread, (int, float)) and self.start_spread > 0):
            raise ValueError(f"PopulationSolve: start_spread must be > 0, got {self.start_spread!r}.")

    def spread(self, n):
        return self.vmap.spread(n)

    def solve(self, problem, spread, u0, u_lot0, solver, max_steps):
        return self.vmap.solve(problem, spread, u0, u_lot0, solver, max_steps)


class PopulationParameter(eqx.Module):
    """The lot distribution of one quantity: `mean` (for a `"log"` parameter the geometric mean, exp(mu)) with
    `mean_stderr`, `spread` (the lot's 1-sigma spread in the quantity's unit; for a `"log"` parameter mean x s)
    with `spread_stderr`, `relative_spread` (s for a `"log"` parameter) and whether the data resolve the spread
    from zero (`resolved`: spread > 2 spread_stderr)."""

    name: str
    unit: str
    mean: float
    mean_stderr: float
    spread: float
    spread_stderr: float
    relative_spread: float
    resolved: bool

    def report(self) -> dict:
        return {"name": self.name, "unit": self.unit, "mean": self.mean, "mean_stderr": self.mean_stderr,
                "spread": self.spread, "spread_stderr": self.spread_stderr,
                "relative_spread": self.relative_spread, "spread_resolved": self.resolved}


class PopulationFit(eqx.Module):
    """The solution of `identify(..., lot_solve=PopulationSolve(...))`.

    **Fields:**

    - `fit`: the last fit of the lot, every device conditioned on the population (a Gaussian prior at the lot
      mean and spread on its random parameters): its values are the shrunken estimates.
    - `random`: the random parameters' names; `parameters`: their `PopulationParameter`s; `scale_factor`: the
      lot distribution of the zero-rate scale factor (moments of the devices' posteriors, see `population_fit`).
    - `estimates`, `estimates_stderr`: (device, random) each device's shrunken estimate and its standard error
      (the posterior's, plus the uncertainty of the lot mean and spread).
    - `sf`, `sf_stderr`: (device,) each device's scale factor (LSB per deg/s) and its standard error likewise;
      for a device whose data miss the sweeps that fix it, a prediction from the lot.
    - `sf_dof`: (device,) the degrees of freedom of each scale factor's interval (Student-t; infinite where the
      lot spread does not enter, see `population_fit`).
    - `missing`: per device the sweeps of the data it has no points in.
    - `hyper`, `hyper_covariance`: (mu, log s) in the fit's coordinates and their covariance.
    - `converged`, `refits`, `warnings` (sentences: non-convergence with what to try, unresolved spreads).
    """

    fit: Fit
    random: tuple[str, ...]
    parameters: tuple[PopulationParameter, ...]
    scale_factor: PopulationParameter
    estimates: np.ndarray
    estimates_stderr: np.ndarray
    sf: np.ndarray
    sf_stderr: np.ndarray
    sf_dof: np.ndarray
    missing: tuple[tuple[str, ...], ...]
    hyper: np.ndarray
    hyper_covariance: np.ndarray
    converged: bool
    refits: int
    warnings: tuple[str, ...]

    @property
    def devices(self) -> tuple[str, ...]:
        return self.fit.devices

    def interval(self, level: float = 0.95):
        """(low, high) per device: the scale factor's `level` interval (a prediction interval where sweeps are
        missing), Student-t with `sf_dof` degrees of freedom."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1), got {level!r}.")
        t = t_quantile(0.5 + level / 2.0, self.sf_dof)
        return self.sf - t * self.sf_stderr, self.sf + t * self.sf_stderr

    @property
    def exit_status(self) -> int:
        """The fit's exit status; 1 (a failed computation) where the population did not converge."""
        return self.fit.exit_status if self.converged else max(self.fit.exit_status, 1)

    def report(self) -> dict:
        """The JSON `population` section (keys in docs/population.md)."""
        low, high = self.interval()
        devices = []
        for i, d in enumerate(self.fit.devices):
            devices.append({
                "device": d, "missing_sweeps": list(self.missing[i]),
                "estimates": {nm: {"value": _num(self.estimates[i, k]), "stderr": _num(self.estimates_stderr[i, k])}
                              for k, nm in enumerate(self.random)},
                "scale_factor_lsb_per_dps": _num(self.sf[i]), "scale_factor_stderr": _num(self.sf_stderr[i]),
                "scale_factor_interval_95": [_num(low[i]), _num(high[i])], "interval_dof": _num(self.sf_dof[i]),
                "prediction": bool(self.missing[i]),
            })
        return {"random": list(self.random), "parameters": [p.report() for p in self.parameters],
                "scale_factor": self.scale_factor.report(), "devices": devices, "converged": self.converged,
                "refits": self.refits, "warnings": list(self.warnings)}

    def summary(self) -> str:
        lines = [f"population fit of {len(self.fit.devices)} device(s), random: {', '.join(self.random)} "
                 f"({'converged' if self.converged else 'NOT CONVERGED'} after {self.refits} refit(s))"]
        for p in self.parameters + (self.scale_factor,):
            rel = f" ({p.relative_spread * 100:.3g} %)" if math.isfinite(p.relative_spread) else ""
            lines.append(f"  lot {p.name}: mean {p.mean:.6g} +/- {p.mean_stderr:.2g}, spread {p.spread:.3g}{rel} "
                         f"+/- {p.spread_stderr:.2g} {p.unit}" + ("" if p.resolved else " (not resolved from zero)"))
        low, high = self.interval()
        for i, d in enumerate(self.fit.devices):
            what = f"predicted (no {', '.join(self.missing[i])})" if self.missing[i] else "shrunken"
            dof = f" (t, {self.sf_dof[i]:.3g} dof)" if self.sf_dof[i] < 1e6 else ""
            if not math.isfinite(self.sf[i]):
                lines.append(f"  {d}: SF not determined, {what} (see the warning)")
                continue
            lines.append(f"  {d}: SF {self.sf[i]:.6f} +/- {self.sf_stderr[i]:.2g} LSB/(deg/s) {what}, 95 % "
                         f"[{low[i]:.6f}, {high[i]:.6f}]{dof}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


def t_quantile(p: float, dof) -> np.ndarray:
    """The `p` quantile (p > 0.5) of Student's t with `dof` degrees of freedom (array; inf: the normal's), by
    bisection of its CDF 1 - I_{nu / (nu + t^2)}(nu / 2, 1 / 2) / 2."""
    dof = np.asarray(dof, dtype=float)
    z = float(jax.scipy.special.ndtri(p))
    out = np.full(dof.shape, z)
    # past 1e6 degrees of freedom the quantile is the normal's to 1e-6 (and the incomplete beta loses precision)
    fin = np.isfinite(dof) & (dof > 0) & (dof < 1e6)
    if fin.any():
        nu = dof[fin]
        lo, hi = np.full(nu.shape, z), np.full(nu.shape, z)

        def upper(t):
            return 0.5 * np.asarray(jax.scipy.special.betainc(nu / 2, 0.5, nu / (nu + t**2)))

        while np.any(grow := upper(hi) > 1 - p):
            hi = np.where(grow, 2 * hi, hi)
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            above = upper(mid) > 1 - p
            lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
        out[fin] = 0.5 * (lo + hi)
    out[np.isnan(dof) | (dof <= 0)] = np.nan  # unknown degrees of freedom (a spread without curvature): no interval
    return out


# --- the lot distribution from the devices' local likelihoods ---------------------------------------------------


def local_likelihoods(fit: Fit, random_index, n_population_rows: int):
    """Per device the data's information `J` (device, k, k) and the linear term `h` (device, k) about the random
    coordinates (as offsets from the fitted ones): log L ~ -d^T J d / 2 + g^T d, every other free parameter
    profiled out. The last `n_population_rows` residuals (the population prior) are left out. Also a (device,)
    flag: finite."""
    jac = np.asarray(fit.jacobian, dtype=float)
    res = np.asarray(fit.residual_vector, dtype=float)
    rows = jac.shape[1] - n_population_rows
    jac, res = jac[:, :rows], res[:, :rows]
    free = [j for j in np.flatnonzero(fit.free) if j not in set(random_index)]
    n, k = jac.shape[0], len(random_index)
    info, grad = np.zeros((n, k, k)), np.zeros((n, k))
    finite = np.all(np.isfinite(jac), axis=(1, 2)) & np.all(np.isfinite(res), axis=1)
    for d in np.flatnonzero(finite):
        jr, r = jac[d][:, random_index], res[d]
        if free:
            jf = jac[d][:, free]
            norm = np.linalg.norm(jf, axis=0)
            u, s, _ = np.linalg.svd(jf / np.where(norm > 0, norm, 1.0), full_matrices=False)
            q = u[:, s > s[:1] * max(jf.shape) * np.finfo(float).eps]
            jr, r = jr - q @ (q.T @ jr), r - q @ (q.T @ r)
        info[d], grad[d] = jr.T @ jr, -jr.T @ r
    return info, grad, finite


def _posterior(hyper, info, h):
    """The Gaussian posterior of every device's (centred) random coordinates given (mu, log s): means (n, k) and
    covariances (n, k, k)."""
    k = info.shape[-1]
    mu, s2 = hyper[:k], jnp.exp(2.0 * hyper[k:])
    a_mat = info + jnp.diag(1.0 / s2)
    cov = jnp.linalg.inv(a_mat)
    return jnp.einsum("nij,nj->ni", cov, h + mu / s2), cov


def _log_marginal(hyper, info, h):
    """log prod_i integral N(theta | mu, diag(s^2)) exp(-theta^T J_i theta / 2 + h_i^T theta) dtheta, up to a
    constant."""
    k = info.shape[-1]
    mu, s2 = hyper[:k], jnp.exp(2.0 * hyper[k:])
    a_mat = info + jnp.diag(1.0 / s2)
    a = h + mu / s2
    chol = jnp.linalg.cholesky(a_mat)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    sol = jax.scipy.linalg.cho_solve((chol, True), a[..., None])[..., 0]
    return jnp.sum(-0.5 * (logdet + jnp.sum(jnp.log(s2))) + 0.5 * jnp.sum(a * sol, axis=-1)
                   - 0.5 * jnp.sum(mu**2 / s2))


def _gls(log_s, info, h):
    """The lot mean given the spread (generalised least squares) and its information sum_i (Omega + C_i)^-1, in
    the information form that holds for J_i = 0 as well: (Omega + J^-1)^-1 = Omega^-1 - Omega^-1 A^-1 Omega^-1."""
    oinv = jnp.exp(-2.0 * log_s)
    a_inv = jnp.linalg.inv(info + jnp.diag(oinv))
    w = jnp.diag(oinv) - oinv[:, None] * a_inv * oinv[None, :]
    wb = oinv * jnp.einsum("nij,nj->ni", a_inv, h)
    w_sum = jnp.sum(w, axis=0)
    return jnp.linalg.solve(w_sum, jnp.sum(wb, axis=0)), w_sum


def _restricted(log_s, info, h):
    """The restricted (REML) log-likelihood of log s: the marginal likelihood at the GLS mean, less half the log
    determinant of that mean's information (which removes ML's downward bias of the spread, ~1/n)."""
    mu, w_sum = _gls(log_s, info, h)
    return _log_marginal(jnp.concatenate([mu, log_s]), info, h) - 0.5 * jnp.linalg.slogdet(w_sum)[1]


_restricted_value_grad = jax.jit(jax.value_and_grad(_restricted))
_restricted_hessian = jax.jit(jax.hessian(_restricted))
_gls_jit = jax.jit(_gls)
_posterior_jacobian = jax.jit(jax.jacfwd(lambda hy, i, h: _posterior(hy, i, h)[0]))


def lot_distribution(info, h, hyper0, em_steps: int, floor: float = 1e-12):
    """(mu, log s) of the lot: closed-form EM iterations of the marginal likelihood from `hyper0`, then the
    restricted likelihood's maximum over log s (Newton from there) with mu its GLS estimate; their covariance
    (mu's from its information, log s's from the restricted likelihood's observed information). Returns
    (hyper, covariance, converged, notes)."""
    k = info.shape[-1]
    mu, s2 = np.array(hyper0[:k], dtype=float), np.exp(2.0 * np.asarray(hyper0[k:], dtype=float))
    notes = []
    converged = False
    eye = np.eye(k)
    step = math.inf
    for _ in range(em_steps):
        cov = np.linalg.inv(info + eye / s2)
        m = np.einsum("nij,nj->ni", cov, h + mu / s2)
        mu_new = m.mean(0)
        s2_new = np.maximum(((m - mu_new) ** 2 + np.diagonal(cov, axis1=1, axis2=2)).mean(0), floor**2)
        step = max(float(np.max(np.abs(mu_new - mu) / np.sqrt(s2_new))),
                   float(np.max(np.abs(np.log(s2_new / s2)))))
        mu, s2 = mu_new, s2_new
        if step < 1e-8:
            converged = True
            break
    if not converged:
        notes.append(f"the EM iterations for the lot mean and spread did not converge in {em_steps} steps (last "
                     f"change {step:.2g} in units of the spread): the spread may be at zero, or the data inform "
                     "too few devices. Try: PopulationSolve(em_steps=...) larger, fewer random parameters, or more "
                     "devices with the sweeps that fix them")
    info_j, h_j = jnp.asarray(info), jnp.asarray(h)

    def value(x):
        return float(_restricted_value_grad(jnp.asarray(x), info_j, h_j)[0])

    def hessian(x):
        return -np.asarray(_restricted_hessian(jnp.asarray(x), info_j, h_j))

    # Newton's method on log s, halving a step that does not raise the restricted likelihood.
    low = math.log(floor)
    log_s, maximised = 0.5 * np.log(s2), False
    for _ in range(100):
        v, g = _restricted_value_grad(jnp.asarray(log_s), info_j, h_j)
        neg = hessian(log_s)
        try:
            d = np.linalg.solve(neg, np.asarray(g)) if np.all(np.linalg.eigvalsh(neg) > 0) else np.asarray(g)
        except np.linalg.LinAlgError:
            d = np.asarray(g)
        t = 1.0
        while t > 1e-6 and not value(np.maximum(log_s + t * d, low)) >= float(v) - 1e-12 * abs(float(v)):
            t /= 2
        new = np.maximum(log_s + t * d, low)
        moved, log_s = float(np.max(np.abs(new - log_s))), new
        if moved < 1e-10:
            maximised = True
            break
    if not maximised:
        converged = False
        notes.append("the restricted likelihood of the lot spread was not maximised in 100 Newton steps. Try: more "
                     "devices with the sweeps that fix the random parameters, or fewer random parameters")
    mu, w_sum = (np.asarray(x) for x in _gls_jit(jnp.asarray(log_s), info_j, h_j))
    hyper = np.concatenate([mu, log_s])
    hcov = np.zeros((2 * k, 2 * k))
    try:
        hcov[:k, :k] = np.linalg.inv(w_sum)
        neg = hessian(log_s)
        ok = bool(np.all(np.linalg.eigvalsh(neg) > 0))
        hcov[k:, k:] = np.linalg.inv(neg) if ok else np.nan
    except np.linalg.LinAlgError:
        ok = False
    if not ok or not np.all(np.isfinite(hcov)):
        hcov[k:, k:] = np.nan
        notes.append("the lot spread's restricted likelihood has no curvature at the estimate (a spread at zero, or "
                     "a parameter no device's data fix): the spread's standard error is NaN")
    return hyper, hcov, converged, notes


def interval_dof(variance, grad_mu, hyper, hcov):
    """Per device the degrees of freedom of an interval of variance `variance` (device,) whose part
    grad_mu_j^2 (s_j^2 + var mu_j) (`grad_mu`: (device, k) its derivative by the lot means mu) the lot spreads
    set: each known with nu_j = 1 / (2 var log s_j), the rest exactly; Welch-Satterthwaite. Infinite where no
    part depends on a spread."""
    k = grad_mu.shape[1]
    diag = np.diagonal(hcov)
    part = grad_mu**2 * (np.exp(2.0 * hyper[k:]) + diag[:k])
    denom = np.sum(part**2 * (2.0 * diag[k:]), axis=1)
    return np.where(denom > 0, variance**2 / np.where(denom > 0, denom, 1.0), np.inf)


# --- the population fit -----------------------------------------------------------------------------------------


def _coordinates(fit: Fit, names):
    """Indices of `names` in `fit.names`, and per name (transform, scale, unit)."""
    index, kinds = [], []
    for nm in names:
        if nm not in fit.names:
            raise ValueError(f"PopulationSolve: random parameter {nm!r} is not a per-device parameter of this fit "
                             f"(the fit has {', '.join(fit.names)}); add it to free=... or drop it from random.")
        entry = next(e for e in fit.entries if e.label == nm)
        index.append(fit.names.index(nm))
        kinds.append((entry.transform, float(entry.scale[0]) if entry.scale else 1.0, PARAMETERS[nm].unit))
    return index, kinds


def _theta(values, kinds):
    """The fit's coordinates of `values` (device, random): log p, or p / scale."""
    return np.stack([np.log(values[:, j]) if t == "log" else values[:, j] / sc for j, (t, sc, _) in enumerate(kinds)],
                    axis=-1)


def _physical(theta, kinds):
    return np.stack([np.exp(theta[..., j]) if t == "log" else theta[..., j] * sc
                     for j, (t, sc, _) in enumerate(kinds)], axis=-1)


def _priors(base, names, kinds, hyper):
    """`base` priors plus the population's, last (their residual rows come last)."""
    k = len(names)
    out = dict(base or {})
    for j, (nm, (t, sc, _)) in enumerate(zip(names, kinds)):
        mu, s = float(hyper[j]), float(math.exp(hyper[k + j]))
        out[nm] = (math.exp(mu), s * math.exp(mu)) if t == "log" else (mu * sc, s * sc)
    return out


def _missing(data):
    out = []
    for d in range(len(data.devices)):
        out.append(tuple(s for s in data.sweeps if not np.any(np.asarray(data.blocks[s].mask)[d])))
    return tuple(out)


def population_fit(identify, model, data, strategy: PopulationSolve, options: dict, say) -> PopulationFit:
    """The population fit of `identify` (the function, called with `options` and `lot_solve=strategy.vmap` for
    every fit): see the module docstring."""
    options = dict(options)
    if options.get("shared"):
        raise ValueError("PopulationSolve: lot-shared parameters (shared=...) are not fitted in a population fit; "
                         "drop shared, or use JointSolve with fixed priors.")
    if options.get("evaluate_only"):
        raise ValueError("PopulationSolve: evaluate_only has no population to estimate; use VmapSolve.")
    user_priors = dict(options.pop("priors", None) or {})
    options["lot_solve"] = strategy.vmap
    random = strategy.random
    if random is None:
        first = identify(model, data, priors=user_priors or None, **options)
        random = tuple(nm for nm, free, e in zip(first.names, first.free, _per_name_entries(first))
                       if free and e.effect_index is None and nm not in user_priors)
        if not random:
            raise ValueError("PopulationSolve: the fit leaves no per-device physical parameter free to treat as a "
                             "random effect; name them (random=...).")
    both = sorted(set(random) & set(user_priors))
    if both:
        raise ValueError(f"PopulationSolve: {', '.join(both)} has a prior (priors=...) and is random: the "
                         "population is its prior; drop it from priors.")
    k = len(random)
    # The weak first prior, at the start values' lot mean: only its information is removed again below.
    start_values = _start_values(model, random)
    theta0 = np.array([np.log(v) if PARAMETERS[nm].transform == "log" else v / PARAMETERS[nm].scale
                       for nm, v in zip(random, start_values)])
    hyper = np.concatenate([theta0, np.full(k, math.log(strategy.start_spread))])
    say(f"population fit: {', '.join(random)} random; first fit with a weak prior ({strategy.start_spread:g} spread)")
    fit = identify(model, data, priors=_priors(user_priors, random, _kinds(random), hyper), **options)
    estimate = options.get("estimate_noise")
    if (not data.weighted) if estimate is None else estimate:
        options["estimate_noise"] = False  # every refit keeps the first fit's noise estimate (its weights)
        data = fit.data
    index, kinds = _coordinates(fit, random)
    warnings, converged, refits = [], False, 0
    hcov = np.full((2 * k, 2 * k), np.nan)
    while True:
        theta_hat = _theta(np.asarray(fit.values)[:, index], kinds)
        info, grad, finite = local_likelihoods(fit, index, k)
        if not np.all(finite):
            bad = [d for d, f in zip(fit.devices, finite) if not f]
            warnings.append(f"device(s) {', '.join(bad)} have a non-finite Jacobian or residuals at their fit: left "
                            "out of the lot distribution")
        # A device informs a coordinate where its data's information passes a millionth of the prior's.
        seen = info[:, range(k), range(k)] * np.exp(2.0 * hyper[k:]) > 1e-6
        if not seen.any(axis=0).all():
            none = [nm for j, nm in enumerate(random) if not seen[:, j].any()]
            raise ValueError(f"PopulationSolve: no device's data fix {', '.join(none)}; a lot distribution needs "
                             "some devices with the sweeps that see it.")
        ref = theta_hat[finite].mean(0)
        h = np.einsum("nij,nj->ni", info, theta_hat - ref) + grad
        h[~finite] = 0.0
        centred = hyper.copy()
        centred[:k] -= ref
        new, hcov, em_ok, notes = lot_distribution(info, h, centred, strategy.em_steps)
        new[:k] += ref
        se = np.sqrt(np.diagonal(hcov))
        change = float(np.max(np.abs(new - hyper) / np.where(np.isfinite(se) & (se > 0), se, 1.0)))
        hyper = new
        if refits >= 1 and change < strategy.tol:
            converged = em_ok
            warnings += notes
            break
        if refits >= strategy.max_refits:
            warnings += notes
            warnings.append(f"the population fit did not converge in {strategy.max_refits} refits (the lot mean and "
                            f"spread last moved {change:.2g} standard errors). Try: PopulationSolve(max_refits=...) "
                            "larger, a start closer to the data, or fewer random parameters")
            break
        refits += 1
        say(f"population fit: refit {refits} with the lot distribution (moved {change:.2g} standard errors)")
        fit = identify(fit.model, data, priors=_priors(user_priors, random, kinds, hyper), **options)
    # Per device: the shrunken estimates, their standard errors with the lot mean's and spread's added.
    info, grad, finite = local_likelihoods(fit, index, k)
    theta_hat = _theta(np.asarray(fit.values)[:, index], kinds)
    ref = theta_hat[finite].mean(0)
    h = np.einsum("nij,nj->ni", info, theta_hat - ref) + grad
    centred = hyper.copy()
    centred[:k] -= ref
    g = np.asarray(_posterior_jacobian(jnp.asarray(centred), jnp.asarray(info), jnp.asarray(h)))  # (n, k, 2k)
    hc = np.nan_to_num(hcov)
    extra = np.einsum("nka,ab,nkb->nk", g, hc, g)
    estimates = np.asarray(fit.values)[:, index]
    post_sd = np.asarray(fit.stderr)[:, index]
    jac_phys = np.stack([estimates[:, j] if t == "log" else np.full(len(estimates), sc)
                         for j, (t, sc, _) in enumerate(kinds)], axis=-1)
    estimates_stderr = np.sqrt(post_sd**2 + extra * jac_phys**2)
    sf = np.asarray(fit.scale_factor, dtype=float)
    sf_var = np.asarray(fit.scale_factor_stderr, dtype=float) ** 2
    sf_grad = np.zeros((len(sf), 2 * k))
    if strategy.propagate and np.all(np.isfinite(se := np.sqrt(np.diagonal(hcov)))):
        say("population fit: the scale factors' sensitivity to the lot mean and spread")
        sf_grad = _sf_hyper_gradient(identify, fit, data, index, kinds, hyper, 0.5 * se,
                                     _priors(user_priors, random, kinds, hyper), options)
        sf_var = sf_var + np.einsum("na,ab,nb->n", sf_grad, hcov, sf_grad)
    elif strategy.propagate:
        warnings.append("the lot mean's and spread's uncertainty is not in the scale factors' standard errors (their "
                        "standard errors are not finite)")
    sf_stderr = np.sqrt(sf_var)
    missing = _missing(fit.data)
    if strategy.propagate and np.all(np.isfinite(hcov)):
        sf_dof = interval_dof(sf_var, sf_grad[:, :k], hyper, hcov)
    elif strategy.propagate:
        sf_dof = np.where([bool(m) for m in missing], np.nan, np.inf)
        warnings.append("the lot spread's standard error is not finite: the scale factors of devices with missing "
                        "sweeps get no interval (NaN)")
    else:
        sf_dof = np.full(len(sf), np.inf)
        warnings.append("propagate=False: the intervals are normal, without the lot mean's and spread's uncertainty "
                        "(too narrow where the spread rests on few devices)")
    parameters = _lot_parameters(random, kinds, hyper, hcov)
    warnings += [f"the lot spread of {p.name} is not resolved from zero ({p.spread:.3g} +/- {p.spread_stderr:.2g} "
                 f"{p.unit}, under 2 standard errors): too few devices fix it, or their own uncertainties explain "
                 "their scatter; its intervals rest on an uncertain spread" for p in parameters if not p.resolved]
    # The scale factor's lot distribution: the moments of the devices' posteriors (what EM's M-step takes).
    ok = np.isfinite(sf) & np.isfinite(sf_var)
    m_sf = float(np.mean(sf[ok]))
    var_sf = float(np.mean((sf[ok] - m_sf) ** 2 + sf_var[ok]))
    gbar = sf_grad[ok].mean(0)
    m_se = math.sqrt(var_sf / max(ok.sum(), 1) + float(gbar @ np.nan_to_num(hcov) @ gbar))
    sd_sf = math.sqrt(var_sf)
    scale_factor = PopulationParameter("scale_factor", "LSB/(deg/s)", m_sf, m_se, sd_sf,
                                       sd_sf / math.sqrt(2.0 * max(ok.sum() - 1, 1)), sd_sf / abs(m_sf), True)
    if not fit.all_converged:
        warnings.append("not every device's conditional fit converged: see fit.status and fit.summary()")
    warnings += _undetermined_scale_factors(fit, sf, random)
    say("population fit: " + ("converged" if converged else "NOT converged") + f" after {refits} refit(s)")
    return PopulationFit(fit, tuple(random), parameters, scale_factor, estimates, estimates_stderr, sf, sf_stderr,
                         sf_dof, missing, hyper, hcov, bool(converged), refits, tuple(warnings))


def _lot_parameters(random, kinds, hyper, hcov) -> tuple:
    """The `PopulationParameter` of each random parameter from the lot mean and log-spread (`hyper`) and their
    covariance, in physical units."""
    k, out = len(random), []
    for j, (nm, (t, sc, unit)) in enumerate(zip(random, kinds)):
        mu, s = hyper[j], math.exp(hyper[k + j])
        se_mu, se_ls = math.sqrt(hcov[j, j]), math.sqrt(hcov[k + j, k + j])
        if t == "log":
            out.append(PopulationParameter(nm, unit, math.exp(mu), math.exp(mu) * se_mu, math.exp(mu) * s,
                                           math.exp(mu) * s * se_ls, s, bool(se_ls < 0.5)))
        else:
            out.append(PopulationParameter(nm, unit, mu * sc, se_mu * sc, s * sc, s * sc * se_ls, math.nan,
                                           bool(se_ls < 0.5)))
    return tuple(out)


def _undetermined_scale_factors(fit, sf, random) -> list[str]:
    """A warning naming the devices whose scale factor is not determined (NaN: no prediction, no interval), with
    the fit's reason for the first and what would fix it."""
    bad = [k for k, v in enumerate(sf) if not np.isfinite(v)]
    if not bad:
        return []
    why = next((w for k in bad for w in fit.warnings[k]), "its fit says why (fit.summary())")
    return [f"the scale factor of {len(bad)} device(s) is not determined, so they get no value and no interval"
            f": {', '.join(fit.devices[k] for k in bad)}. {fit.devices[bad[0]]}: {why}. The lot distribution "
            f"fixes only {', '.join(random)}: make the parameters it names random too (random=...), or measure "
            "these devices with a sweep that sees them"]


def _sf_hyper_gradient(identify, fit, data, index, kinds, hyper, steps, priors, options):
    """(device, 2k) d SF / d (mu, log s): each device's solution moved to first order (the implicit function of
    its normal equations J^T r + e_j (theta_j - mu_j) / s_j^2 = 0: du/dmu_j = C e_j / s_j^2, du/dlog s_j =
    2 C e_j (theta_j - mu_j) / s_j^2, C the posterior covariance) by `steps` of each, and its scale factor
    evaluated there (one `evaluate_only` pass per hyperparameter instead of a refit)."""
    k = len(index)
    cov = np.asarray(fit.covariance, dtype=float)
    theta = _theta(np.asarray(fit.values)[:, index], kinds)
    s2 = np.exp(2.0 * hyper[k:])
    sf = np.asarray(fit.scale_factor, dtype=float)
    out = np.zeros((len(sf), 2 * k))
    n_lot = len(fit.lot_names)
    for a in range(2 * k):
        j = a % k
        col = cov[:, :, index[j]] / s2[j]
        du = steps[a] * (col if a < k else 2.0 * col * (theta[:, j] - hyper[j])[:, None])
        moved = eqx.filter_vmap(lambda m, d: apply_u(m, fit.entries, read_values(m, fit.entries), d,
                                                     jnp.zeros(n_lot)))(fit.model, jnp.asarray(du))
        other = identify(moved, data, **(options | {"priors": priors, "evaluate_only": True}))
        out[:, a] = (np.asarray(other.scale_factor, dtype=float) - sf) / steps[a]
    return out


def _per_name_entries(fit):
    return [e for e in fit.entries if not e.shared for _ in e.names()]


def _kinds(names):
    return [(PARAMETERS[nm].transform, float(PARAMETERS[nm].scale), PARAMETERS[nm].unit) for nm in names]


def _start_values(model, names):
    """The lot mean of each random parameter's start value (raises naming one the device lacks)."""
    gyro = model.device
    out = []
    for nm in names:
        p = PARAMETERS[nm]
        if not p.exists_on(gyro):
            raise ValueError(f"PopulationSolve: the device has no {nm!r}; random names per-device parameters it has.")
        v = np.asarray(p.where(gyro), dtype=float)
        out.append(float(np.exp(np.mean(np.log(v)))) if p.transform == "log" else float(np.mean(v)))
    return out
