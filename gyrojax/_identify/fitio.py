"""`save_fit` / `load_fit`: a `Fit` on disk, round-tripped exactly.

A fit file is one binary file:

    GYROJAX-FIT\\n  <8-byte little-endian header length>  <JSON header>  <equinox leaves>

The header holds everything static (preset and effect names, parameter names, devices, entries, messages,
unidentifiable directions, each device's status and warnings, the data's runs, source and recorded fields,
the gyrojax version), a description of every leaf (kind, shape, dtype), a SHA-256 of the leaves and a SHA-256 of
the header itself (`header_digest`); the leaves are `eqx.tree_serialise_leaves` of the `Fit`. Loading rebuilds
the skeleton from the preset (`gyrojax.preset`), or from the device file's text the header stores for a device
of no preset's structure, and the effects (`zero_effect`), lays the described leaves into it and deserialises:
values are bit-for-bit those saved.

Loading reads only a regular file (`_reading.open_regular`), and within bounds: a header of at most
`MAX_HEADER_BYTES`, no larger than the file; arrays whose described sizes the file holds, and no more than
that (each stored array's own shape is checked against its description before it is read). Nothing of a size
the header claims is allocated before the file is known to hold it.

Format versions: 3 adds the header's checksum; 2 adds each device's status and warnings (and the arrays that go
with them); version 1 files are still read, with every device's status `"unknown"`, and version 2 files with a
warning that their header is not covered. A file whose devices are not all `"ok"` loads with a `UserWarning`
naming them: a failed fit is saved like a good one, but never read back silently.
"""

import dataclasses
import hashlib
import io
import json
import math
import os
import struct
import warnings
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data.arrays import ARRAY_FIELDS, SweepArrays
from .._data.io import atomic_write_bytes
from .._data.reading import open_regular, read_exactly
from .._effects.plugins import user_code_changes, user_effect_code
from .._model.fitdata import FIT_COLUMNS, FitData
from .._model.parameters import Entry, Model, batched, zero_effect
from .._version import __version__
from . import Fit, Unidentifiable, chi2_p_value


MAGIC = b"GYROJAX-FIT\n"
FORMAT_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
EXPECTED = "give a fit file written by gyrojax.save_fit or `gyrojax identify --save`"

MAX_HEADER_BYTES = 64 * 2**20
"""The largest header a fit file may have: one of a lot of a thousand devices is a few MB."""

_NPY_HEADER_MAX = 4096
"""The most bytes numpy's `.npy` header of one stored array takes (a multiple of 64; about 128 for a fit's)."""

# The array fields of a sweep's arrays that version 1 files stored (later ones were added to the class since).
_V1_BLOCK_FIELDS = ("inputs", "outputs", "sigmas", "temperatures", "mask")
_V1_NOTE = ("this fit file (format version 1) predates the status checks: its scale factor was not checked for "
            "being determined by the data, for misfit or for plausibility")
_V2_NOTE = ("this fit file (format version 2) predates the header's checksum: an edit of its statuses, names or "
            "data labels cannot be detected. Save the fit again (gyrojax.save_fit) or fit the data again to have it "
            "covered")


def _unbatched_device(model: Model):
    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, model.device)


def _preset_of(model: Model) -> str | None:
    """The preset whose tree structure (static configuration included) the fitted device has; None for another
    device (one from a device file: the header then stores the device as a device file's text)."""
    from .._presets import PRESETS, preset

    target = jax.tree.structure(_unbatched_device(model))
    for name in PRESETS:
        if jax.tree.structure(preset(name)) == target:
            return name
    return None


def _skeleton_model(preset_name: str | None, effects: tuple[str, ...], n: int, device_file: str | None = None):
    from .._device.file import device_from_text
    from .._presets import preset

    if device_file is not None:
        device = device_from_text(device_file, check_loops=False).device
    elif preset_name is not None:
        device = preset(preset_name)
    else:
        raise ValueError("the fit file names no preset and holds no device file: its model cannot be rebuilt.")
    return batched(Model(device, tuple(zero_effect(e) for e in effects)), n)


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


def _block_fields(block: SweepArrays) -> list[str]:
    """The array fields a sweep's arrays hold data in (optional ones may be None)."""
    return [f for f in ARRAY_FIELDS if getattr(block, f) is not None]


def _skeleton_block(sweep: str, fields, runs) -> SweepArrays:
    """Arrays of `sweep` with the labels `runs` (per device) and zeros in `fields` (the others None), shaped so
    that they are valid (the leaves are replaced on loading)."""
    shape = (len(runs), max((len(r) for r in runs), default=0), 1)
    leaves = {f: (np.zeros(shape, dtype=bool if f == "mask" else np.float64) if f in fields else None)
              for f in ARRAY_FIELDS}
    # NumPy placeholders for the stored leaves (loaded as saved), in the fields' places: typed as what they become.
    return SweepArrays(**cast(dict[str, Any], leaves), kind=sweep, devices=tuple(d for d, _ in runs),
                       runs=tuple(r for _, r in runs), column_order=FIT_COLUMNS)


def _skeleton_fit(header: dict, model: Model) -> Fit:
    """A `Fit` with the header's static fields, `model`, and zero-size placeholders for every other leaf
    (replaced by the described leaves before deserialising). A version 1 header gives None for the arrays that
    version added (no leaves: the payload has none for them); `_from_v1` fills them."""
    z = np.zeros(())
    v1 = header["format_version"] == 1
    sweeps = header["sweeps"]
    stored = header.get("block_fields") or {s: list(_V1_BLOCK_FIELDS) for s in sweeps}
    unknown = sorted({nm for s in sweeps for nm in stored[s]} - set(ARRAY_FIELDS))
    if unknown:
        raise ValueError(f"the file's data hold fields this gyrojax does not know: {', '.join(unknown)}")
    # By name, so that fields added to SweepArrays later are None (not stored) rather than misplaced.
    runs = {s: tuple(zip(header["devices"], (tuple(r) for r in per_device))) for s, per_device in header["data_runs"]}
    blocks = {s: _skeleton_block(s, stored[s], runs[s]) for s in sweeps}
    data = FitData(blocks, bool(header["data_weighted"]), header["data_source"])
    per_sweep = {s: z for s in header["result_sweeps"]}
    n = len(header["devices"])
    # A version 1 payload has no leaves for these: None in the skeleton, and `_from_v1` fills them after loading.
    new = cast(np.ndarray, None) if v1 else z
    return Fit(model=model, names=tuple(header["names"]), lot_names=tuple(header["lot_names"]), values=z,
               stderr=z, lot_values=z, lot_stderr=z, free=tuple(bool(f) for f in header["free"]), covariance=z,
               u=z, u_lot=z, residuals=dict(per_sweep), predictions=dict(per_sweep), biases=dict(per_sweep),
               chi2=z, dof=z, converged=z, result_message=tuple(header["result_message"]), num_steps=z,
               unsettled=z, unidentifiable=tuple(Unidentifiable(parameters=tuple(u["parameters"]), held=u["held"],
                                                                singular_value=float(u["singular_value"]))
                                                 for u in header["unidentifiable"]),
               scale_factor=z, scale_factor_stderr=z, devices=tuple(header["devices"]), data=data,
               entries=tuple(_entry_from(e) for e in header["entries"]), weighted=bool(header["weighted"]),
               jacobian=z, residual_vector=z,
               status=("unknown",) * n if v1 else tuple(header["status"]),
               warnings=((_V1_NOTE,),) * n if v1 else tuple(tuple(w) for w in header["warnings"]),
               reject_alpha=float("nan") if v1 else float(header["reject_alpha"]),
               stderr_scaled=new, lot_stderr_scaled=new, scale_factor_stderr_scaled=new, noise_dof=new,
               p_value=new, p_value_total=new)


def _from_v1(fit: Fit) -> Fit:
    """A version 1 fit with the arrays version 2 added: unscaled errors (nothing was tested), the noise taken
    as given and the chi2 test's p-values (a version 1 fit of data without output_sigma had unit weights and
    its covariance scaled by chi2_red: its p-values mean nothing, which its status "unknown" says)."""
    inf = np.full(len(fit.devices), np.inf)
    p = chi2_p_value(np.asarray(fit.chi2), np.asarray(fit.dof), inf)
    p_total = chi2_p_value(np.asarray(fit.chi2_total), np.asarray(fit.dof_total), np.asarray(np.inf))
    return dataclasses.replace(fit, stderr_scaled=fit.stderr, lot_stderr_scaled=fit.lot_stderr,
                               scale_factor_stderr_scaled=fit.scale_factor_stderr, noise_dof=jnp.asarray(inf),
                               p_value=jnp.asarray(p), p_value_total=jnp.asarray(p_total))


def _header(fit: Fit, preset_name: str | None) -> dict:
    """Everything static of `fit` for the file's header (without the leaves' description and checksum)."""
    held = [nm for nm, f in zip(fit.names, fit.free) if not f]
    return {
        "format": "gyrojax-fit", "format_version": FORMAT_VERSION, "gyrojax_version": __version__,
        "preset": preset_name, "effects": list(fit.model.effect_names),
        "free": [bool(f) for f in fit.free], "held": held, "shared": list(fit.lot_names),
        "names": list(fit.names), "lot_names": list(fit.lot_names), "devices": list(fit.devices),
        "result_message": list(fit.result_message),
        "status": list(fit.status), "warnings": [list(w) for w in fit.warnings],
        "reject_alpha": float(fit.reject_alpha),
        "block_fields": {s: _block_fields(b) for s, b in fit.data.blocks.items()},
        "unidentifiable": [{"parameters": list(u.parameters), "held": u.held, "singular_value": float(u.singular_value)}
                           for u in fit.unidentifiable],
        "entries": [_entry_json(e) for e in fit.entries], "weighted": bool(fit.weighted),
        "sweeps": list(fit.data.blocks), "result_sweeps": list(fit.residuals),
        "data_runs": [[s, [list(r) for r in runs]] for s, runs in fit.data.runs],
        "data_weighted": bool(fit.data.weighted), "data_source": fit.data.source,
        # the code of the user effects the fit used (gyrojax._effects.plugins): loading with other code warns
        "user_effects": user_effect_code(fit.model.effect_names),
    }


def save_fit(fit: Fit, path: str | os.PathLike) -> None:
    """Write `fit` to `path` (atomically), to be read back exactly by `load_fit`.

    **Arguments:**

    - `fit`: a `gyrojax.Fit` whose device is built from a preset (the file names the preset and rebuilds
      the model's structure from it and the effects' names) or is any other device a device file can hold (the
      header stores it as a device file's text, `gyrojax.load_device`, and rebuilds the structure from that).
    - `path`: the file to write (any suffix; `.fit` by convention).
    """
    if not isinstance(fit, Fit):
        raise TypeError(f"save_fit: fit must be a gyrojax.Fit, got {type(fit).__name__}.")
    n = len(fit.devices)
    preset_name = _preset_of(fit.model)
    device_file = None
    if preset_name is None:  # not a preset's structure: the device's own file rebuilds it (its terms cannot)
        from .._device.file import device_file_text

        device_file = device_file_text(_unbatched_device(fit.model))
    effects = fit.model.effect_names
    skeleton = _skeleton_model(preset_name, effects, n, device_file)
    if jax.tree.structure(skeleton) != jax.tree.structure(fit.model):
        raise ValueError(f"save_fit: the fit's model does not have the structure of "
                         f"{'preset ' + repr(preset_name) if preset_name else 'its device file'} with "
                         f"effects {list(effects)}; it cannot be rebuilt on loading.")
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, fit)
    payload = buf.getvalue()
    header = _header(fit, preset_name) | {"leaves": [_leaf_spec(x) for x in jax.tree.leaves(fit)],
                                          "sha256": hashlib.sha256(payload).hexdigest()}
    if device_file is not None:
        header["device_file"] = device_file
    header["header_sha256"] = header_digest(header)
    head = json.dumps(header, allow_nan=False).encode()
    atomic_write_bytes(path, MAGIC + struct.pack("<Q", len(head)) + head + payload)


def _described_bytes(specs) -> tuple[int, int, str]:
    """The bytes of array data the header's leaf descriptions claim, the number of serialised leaves, and the
    largest array's description; raises `ValueError` for a description that is not a numeric array's."""
    total, count, largest, largest_bytes = 0, 0, "none", -1
    if not isinstance(specs, list):
        raise ValueError("the header's leaf descriptions are not a list")
    for i, spec in enumerate(specs):
        kind = spec.get("kind") if isinstance(spec, dict) else None
        if kind == "scalar":
            total, count = total + 16, count + 1  # saved as a 0-d array of at most 16 bytes
        elif kind in ("jax", "numpy"):
            shape = spec.get("shape")
            if not isinstance(shape, list) or not all(type(n) is int and n >= 0 for n in shape):
                raise ValueError(f"array {i}: shape {shape!r} is not a list of sizes")
            try:
                dtype = np.dtype(spec.get("dtype"))
            except TypeError:
                raise ValueError(f"array {i}: dtype {spec.get('dtype')!r} is not a dtype") from None
            if dtype.kind not in "biufc":
                raise ValueError(f"array {i}: dtype {dtype} is not numeric")
            nbytes = math.prod(shape) * dtype.itemsize
            if nbytes > largest_bytes:
                largest, largest_bytes = f"array {i} of shape {shape} and dtype {dtype}, {nbytes} bytes", nbytes
            total, count = total + nbytes, count + 1
        elif kind != "other":
            raise ValueError(f"leaf {i}: unknown description {spec!r}")
    return total, count, largest


def _check_payload_size(header: dict, size: int, path: str) -> None:
    """Refuse a file whose header describes more array data than the file holds (before anything of that size
    is allocated), or whose arrays are larger than the header describes."""
    try:
        described, count, largest = _described_bytes(header.get("leaves"))
    except (ValueError, AttributeError) as e:
        raise ValueError(f"{path}: corrupt gyrojax fit file: {e}.") from None
    if described > size:
        raise ValueError(f"{path}: corrupt gyrojax fit file: its header describes {described} bytes of arrays (the "
                         f"largest: {largest}) but the file holds {size} bytes after its header.")
    if size > described + count * _NPY_HEADER_MAX:
        raise ValueError(f"{path}: corrupt gyrojax fit file: it holds {size} bytes of arrays after its header, more "
                         f"than the {described} bytes of {count} arrays (with at most {_NPY_HEADER_MAX} bytes of "
                         "header each) that its header describes.")


def _checked_leaf(f, like):
    """Deserialise one leaf as equinox does, after checking that the stored array has the shape and dtype the
    header described (so that no stored array is larger than the file's checked size allows)."""
    if isinstance(like, (jax.Array, np.ndarray)):
        start = f.tell()
        version = np.lib.format.read_magic(f)
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = read(f)
        if tuple(shape) != tuple(np.shape(like)) or np.dtype(dtype) != np.dtype(like.dtype):
            raise ValueError(f"a stored array of shape {list(shape)} and dtype {dtype} where the header describes "
                             f"{list(np.shape(like))} and {like.dtype}")
        f.seek(start)
    return eqx.default_deserialise_filter_spec(f, like)


def header_digest(header: dict) -> str:
    """The SHA-256 of a fit file's header (its `header_sha256` left out) in a canonical JSON form; the header
    holds the SHA-256 of the arrays, so this covers the whole file."""
    body = {k: v for k, v in header.items() if k != "header_sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, allow_nan=False, separators=(",", ":")).encode()).hexdigest()


def _read(path: str) -> tuple[dict, bytes]:
    """The header and the arrays' bytes of the fit file at `path`, read within the bounds its size and header
    give; raises `ValueError` naming the file for anything else."""
    with open_regular(path, EXPECTED) as f:
        size = os.fstat(f.fileno()).st_size
        lead = f.read(len(MAGIC) + 8)
        if not lead.startswith(MAGIC):
            raise ValueError(f"{path}: not a gyrojax fit file (it does not start with {MAGIC!r}); write one with "
                             "gyrojax.save_fit or `gyrojax identify --save`.")
        try:
            (length,) = struct.unpack("<Q", lead[len(MAGIC):])
            rest = size - len(lead)
            if length > min(rest, MAX_HEADER_BYTES):
                raise ValueError(f"its header claims {length} bytes; the file holds {rest} after the header's length "
                                 f"and a header has at most {MAX_HEADER_BYTES}")
            header = json.loads(read_exactly(f, length, path).decode())
            if not isinstance(header, dict) or header.get("format") != "gyrojax-fit":
                raise ValueError("the header does not describe a gyrojax fit")
        except (struct.error, UnicodeDecodeError, json.JSONDecodeError, ValueError, AttributeError) as e:
            raise ValueError(f"{path}: corrupt gyrojax fit file: unreadable header ({e}).") from None
        if header.get("format_version") not in READABLE_VERSIONS:
            raise ValueError(f"{path}: fit file format version {header.get('format_version')!r}; this gyrojax reads "
                             f"versions {', '.join(map(str, READABLE_VERSIONS))}.")
        _check_payload_size(header, size - len(lead) - length, path)
        payload = read_exactly(f, size - len(lead) - length, path)
        if f.read(1):
            raise ValueError(f"{path}: the file grew while it was read; read it again when it is complete.")
    return header, payload


def load_fit(path: str | os.PathLike) -> Fit:
    """Read a fit written by `save_fit`. Raises a `ValueError` naming the file if it is not a regular file (a
    folder, a FIFO, a device), is not a gyrojax fit file, is truncated, corrupt or edited (its header and its
    arrays are covered by checksums), describes arrays that the file does not hold, or was written by an
    incompatible format version. Warns (`UserWarning`, naming the file and the devices) when some device's
    status is not `"ok"`, and for files of format versions 1 (whose results predate the status checks) and 2
    (whose header no checksum covers)."""
    path = os.fspath(path)
    header, payload = _read(path)
    version = header["format_version"]
    if version >= 3:
        try:
            digest = header_digest(header)
        except ValueError as e:  # a NaN or infinity written into the header by hand
            raise ValueError(f"{path}: corrupt gyrojax fit file: unreadable header ({e}).") from None
        if digest != header.get("header_sha256"):
            raise ValueError(f"{path}: corrupt gyrojax fit file: its header does not match the header's checksum "
                             "(edited or damaged). A fit file is not edited by hand: its statuses, names and data "
                             "are what the fit found; fit the data again.")
    if hashlib.sha256(payload).hexdigest() != header.get("sha256"):
        raise ValueError(f"{path}: corrupt gyrojax fit file: the stored arrays do not match the header's "
                         "checksum (truncated or modified).")
    try:
        model = _skeleton_model(header["preset"], tuple(header["effects"]), len(header["devices"]),
                                header.get("device_file"))
        skeleton = _skeleton_fit(header, model)
        leaves, treedef = jax.tree.flatten(skeleton)
        specs = header["leaves"]
        if len(specs) != len(leaves):
            raise ValueError(f"the header describes {len(specs)} arrays, the rebuilt fit has {len(leaves)}")
        like = jax.tree.unflatten(treedef, [_placeholder(s, x) for s, x in zip(specs, leaves)])
        fit = eqx.tree_deserialise_leaves(io.BytesIO(payload), like, filter_spec=_checked_leaf)
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        raise ValueError(f"{path}: cannot rebuild the fit (preset {header.get('preset')!r}, effects "
                         f"{header.get('effects')!r}): {e}.") from None
    if "user_effects" in header:
        for change in user_code_changes(header["user_effects"], tuple(header["effects"])):
            warnings.warn(f"{path}: {change}: the fit's numbers may not be what this code computes; fit the data "
                          "again with it.", UserWarning, stacklevel=2)
    if version == 2:
        warnings.warn(f"{path}: {_V2_NOTE}.", UserWarning, stacklevel=2)
    if version == 1:
        fit = _from_v1(fit)
        warnings.warn(f"{path}: {_V1_NOTE}; its {len(fit.devices)} device(s) have status 'unknown'. Fit the data "
                      "again to have them checked.", UserWarning, stacklevel=2)
        return fit
    bad = [f"{d} ({s}: {w[0]})" if w else f"{d} ({s})"
           for d, s, w in zip(fit.devices, fit.status, fit.warnings) if s != "ok"]
    if bad:
        warnings.warn(f"{path}: {len(bad)} of {len(fit.devices)} device(s) are not 'ok': " + "; ".join(bad),
                      UserWarning, stacklevel=2)
    return fit
