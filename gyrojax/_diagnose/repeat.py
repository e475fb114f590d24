"""A guard that does not depend on the list of shapes: a library effect is a property of the device, so fitted on
some power-ons of a device it must predict another one (leave-one-run-out cross-validation).

A misfit that differs from power-on to power-on (a bias following an unrecorded environment, a zero-rate output
whose tempco changes at each turn-on) projects on a candidate's columns with a coefficient of its own in each
run: the score test sees a significant sum, but the coefficient fitted on one run predicts the next no better
than chance, and usually worse. The test is linear, at the fit before the step, as the score test is: for each
device and each run r, the fit's free columns shared by the runs (a device's gains) are fitted by least squares
on the device's other runs with and without the candidate's columns, and each predicts run r, whose own columns
(its turn-on biases) are fitted on it; the held-out chi2 change is

    C_r = chi2_r(without the candidate) - chi2_r(with it)

on the standardised residuals. A real effect gives sum C ~ its score (the coefficients are the same in every
run, and what it says between the runs, a gain at another temperature, is predicted too); one whose coefficient
changes from run to run gives sum C <= 0. Independent runs make the test robust to noise correlated within a
run, which inflates the score test but not the prediction of another run.

A weak real effect also gives sum C <= 0: its coefficients fitted on the other runs carry their noise into the
held-out run, and at a score near the threshold that noise costs as much as the signal gains (low-SNR lots, where
the first version of this guard refused the truth in 26 of 120 library lots). So the guard also asks whether the
coefficient differs from run to run: a heterogeneity test (as Cochran's Q) of the candidate's columns split per
run against the columns shared by the runs, linear at the fit before the step,

    Q = chi2([base, J]) - chi2([base, J_run0, J_run1, ...]) ~ chi2(df),  df = the split's added rank,

summed over the devices that give folds. A candidate is refused when both hold: it does not predict the
held-out runs (sum C <= 0) and its coefficient differs between them (Q significant at the diagnosis's alpha).

The held-out change reads the device's shared gains fitted on the other runs, so a misfit of one power-on that
corrupts them is taken up by any candidate that absorbs it there: a bias relaxing in the first power-on only, on a
protocol whose set points follow the time, lowers the other run's chi2 through a reference drift fitted beside
the gain. The guard also refuses a candidate that is absent from a run: per device, the candidate's fitted change
g (its columns at the one-step coefficients beside the free columns) is split per run, and each run's factor a_r
(1 for a property of the device) is fitted beside the free columns and pooled over the devices by its
information. A run whose factor is below `MAX_ABSENT_FACTOR` and below 1 by more than the one-sided normal
quantile of alpha / runs has less than half the effect the device's other runs carry: a property of the device
does not switch off between power-ons."""

import numpy as np

from .._identify import Fit
from .._numerics.stats import chi2_isf, chi2_sf
from .columns import base_columns, effect_columns, row_blocks
from .probes import project_out, span_basis


# ASSUMPTION: a run carrying less than half the effect the device's other runs carry does not hold that effect;
# a real effect beside a second misfit keeps factors near 1 (leakage moves them by tens of percent, not half).
MAX_ABSENT_FACTOR = 0.5
MIN_RUN_INFORMATION = 0.1  # a run whose columns carry less than this share of the richest run's is not a fold
RCOND = 1e-10  # relative singular-value cut of the folds' least squares (an effect's degenerate directions)


def run_of_rows(fit: Fit) -> np.ndarray:
    """The run index (position within the sweep's runs) of each residual row; -1 on rows of no run (priors)."""
    run = np.full(np.asarray(fit.residual_vector).shape[1], -1)
    for sweep, i, j in row_blocks(fit.data):
        _, n_run, n_pt = fit.data.blocks[sweep].inputs.shape
        run[i:j] = np.repeat(np.arange(n_run), n_pt)
    return run


def _device_arrays(fit: Fit, effect: str):
    """(residuals (device, row), `effect`'s columns (device, row, k), the fit's free columns, the run of each
    row): what both tests read."""
    return (np.asarray(fit.residual_vector, float), np.asarray(fit.jacobian, float)[:, :, effect_columns(fit, effect)],
            base_columns(fit), run_of_rows(fit))


def _folds_of(jac_d, run) -> list:
    """The runs of one device that give folds (see `held_out_change`); [] where the device gives none."""
    runs = [r for r in np.unique(run[run >= 0]) if np.any(jac_d[run == r])]
    info = [float(np.sum(jac_d[run == r] ** 2)) for r in runs]
    if len(runs) < 2 or min(info) < MIN_RUN_INFORMATION * max(info):
        return []  # what tells the candidate lives in one run (a revealing sweep run once): no other run predicts it
    return runs


def held_out_change(fit: Fit, effect: str) -> tuple[float, int]:
    """(sum over devices and runs of the held-out chi2 decrease C_r, the number of folds): see the module
    docstring. A device gives no fold where fewer than two runs carry the candidate's columns, or where one of
    them carries less than `MIN_RUN_INFORMATION` of the richest run's information; no fold at all gives (0, 0)."""
    res, jac, base, run = _device_arrays(fit, effect)
    total, folds = 0.0, 0
    for d in range(res.shape[0]):
        for r in _folds_of(jac[d], run):
            train, test = run != r, run == r  # rows of no run (priors) always train
            on_train = np.any(base[d][train] != 0, axis=0)
            shared, own = base[d][:, on_train], base[d][:, ~on_train & np.any(base[d][test] != 0, axis=0)]
            change = _held_out_chi2(shared, own[test], res[d], None, train, test) - _held_out_chi2(
                shared, own[test], res[d], jac[d], train, test)
            total += change
            folds += 1
    return total, folds


def _held_out_chi2(shared, own_test, y, j, train, test) -> float:
    """The held-out rows' chi2 beyond their own columns (`own_test`: the run's turn-on biases) of the linear
    model [shared, j] fitted on the training rows."""
    a = shared if j is None else np.concatenate([shared, j], axis=1)
    theta = np.linalg.lstsq(a[train], -y[train], rcond=RCOND)[0]
    left = y[test] + a[test] @ theta
    return float(np.sum(project_out(left[:, None], own_test) ** 2))


def run_heterogeneity(fit: Fit, effect: str) -> tuple[float, int]:
    """(Q, df): the chi2 that `effect`'s columns split per run remove beyond the same columns shared by the runs
    (and the fit's free columns), summed over the devices that give folds (see the module docstring); (0, 0)
    where none does. Rows of no run (priors) keep a column of their own."""
    res, jac, base, run = _device_arrays(fit, effect)
    q, df = 0.0, 0
    for d in range(res.shape[0]):
        runs = _folds_of(jac[d], run)
        if not runs:
            continue
        split = [jac[d] * (run == r)[:, None] for r in runs] + [jac[d] * ~np.isin(run, runs)[:, None]]
        shared = span_basis(np.concatenate([base[d], jac[d]], axis=1))
        per_run = span_basis(np.concatenate([base[d], *split], axis=1))
        q += float(np.sum((per_run.T @ res[d]) ** 2) - np.sum((shared.T @ res[d]) ** 2))
        df += per_run.shape[1] - shared.shape[1]
    return max(q, 0.0), df


def run_factors(fit: Fit, effect: str) -> list[tuple[int, float, float]]:
    """[(run, factor a_r, its standard error)]: how much of the candidate's fitted change each run carries,
    pooled over the devices that give folds (see the module docstring); [] where none does."""
    res, jac, base, run = _device_arrays(fit, effect)
    info, weighted = {}, {}
    for d in range(res.shape[0]):
        runs = _folds_of(jac[d], run)
        if not runs:
            continue
        a = np.concatenate([base[d], jac[d]], axis=1)
        theta = np.linalg.lstsq(a, -res[d], rcond=RCOND)[0]
        g = jac[d] @ theta[base[d].shape[1]:]  # the candidate's one-step change in this device
        split = np.stack([g * (run == r) for r in runs], axis=1)
        x = np.concatenate([base[d], split, (g * ~np.isin(run, runs))[:, None]], axis=1)
        coef, cov = _least_squares(x, -res[d])
        for k, r in enumerate(runs):
            i = base[d].shape[1] + k
            if np.isfinite(cov[i, i]) and cov[i, i] > 0:
                info[r] = info.get(r, 0.0) + 1.0 / cov[i, i]
                weighted[r] = weighted.get(r, 0.0) + coef[i] / cov[i, i]
    return [(int(r), weighted[r] / info[r], 1.0 / np.sqrt(info[r])) for r in sorted(info)]


def _least_squares(x, y):
    """Coefficients and their covariance (unit noise) of y ~ x, on the span x resolves (degenerate directions
    get an infinite variance)."""
    u, s, vt = np.linalg.svd(x, full_matrices=False)
    keep = s > RCOND * max(float(s[0]), 1e-300)
    coef = vt[keep].T @ ((u[:, keep].T @ y) / s[keep])
    cov = vt[keep].T @ np.diag(1.0 / s[keep] ** 2) @ vt[keep]
    resolved = np.sum(vt[keep] ** 2, axis=0)  # each coefficient's share in the resolved span
    cov[np.diag_indices_from(cov)] = np.where(resolved > 1 - 1e-9, np.diag(cov), np.inf)
    return coef, cov


def absent_run(fit: Fit, effect: str, alpha: float) -> tuple[int, float, float] | None:
    """(run, factor, standard error) of a run that lacks the candidate (see the module docstring), the most
    significant one; None where every run carries it."""
    factors = run_factors(fit, effect)
    if len(factors) < 2:
        return None
    z_cut = float(np.sqrt(chi2_isf(2.0 * alpha / len(factors), 1)))  # one-sided normal quantile
    lacking = [(r, a, se) for r, a, se in factors if a < MAX_ABSENT_FACTOR and (1.0 - a) / se > z_cut]
    return min(lacking, key=lambda x: -(1.0 - x[1]) / x[2]) if lacking else None


def absent_run_guard(fit: Fit, effect: str, score: float, alpha: float) -> str | None:
    """A reason not to confirm `effect` (score test statistic `score` at `fit`), or None: a run carries less
    than `MAX_ABSENT_FACTOR` of the change it fits in the device's other runs (see `absent_run`).

    The diagnosis asks this after the constancy guard: a size that follows a recorded coordinate (a compression
    growing with the temperature, small in a run that stays cool) is also absent from a run, and the coordinate
    says why."""
    absent = absent_run(fit, effect, alpha)
    if absent is None:
        return None
    r, a, se = absent
    return (f"it does not repeat from power-on to power-on: run {r} carries {a:.2g} +/- {se:.2g} of the "
            f"change it fits in the device's runs (score S = {score:.4g}), where a property of the device gives "
            f"1 in every run; what it takes lives in some power-ons only")


def held_out_guard(fit: Fit, effect: str, score: float, alpha: float) -> str | None:
    """A reason not to confirm `effect` (score test statistic `score` at `fit`), or None: fitted on the other
    power-ons of each device, it does not predict the held-out one (the held-out chi2 does not fall), and its
    coefficient differs from run to run (the heterogeneity Q significant at `alpha`)."""
    change, folds = held_out_change(fit, effect)
    if not folds or change > 0:
        return None
    q, df = run_heterogeneity(fit, effect)
    p = chi2_sf(q, df) if df else 1.0
    if p >= alpha:
        return None  # a weak effect whose noise the other runs cannot predict, not one that changes between them
    return (f"it does not repeat from power-on to power-on: fitted on each device's other runs, it changes the "
            f"held-out run's chi2 by {-change:+.4g} over {folds} (device, run) folds, where a property of the "
            f"device (score S = {score:.4g}) would lower it by about its score, and its coefficient differs "
            f"from run to run (Q = {q:.4g}, df {df}, p = {p:.2g}); what it takes differs from run to run")


def repeatability_guard(fit: Fit, effect: str, score: float, alpha: float) -> str | None:
    """Both tests of this module: the absent-run test, then the held-out prediction (see `absent_run_guard` and
    `held_out_guard`)."""
    return absent_run_guard(fit, effect, score, alpha) or held_out_guard(fit, effect, score, alpha)
