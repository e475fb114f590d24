"""The key of an exported program (`export.py`).

The key is a SHA-256 of everything that can change the program: the program's name; gyrojax's version and
a hash of every file of the installed package; the versions of Python, jax, jaxlib, numpy, equinox, lineax,
optimistix and diffrax; JAX's tracing configuration (`jax_enable_x64` and the rest of its trace context); the
backend, device kind and count; and a walk of the arguments: the shape, dtype and weak type of every array,
the value of every other leaf, every container and `equinox.Module`/dataclass field by name, and for every
class and function met, its qualified name, its closure and defaults, and, where it comes from a module that is
neither one of those versioned packages nor Python's standard library (a user's effect module, see
`docs/adding_an_effect.md`), a hash of that module's source file. An object the walk does not understand (one
with state it cannot see, a module without a source file, a tracer) means no key: the call takes the plain
`equinox.filter_jit` path. A gyrojax module-level function or class replaced at run time by one from a user's
file (a test's monkeypatch) is part of the key. The key also holds
`gyrojax._effects.plugins.user_code_digest()`, a hash of the sources of the user effect modules loaded and of the
modules they import from the user's folders: a helper module edited since gives a new key.
A source file (gyrojax's or a user's) changed after gyrojax was imported means no key: the code running may not
be the code on disk.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import os
import sys
import sysconfig
import time
import types

import equinox as eqx
import jax
import jax.core  # Tracer: jax.core is not imported by `import jax` for type checkers
import numpy as np
from jax._src import config as jax_config  # noqa: PLC2701 - trace_context has no public form

from .._version import __version__
from .cache import jax_flag


_VERSIONED = ("gyrojax", "jax", "jaxlib", "numpy", "equinox", "lineax", "optimistix", "diffrax")
"""Packages whose code is identified by their version (and, for gyrojax, the hash of its files)."""


class Unhashable(Exception):
    """Something in the arguments that the key cannot describe deterministically."""


def _package_root(module: str) -> str:
    return module.split(".", 1)[0]


_IMPORTED_NS = time.time_ns()
"""When this module was imported (with gyrojax): a source file changed later may differ from the code loaded."""


def _stat(path: str) -> os.stat_result:
    st = os.stat(path)
    if st.st_mtime_ns > _IMPORTED_NS:
        raise Unhashable(f"{path} was changed after gyrojax was imported")
    return st


def _versions() -> tuple:
    return (sys.version, __version__, _gyrojax_files_hash(), _package_versions())


@functools.cache
def _package_versions() -> tuple:
    import importlib.metadata as md

    def version(p):
        try:
            return md.version(p)
        except md.PackageNotFoundError:
            return None

    return tuple((p, version(p)) for p in _VERSIONED[1:])


def _gyrojax_files_hash() -> str:
    """A hash of every file of the gyrojax package (its code and data)."""
    return _files_hash(_gyrojax_files())


def _gyrojax_files() -> tuple:
    """(path relative to the package, path, mtime, size) of every file of the gyrojax package, in order."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # gyrojax/, not this wing's folder
    files = []
    for folder, dirs, names in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(names):
            if not name.endswith((".pyc", ".pyo")):
                path = os.path.join(folder, name)
                st = _stat(path)
                files.append((os.path.relpath(path, root), path, st.st_mtime_ns, st.st_size))
    return tuple(files)


@functools.cache
def _files_hash(files: tuple) -> str:
    h = hashlib.sha256()
    for relative, path, _, _ in files:
        h.update(relative.encode() + b"\0")
        with open(path, "rb") as f:
            h.update(hashlib.sha256(f.read()).digest())
    return h.hexdigest()


@functools.cache
def _file_hash(path: str, mtime_ns: int, size: int) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _module_source(module_name: str) -> str:
    """A hash of the source file of a module outside the versioned packages and the standard library; the
    empty string for those."""
    root = _package_root(module_name)
    if root in _VERSIONED or root in sys.stdlib_module_names:
        return ""
    module = sys.modules.get(module_name)
    path = getattr(module, "__file__", None)
    if not path or not path.endswith(".py") or not os.path.isfile(path):
        raise Unhashable(f"module {module_name} has no Python source file")
    st = _stat(path)
    return _file_hash(os.path.abspath(path), st.st_mtime_ns, st.st_size)


def _name(obj) -> str:
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not isinstance(module, str) or not isinstance(qualname, str):
        raise Unhashable(f"{type(obj).__name__} without a module and qualified name")
    return f"{module}:{qualname}:{_module_source(module)}"


def _class(cls: type) -> str:
    # Every class of the MRO: a user's subclass of a gyrojax effect, or a gyrojax class over a user's base.
    return "class(" + ",".join(_name(c) for c in cls.__mro__ if c is not object) + ")"


def _describe(obj, out: list, active: set) -> None:
    """Append a deterministic description of `obj` to `out` (raises `Unhashable`)."""
    if obj is None or type(obj) in (bool, int, str, bytes):
        out.append(f"{type(obj).__name__}:{obj!r}")
        return
    if type(obj) is float:
        out.append(f"float:{obj.hex()}")
        return
    if type(obj) is complex:
        out.append(f"complex:{obj.real.hex()},{obj.imag.hex()}")
        return
    if isinstance(obj, jax.core.Tracer):
        raise Unhashable("a tracer (called inside a transformation)")
    if eqx.is_array(obj):
        aval = jax.typeof(obj) if isinstance(obj, jax.Array) else None
        weak = bool(getattr(aval, "weak_type", False))
        out.append(f"array:{type(obj).__name__}:{tuple(np.shape(obj))}:{np.dtype(obj.dtype)}:{weak}")
        return
    if id(obj) in active:
        raise Unhashable("a reference cycle")
    active.add(id(obj))
    try:
        _describe_object(obj, out, active)
    finally:
        active.discard(id(obj))


def _describe_object(obj, out: list, active: set) -> None:
    if isinstance(obj, type):
        out.append(_class(obj))
    elif isinstance(obj, enum.Enum):
        out.append(f"enum:{_class(type(obj))}:{obj.name}")
    elif isinstance(obj, np.dtype):
        out.append(f"dtype:{obj.str}")
    elif type(obj) in (tuple, list) or isinstance(obj, tuple) and hasattr(obj, "_fields"):
        out.append(f"{_class(type(obj))}[{len(obj)}")
        for x in obj:
            _describe(x, out, active)
        out.append("]")
    elif type(obj) is dict:
        items = []
        for k, v in obj.items():
            key: list = []
            _describe(k, key, active)
            items.append(("\n".join(key), v))
        items.sort(key=lambda kv: kv[0])
        out.append(f"dict[{len(items)}")
        for k, v in items:
            out.append(k)
            _describe(v, out, active)
        out.append("]")
    elif type(obj) in (set, frozenset):
        parts = []
        for x in obj:
            part: list = []
            _describe(x, part, active)
            parts.append("\n".join(part))
        out.append(f"{type(obj).__name__}[{len(parts)}")
        out.extend(sorted(parts))
        out.append("]")
    elif type(obj) is functools.partial:
        out.append("partial(")
        for item in (obj.func, obj.args, obj.keywords):
            _describe(item, out, active)
        out.append(")")
    elif isinstance(obj, types.MethodType):
        out.append("method(")
        _describe(obj.__self__, out, active)
        _describe(obj.__func__, out, active)
        out.append(")")
    elif isinstance(obj, types.FunctionType):
        # Two lambdas of one function share a qualified name: the line tells them apart.
        out.append(f"function:{_name(obj)}:{obj.__code__.co_firstlineno}(")
        for item in (obj.__defaults__, obj.__kwdefaults__,
                     tuple(c.cell_contents for c in obj.__closure__ or ())):
            _describe(item, out, active)
        out.append(")")
    elif dataclasses.is_dataclass(obj):  # equinox.Module included: every field, static or not
        out.append(f"{_class(type(obj))}(")
        for field in dataclasses.fields(obj):
            out.append(f"{field.name}=")
            try:
                value = getattr(obj, field.name)
            except AttributeError:
                out.append("<unset>")
                continue
            _describe(value, out, active)
        out.append(")")
    elif isinstance(obj, (types.BuiltinFunctionType, np.ufunc)) or (
            callable(obj) and hasattr(obj, "__wrapped__")
            and _package_root(getattr(obj, "__module__", None) or "?") in _VERSIONED):
        # A builtin, a ufunc, or a wrapped (jitted, custom_jvp) function of a versioned package: its name
        # says what it does.
        out.append(f"callable:{_class(type(obj))}:{_name(obj)}")
    else:
        raise Unhashable(f"an object of type {type(obj).__module__}.{type(obj).__qualname__}")


def _replaced() -> list[str]:
    """gyrojax's module-level functions and classes that come from elsewhere than the versioned packages and
    the standard library: a function swapped in at run time (a test's monkeypatch) changes traced programs
    without changing any file of gyrojax."""
    out = []
    for module_name, module in list(sys.modules.items()):
        if _package_root(module_name) != "gyrojax" or module is None:
            continue
        for attr, value in list(vars(module).items()):
            if isinstance(value, (types.FunctionType, type)) and not _installed(value):
                line = getattr(getattr(value, "__code__", None), "co_firstlineno", "")
                out.append(f"{module_name}.{attr}={_name(value)}:{line}")
    return sorted(out)


@functools.cache
def _install_folders() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    return tuple(os.path.join(os.path.realpath(paths[k]), "") for k in ("purelib", "platlib", "stdlib"))


def _installed(value) -> bool:
    """Whether `value` comes from the versioned packages, the standard library or an installed package (what
    gyrojax's modules import: `jaxtyping.Float`, ...), rather than from a user's file."""
    module_name = getattr(value, "__module__", None) or "?"
    root = _package_root(module_name)
    if root in _VERSIONED or root in sys.stdlib_module_names:
        return True
    path = getattr(sys.modules.get(module_name), "__file__", None)
    return bool(path) and os.path.realpath(path).startswith(_install_folders())


def _trace_context() -> str:
    """JAX's configuration that changes traced programs, without the (empty, top-level) axis environment."""
    parts = []
    for x in jax_config.trace_context():  # JAX's own jit cache key for the configuration
        if type(x).__name__ == "AxisEnv":
            if x.axis_sizes or x.spmd_axis_names or x.explicit_mesh_axis_names:
                raise Unhashable("a non-empty axis environment")
            continue
        text = repr(x)
        if " at 0x" in text:
            raise Unhashable(f"configuration value {text}")
        parts.append(text)
    return repr((jax_flag("jax_enable_x64"), tuple(parts)))


def program_key(name: str, args: tuple) -> str:
    """The key of program `name` called with `args` (a hex SHA-256); raises `Unhashable` when some part of it
    cannot be described deterministically."""
    from .._effects.plugins import user_code_digest  # user effect modules and the helpers they import

    devices = jax.devices()
    out = [name, repr(_versions()), user_code_digest(), _trace_context(), *_replaced(), jax.default_backend(),
           repr(sorted({d.device_kind for d in devices})), str(len(devices))]
    _describe(args, out, set())
    return hashlib.sha256("\n".join(out).encode()).hexdigest()
