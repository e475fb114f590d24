"""`save_fit` / `load_fit`: a `Fit` on disk, round-tripped exactly.

A fit file is one binary file:

    GYROJAX-FIT\\n  <8-byte little-endian header length>  <JSON header>  <equinox leaves>

The header holds everything static (preset and effect names, parameter names, devices, entries, messages,
unidentifiable directions, the data's runs and source, the gyrojax version), a description of every leaf
(kind, shape, dtype) and a SHA-256 of the leaves; the leaves are `eqx.tree_serialise_leaves` of the `Fit`.
Loading rebuilds the skeleton from the preset (`gyrojax.preset`) and the effects (`zero_effect`), lays the
described leaves into it and deserialises: values are bit-for-bit those saved.
"""

import hashlib
import io
import json
import os
import struct

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._fitdata import FitData, SweepBlock
from ._identify import Fit, Unidentifiable, _batched
from ._io import atomic_write_bytes
from ._parameters import Entry, Model, zero_effect


MAGIC = b"GYROJAX-FIT\n"
FORMAT_VERSION = 1


def _unbatched_device(model: Model):
    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, model.device)


def _preset_of(model: Model) -> str:
    """The preset whose tree structure (static configuration included) the fitted device has."""
    from ._presets import PRESETS, preset

    target = jax.tree.structure(_unbatched_device(model))
    for name in PRESETS:
        if jax.tree.structure(preset(name)) == target:
            return name
    raise ValueError(f"save_fit: the fit's device has the structure of none of the presets ({', '.join(PRESETS)}); "
                     "a fit file rebuilds its model from a preset, so fit a device built from one.")


def _skeleton_model(preset_name: str, effects: tuple[str, ...], n: int) -> Model:
    from ._presets import preset

    return _batched(Model(preset(preset_name), tuple(zero_effect(e) for e in effects)), n)


def _leaf_spec(x):
    if eqx.is_array(x):
        return {"kind": "jax" if isinstance(x, jax.Array) else "numpy", "shape": list(np.shape(x)),
                "dtype": str(np.asarray(x).dtype) if not isinstance(x, jax.Array) else str(x.dtype)}
    if isinstance(x, (bool, int, float, complex, np.generic)):
        return {"kind": "scalar", "type": type(x).__name__}
    return {"kind": "other"}


def _placeholder(spec, like):
    if spec["kind"] == "jax":
        return jnp.zeros(spec["shape"], dtype=spec["dtype"])
    if spec["kind"] == "numpy":
        return np.zeros(spec["shape"], dtype=spec["dtype"])
    if spec["kind"] == "scalar":
        return {"bool": bool, "int": int, "float": float, "complex": complex}.get(spec["type"], float)(0)
    return like


def _entry_json(e: Entry) -> dict:
    return {"label": e.label, "size": e.size, "shape": list(e.shape), "transform": e.transform,
            "effect_index": e.effect_index, "field": e.field, "shared": e.shared, "scale": list(e.scale)}


def _entry_from(d: dict) -> Entry:
    return Entry(d["label"], int(d["size"]), tuple(d["shape"]), d["transform"], d["effect_index"], d["field"],
                 bool(d["shared"]), tuple(float(s) for s in d["scale"]))


def _skeleton_fit(header: dict, model: Model) -> Fit:
    """A `Fit` with the header's static fields, `model`, and zero-size placeholders for every other leaf
    (replaced by the described leaves before deserialising)."""
    z = np.zeros(())
    sweeps = header["sweeps"]
    block = SweepBlock(z, z, z, z, z)
    data = FitData({s: block for s in sweeps}, tuple(header["devices"]),
                   tuple((s, tuple(tuple(r) for r in runs)) for s, runs in header["data_runs"]),
                   bool(header["data_weighted"]), header["data_source"])
    per_sweep = {s: z for s in header["result_sweeps"]}
    return Fit(model=model, names=tuple(header["names"]), lot_names=tuple(header["lot_names"]), values=z,
               stderr=z, lot_values=z, lot_stderr=z, free=tuple(bool(f) for f in header["free"]), covariance=z,
               u=z, u_lot=z, residuals=dict(per_sweep), predictions=dict(per_sweep), biases=dict(per_sweep),
               chi2=z, dof=z, converged=z, result_message=tuple(header["result_message"]), num_steps=z,
               unsettled=z, unidentifiable=tuple(Unidentifiable(tuple(u["parameters"]), u["held"],
                                                                float(u["singular_value"]))
                                                 for u in header["unidentifiable"]),
               scale_factor=z, scale_factor_stderr=z, devices=tuple(header["devices"]), data=data,
               entries=tuple(_entry_from(e) for e in header["entries"]), weighted=bool(header["weighted"]),
               jacobian=z, residual_vector=z)


def save_fit(fit: Fit, path) -> None:
    """Write `fit` to `path` (atomically), to be read back exactly by `load_fit`.

    **Arguments:**

    - `fit`: a `gyrojax.Fit` whose device is built from a preset (the file names the preset and rebuilds
      the model's structure from it and the effects' names).
    - `path`: the file to write (any suffix; `.fit` by convention).
    """
    if not isinstance(fit, Fit):
        raise TypeError(f"save_fit: fit must be a gyrojax.Fit, got {type(fit).__name__}.")
    from . import __version__

    n = len(fit.devices)
    preset_name = _preset_of(fit.model)
    effects = fit.model.effect_names
    skeleton = _skeleton_model(preset_name, effects, n)
    if jax.tree.structure(skeleton) != jax.tree.structure(fit.model):
        raise ValueError(f"save_fit: the fit's model does not have the structure of preset {preset_name!r} with "
                         f"effects {list(effects)}; it cannot be rebuilt on loading.")
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, fit)
    payload = buf.getvalue()
    held = [nm for nm, f in zip(fit.names, fit.free) if not f]
    header = {
        "format": "gyrojax-fit", "format_version": FORMAT_VERSION, "gyrojax_version": __version__,
        "preset": preset_name, "effects": list(effects),
        "free": [bool(f) for f in fit.free], "held": held, "shared": list(fit.lot_names),
        "names": list(fit.names), "lot_names": list(fit.lot_names), "devices": list(fit.devices),
        "result_message": list(fit.result_message),
        "unidentifiable": [{"parameters": list(u.parameters), "held": u.held, "singular_value": float(u.singular_value)}
                           for u in fit.unidentifiable],
        "entries": [_entry_json(e) for e in fit.entries], "weighted": bool(fit.weighted),
        "sweeps": list(fit.data.blocks), "result_sweeps": list(fit.residuals),
        "data_runs": [[s, [list(r) for r in runs]] for s, runs in fit.data.runs],
        "data_weighted": bool(fit.data.weighted), "data_source": fit.data.source,
        "leaves": [_leaf_spec(x) for x in jax.tree.leaves(fit)],
        "sha256": hashlib.sha256(payload).hexdigest(),
    }
    head = json.dumps(header, allow_nan=False).encode()
    atomic_write_bytes(path, MAGIC + struct.pack("<Q", len(head)) + head + payload)


def load_fit(path) -> Fit:
    """Read a fit written by `save_fit`. Raises a `ValueError` naming the file if it is not a gyrojax fit
    file, is truncated or corrupt, or was written by an incompatible format version."""
    path = os.fspath(path)
    with open(path, "rb") as f:
        raw = f.read()
    if not raw.startswith(MAGIC):
        raise ValueError(f"{path}: not a gyrojax fit file (it does not start with {MAGIC!r}); write one with "
                         "gyrojax.save_fit or `gyrojax identify --save`.")
    try:
        (length,) = struct.unpack("<Q", raw[len(MAGIC):len(MAGIC) + 8])
        start = len(MAGIC) + 8
        header = json.loads(raw[start:start + length].decode())
        payload = raw[start + length:]
        if header.get("format") != "gyrojax-fit":
            raise ValueError("the header does not describe a gyrojax fit")
    except (struct.error, UnicodeDecodeError, json.JSONDecodeError, ValueError, AttributeError) as e:
        raise ValueError(f"{path}: corrupt gyrojax fit file: unreadable header ({e}).") from None
    if header.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{path}: fit file format version {header.get('format_version')!r}; this gyrojax reads "
                         f"version {FORMAT_VERSION}.")
    if hashlib.sha256(payload).hexdigest() != header.get("sha256"):
        raise ValueError(f"{path}: corrupt gyrojax fit file: the stored arrays do not match the header's "
                         "checksum (truncated or modified).")
    try:
        model = _skeleton_model(header["preset"], tuple(header["effects"]), len(header["devices"]))
        skeleton = _skeleton_fit(header, model)
        leaves, treedef = jax.tree.flatten(skeleton)
        specs = header["leaves"]
        if len(specs) != len(leaves):
            raise ValueError(f"the header describes {len(specs)} arrays, the rebuilt fit has {len(leaves)}")
        like = jax.tree.unflatten(treedef, [_placeholder(s, x) for s, x in zip(specs, leaves)])
        return eqx.tree_deserialise_leaves(io.BytesIO(payload), like)
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        raise ValueError(f"{path}: cannot rebuild the fit (preset {header.get('preset')!r}, effects "
                         f"{header.get('effects')!r}): {e}.") from None
