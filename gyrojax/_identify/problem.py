"""The problem of one device: its parameters in internal coordinates (0 = start; held ones masked), the priors,
and the standardised residuals of every sweep; `make_problem` builds it from a model, the data and the choice
of free, shared, held and prior parameters."""

import contextlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._model.fitdata import FitData
from .._model.parameters import PARAMETERS, Entry, Model, apply_u, batched, build_entries, read_values
from .._model.residuals import device_residuals
from .._simulate.tiers import Steady


@contextlib.contextmanager
def nonfinite_explained(stage: str):
    """Turn a runtime error from inside the compiled model (a linear solve of a steady state or of its implicit
    derivative that got NaN/inf) into one that says where and what to try, keeping the original as cause."""
    try:
        yield
    except eqx.EquinoxRuntimeError as e:
        # equinox prefixes the stack; the message is on the line naming the error, or else the last one
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        named = [i for i, ln in enumerate(lines) if "EquinoxRuntimeError:" in ln and "stack" not in ln]
        if named:  # its first sentence, which may wrap onto the next lines
            text = " ".join(lines[named[-1]:]).split("EquinoxRuntimeError:", 1)[1].strip()
            reason = text.split("---")[0].split(". ")[0].strip().rstrip(".")[:300]
        else:
            reason = lines[-1] if lines else type(e).__name__
        raise RuntimeError(
            f"identify: the model's predictions or their derivatives are not finite {stage} (the error inside "
            f"the compiled model: {reason!r}). Some device has no steady "
            "state there, or one whose derivative is singular. Try: starting closer to the data (a Model with "
            "data-based values), holding parameters (hold=...) or priors on the design values, or fitting the "
            "sweeps one at a time (fit_data(table, sweeps=...)) to find the one that fails.") from e


class Problem(eqx.Module):
    """Everything one device's residual function needs besides the internal vector."""

    model: Model
    start: list
    data: FitData
    free_mask: jax.Array  # (n_dev,) 1.0 where free: the solve runs in the full space with held ones masked
    n_dev: int = eqx.field(static=True)
    entries: tuple = eqx.field(static=True)
    tier: Steady
    prior_index: jax.Array
    prior_mean: jax.Array
    prior_sigma: jax.Array
    sf_temperature: jax.Array  # deg C: where the scale factor is reported (`sf_temperature`)

    def residuals(self, u_free, u_lot):
        """Standardised residuals (data, then priors) at `u_free`, held entries masked to their start (the
        value only: `identify`'s solvers run `evaluation.evaluated`, which also carries the Jacobian)."""
        return evaluate_at(self, u_free * self.free_mask, u_lot)[0]


# Its own jit: optimistix and the Jacobians trace the residual function several times inside one outer
# trace; a jitted body is traced once per signature and reused (measured: tracing 55 s of a 132 s fit).
@eqx.filter_jit
def evaluate_at(problem, u, u_lot):
    """One device's standardised residuals (data, then priors), the count of points that did not settle, the
    predictions per sweep, the device and its zero-rate scale factor (LSB per deg/s) at the model's coordinates
    `u` (every per-device entry; the solver's are masked by `free_mask` before this)."""
    gyro = apply_u(problem.model, problem.entries, problem.start, u, u_lot).gyroscope()
    # The scale factor's two points settle with the data's (one program): the solve carries them too, at
    # the cost of two points per device, so that the fit and its evaluation share every compiled settle.
    r, failed, preds, sf = device_residuals(gyro, problem.data, problem.tier, problem.sf_temperature)
    prior = (u[problem.prior_index] - problem.prior_mean) / problem.prior_sigma
    return jnp.concatenate([r, prior]), failed, preds, gyro, sf


def sf_temperature(data):
    """Temperature at which the fit's scale factor is reported: the mean of the points of rate-input sweeps
    (a rate table; else of all recorded points, else the reference 25 C)."""
    blocks = [b for b in data.blocks.values() if b.kind.rate_input] or list(data.blocks.values())
    # numpy: a few host operations, not a compiled program per operation
    used = [np.asarray(b.mask) & np.isfinite(np.asarray(b.temperatures)) for b in blocks]
    total = sum(np.sum(np.where(m, np.asarray(b.temperatures), 0.0), axis=(1, 2)) for m, b in zip(used, blocks))
    count = np.asarray(sum(np.sum(m, axis=(1, 2)) for m in used), dtype=float)
    return np.where(count > 0, total / np.maximum(count, 1.0), 25.0)


class Layout(eqx.Module):
    """What the internal vector of a fit means: the entries (per device and shared), their flattened names,
    and `candidates`, the per-device indices not held by `hold` (those the identifiability test may free)."""

    entries: tuple[Entry, ...] = eqx.field(static=True)
    names_dev: tuple[str, ...] = eqx.field(static=True)
    names_lot: tuple[str, ...] = eqx.field(static=True)
    candidates: tuple[int, ...] = eqx.field(static=True)


def make_problem(model: Model, data: FitData, *, free, shared, hold, priors, tier) -> tuple[Problem, Layout]:
    """The problem of every device of `data` (device axis first) with every per-device entry free, and its
    layout. Raises a `ValueError` naming a parameter of `free`, `shared`, `hold` or `priors` the fit lacks."""
    n = len(data.device_names())
    model = batched(model, n)
    one = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, model)
    free = tuple(name for name in free if PARAMETERS.get(name) is None or PARAMETERS[name].exists_on(one.device))
    for name in free:
        if name not in PARAMETERS:
            raise ValueError(f"unknown parameter {name!r} in free; expected one of {', '.join(PARAMETERS)}.")
    entries = build_entries(one, free, tuple(shared))
    known = {e.label for e in entries} | {e.label.split(".")[0] for e in entries if e.effect_index is not None}
    for name in tuple(shared) + tuple(hold) + tuple(priors or {}):
        if name not in known:
            raise ValueError(f"{name!r} (in shared, hold or priors) is not a parameter of this fit; the fit has "
                             f"{', '.join(sorted(known))}.")
    dev_entries = [e for e in entries if not e.shared]
    names_dev = tuple(nm for e in dev_entries for nm in e.names())
    names_lot = tuple(nm for e in entries if e.shared for nm in e.names())
    n_dev = len(names_dev)
    start = eqx.filter_vmap(lambda m: read_values(m, entries))(model)
    # Priors: residuals (u - mu) / s in internal coordinates of per-device physical parameters.
    prior_idx, prior_mu, prior_sd = [], [], []
    for name, (value, sigma) in (priors or {}).items():
        e = next(e for e in dev_entries if e.label == name)
        p0 = np.asarray(start[entries.index(e)])
        if e.transform == "log":
            mu, sd = np.log(value / p0), sigma / value * np.ones(n)
        else:
            mu, sd = (value - p0) / e.scale[0], sigma / e.scale[0] * np.ones(n)
        prior_idx.append(names_dev.index(name))
        prior_mu.append(mu)
        prior_sd.append(sd)
    # Names, run ids and the source are labels for reports: keep them out of the compiled functions' keys, so
    # that every lot of the same shapes shares one trace and one compile.
    problem = Problem(model, start, data.unlabelled(), jnp.broadcast_to(jnp.asarray(np.ones(n_dev)), (n, n_dev)), n_dev,
                      entries, tier, jnp.broadcast_to(jnp.asarray(prior_idx, dtype=int), (n, len(prior_idx))),
                      jnp.asarray(np.stack(prior_mu, -1) if prior_mu else np.zeros((n, 0))),
                      jnp.asarray(np.stack(prior_sd, -1) if prior_sd else np.ones((n, 0))),
                      sf_temperature=jnp.asarray(sf_temperature(data)))
    candidates = tuple(i for i, nm in enumerate(names_dev)
                       if not any(nm == h or nm.startswith(h + "[") or nm.startswith(h + ".") for h in hold))
    return problem, Layout(entries, names_dev, names_lot, candidates)


def with_free(problem: Problem, free_index) -> Problem:
    """`problem` with only the per-device entries `free_index` free (the others held at their start)."""
    mask = np.zeros(problem.n_dev)
    mask[np.asarray(free_index, dtype=int)] = 1.0
    return eqx.tree_at(lambda p: p.free_mask, problem, jnp.broadcast_to(jnp.asarray(mask), problem.free_mask.shape))
