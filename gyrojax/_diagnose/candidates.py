"""The baseline and its candidates, shared by `diagnose` and `plan`: a given fit as the baseline, a lot's first
device, the candidate effects checked against the device, the baseline fit with every candidate at zero, and what
decides a new compile of the fit with all of them."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._effects.registry import EFFECTS
from .._identify import Fit, identify
from .._identify.fitmatch import check_fit_data
from .._identify.spec import FitSpec
from .._model.fitdata import FitData
from .._model.parameters import Model, zero_effect


def full_key(model: Model, data: FitData):
    """What decides whether a fit of `model` to `data` compiles anew: the model's structure and the data's
    shapes."""
    shapes = tuple((s, tuple(np.shape(data.blocks[s].inputs))) for s in data.sweeps)
    return jax.tree.structure(eqx.filter(model, eqx.is_array)), shapes


def baseline_model(fit: Fit, data: FitData | None) -> Model:
    """The fitted model of `fit` as the baseline, after checking that it was fitted to `data` (None: the fit's
    own data, nothing to check)."""
    if not isinstance(fit, Fit):
        raise TypeError(f"fit must be a gyrojax.Fit (from identify or load_fit), got {type(fit).__name__}.")
    if data is not None:
        check_fit_data(fit, data)
    # Effects held at exactly zero (a previous diagnosis's candidates) were never fitted: candidates again.
    kept = tuple(e for e in fit.model.effects
                 if any(np.any(np.asarray(x) != 0) for x in jax.tree.leaves(e)))
    return Model(fit.model.device, kept)


def is_lot(device) -> bool:
    """Whether `device` is a lot: every array leaf has a leading device axis."""
    leaves = [x for x in jax.tree.leaves(device) if eqx.is_array(x)]
    return bool(leaves) and all(jnp.ndim(x) >= 1 for x in leaves)


def first_device(device):
    """The first device of a lot (leaves indexed at 0 on their device axis)."""
    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, device)


def candidate_effects(base: Model, candidates, who: str) -> tuple[str, ...]:
    """The candidate effects to test against the baseline `base`: `candidates` (default: every registered
    effect that the device supports and `base` does not hold), each checked to be a registered effect that can
    act on the device and is not fitted in `base` already. `who` names the caller in the messages."""
    from .._effects.registry import supported_effects

    one = first_device(base.device) if is_lot(base.device) else base.device
    available = supported_effects(one)
    present = set(base.effect_names)
    if candidates is None:
        candidates = tuple(c for c in available if c not in present)
    candidates = tuple(candidates)
    for c in candidates:
        if c not in EFFECTS:
            raise ValueError(f"unknown candidate effect {c!r}; expected names of gyrojax.EFFECTS: "
                             f"{', '.join(EFFECTS)}.")
        if c not in available:
            raise ValueError(f"candidate effect {c!r} cannot act on device {one.name!r} "
                             f"(supported: {', '.join(available)}).")
        if c in present:
            raise ValueError(f"candidate effect {c!r} is already fitted in the baseline; {who} tests the others.")
    if not candidates:
        raise ValueError(f"{who} needs at least one candidate effect not already in the model.")
    return candidates


def baseline_fit(base: Model, data: FitData, candidates: tuple[str, ...], spec: FitSpec, *,
                 also_held: tuple[str, ...] = (), evaluate_only: bool = False, estimate_noise: bool | str | None = None,
                 say) -> tuple[Model, Fit]:
    """The baseline with every candidate at zero, as `diagnose` and `plan` fit it: `base` with each of
    `candidates` added at zero (the model every later fit of the diagnosis starts from) and its fit to `data`
    as `spec` says, with the candidates (and `also_held`) held too, or with `evaluate_only` evaluated where its
    parameters are. `say` is the caller's progress. Returns (that model, its fit)."""
    full = Model(base.device, base.effects + tuple(zero_effect(c) for c in candidates))
    if not evaluate_only:
        n_devices = np.shape(next(iter(data.blocks.values())).mask)[0]
        say(f"fitting the baseline: {n_devices} device(s), {data.num_points()} points, every one of "
            f"{len(candidates)} candidate effects held at zero")
        say.compiling(("identify", full_key(full, data)), "the lot's fit with every candidate")
    fit = identify(full, data, spec=spec.holding(tuple(candidates) + tuple(also_held)), evaluate_only=evaluate_only,
                   estimate_noise=estimate_noise, progress=False)
    assert isinstance(fit, Fit)  # a lot strategy other than a population is not in the spec a diagnosis passes
    return full, fit
