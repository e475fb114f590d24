"""From a solution to a `Fit`: the covariance and physical values with their standard errors, each device's
status (did the solve converge, do the data determine the scale factor and its noise, does the chi2 test
reject the model, are the fitted values plausible) and the warnings that say why."""

import functools as ft
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._compile.jit import jit
from .._model.fitdata import FitData
from .._model.parameters import apply_u
from .._model.residuals import block_residuals, num_biases, num_points
from .._solution import RESULTS, result_code, result_message
from .covariance import chi2_p_value, covariance, joint_jacobian
from .fit import Fit, p_text
from .identifiability import sf_determinacy, undetermined_reason, weak_at_solution
from .noise import null_p_values
from .plausibility import ASTRONOMICAL_CHI2_RED, implausible_values, scale_hint, temperature_hint
from .problem import Layout, Problem
from .recovery import Solution


def _message(converged, result_text, unsettled):
    if unsettled > 0:
        return (f"{unsettled} point(s) had no steady state at the solution; check the loop design, or fit "
                "fewer parameters")
    if converged:
        return "converged"
    return (f"{result_text}. Try: more starts (start=MultiStart(starts=8)), a larger max_steps, another solver "
            "(solver='gauss-newton' or 'bfgs'), holding a parameter (free=...), or priors on the design values")


def _covariances(jac, jac_lot, n: int, n_lot: int, n_free: int):
    """(per-device covariance, the shared entries', their cross terms) of the internal coordinates: (J^T J)^+,
    block-diagonal over devices unless some entries are shared (then the whole lot's normal matrix is
    inverted)."""
    if n_lot:
        cov_all = covariance(joint_jacobian(jac, jac_lot))
        cov_dev = np.stack([cov_all[d * n_free:(d + 1) * n_free, d * n_free:(d + 1) * n_free] for d in range(n)])
        cov_lot = cov_all[n * n_free:, n * n_free:]
        cross = np.stack([cov_all[d * n_free:(d + 1) * n_free, n * n_free:] for d in range(n)])
    else:
        cov_dev = covariance(jac)
        cov_lot = np.zeros((0, 0))
        cross = np.zeros((n, n_free, 0))
    return cov_dev, cov_lot, cross


def _sf_stderr(g, g_lot, cov_dev, cov_lot, cross, n_lot: int):
    """The scale factor's standard error per device from its gradients (per device `g`, shared `g_lot`)."""
    var = np.einsum("di,dij,dj->d", g, cov_dev, g)
    if n_lot:
        var = var + np.einsum("di,ij,dj->d", g_lot, cov_lot, g_lot) + 2 * np.einsum("di,dij,dj->d", g, cross, g_lot)
    return np.sqrt(np.maximum(var, 0.0))


# How the warning of a device whose chi2 rejects the model begins (`diagnose` reports the misfit itself, and shows
# only the other warnings of its baseline).
REJECTED_NOTE = "the model does not describe the data"


def _statuses(data, predictions, ok, failed, determined, noise_ok, noise_notes, rejected, implausible, chi2, dof,
              chi2_red, p_value, reject_alpha, cand_names, weak_part, n_free, threshold):
    """Each device's status (not converged, not determined, model rejected, ok) and its warnings, with the
    reasons in words."""
    n = len(data.devices)
    status, warnings = [], []
    for d in range(n):
        notes_d = []
        if not ok[d] or failed[d]:
            status.append("not converged")
        elif not determined[d] or not noise_ok[d]:
            status.append("not determined")
            if not determined[d]:
                notes_d.append(undetermined_reason(data, d, list(cand_names), weak_part[d], n_free, threshold))
            else:  # the reason first: the noise (hence every uncertainty) is what the data leave open
                notes_d.append(noise_notes[d][-1])
        elif rejected[d] or implausible[d]:
            status.append("model rejected")
        else:
            status.append("ok")
        if rejected[d] and status[d] != "not converged":
            notes_d.append(f"{REJECTED_NOTE}: chi2 {chi2[d]:.4g} over {int(dof[d])} degrees of "
                           f"freedom has {p_text(p_value[d])} < reject_alpha = {reject_alpha:g}; the standard errors "
                           f"are also given scaled by sqrt(chi2_red) = {math.sqrt(chi2_red[d]):.3g} (stderr_scaled). "
                           "gyrojax.compare shows where the misfit sits")
        if chi2_red[d] > ASTRONOMICAL_CHI2_RED and status[d] != "not converged":
            hint = scale_hint(data, predictions, d)
            notes_d.append(f"chi2_red {chi2_red[d]:.3g}: the solve stopped (its steps no longer lowered the chi2) "
                           f"~{math.sqrt(chi2_red[d]):.2g} standard errors per point from the data: this is no fit "
                           "of them" + (f"; {hint}" if hint else ": check the units of output and output_sigma"))
        if dof[d] <= 0 and status[d] != "not converged":
            notes_d.append(f"no degrees of freedom are left ({int(dof[d])}): nothing tests the model")
        notes_d += implausible[d] + [w for w in noise_notes[d] if w not in notes_d]
        warnings.append(tuple(notes_d))
    return status, warnings


def _weighted(data: FitData) -> bool:
    """`data.weighted`; a ValueError for unlabelled data (`FitData.unlabelled()` drops it)."""
    if data.weighted is None:
        raise ValueError("assemble_fit: the data are unlabelled (FitData.unlabelled()); a Fit needs the labelled data.")
    return data.weighted


def _chi2_test(data: FitData, final, chi2, dof, n_lot: int, noise):
    """The chi2 test per device and for the lot: against chi2(dof) with given sigmas (`noise` None), else the
    refit's chi2 over the data rows against the estimated noise's null draws (`null_p_values`). Returns
    (noise_dof, noise notes, noise determined, p-values, the lot's p-value)."""
    n = len(chi2)
    if noise is None:
        noise_dof = np.full(n, np.inf)
        p_lot = float(chi2_p_value(np.asarray(chi2.sum()), np.asarray(int(dof.sum()) - n_lot), np.asarray(np.inf)))
        return noise_dof, [()] * n, [True] * n, chi2_p_value(chi2, dof, noise_dof), p_lot
    noise_dof, noise_notes, noise_ok, draws = noise
    rows = sum(int(np.prod(data.blocks[s].inputs.shape[1:])) for s in data.sweeps)  # the prior rows left out
    p_value, p_lot = null_p_values(np.sum(np.asarray(final.residuals)[:, :rows] ** 2, axis=-1), dof, noise_dof, draws)
    return noise_dof, noise_notes, noise_ok, p_value, p_lot


def assemble_fit(problem_all: Problem, data: FitData, layout: Layout, free_index, solution: Solution, held_reports,
                 threshold: float, reject_alpha: float, noise) -> Fit:
    """The `Fit` of `solution`: covariance and physical values with standard errors (free parameters
    `free_index`, the others held: `held_reports` for those the data could not fix at `threshold`), each
    device's status and warnings (the chi2 test at `reject_alpha`; `noise` as for `identify`'s second fit of
    data without `output_sigma`, else None)."""
    entries, names_dev, names_lot = layout.entries, layout.names_dev, layout.names_lot
    u_full, u_lot, code, steps = solution.u_full, np.asarray(solution.u_lot), solution.code, solution.steps
    final, notes, candidates = solution.final, solution.notes, list(layout.candidates)
    n, n_dev, n_lot = len(data.device_names()), len(names_dev), len(names_lot)
    f = np.asarray(free_index, dtype=int)
    jac = np.asarray(final.jac)[:, :, f]  # (device, residual, free)
    jac_lot = np.asarray(final.jac_lot)
    chi2 = np.sum(np.asarray(final.residuals) ** 2, axis=-1)
    dof = np.asarray(num_points(data) - num_biases(data)) - f.size
    # Covariance of the internal coordinates: (J^T J)^+, block-diagonal over devices unless some entries
    # are shared (then the whole lot's normal matrix is inverted). Data without output_sigma were weighted by
    # their estimated noise before this (`identify`), so the covariance is that of the weights in both cases.
    cov_dev, cov_lot, cross = _covariances(jac, jac_lot, n, n_lot, f.size)
    cov_full = np.zeros((n, n_dev, n_dev))
    cov_full[:, f[:, None], f[None, :]] = cov_dev
    values, stderr = _physical(problem_all.start, entries, u_full, cov_full, f, shared=False)
    lot_values, lot_stderr = _physical(problem_all.start, entries, u_lot[None], cov_lot[None],
                                       np.arange(n_lot), shared=True)
    # Unlabelled: the device names are static, and a lot with new names would trace and keep a program of its own.
    fitted, residuals = _fitted_and_residuals(problem_all, jnp.asarray(u_full), jnp.asarray(u_lot),
                                              data.unlabelled().blocks, final.predictions)
    g = np.asarray(final.sf_grad)[:, f]
    g_lot = np.asarray(final.sf_grad_lot)
    sf_stderr = _sf_stderr(g, g_lot, cov_dev, cov_lot, cross, n_lot)
    failed = np.asarray(final.failed)
    ok = np.asarray(code) == result_code(RESULTS.successful)
    messages = [_message(bool(o), "" if o else result_message(c).split(".")[0], int(fl))
                for o, c, fl in zip(ok, np.asarray(code), failed)]
    weak = weak_at_solution(jac, [names_dev[i] for i in f], threshold)
    messages = tuple(m if not w else f"{m}; but {w}" for m, w in zip(messages, weak))
    messages = tuple(m if not note else f"{m} ({note})" for m, note in zip(messages, notes))
    free_mask = tuple(bool(i in set(f.tolist())) for i in range(n_dev))

    # What the data determine: the scale factor's gradient over every candidate parameter (free, or held as
    # unidentifiable) against the weighted Jacobian's row space.
    cand = np.asarray(candidates, dtype=int)
    determined, weak_part, _ = sf_determinacy(
        np.asarray(final.jac)[:, :, cand], jac_lot if n_lot else None, np.asarray(final.sf_grad)[:, cand],
        g_lot if n_lot else None, sf_stderr, threshold)
    noise_dof, noise_notes, noise_ok, p_value, p_lot = _chi2_test(data, final, chi2, dof, n_lot, noise)
    chi2_red = chi2 / np.maximum(dof, 1)
    rejected = np.nan_to_num(p_value, nan=1.0) < reject_alpha
    implausible = implausible_values(entries, problem_all.start, values, lot_values[0], free_mask, n)
    status, warnings = _statuses(data, final.predictions, ok, failed, determined, noise_ok, noise_notes, rejected,
                                 implausible, chi2, dof, chi2_red, p_value, reject_alpha,
                                 [names_dev[i] for i in cand] + list(names_lot), weak_part, f.size, threshold)
    for d in np.flatnonzero(rejected):
        hint = temperature_hint(problem_all.model.device, data, int(d))
        if hint:
            warnings[d] = warnings[d] + (hint,)
    undetermined = np.array([s == "not determined" for s in status])
    messages = tuple(f"{m}, but far from the data (chi2_red {chi2_red[d]:.3g})"
                     if m == "converged" and chi2_red[d] > ASTRONOMICAL_CHI2_RED else m for d, m in enumerate(messages))
    scale = np.where(rejected, np.sqrt(np.maximum(chi2_red, 1.0)), 1.0)
    sf = np.where(undetermined, np.nan, np.asarray(final.scale_factor))
    sf_stderr = np.where(undetermined, np.nan, sf_stderr)
    lot_rejected = bool(n_lot) and np.nan_to_num(p_lot, nan=1.0) < reject_alpha
    lot_scale = math.sqrt(max(float(chi2.sum()) / max(int(dof.sum()) - n_lot, 1), 1.0)) if lot_rejected else 1.0
    return Fit(model=fitted, names=names_dev, lot_names=names_lot, values=values[:, :n_dev],
               stderr=stderr[:, :n_dev], lot_values=lot_values[0], lot_stderr=lot_stderr[0], free=free_mask,
               covariance=jnp.asarray(cov_full), u=jnp.asarray(u_full), u_lot=jnp.asarray(u_lot),
               residuals=residuals, predictions=dict(final.predictions), biases=dict(final.biases),
               chi2=jnp.asarray(chi2), dof=jnp.asarray(dof),
               converged=jnp.asarray(ok & (failed == 0) & ~undetermined),
               result_message=messages, num_steps=jnp.asarray(steps), unsettled=jnp.asarray(failed),
               unidentifiable=held_reports, scale_factor=jnp.asarray(sf), scale_factor_stderr=jnp.asarray(sf_stderr),
               devices=data.device_names(), data=data, entries=entries, weighted=_weighted(data), jacobian=final.jac,
               residual_vector=final.residuals, status=tuple(status), warnings=tuple(warnings),
               reject_alpha=float(reject_alpha), stderr_scaled=jnp.asarray(stderr[:, :n_dev] * scale[:, None]),
               lot_stderr_scaled=jnp.asarray(lot_stderr[0] * lot_scale),
               scale_factor_stderr_scaled=jnp.asarray(sf_stderr * scale),
               noise_dof=jnp.asarray(np.asarray(noise_dof, dtype=float)),
               p_value=jnp.asarray(np.asarray(p_value, dtype=float)), p_value_total=jnp.asarray(float(p_lot)))


@jit  # one small program rather than one per operation (eager vmaps compile each)
def _fitted_and_residuals(problem_all, u_full, u_lot, blocks, predictions):
    """The fitted models (device batched) and the standardised residuals per sweep (device, run, point)."""
    fitted = eqx.filter_vmap(lambda p, u: apply_u(p.model, p.entries, p.start, u, u_lot))(problem_all, u_full)
    residuals = {sweep: jax.vmap(ft.partial(block_residuals, sweep))(blocks[sweep], pred)
                 for sweep, pred in predictions.items()}
    return fitted, residuals


def _physical(start, entries, u, cov, free_index, *, shared):
    """Physical values and standard errors (delta method) of the per-device (or shared) entries."""
    values, ses = [], []
    var_all = np.diagonal(cov, axis1=1, axis2=2)
    k = 0
    for e, p0 in zip(entries, start):
        if e.shared != shared:
            continue
        uu = u[:, k:k + e.size]
        var = var_all[:, k:k + e.size]
        p0 = np.reshape(np.asarray(p0), (np.shape(p0)[0], -1))[: uu.shape[0]]
        if e.transform == "log":
            v = p0 * np.exp(uu)
            sd = v * np.sqrt(var)
        else:
            sc = np.asarray(e.scale)
            v, sd = p0 + sc * uu, sc * np.sqrt(var)
        held = ~np.isin(np.arange(k, k + e.size), free_index)
        values.append(v)
        ses.append(np.where(held[None, :], np.nan, sd))
        k += e.size
    if not values:
        return np.zeros((u.shape[0], 0)), np.zeros((u.shape[0], 0))
    return np.concatenate(values, axis=1), np.concatenate(ses, axis=1)
