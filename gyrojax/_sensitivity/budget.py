r"""Nonlinearity budget: how many ppm of scale-factor nonlinearity each effect causes, and its gradients.

Seed 000 §3 splits its closed-loop gyro's scale-factor nonlinearity by source: the FTR DAC stage alone
contributes 460.679 ppm of the 539.281 ppm measured for the whole loop, a share of 85.424 %
(460.679 / 539.281). [`gyrojax.nonlinearity_budget`][] does the same for a model: on a rate-table sweep
(steady tier) it evaluates the device

- with no effect (the *base*: what the resonator and loops give on their own),
- with each effect *alone* (the others at zero: every effect is nested at zero),
- with all effects *jointly*,

and from each rate-table curve the scale-factor nonlinearity of [`gyrojax.fit_scale_factor`][] (least-squares
line, max |residual| / full scale, and the RMS figure beside it). An effect's *own* curve is its alone residual
minus the base residual (what it adds). The joint curve is exactly the base curve plus the sum of the own
curves plus an *interaction* curve (zero to first order in the effects' sizes; `interaction_ppm` is its max):
one effect can change the operating point another acts at (a gain error moves the DAC word the INL bends).

Shares. Seed 000's share is a source's figure over the whole loop's (460.679 / 539.281 = 85.424 %). Over
several effects such ratios do not add up to 100 %, and one of them can exceed 100 %: a max of a sum is not
the sum of the maxima, and an effect that does not bend the curve itself can still shrink another's (on
paper-qmg, `pushpull_mismatch` and `duffing_drive` are pure gain changes alone, but with the INL present
they move the word the DAC sees: at typical sizes on seed 000's 22 rates the INL's own 459.856 ppm is
100.04 % of the joint 459.664 ppm). So a
share here is of the *stack-up*: the sum of the max figures of the parts the joint curve is made of (base,
each effect's own curve, the interaction), the worst case the joint could reach if every part peaked at the
same rate with the same sign (the joint max never exceeds it). The shares of the base, of every effect and
of the interaction are between 0 and 100 % and add to 100 %; with one dominant source the stack-up is close
to the joint figure, and its share to seed 000's ratio.

The gradient of the joint nonlinearity (max definition) with respect to every physical parameter of
`gyrojax.PARAMETERS` that the device has and to every parameter of every effect is taken with `jax.grad`
through the steady tier (implicit differentiation of the root find). A max has a kink where two residuals
tie; elsewhere the gradient is exact.
"""

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._compile.jit import jit
from .._effects.base import AbstractEffect
from .._effects.registry import EFFECTS, effect as _named_effect
from .._gyroscope import Gyroscope
from .._lots.stack import as_arrays
from .._metrics import FULL_SCALE_CONVENTIONS, fit_scale_factor
from .._model.parameters import PARAMETERS, Model, effect_leaves
from .._simulate.tiers import Steady
from .._sweeps.rate_table import DING_ZHOU_2025_RATES_DPS, rate_sweep
from .._units import DEG


SEED000_BUDGET = {"dac_ppm": 460.679, "total_ppm": 539.281, "dac_share_pct": 85.424}
"""Seed 000 §3: the DAC stage's nonlinearity, the closed loop's, and the DAC's share (ppm, ppm, %)."""


class EffectContribution(eqx.Module):
    """One effect's line of a [`gyrojax.metrics.NonlinearityBudget`][].

    **Fields:** `name`; `alone_max_ppm`, `alone_rms_ppm` (the device with this effect only);
    `own_max_ppm`, `own_rms_ppm` (its own residual curve: alone minus base); `share_pct` (own max over the
    stack-up `NonlinearityBudget.stack_ppm`, in %: between 0 and 100, and with the base's and the
    interaction's shares adding to 100); `own_residual_ppm` (the own curve per rate, ppm of full scale).
    """

    name: str = eqx.field(static=True)
    alone_max_ppm: float
    alone_rms_ppm: float
    own_max_ppm: float
    own_rms_ppm: float
    share_pct: float
    own_residual_ppm: Float[np.ndarray, " point"]


class NonlinearityBudget(eqx.Module):
    """The solution of [`gyrojax.nonlinearity_budget`][].

    **Fields:**

    - `rates_dps`: the table rates, deg/s.
    - `base_max_ppm`, `base_rms_ppm`: the device without any of the effects.
    - `joint_max_ppm`, `joint_rms_ppm`: with all of them.
    - `effects`: one `EffectContribution` per effect, in the order given.
    - `interaction_ppm`: max |joint - base - sum of own curves| / full scale, ppm.
    - `stack_ppm` (property): base max + the own maxima + the interaction, ppm: what the shares are of;
      `base_share_pct`, `interaction_share_pct` (properties): the base's and the interaction's shares.
    - `residual_ppm`: dict `"base"`, `"joint"` and each effect name (alone) -> residual per rate, ppm of full
      scale.
    - `gradient`: dict parameter name -> d(joint_max_ppm)/d(parameter), in ppm per unit of the parameter
      (effect parameters as `"effect.field"`, arrays as lists).
    - `relative_gradient`: dict name -> parameter x gradient: ppm per unit relative change (a 1 % change
      moves the nonlinearity by 0.01 x this), for the physical parameters.
    - `full_scale`: the convention of [`gyrojax.fit_scale_factor`][].
    """

    rates_dps: Float[np.ndarray, " point"]
    base_max_ppm: float
    base_rms_ppm: float
    joint_max_ppm: float
    joint_rms_ppm: float
    effects: tuple[EffectContribution, ...]
    interaction_ppm: float
    residual_ppm: dict[str, Float[np.ndarray, " point"]]
    gradient: dict[str, float | list]
    relative_gradient: dict[str, float]
    full_scale: str = eqx.field(static=True)

    @property
    def stack_ppm(self) -> float:
        return self.base_max_ppm + sum(e.own_max_ppm for e in self.effects) + self.interaction_ppm

    @property
    def base_share_pct(self) -> float:
        return _share(self.base_max_ppm, self.stack_ppm)

    @property
    def interaction_share_pct(self) -> float:
        return _share(self.interaction_ppm, self.stack_ppm)

    def table(self) -> str:
        """The budget as a plain-text table. Figures below 0.0005 ppm (round-off of the steady-state root
        finds, about 1e-10 ppm, for an effect that does not bend the curve) read "< 0.001"."""
        lines = [f"{'source':<20} {'alone max':>10} {'own max':>9} {'own rms':>9} {'share':>8}",
                 f"{'':<20} {'ppm':>10} {'ppm':>9} {'ppm':>9} {'% stack':>8}",
                 f"{'base (no effect)':<20} {_fmt(self.base_max_ppm, 10)} {_fmt(self.base_max_ppm, 9)} "
                 f"{_fmt(self.base_rms_ppm, 9)} {_fmt(self.base_share_pct, 8)}"]
        for e in self.effects:
            lines.append(f"{e.name:<20} {_fmt(e.alone_max_ppm, 10)} {_fmt(e.own_max_ppm, 9)} "
                         f"{_fmt(e.own_rms_ppm, 9)} {_fmt(e.share_pct, 8)}")
        lines.append(f"{'interaction':<20} {'':>10} {_fmt(self.interaction_ppm, 9)} {'':>9} "
                     f"{_fmt(self.interaction_share_pct, 8)}")
        lines.append(f"{'joint':<20} {_fmt(self.joint_max_ppm, 10)} {'':>9} {_fmt(self.joint_rms_ppm, 9)} {'':>8}")
        lines.append(f"shares are of the stack-up, base + own maxima + interaction = {self.stack_ppm:.3f} ppm "
                     f"(the joint max, {self.joint_max_ppm:.3f} ppm, is at most that)")
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "rates_dps": [float(x) for x in self.rates_dps],
            "full_scale": self.full_scale,
            "base": {"max_ppm": self.base_max_ppm, "rms_ppm": self.base_rms_ppm},
            "joint": {"max_ppm": self.joint_max_ppm, "rms_ppm": self.joint_rms_ppm},
            "effects": [{"effect": e.name, "alone_max_ppm": e.alone_max_ppm, "alone_rms_ppm": e.alone_rms_ppm,
                         "own_max_ppm": e.own_max_ppm, "own_rms_ppm": e.own_rms_ppm, "share_pct": e.share_pct}
                        for e in self.effects],
            "interaction_ppm": self.interaction_ppm,
            "stack_ppm": self.stack_ppm,
            "base_share_pct": self.base_share_pct,
            "interaction_share_pct": self.interaction_share_pct,
            "gradient_ppm_per_unit": self.gradient,
            "relative_gradient_ppm": self.relative_gradient,
        }


def _share(ppm, stack_ppm):
    """ppm as a percentage of the stack-up (NaN when the stack-up is zero)."""
    return 100.0 * ppm / stack_ppm if stack_ppm > 0 else float("nan")


def _fmt(value, width):
    """A ppm or % figure to 3 decimals; below 0.0005 (round-off for a curve that does not bend) "< 0.001"."""
    if not np.isfinite(value):
        return f"{'n/a':>{width}}"
    return f"{value:{width}.3f}" if abs(value) >= 5e-4 else f"{'< 0.001':>{width}}"


def _split(model, effects, device):
    """(base device, effect modules) from the accepted inputs."""
    if hasattr(model, "model") and isinstance(getattr(model, "model"), Model):  # a Fit
        model = model.model
    if isinstance(model, Model):
        base, present = model.device, tuple(model.effects)
    elif isinstance(model, Gyroscope):
        base, present = model, ()
    else:
        raise ValueError(f"nonlinearity_budget: model must be a gyrojax.Gyroscope, a gyrojax Model or a Fit, "
                         f"got {type(model).__name__}.")
    base = as_arrays(base)  # Python numbers become 0-d arrays: a single device then has 0-d leaves
    leaves = [x for x in jax.tree.leaves(base) if eqx.is_array(x)]
    lot = bool(leaves) and all(jnp.ndim(x) >= 1 for x in leaves)
    if lot:
        if device is None:
            raise ValueError("nonlinearity_budget: model is a lot (a leading device axis); pass device=INDEX "
                             "to choose one device.")
        pick = lambda t: jax.tree.map(lambda x: x[device] if eqx.is_array(x) and jnp.ndim(x) >= 1 else x, t)  # noqa: E731
        base, present = pick(base), tuple(pick(e) for e in present)
    elif device not in (None, 0):
        raise ValueError(f"nonlinearity_budget: device={device!r} given but model is a single device.")
    by_name = {e.name: e for e in present}
    if effects is None:
        chosen = tuple(e for e in present if any(np.any(np.asarray(x) != 0) for x in jax.tree.leaves(e)))
        if not chosen:
            raise ValueError("nonlinearity_budget: the model has no active (nonzero) effect; pass effects= "
                             "(names at typical size, or effect modules).")
    else:
        if isinstance(effects, (str, AbstractEffect)):
            effects = (effects,)
        chosen = []
        for e in effects:
            if isinstance(e, AbstractEffect):
                chosen.append(e)
            elif isinstance(e, str):
                if e in by_name:
                    chosen.append(by_name[e])
                elif e in EFFECTS:
                    chosen.append(_named_effect(e, 1.0))
                else:
                    raise ValueError(f"nonlinearity_budget: effects names unknown effect {e!r}; expected names "
                                     f"of gyrojax.EFFECTS: {', '.join(EFFECTS)}.")
            else:
                raise ValueError(f"nonlinearity_budget: effects must hold effect names or gyrojax effect "
                                 f"modules, got {e!r}.")
        chosen = tuple(chosen)
    names = [e.name for e in chosen]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"nonlinearity_budget: effects lists {', '.join(twice)} more than once.")
    for e in chosen:
        if not type(e).supports(base):
            raise ValueError(f"nonlinearity_budget: effect {e.name!r} cannot act on device {base.name!r}.")
    # effects of the model that are not budgeted stay in the base
    rest = tuple(e for e in present if e.name not in names)
    for e in rest:
        base = e.apply(base)
    return as_arrays(base), tuple(as_arrays(e) for e in chosen)


@jit
def _curves(base, effects, on, x_dps, rates, full_scale):
    """Residual curves (ppm of full scale) and max / RMS figures for each row of switches `on`."""

    def one(switch):
        g = base
        for k, eff in enumerate(effects):
            g = jax.tree.map(lambda p, s=switch[k]: s * p if eqx.is_inexact_array(p) else p, eff).apply(g)
        out = rate_sweep(g, rates, tier=Steady()).rate
        fit = fit_scale_factor(x_dps, out, full_scale=full_scale)
        return fit.residuals / fit.full_scale * 1e6, fit.nonlinearity_max_ppm, fit.nonlinearity_rms_ppm

    return jax.lax.map(one, on)


def _joint_max_ppm(params, base, effects, x_dps, rates, full_scale, where):
    phys, effs = params
    g = eqx.tree_at(lambda g: [w(g) for w in where], base, list(phys)) if where else base
    for eff in effs:
        g = eff.apply(g)
    out = rate_sweep(g, rates, tier=Steady()).rate
    return fit_scale_factor(x_dps, out, full_scale=full_scale).nonlinearity_max_ppm


_joint_grad = jit(eqx.filter_grad(_joint_max_ppm))


def nonlinearity_budget(model: Model | Gyroscope | str, effects: Sequence | None = None, *,
                        rates_dps: Float[ArrayLike, " point"] | Sequence[float] = DING_ZHOU_2025_RATES_DPS,
                        device: int | None = None, full_scale: str = "half_range",
                        gradients: bool = True) -> NonlinearityBudget:
    r"""Scale-factor nonlinearity of each effect alone and of all jointly, shares and gradients.

    **Arguments:**

    - `model`: a `gyrojax.Gyroscope` (the base; `effects` are added to it), a gyrojax `Model` (device plus
      effects, e.g. `fit.model`) or a `Fit` (its model). A lot needs `device`.
    - `effects`: what to budget: effect names (the model's own effect of that name, else the named effect at
      its typical size) or effect modules. Default: the model's nonzero effects. A model's effects that are
      not budgeted stay in the base.
    - `rates_dps`: the rate table, deg/s (default seed 000's 22 rates).
    - `device`: index of the device in a lot.
    - `full_scale`: convention of [`gyrojax.fit_scale_factor`][] (default `"half_range"`).
    - `gradients`: also take the gradients (one reverse pass through the steady tier).

    **Returns:** a [`gyrojax.metrics.NonlinearityBudget`][].
    """
    if full_scale not in FULL_SCALE_CONVENTIONS:
        raise ValueError(f"full_scale must be one of {', '.join(FULL_SCALE_CONVENTIONS)}, got {full_scale!r}.")
    x = np.asarray(rates_dps, dtype=float)
    if x.ndim != 1 or x.size < 3 or not np.all(np.isfinite(x)) or np.unique(x).size < 2:
        raise ValueError(f"rates_dps must be at least 3 finite rates (deg/s) with two distinct values, got "
                         f"{rates_dps!r}.")
    base, effs = _split(model, effects, device)
    n = len(effs)
    on = np.zeros((n + 2, n))
    on[1:n + 1] = np.eye(n)
    on[n + 1] = 1.0
    x_dps = jnp.asarray(x)
    rates = x_dps * DEG
    res, mx, rms = (np.asarray(a) for a in _curves(base, effs, jnp.asarray(on), x_dps, rates, full_scale))
    own = res[1:n + 1] - res[0]
    joint_max = float(mx[n + 1])
    interaction = float(np.max(np.abs(res[n + 1] - res[0] - own.sum(axis=0))))
    own_max = [float(np.max(np.abs(own[k]))) for k in range(n)]
    stack = float(mx[0]) + sum(own_max) + interaction  # = NonlinearityBudget.stack_ppm
    contributions = tuple(
        EffectContribution(name=e.name, alone_max_ppm=float(mx[1 + k]), alone_rms_ppm=float(rms[1 + k]),
                           own_max_ppm=own_max[k], own_rms_ppm=float(np.sqrt(np.mean(own[k] ** 2))),
                           share_pct=_share(own_max[k], stack), own_residual_ppm=own[k])
        for k, e in enumerate(effs))
    residual = {"base": res[0], "joint": res[n + 1]} | {e.name: res[1 + k] for k, e in enumerate(effs)}
    gradient, relative = {}, {}
    if gradients:
        phys = [(name, p) for name, p in PARAMETERS.items() if p.exists_on(base)]
        where = [p.where for _, p in phys]
        values = [jnp.asarray(w(base), dtype=float) for w in where]
        g_phys, g_eff = _joint_grad((values, effs), base, effs, x_dps, rates, full_scale, where)
        for (name, _), v, gv in zip(phys, values, g_phys):
            gradient[name] = float(gv)
            relative[name] = float(v * gv)
        for e, ge in zip(effs, g_eff):
            for f in effect_leaves(e):
                val = getattr(ge, f)
                if val is None:
                    continue
                val = np.asarray(val)
                gradient[f"{e.name}.{f}"] = float(val) if val.ndim == 0 else val.tolist()
    return NonlinearityBudget(rates_dps=x, base_max_ppm=float(mx[0]), base_rms_ppm=float(rms[0]),
                              joint_max_ppm=joint_max, joint_rms_ppm=float(rms[n + 1]), effects=contributions,
                              interaction_ppm=interaction, residual_ppm=residual, gradient=gradient,
                              relative_gradient=relative, full_scale=full_scale)
