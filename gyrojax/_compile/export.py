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

**The key** (`program_key.py`) is a SHA-256 of everything that can change the program: its name, the code
of gyrojax, of the packages it uses and of a user's effect modules, JAX's configuration, the devices, and a
walk of the arguments. The stored form is `artifact.py`'s.

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
import functools
import logging
import os
import stat
import tempfile
from collections.abc import Callable

import equinox as eqx
import jax
import numpy as np
from jax import export

from .._data.io import atomic_write_bytes
from .._data.reading import open_regular, read_exactly
from .artifact import deserialize, serialize
from .cache import folder_problem, jax_flag, warn_once
from .jit import compiler_options, jit, top_level
from .program_key import Unhashable, program_key


FOLDER = "gyrojax_export"
"""The sub-folder of the compilation cache folder that holds the exported programs."""

KEY_FILE = "gyrojax_export.key"
"""The per-user secret (32 random bytes, mode 0o600) in the cache folder that keys every artifact's digest."""

MAX_ENTRY_BYTES = 64 * 2**20
"""The largest artifact written or read (identify's solve of the demo lot is about 200 kB)."""

_log = logging.getLogger(__name__)
_loaded: dict[str, Callable | None] = {}  # key -> jitted call of the exported program, None: use the plain path


def _folder() -> str | None:
    """The compilation cache folder, or None when it is off."""
    cache = jax_flag("jax_compilation_cache_dir")
    if not cache or not jax_flag("jax_enable_compilation_cache"):
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
    exported = deserialize(data, key, secret)
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
        data = serialize(exported, key, secret)
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
    except Unhashable as e:
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
        if call is None or key is None:  # (a call always comes with its key)
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
