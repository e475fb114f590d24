"""The stored form of an exported program (`export.py`): gyrojax's own format (`jax.export`'s serialization needs
the `flatbuffers` package, which gyrojax does not require) of a single-device program without effects or
shardings: a header with the program's key, an HMAC-SHA256 of the rest under the user's secret, the inputs' and
outputs' shapes and dtypes, the outputs' tree (arrays in tuples, lists and dicts) and the module's bytes."""

from __future__ import annotations

import hashlib
import hmac
import json

import jax
import jax.core  # ShapedArray: jax.core is not imported by `import jax` for type checkers
import numpy as np
from jax import export


_MAGIC = b"gyrojax-export 2\n"


def _tree_description(tree):
    """A JSON form of a tree of tuples, lists, dicts with string keys and None (`*`: a leaf)."""
    if tree.num_nodes == 1 and tree.num_leaves == 1:
        return "*"
    kind, data = tree.node_data()
    children = [_tree_description(c) for c in tree.children()]
    if kind is type(None):
        return None
    if kind in (tuple, list):
        return {kind.__name__: children}
    if kind is dict and all(type(k) is str for k in data):
        return {"dict": [list(data), children]}
    raise ValueError(f"outputs hold a {kind.__name__}: only arrays in tuples, lists and dicts are stored")


def _tree_example(description):
    if description == "*":
        return 0
    if description is None:
        return None
    (kind, value), = description.items()
    if kind == "dict":
        return dict(zip(value[0], (_tree_example(c) for c in value[1])))
    return {"tuple": tuple, "list": list}[kind](_tree_example(c) for c in value)


def _avals_json(avals):
    return [[list(a.shape), np.dtype(a.dtype).str, bool(a.weak_type)] for a in avals]


def _avals_from(items):
    return tuple(jax.core.ShapedArray(tuple(shape), np.dtype(dtype), weak_type=weak) for shape, dtype, weak in items)


def serialize(exported: export.Exported, key: str, secret: bytes) -> bytes:
    """The stored form of a single-device program without effects or shardings (`jax.export`'s own
    serialization needs the `flatbuffers` package, which gyrojax does not require)."""
    if (exported.nr_devices != 1 or exported.ordered_effects or exported.unordered_effects
            or exported.disabled_safety_checks
            or any(s is not None for s in (*exported.in_shardings_hlo, *exported.out_shardings_hlo,
                                           *exported._in_named_shardings, *exported._out_named_shardings))):
        raise ValueError("a program with effects, shardings or more than one device")
    meta = {"fun_name": exported.fun_name, "in_avals": _avals_json(exported.in_avals),
            "out_avals": _avals_json(exported.out_avals), "out_tree": _tree_description(exported.out_tree),
            "has_named_shardings": bool(exported._has_named_shardings), "platforms": list(exported.platforms),
            "calling_convention_version": int(exported.calling_convention_version),
            "module_kept_var_idx": [int(i) for i in exported.module_kept_var_idx],
            "uses_global_constants": bool(exported.uses_global_constants)}
    module = bytes(exported.mlir_module_serialized)
    meta["module_bytes"] = len(module)
    text = json.dumps(meta, sort_keys=True).encode()
    body = str(len(text)).encode() + b"\n" + text + module
    return _MAGIC + key.encode() + b"\n" + _digest(secret, body) + b"\n" + body


def _digest(secret: bytes, body: bytes) -> bytes:
    # Keyed: whoever can change an artifact but cannot read the user's secret cannot make a valid one.
    return hmac.new(secret, body, hashlib.sha256).hexdigest().encode()


def deserialize(data: bytes, key: str, secret: bytes) -> export.Exported:
    header = _MAGIC + key.encode() + b"\n"
    if not data.startswith(header):
        raise ValueError("wrong header")
    digest, body = data[len(header):].split(b"\n", 1)
    if not hmac.compare_digest(_digest(secret, body), digest):
        raise ValueError("damaged or not written by this user (its keyed digest differs)")
    size, rest = body.split(b"\n", 1)
    meta, module = json.loads(rest[:int(size)]), rest[int(size):]
    if len(module) != meta["module_bytes"]:
        raise ValueError("its module's size differs from its header's")
    in_avals, out_avals = _avals_from(meta["in_avals"]), _avals_from(meta["out_avals"])
    n, m = len(in_avals), len(out_avals)
    out_tree = jax.tree.structure(_tree_example(meta["out_tree"]))
    if out_tree.num_leaves != m:
        raise ValueError("outputs and their tree differ")
    return export.Exported(
        fun_name=meta["fun_name"], in_tree=jax.tree.structure((tuple(range(n)), {})), in_avals=in_avals,
        out_tree=out_tree, out_avals=out_avals, _has_named_shardings=meta["has_named_shardings"],
        _in_named_shardings=(None,) * n, _out_named_shardings=(None,) * m, in_shardings_hlo=(None,) * n,
        out_shardings_hlo=(None,) * m, nr_devices=1, platforms=tuple(meta["platforms"]), ordered_effects=(),
        unordered_effects=(), disabled_safety_checks=(), mlir_module_serialized=module,
        calling_convention_version=meta["calling_convention_version"],
        module_kept_var_idx=tuple(meta["module_kept_var_idx"]), uses_global_constants=meta["uses_global_constants"],
        _get_vjp=None)
