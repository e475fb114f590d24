"""`population_fit`: the method of the package's docstring, steps 1-4, then each device's estimates and scale
factor with the uncertainty of the lot mean and spread added."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._model.parameters import PARAMETERS, apply_u, read_values
from ..fit import Fit
from .distribution import local_likelihoods, lot_distribution, posterior_jacobian
from .intervals import interval_dof
from .results import PopulationFit, PopulationParameter
from .solve import PopulationSolve


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
    every fit): see the package's docstring."""
    options = dict(options)
    if options.get("shared"):
        raise ValueError("PopulationSolve: lot-shared parameters (shared=...) are not fitted in a population fit; "
                         "drop shared, or use JointSolve with fixed priors.")
    if options.get("evaluate_only"):
        raise ValueError("PopulationSolve: evaluate_only has no population to estimate; use VmapSolve.")
    user_priors = dict(options.pop("priors", None) or {})
    options["lot_solve"] = strategy.vmap
    random = _random_parameters(identify, model, data, strategy.random, user_priors, options)
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

    def refit(fit, hyper):
        return identify(fit.model, data, priors=_priors(user_priors, random, kinds, hyper), **options)

    fit, hyper, hcov, converged, refits, warnings = _converge(fit, refit, random, index, kinds, hyper, strategy, say)
    estimates, estimates_stderr = _shrunken_estimates(fit, index, kinds, hyper, hcov)
    missing = _missing(fit.data)
    sf, sf_var, sf_grad, sf_dof = _device_scale_factors(identify, fit, data, index, kinds, hyper, hcov, missing,
                                                        strategy, _priors(user_priors, random, kinds, hyper),
                                                        options, say, warnings)
    sf_stderr = np.sqrt(sf_var)
    parameters = _lot_parameters(random, kinds, hyper, hcov)
    warnings += [f"the lot spread of {p.name} is not resolved from zero ({p.spread:.3g} +/- {p.spread_stderr:.2g} "
                 f"{p.unit}, under 2 standard errors): too few devices fix it, or their own uncertainties explain "
                 "their scatter; its intervals rest on an uncertain spread" for p in parameters if not p.resolved]
    scale_factor = _scale_factor_distribution(sf, sf_var, sf_grad, hcov)
    if not fit.all_converged:
        warnings.append("not every device's conditional fit converged: see fit.status and fit.summary()")
    warnings += _undetermined_scale_factors(fit, sf, random)
    say("population fit: " + ("converged" if converged else "NOT converged") + f" after {refits} refit(s)")
    return PopulationFit(fit=fit, random=tuple(random), parameters=parameters, scale_factor=scale_factor,
                         estimates=estimates, estimates_stderr=estimates_stderr, sf=sf, sf_stderr=sf_stderr,
                         sf_dof=sf_dof, missing=missing, hyper=hyper, hyper_covariance=hcov,
                         converged=bool(converged), refits=refits, warnings=tuple(warnings))


def _random_parameters(identify, model, data, random, user_priors, options) -> tuple:
    """The random parameters: those named, or (None) every per-device physical parameter a first independent fit
    leaves free; refused where one also has a prior of the user's."""
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
    return random


def _converge(fit, refit, random, index, kinds, hyper, strategy: PopulationSolve, say):
    """Steps 2-4 of the method: the lot distribution from the devices' fits, the lot refitted with it (`refit(fit,
    hyper)`), until mu and log s move by less than `strategy.tol` of their standard errors. Returns the last fit,
    (mu, log s) and their covariance, whether it converged, the number of refits and the warnings."""
    k = len(random)
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
        fit = refit(fit, hyper)
    return fit, hyper, hcov, converged, refits, warnings


def _shrunken_estimates(fit, index, kinds, hyper, hcov):
    """Per device the shrunken estimates of the random parameters and their standard errors with the lot mean's
    and spread's uncertainty added (through the Gaussian posterior's derivative)."""
    k = len(index)
    info, grad, finite = local_likelihoods(fit, index, k)
    theta_hat = _theta(np.asarray(fit.values)[:, index], kinds)
    ref = theta_hat[finite].mean(0)
    h = np.einsum("nij,nj->ni", info, theta_hat - ref) + grad
    centred = hyper.copy()
    centred[:k] -= ref
    g = np.asarray(posterior_jacobian(jnp.asarray(centred), jnp.asarray(info), jnp.asarray(h)))  # (n, k, 2k)
    hc = np.nan_to_num(hcov)
    extra = np.einsum("nka,ab,nkb->nk", g, hc, g)
    estimates = np.asarray(fit.values)[:, index]
    post_sd = np.asarray(fit.stderr)[:, index]
    jac_phys = np.stack([estimates[:, j] if t == "log" else np.full(len(estimates), sc)
                         for j, (t, sc, _) in enumerate(kinds)], axis=-1)
    return estimates, np.sqrt(post_sd**2 + extra * jac_phys**2)


def _device_scale_factors(identify, fit, data, index, kinds, hyper, hcov, missing, strategy: PopulationSolve, priors,
                          options, say, warnings: list):
    """Per device the scale factor, its variance with the lot mean's and spread's uncertainty added (with
    `strategy.propagate`), its derivative by (mu, log s) and its interval's degrees of freedom; what is left out
    is appended to `warnings`."""
    k = len(index)
    sf = np.asarray(fit.scale_factor, dtype=float)
    sf_var = np.asarray(fit.scale_factor_stderr, dtype=float) ** 2
    sf_grad = np.zeros((len(sf), 2 * k))
    if strategy.propagate and np.all(np.isfinite(se := np.sqrt(np.diagonal(hcov)))):
        say("population fit: the scale factors' sensitivity to the lot mean and spread")
        sf_grad = _sf_hyper_gradient(identify, fit, data, index, kinds, hyper, 0.5 * se, priors, options)
        sf_var = sf_var + np.einsum("na,ab,nb->n", sf_grad, hcov, sf_grad)
    elif strategy.propagate:
        warnings.append("the lot mean's and spread's uncertainty is not in the scale factors' standard errors (their "
                        "standard errors are not finite)")
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
    return sf, sf_var, sf_grad, sf_dof


def _scale_factor_distribution(sf, sf_var, sf_grad, hcov) -> PopulationParameter:
    """The scale factor's lot distribution: the moments of the devices' posteriors (what EM's M-step takes)."""
    ok = np.isfinite(sf) & np.isfinite(sf_var)
    m_sf = float(np.mean(sf[ok]))
    var_sf = float(np.mean((sf[ok] - m_sf) ** 2 + sf_var[ok]))
    gbar = sf_grad[ok].mean(0)
    m_se = math.sqrt(var_sf / max(ok.sum(), 1) + float(gbar @ np.nan_to_num(hcov) @ gbar))
    sd_sf = math.sqrt(var_sf)
    return PopulationParameter(name="scale_factor", unit="LSB/(deg/s)", mean=m_sf, mean_stderr=m_se, spread=sd_sf,
                               spread_stderr=sd_sf / math.sqrt(2.0 * max(ok.sum() - 1, 1)),
                               relative_spread=sd_sf / abs(m_sf), resolved=True)


def _lot_parameters(random, kinds, hyper, hcov) -> tuple:
    """The `PopulationParameter` of each random parameter from the lot mean and log-spread (`hyper`) and their
    covariance, in physical units."""
    k, out = len(random), []
    for j, (nm, (t, sc, unit)) in enumerate(zip(random, kinds)):
        mu, s = hyper[j], math.exp(hyper[k + j])
        se_mu, se_ls = math.sqrt(hcov[j, j]), math.sqrt(hcov[k + j, k + j])
        if t == "log":
            out.append(PopulationParameter(name=nm, unit=unit, mean=math.exp(mu), mean_stderr=math.exp(mu) * se_mu,
                                           spread=math.exp(mu) * s, spread_stderr=math.exp(mu) * s * se_ls,
                                           relative_spread=s, resolved=bool(se_ls < 0.5)))
        else:
            out.append(PopulationParameter(name=nm, unit=unit, mean=mu * sc, mean_stderr=se_mu * sc, spread=s * sc,
                                           spread_stderr=s * sc * se_ls, relative_spread=math.nan,
                                           resolved=bool(se_ls < 0.5)))
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
