"""What a fit may move: named physical parameters of a device, effect parameters, and their transforms.

A fit works in internal coordinates u, one float per scalar parameter, chosen so that u = 0 is the start
value and u = 1 is a change of natural size:

- `"log"` (positive quantities: frequencies, Q, masses, gains): p = p0 exp(u), so u is the relative change;
- `"linear"` (signed quantities: couplings, gain errors, effect parameters): p = p0 + scale u.

Effect parameters are nested at zero and scaled by the effect's typical size (`typical(1.0)`), so u = 1
means "the effect at its typical size".
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._device.file import is_device_file, load_device
from .._effects.base import AbstractEffect
from .._effects.registry import EFFECTS
from .._gyroscope import Gyroscope
from .._presets import preset
from .catalog import DEFAULT_FREE as DEFAULT_FREE, PARAMETERS, Parameter as Parameter  # what fits move, by name


class Model(eqx.Module):
    """A device and the effects added to it: what `identify` fits and `diagnose` extends.

    `device` may be a lot (leaves with a leading device axis); `effects` then carry the same axis.
    """

    device: Gyroscope
    effects: tuple[AbstractEffect, ...] = ()

    def gyroscope(self) -> Gyroscope:
        """The device with every effect applied."""
        gyro = self.device
        for eff in self.effects:
            gyro = eff.apply(gyro)
        return gyro

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)


def as_model(model) -> Model:
    """`model` as a `Model`: a `Model` as it is, a `Gyroscope`, a preset name or a device file's path (ending in
    .toml, `gyrojax.load_device`) without effects."""
    if isinstance(model, Model):
        return model
    if isinstance(model, Gyroscope):
        return Model(model)
    if isinstance(model, str):
        return Model(load_device(model) if is_device_file(model) else preset(model))
    raise TypeError(f"model must be a gyrojax.Model, a Gyroscope, a preset name or a device file (.toml), got "
                    f"{type(model).__name__}.")


def batched(model: Model, n: int) -> Model:
    """`model` with a leading axis of `n` devices on every leaf (a lot's device is kept as it is).

    An effect's leaf carries the device axis when it has one dimension more than the same leaf of one device
    (the effect's `typical` instance): a DAC INL's 4 coefficients on a lot of 4 devices are one device's, to be
    broadcast, not one coefficient per device."""
    def lead(x, one_ndim, name):
        x = jnp.asarray(x, dtype=x.dtype if hasattr(x, "dtype") else float)
        if one_ndim is None:  # an effect whose structure differs from its typical one: a leading n is the lot's
            per_device = x.ndim >= 1 and x.shape[0] == n
        else:
            per_device = x.ndim == one_ndim + 1
            if per_device and x.shape[0] != n:
                raise ValueError(f"effect {name!r}: a parameter of shape {x.shape} has a device axis of "
                                 f"{x.shape[0]}, the lot has {n} device(s).")
        return x if per_device else jnp.broadcast_to(x, (n,) + x.shape)

    def lot_effect(e):
        leaves, tree = jax.tree.flatten(e)
        one, one_tree = jax.tree.flatten(type(e).typical(1.0))
        ndims = [jnp.ndim(r) for r in one] if one_tree == tree else [None] * len(leaves)
        return jax.tree.unflatten(tree, [lead(x, d, e.name) for x, d in zip(leaves, ndims)])

    # Effects are per device: broadcast their leaves; the device is batched already (a lot) or broadcast.
    dev_leaves = jax.tree.leaves(model.device)
    lot = bool(dev_leaves) and all(jnp.ndim(x) >= 1 and jnp.shape(x)[0] == n for x in dev_leaves
                                   if eqx.is_array(x))
    device = model.device if lot else jax.tree.map(lambda x: jnp.broadcast_to(x, (n,) + jnp.shape(x))
                                                    if eqx.is_array(x) else x, model.device)
    return Model(device, tuple(lot_effect(e) for e in model.effects))


def effect_leaves(eff: AbstractEffect) -> tuple[str, ...]:
    """Names of the array fields of an effect (its parameters)."""
    return tuple(f.name for f in dataclasses.fields(eff)
                 if not f.metadata.get("static", False)
                 and isinstance(getattr(eff, f.name), (jax.Array, np.ndarray, float)))


def zero_effect(name: str) -> AbstractEffect:
    """The named effect with all its parameters zero (the model without it, in its shape)."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; expected one of {sorted(EFFECTS)}.")
    typical = EFFECTS[name].typical(1.0)
    return jax.tree.map(lambda x: jnp.zeros_like(jnp.asarray(x, dtype=float)), typical)


class Entry(eqx.Module):
    """One block of the internal vector: a physical parameter or one array field of an effect."""

    label: str = eqx.field(static=True)  # "k_vf" or "dac_inl.coefficients"
    size: int = eqx.field(static=True)
    shape: tuple[int, ...] = eqx.field(static=True)
    transform: str = eqx.field(static=True)
    effect_index: int | None = eqx.field(static=True)  # None: physical
    field: str | None = eqx.field(static=True)
    shared: bool = eqx.field(static=True)
    scale: tuple[float, ...] = eqx.field(static=True)  # per element (linear), flattened

    def names(self) -> tuple[str, ...]:
        if self.size == 1 and self.shape == ():
            return (self.label,)
        return tuple(f"{self.label}[{i}]" for i in range(self.size))

    def getter(self):
        if self.effect_index is None:
            return PARAMETERS[self.label].where
        i, f = self.effect_index, self.effect_field
        return lambda g, i=i, f=f: getattr(g, f)  # applied to the effect module

    @property
    def effect_field(self) -> str:
        """The field of the effect this entry is; a ValueError for a physical parameter's entry."""
        if self.field is None:
            raise ValueError(f"Entry {self.label!r} is a physical parameter, not a field of an effect.")
        return self.field


def _effect_scale(eff_name: str, field: str) -> np.ndarray:
    typ = np.asarray(getattr(EFFECTS[eff_name].typical(1.0), field), dtype=float).ravel()
    fallback = np.max(np.abs(typ)) if np.any(typ != 0) else 1.0
    return np.where(typ != 0, np.abs(typ), fallback)


def build_entries(model: Model, free: tuple[str, ...], shared: tuple[str, ...] = ()) -> tuple[Entry, ...]:
    """Entries for the physical parameters in `free` (names of `PARAMETERS`) and every field of every
    effect in the model (effects are always free: they were added to be fitted). `shared` names are one
    value for the whole lot."""
    entries = []
    for name in free:
        if name not in PARAMETERS:
            raise ValueError(f"unknown parameter {name!r} in free; expected names of gyrojax.PARAMETERS: "
                             f"{', '.join(PARAMETERS)}.")
        p = PARAMETERS[name]
        entries.append(Entry(name, 1, (), p.transform, None, None, name in shared, (float(p.scale),)))
    for i, eff in enumerate(model.effects):
        for f in effect_leaves(eff):
            shape = tuple(np.shape(getattr(EFFECTS[eff.name].typical(1.0), f)))
            label = f"{eff.name}.{f}"
            entries.append(Entry(label, int(np.prod(shape, dtype=int)), shape, "linear", i, f, label in shared,
                                 tuple(float(x) for x in _effect_scale(eff.name, f))))
    return tuple(entries)


def read_values(model: Model, entries) -> list:
    """Current values of the entries' leaves, for one device (unbatched model)."""
    out = []
    for e in entries:
        if e.effect_index is None:
            out.append(jnp.asarray(e.getter()(model.device), dtype=float))
        else:
            out.append(jnp.asarray(getattr(model.effects[e.effect_index], e.field), dtype=float))
    return out


def apply_u(model: Model, entries, start: list, u_dev, u_lot):
    """The model with internal coordinates applied: `start` holds the u = 0 values of each entry (one
    device), `u_dev` and `u_lot` the flat per-device and lot-shared vectors."""
    k_dev = k_lot = 0
    new_phys, phys_where, new_eff = [], [], {}
    for e, p0 in zip(entries, start):
        if e.shared:
            u = u_lot[k_lot:k_lot + e.size]
            k_lot += e.size
        else:
            u = u_dev[k_dev:k_dev + e.size]
            k_dev += e.size
        u = jnp.reshape(u, e.shape)
        if e.transform == "log":
            value = p0 * jnp.exp(u)
        else:
            value = p0 + jnp.reshape(jnp.asarray(e.scale), e.shape) * u
        if e.effect_index is None:
            new_phys.append(value)
            phys_where.append(e.getter())
        else:
            new_eff[(e.effect_index, e.field)] = value
    device = model.device
    if phys_where:
        device = eqx.tree_at(lambda g: [w(g) for w in phys_where], device, new_phys)
    effects = list(model.effects)
    for (i, f), value in new_eff.items():
        effects[i] = eqx.tree_at(lambda e, f=f: getattr(e, f), effects[i], value)
    return Model(device, tuple(effects))


def sizes(entries) -> tuple[int, int]:
    """(per-device, lot-shared) lengths of the internal vector."""
    return (sum(e.size for e in entries if not e.shared), sum(e.size for e in entries if e.shared))


def names(entries, shared: bool) -> tuple[str, ...]:
    return tuple(n for e in entries if e.shared == shared for n in e.names())
