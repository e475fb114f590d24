"""The uncertainty of a fit: the covariance of its internal coordinates from the weighted Jacobian's scaled SVD,
the Gauss-Newton decrement (how far a stopped solve is from the minimum), and the chi2 test's p-values."""

import math

import numpy as np
from jax.scipy.special import betainc, gammaincc

from .._numerics.stats import chi2_sf


def chi2_p_value(chi2, dof, noise_dof):
    """p-value of a chi2 over `dof` degrees of freedom. With known sigmas (`noise_dof` inf) the chi2 test;
    with the noise estimated from `noise_dof` effective degrees of freedom, the F test of chi2 / dof against
    the estimate, which takes the two as independent. Where they share the residuals they correlate
    positively and their ratio is narrower than F: the F p-value is then an upper bound (measured on a
    22-point rate table: 0.03 % of right models below 1 %), used only beyond the reach of
    the Monte Carlo null distribution (`noise.py`).
    NaN where `dof` <= 0 (nothing to test)."""
    chi2, dof, nu = np.broadcast_arrays(np.asarray(chi2, dtype=float), np.asarray(dof, dtype=float),
                                        np.asarray(noise_dof, dtype=float))
    out = np.full(chi2.shape, np.nan)
    for i in np.ndindex(chi2.shape):
        c, d, v = float(chi2[i]), float(dof[i]), float(nu[i])
        if d <= 0 or math.isnan(c):
            continue
        if math.isinf(v) and d.is_integer():  # plain numpy (no compiled program), exact recurrence
            out[i] = chi2_sf(c, int(d))
        elif math.isinf(v):
            out[i] = float(gammaincc(d / 2.0, max(c, 0.0) / 2.0))
        elif v > 0:  # the F distribution's survival: I_{v / (v + d x)}(v / 2, d / 2), x = c / d
            out[i] = float(betainc(v / 2.0, d / 2.0, v / (v + max(c, 0.0))))
    return out


def pooled_dof(noise_dof, weight):
    """Effective degrees of freedom of a sum of chi2 parts, each over its own noise estimate with `noise_dof`,
    weighted by its share `weight` of the degrees of freedom (Satterthwaite: var(sum w_i s_i^2 / s^2) =
    sum w_i^2 2 / nu_i); inf when every part had known sigmas."""
    nu = np.asarray(noise_dof, dtype=float)
    w = np.asarray(weight, dtype=float)
    w = w / w.sum() if w.sum() > 0 else np.full(w.shape, 1.0 / max(w.size, 1))
    inv = float(np.sum(np.where(np.isinf(nu), 0.0, w**2 / np.where(nu > 0, nu, np.nan))))
    return np.inf if inv == 0.0 else (1.0 / inv if math.isfinite(inv) else 0.0)


def mc_p_value(chi2, draws, dof, noise_dof):
    """p-value of `chi2` against its Monte Carlo null `draws`: (k + 1) / (N + 1) with k draws at or above it,
    or the F test's where that is smaller (it is conservative, so an upper bound: it resolves the tail beyond
    the draws)."""
    mc = (np.sum(draws >= chi2) + 1.0) / (draws.size + 1.0)
    return float(min(mc, chi2_p_value(np.asarray(chi2), np.asarray(dof), np.asarray(noise_dof))[()]))


def gauss_newton_decrement(jac, jac_lot, residuals, *, joint):
    """The Gauss-Newton decrement per device, r^T J (J^T J)^+ J^T r = |P r|^2 with P the projector onto the
    columns of the weighted Jacobian (from its SVD, columns scaled to unit norm): the chi2 fall a full
    Gauss-Newton step would still give. A joint fit's (one number for the lot) is repeated per device."""
    if joint:
        full = joint_jacobian(jac, jac_lot)
        lot = gauss_newton_decrement(full[None], None, np.reshape(residuals, (1, -1)), joint=False)[0]
        return np.full(jac.shape[0], lot)
    finite = np.all(np.isfinite(jac), axis=(-2, -1)) & np.all(np.isfinite(residuals), axis=-1)
    jac, residuals = np.where(finite[:, None, None], jac, 0.0), np.where(finite[:, None], residuals, 0.0)
    u, _, _, _, keep = scaled_svd(jac)
    dec = np.sum(np.where(keep, np.einsum("...rk,...r->...k", u, residuals), 0.0) ** 2, axis=-1)
    return np.where(finite, dec, np.inf)


def joint_jacobian(jac, jac_lot):
    """The lot's Jacobian of a joint fit: per-device blocks (device, residual, free) on the diagonal, the
    shared columns (device, residual, n_lot) beside them."""
    n, rows, p = jac.shape
    full = np.zeros((n * rows, n * p + jac_lot.shape[-1]))
    for d in range(n):
        full[d * rows:(d + 1) * rows, d * p:(d + 1) * p] = jac[d]
        full[d * rows:(d + 1) * rows, n * p:] = jac_lot[d]
    return full


def covariance(jac):
    """(J^T J)^+ of weighted Jacobians (..., residual, parameter), from the SVD of J with unit-norm columns.

    Forming J^T J squares J's condition number: a dynamic VCF sweep pins the sense resonance ~1e5 times
    better than a prior fixes the angular gain, J^T J's condition passed 1e15 and its pseudo-inverse dropped
    the weak directions (a 6-device lot: shared-gain stderr off by 3681 sigma). Zero columns (held
    parameters) get zero rows and columns, as a pseudo-inverse gives them; directions with a singular value
    below round-off of the largest are dropped likewise."""
    _, sv, vt, d, keep = scaled_svd(jac)
    inv2 = np.where(keep, 1.0 / np.where(sv > 0, sv, 1.0) ** 2, 0.0)
    cov = np.einsum("...ki,...k,...kj->...ij", vt, inv2, vt)
    return cov * d[..., :, None] * d[..., None, :]


def scaled_svd(jac):
    """SVD of the Jacobian (..., residual, parameter) with its columns scaled to unit norm (zero columns stay
    zero): (u, s, vt, column scales d, s above round-off of the largest)."""
    jac = np.asarray(jac, dtype=float)
    norm = np.sqrt(np.sum(jac**2, axis=-2))
    d = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    u, sv, vt = np.linalg.svd(jac * d[..., None, :], full_matrices=False)
    return u, sv, vt, d, sv > sv[..., :1] * max(jac.shape[-2:]) * np.finfo(float).eps
