"""The Fisher information algebra of the planner (see `plan.py`'s docstring): triangular factors of
standardised rows, identification's hold rule on them, an effect's chi2 after the nuisances, one run's
information with its bias projected out, and the scale factor's variance."""

import math

import numpy as np


SF_HELD_TOL = 0.1
"""A design determines the scale factor when the part of its gradient along directions the design cannot fix
is below this many standard errors (identification's own test). On the data given, whether the scale factor
is determined is identification's own verdict: the baseline fit's status."""


def reduce_rows(rows: np.ndarray) -> np.ndarray:
    """A triangular factor R with R^T R = rows^T rows (fewer rows, the same Fisher information, without
    squaring the condition)."""
    rows = np.asarray(rows, dtype=float)
    if rows.shape[0] == 0:
        return np.zeros((0, rows.shape[1]))
    # numpy's stubs type every mode's result as QRResult; mode="r" returns the array R.
    return np.linalg.qr(rows, mode="r")  # pyright: ignore[reportReturnType]


def kept_columns(blocks, cols, threshold):
    """Which of `cols` a joint fit would free: identification's rule on the lot's stacked Jacobian (a column
    below `threshold` is held; then, while a combination is, its last member in order of preference).
    `blocks`: per device, a matrix whose Gram matrix is the information."""
    stacked = np.concatenate([b[:, cols] for b in blocks]) / math.sqrt(len(blocks))
    keep = list(range(len(cols)))
    norms = np.linalg.norm(stacked, axis=0)
    top = float(np.max(norms)) if norms.size else 0.0
    keep = [j for j in keep if norms[j] >= threshold and norms[j] >= 1e-12 * top]
    while keep:
        a = stacked[:, keep]
        if a.shape[0] < a.shape[1]:
            a = np.concatenate([a, np.zeros((a.shape[1] - a.shape[0], a.shape[1]))])
        _, s, vt = np.linalg.svd(a, full_matrices=False)
        i = int(np.argmin(s))
        if s[i] >= threshold and s[i] >= 1e-12 * s.max():
            break
        v = np.abs(vt[i])
        keep.remove(keep[int(np.max(np.nonzero(v > 0.3 * v.max())[0]))])
    return [cols[j] for j in keep]


def nuisances(blocks, counts, base_free, pool, reading, threshold):
    """The columns a joint fit of the data given and `counts` runs of each experiment would free: the
    baseline's free ones without added runs; else identification's rule (`kept_columns`) over `pool` and the
    columns `reading[j]` of the parameters experiment j reads, for each experiment with runs."""
    if not any(counts):
        return list(base_free)
    read = {i for j, k in enumerate(counts) if k for i in reading[j]}
    return kept_columns(blocks, sorted(set(pool) | read), threshold)


def residual_chi2(a, nuisance, effect, theta):
    """|(1 - P_b) A_e theta|^2 for one device's factor `a`: what the effect leaves after the nuisance
    columns (scaled to unit norm for the least squares) took their share."""
    f = a[:, effect] @ theta
    if not nuisance:
        return float(f @ f)
    b = a[:, nuisance]
    norm = np.linalg.norm(b, axis=0)
    b = b / np.where(norm > 0, norm, 1.0)
    c = np.linalg.lstsq(b, f, rcond=None)[0]
    r = f - b @ c
    return float(r @ r)


def sf_variance(info, g, cols, threshold, meat=None):
    """Variance of the scale factor g^T I^+ g over the columns `cols` a fit of this information would free,
    and whether those determine it (its gradient's part along what the design cannot fix is below
    `SF_HELD_TOL` standard errors). `info` is (param, param). With `meat` (param, param: J^T R J, R the
    standardised noise's correlation), the variance of the weighted least-squares estimate under correlated
    noise, g^T I^+ meat I^+ g."""
    sub = info[np.ix_(cols, cols)]
    d = np.sqrt(np.maximum(np.diag(sub), 0.0))
    if not cols or np.any(d <= 0):
        return math.inf
    evals, evecs = np.linalg.eigh(sub / np.outer(d, d))
    keep = evals > evals.max() * 1e-12
    gs = g[cols] / d
    proj = evecs[:, keep].T @ gs
    if meat is None:
        var = float(np.sum(proj**2 / evals[keep]))
    else:
        h = evecs[:, keep] @ (proj / evals[keep])  # I^+ g in the scaled coordinates
        var = float(h @ (meat[np.ix_(cols, cols)] / np.outer(d, d)) @ h)
    # determined: the gradient lies in the span of what the data fix (singular values >= threshold)
    ev_all, vec_all = np.linalg.eigh(sub)
    weak = vec_all[:, np.sqrt(np.maximum(ev_all, 0.0)) < threshold]
    part = float(np.linalg.norm(weak.T @ g[cols])) if weak.size else 0.0
    return var if part <= SF_HELD_TOL * math.sqrt(max(var, 0.0)) else math.inf


def run_info(rows_j, sig, subset, corr=None):
    """Fisher information of one run at the points `subset` (their Jacobian rows and sigmas), its bias
    projected out, and the matching J^T R J of its noise's correlation `corr` (a function of the number of
    points, applied back to back in the listed order; None: independent points)."""
    w = 1.0 / sig[subset] ** 2
    mean = (w @ rows_j[subset]) / np.sum(w)
    jp = (rows_j[subset] - mean) / sig[subset, None]
    info = jp.T @ jp
    return info, (info if corr is None else jp.T @ corr(len(subset)) @ jp)


def sqrt_info(info):
    """A matrix whose Gram matrix is `info` (for the hold rule)."""
    evals, evecs = np.linalg.eigh(info)
    return (evecs * np.sqrt(np.maximum(evals, 0.0))).T
