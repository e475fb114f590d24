"""The Student-t intervals of a population fit: the quantile of t and the degrees of freedom that the lot spreads'
uncertainty leaves a variance (Welch-Satterthwaite)."""

import jax
import numpy as np


Z95 = 1.959963984540054
"""The two-sided 95 % point of the standard normal."""


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
