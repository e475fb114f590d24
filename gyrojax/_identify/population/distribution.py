"""The lot distribution from the devices' local likelihoods (steps 2 and 3 of the method, see the package's
docstring): each device's information about the random coordinates, the marginal and restricted likelihoods
of the lot mean and spread, and their maximum with its covariance."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..fit import Fit


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
posterior_jacobian = jax.jit(jax.jacfwd(lambda hy, i, h: _posterior(hy, i, h)[0]))


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
