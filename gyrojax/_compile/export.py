"""Skip tracing in a later process: a program exported with `jax.export`, kept beside the persistent compilation
cache and loaded by any later process that calls it with the same structure.

The persistent compilation cache (`_cache.py`) makes XLA's compile of a known program nearly free, but every process
still traces it, and for a fit's largest program (the vmapped solve, which also evaluates at the start) tracing is
most of a warm first `identify`. `cached_program(name, fn)` wraps `fn` like `equinox.filter_jit` (arrays are traced,
every other leaf is static) and, when the compilation cache is on, exports the traced program (`jax.export`:
StableHLO) to `<cache folder>/gyrojax_export/<name>-<key>.jaxexport`. A later process whose call has the same key
rebuilds the `jax.export.Exported` and runs it through `jax.jit(exported.call)`: no tracing of `fn`; the compile of
the embedded module hits the persistent cache. The file holds the module's bytes, its inputs' and outputs' shapes
and dtypes, the outputs' tree and an HMAC-SHA256 of all of them, in a format of gyrojax's own (`jax.export`'s
`serialize` needs the `flatbuffers` package, which gyrojax does not require); only single-device programs without
effects or shardings are stored, and outputs must be arrays in tuples, lists and dicts.

**Measured** (`benchmarks/bench_compile.py --entries identify`, 2-core CPU, load 4.5-6, 2026-11-26): the
first `identify` of the demo lot in a process with a warm cache 5.2 s with the exported programs against
28.7 s traced (tracing 0.1 s against 20.8 s); the fit's arrays are identical bit for bit.

**The key** is a SHA-256 of everything that can change the program: the program's name; gyrojax's version and
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
`gyrojax._plugins.user_code_digest()`, a hash of the sources of the user effect modules loaded and of the modules
they import from the user's folders: a helper module edited since gives a new key.
A source file (gyrojax's or a user's) changed after gyrojax was imported means no key: the code running may not
be the code on disk.

**Fallback.** The plain path runs, with the same results, whenever the cache is off, the key cannot be made,
an argument is spread over more than one device, the program cannot be exported (a host callback, such as an
`equinox.error_if` kept in the compiled code: then a small marker file stops later processes from trying
again), or an artifact cannot be read, deserialized or called (it is then rewritten). Artifacts are written
atomically; the folder may be deleted at any time.

**Trust.** An artifact is code that runs: whoever could change one could change what your programs compute. So
the digest is keyed (HMAC-SHA256) with a per-user secret, `KEY_FILE` in the cache folder (32 random bytes, mode
0o600, replaced if it is not a private file of the user's): a file changed without that key is refused and the
program traced and written again. The cache folder and `gyrojax_export` must be the user's own and writable by
no one else (`_cache.folder_problem`; otherwise one warning and no export), `gyrojax_export` must not be a
symbolic link, and an artifact or marker that is a link is neither read nor written through (it is replaced).
Artifacts are read only as regular files of at most `MAX_ENTRY_BYTES`, their module's size checked against
their header.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import functools
import hashlib
import hmac
import json
import logging
import os
import stat
import sys
import sysconfig
import tempfile
import time
import types
from collections.abc import Callable

import equinox as eqx
import jax
import numpy as np
from jax import export

from .._data.io import atomic_write_bytes
from .._data.reading import open_regular, read_exactly
from .._version import __version__
from .cache import folder_problem, warn_once
from .jit import compiler_options, jit, top_level


FOLDER = "gyrojax_export"
"""The sub-folder of the compilation cache folder that holds the exported programs."""

_MAGIC = b"gyrojax-export 2\n"
KEY_FILE = "gyrojax_export.key"
"""The per-user secret (32 random bytes, mode 0o600) in the cache folder that keys every artifact's digest."""

MAX_ENTRY_BYTES = 64 * 2**20
"""The largest artifact written or read (identify's solve of the demo lot is about 200 kB)."""

_VERSIONED = ("gyrojax", "jax", "jaxlib", "numpy", "equinox", "lineax", "optimistix", "diffrax")
"""Packages whose code is identified by their version (and, for gyrojax, the hash of its files)."""

_log = logging.getLogger(__name__)
_loaded: dict[str, Callable | None] = {}  # key -> jitted call of the exported program, None: use the plain path


class _Unhashable(Exception):
    """Something in the arguments that the key cannot describe deterministically."""


def _package_root(module: str) -> str:
    return module.split(".", 1)[0]


_IMPORTED_NS = time.time_ns()
"""When this module was imported (with gyrojax): a source file changed later may differ from the code loaded."""


def _stat(path: str) -> os.stat_result:
    st = os.stat(path)
    if st.st_mtime_ns > _IMPORTED_NS:
        raise _Unhashable(f"{path} was changed after gyrojax was imported")
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
    root = os.path.dirname(os.path.abspath(__file__))
    files = []
    for folder, dirs, names in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(names):
            if not name.endswith((".pyc", ".pyo")):
                path = os.path.join(folder, name)
                st = _stat(path)
                files.append((os.path.relpath(path, root), path, st.st_mtime_ns, st.st_size))
    return _files_hash(tuple(files))


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
        raise _Unhashable(f"module {module_name} has no Python source file")
    st = _stat(path)
    return _file_hash(os.path.abspath(path), st.st_mtime_ns, st.st_size)


def _name(obj) -> str:
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not isinstance(module, str) or not isinstance(qualname, str):
        raise _Unhashable(f"{type(obj).__name__} without a module and qualified name")
    return f"{module}:{qualname}:{_module_source(module)}"


def _class(cls: type) -> str:
    # Every class of the MRO: a user's subclass of a gyrojax effect, or a gyrojax class over a user's base.
    return "class(" + ",".join(_name(c) for c in cls.__mro__ if c is not object) + ")"


def _describe(obj, out: list, active: set) -> None:
    """Append a deterministic description of `obj` to `out` (raises `_Unhashable`)."""
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
        raise _Unhashable("a tracer (called inside a transformation)")
    if eqx.is_array(obj):
        aval = jax.typeof(obj) if isinstance(obj, jax.Array) else None
        weak = bool(getattr(aval, "weak_type", False))
        out.append(f"array:{type(obj).__name__}:{tuple(np.shape(obj))}:{np.dtype(obj.dtype)}:{weak}")
        return
    if id(obj) in active:
        raise _Unhashable("a reference cycle")
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
        for part in (obj.func, obj.args, obj.keywords):
            _describe(part, out, active)
        out.append(")")
    elif isinstance(obj, types.MethodType):
        out.append("method(")
        _describe(obj.__self__, out, active)
        _describe(obj.__func__, out, active)
        out.append(")")
    elif isinstance(obj, types.FunctionType):
        # Two lambdas of one function share a qualified name: the line tells them apart.
        out.append(f"function:{_name(obj)}:{obj.__code__.co_firstlineno}(")
        for part in (obj.__defaults__, obj.__kwdefaults__,
                     tuple(c.cell_contents for c in obj.__closure__ or ())):
            _describe(part, out, active)
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
        raise _Unhashable(f"an object of type {type(obj).__module__}.{type(obj).__qualname__}")


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
    for x in jax._src.config.trace_context():  # noqa: SLF001 - JAX's own jit cache key for the configuration
        if type(x).__name__ == "AxisEnv":
            if x.axis_sizes or x.spmd_axis_names or x.explicit_mesh_axis_names:
                raise _Unhashable("a non-empty axis environment")
            continue
        text = repr(x)
        if " at 0x" in text:
            raise _Unhashable(f"configuration value {text}")
        parts.append(text)
    return repr((jax.config.jax_enable_x64, tuple(parts)))


def program_key(name: str, args: tuple) -> str:
    """The key of program `name` called with `args` (a hex SHA-256); raises `_Unhashable` when some part of it
    cannot be described deterministically."""
    from .._plugins import user_code_digest  # user effect modules and the helpers they import

    devices = jax.devices()
    out = [name, repr(_versions()), user_code_digest(), _trace_context(), *_replaced(), jax.default_backend(),
           repr(sorted({d.device_kind for d in devices})), str(len(devices))]
    _describe(args, out, set())
    return hashlib.sha256("\n".join(out).encode()).hexdigest()


def _folder() -> str | None:
    """The compilation cache folder, or None when it is off."""
    cache = jax.config.jax_compilation_cache_dir
    if not cache or not jax.config.jax_enable_compilation_cache:
        return None
    return cache


_trusted: dict[str, tuple[str, bytes] | None] = {}  # cache folder -> (export folder, secret), None: no export


def _export_folder() -> tuple[str, bytes] | None:
    """The export folder of the cache folder in use and its secret, or None (cache off, or a folder that others
    could change: then one warning says why)."""
    cache = _folder()
    if cache is None:
        return None
    if cache not in _trusted:
        _trusted[cache] = _trust(os.path.join(cache, FOLDER))
    return _trusted[cache]


def _trust(folder: str) -> tuple[str, bytes] | None:
    try:
        if os.path.islink(folder):
            problem = "it is a symbolic link (links inside the cache are not followed)"
        else:
            os.makedirs(folder, mode=0o700, exist_ok=True)
            problem = folder_problem(os.path.dirname(folder)) or folder_problem(folder)
        if problem is None:
            return folder, _secret(os.path.dirname(folder))
    except OSError as e:
        problem = f"{type(e).__name__}: {e.strerror or e}"
    warn_once(f"the exported programs' folder {folder} is not used: {problem}. Programs are traced in every "
              "process instead of loaded.")
    return None


def _secret(folder: str) -> bytes:
    """The folder's secret key, made now if it has none usable (a new key only means the programs stored so
    far are traced and written again)."""
    path = os.path.join(folder, KEY_FILE)
    for _ in range(3):
        key = _read_secret(path)
        if key is not None:
            return key
        fd, tmp = tempfile.mkstemp(dir=folder)  # mode 0o600
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(os.urandom(32))
            try:
                os.link(tmp, path)  # the key appears whole, and of two processes making one, one wins
            except FileExistsError:
                pass
            except OSError:  # a file system without hard links
                os.replace(tmp, path)
        finally:
            with contextlib.suppress(FileNotFoundError):
                os.remove(tmp)
    raise OSError(f"cannot make the key file {path}")


def _read_secret(path: str) -> bytes | None:
    """The key at `path`; None if there is none, or it is not a private file of the user's (then removed)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    ours = not hasattr(os, "getuid") or st.st_uid == os.getuid()
    if stat.S_ISREG(st.st_mode) and st.st_size == 32 and ours and not st.st_mode & 0o077:
        with open_regular(path, "give the export folder's key file") as f:
            return read_exactly(f, 32, path)
    os.remove(path)
    return None


def _single_device(leaves) -> bool:
    return all(not isinstance(x, jax.Array) or len(x.sharding.device_set) == 1 for x in leaves)


def _avals(leaves):
    return [jax.ShapeDtypeStruct(np.shape(x), np.dtype(x.dtype),
                                 weak_type=isinstance(x, jax.Array) and jax.typeof(x).weak_type) for x in leaves]


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


def _serialize(exported: export.Exported, key: str, secret: bytes) -> bytes:
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


def _deserialize(data: bytes, key: str, secret: bytes) -> export.Exported:
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


def _jitted_call(exported: export.Exported) -> Callable:
    def call(*xs):
        return exported.call(*xs)

    # Named after the program, for JAX's logs and monitoring events.
    call.__name__ = call.__qualname__ = f"exported_{exported.fun_name.removeprefix('export_')}"
    return jax.jit(call, compiler_options=compiler_options())


def _regular(path: str) -> bool:
    """Whether `path` is a regular file itself (a symbolic link inside the cache is not followed)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except FileNotFoundError:
        return False


def _load(path: str, key: str, secret: bytes, leaves) -> Callable | None:
    """The jitted call of the program stored at `path`, or None if there is none usable."""
    if not _regular(path):
        return None
    with open_regular(path, "give an exported program") as f:
        size = os.fstat(f.fileno()).st_size
        if size > MAX_ENTRY_BYTES:
            raise ValueError(f"{size} bytes, more than the {MAX_ENTRY_BYTES} an exported program may have")
        data = read_exactly(f, size, path)
    exported = _deserialize(data, key, secret)
    if exported.nr_devices != 1 or [(a.shape, a.dtype) for a in exported.in_avals] != [
            (a.shape, a.dtype) for a in _avals(leaves)]:
        raise ValueError("inputs differ from the key's")
    return _jitted_call(exported)


def _export(fn, static, treedef, leaves, path: str, key: str, secret: bytes) -> Callable | None:
    """Trace `fn`, store it at `path` and return the jitted call of the stored form; None if it cannot be
    exported (a marker is written then, so that later processes do not trace it twice)."""
    def flat(*xs):
        out = fn(*eqx.combine(jax.tree.unflatten(treedef, xs), static))
        # filter_jit returns a Python value as it is, jax.jit as an array: such a program stays plain.
        if not all(isinstance(x, jax.Array) for x in jax.tree.leaves(out)):
            raise TypeError("an output that is not an array")
        return out

    flat.__name__ = flat.__qualname__ = f"export_{os.path.basename(path).split('-')[0]}"

    try:
        os.makedirs(os.path.dirname(path), mode=0o700, exist_ok=True)
    except OSError as e:
        _log.debug("gyrojax export: %s not written (%s)", path, e)
        return None
    try:
        exported = export.export(jax.jit(flat))(*_avals(leaves))
        data = _serialize(exported, key, secret)
        if len(data) > MAX_ENTRY_BYTES:
            raise ValueError(f"{len(data)} bytes, more than the {MAX_ENTRY_BYTES} an exported program may have")
    except Exception as e:  # noqa: BLE001 - host callbacks, outputs that are not arrays, ...
        _log.debug("gyrojax export: %s not exported (%s: %s)", path, type(e).__name__, e)
        try:
            _write(path + ".refused", f"{type(e).__name__}: {e}"[:2000].encode())
        except OSError:
            pass
        return None
    try:
        _write(path, data)
    except OSError as e:
        _log.debug("gyrojax export: %s not written (%s)", path, e)
    return _jitted_call(exported)


def _write(path: str, data: bytes) -> None:
    """Write `path` atomically, replacing whatever is there that is not a regular file (a symbolic link, a FIFO,
    a device) rather than writing through it or into it."""
    with contextlib.suppress(FileNotFoundError):
        if not stat.S_ISREG(os.lstat(path).st_mode):
            os.remove(path)
    atomic_write_bytes(path, data)


def _exported_call(name: str, fn, args) -> tuple[Callable | None, str | None, list]:
    """The jitted call of `fn`'s exported program for `args` (loaded or made now), its key and the array
    leaves it takes; the call None: the plain path."""
    trusted = _export_folder()
    if trusted is None:
        return None, None, []
    secret = trusted[1]
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree.flatten(dynamic)
    if not _single_device(leaves):
        return None, None, leaves
    try:
        key = program_key(name, args)
    except _Unhashable as e:
        _log.debug("gyrojax export: %s has no key (%s)", name, e)
        return None, None, leaves
    if key in _loaded:
        return _loaded[key], key, leaves
    path = _path(name, key)
    call = None
    if not _regular(path + ".refused"):
        try:
            call = _load(path, key, secret, leaves)
        except Exception as e:  # noqa: BLE001 - a corrupt, tampered or foreign file: made again below
            _log.debug("gyrojax export: %s unreadable (%s: %s)", path, type(e).__name__, e)
        if call is None:
            call = _export(fn, static, treedef, leaves, path, key, secret)
    _loaded[key] = call
    return call, key, leaves


def _path(name: str, key: str) -> str:
    return os.path.join(_folder() or "", FOLDER, f"{name}-{key}.jaxexport")


def cached_program(name: str, fn: Callable) -> Callable:
    """`gyrojax._compile.jit.jit(fn)` (`equinox.filter_jit` with gyrojax's XLA options), whose traced program is
    kept beside the compilation cache (see the module's docstring) so that a later process with the same
    structure does not trace it again. Called inside another trace, it is `fn` traced into that program.

    **Arguments:**

    - `name`: the program's name, part of its key and of its file's name.
    - `fn`: the function; its outputs must be arrays in tuples, lists and dicts (what `jax.export` can store),
      otherwise it always takes the plain path.

    **Returns:** a function with `fn`'s signature (positional arguments only).
    """
    plain = jit(fn)

    @functools.wraps(fn)
    def run(*args):
        if not top_level():
            return plain(*args)
        call, key, leaves = _exported_call(name, fn, args)
        if call is None:
            return plain(*args)
        try:
            return call(*leaves)
        except Exception as e:  # noqa: BLE001 - the plain path gives the same results
            _log.debug("gyrojax export: %s failed to run (%s: %s); plain path", name, type(e).__name__, e)
            _loaded[key] = None
            try:  # no later process should try it again
                os.remove(_path(name, key))
            except OSError:
                pass
            return plain(*args)

    return run
