"""Compile once per machine: gyrojax turns on JAX's persistent compilation cache when it is imported.

A first `identify`, `simulate_table` or `diagnose` spends most of its time tracing and XLA-compiling programs.
The persistent cache keeps the compiled executables on disk, keyed by the program, the backend, the XLA flags and
the JAX version, so a later process with the same shapes loads them instead of compiling again; tracing still
happens in every process, except for the programs `_export.py` keeps in the cache folder's `gyrojax_export`
sub-folder (identify's vmapped solve, which also evaluates at the start), which a later process loads
without tracing.
Measured on the demo lot (2-core CPU, `benchmarks/bench_compile.py`): `diagnose` 115 s without the cache, 25 s
with it; the first `identify` of a process 47 s without the cache and 21 s with it when every program is traced
(17 s of them tracing), 5.2 s with identify's exported programs loaded (against 28.7 s traced, in one run of
2026-11-26 at load 4.5-6).

Programs that call back into Python (an `equinox.error_if` left in the compiled code, as diffrax's checks of
traced times are in the averaged and full tiers) are never written by JAX: those tiers compile in every
process. On loading an executable XLA:CPU checks that the host has the CPU features it was compiled for, and
compiles again if not.

**Where.** On import, unless disabled, the cache goes to a per-user folder:

- Linux and other Unix: `$XDG_CACHE_HOME/gyrojax/jax`, or `~/.cache/gyrojax/jax`;
- macOS: `~/Library/Caches/gyrojax/jax`;
- Windows: `%LOCALAPPDATA%\\gyrojax\\Cache\\jax`.

**Controls.**

- The environment variable `GYROJAX_CACHE_DIR` moves it (a path), or disables it (`off`, or empty).
- `gyrojax.io.compilation_cache(path)` moves it, `gyrojax.io.compilation_cache(None)` disables it, and
  `gyrojax.io.compilation_cache()` says where it is.
- A cache that JAX was already given (`JAX_COMPILATION_CACHE_DIR`, `jax.config.update(
  "jax_compilation_cache_dir", ...)` before gyrojax is imported, or `JAX_ENABLE_COMPILATION_CACHE=false`) is
  left exactly as it is: gyrojax sets nothing then.

A folder that cannot be written does not stop the import: gyrojax warns once and runs without the cache. The
folder may be deleted at any time (it is only a cache); it grows by one file per compiled program (a few MB
for a fit) and JAX never trims it unless `jax_compilation_cache_max_size` is set (that needs the `filelock`
package).

**Trust.** Anyone who can write to the folder can make your JAX processes run code of their choosing, so
gyrojax creates it with mode 0o700 and uses an existing folder only if it is owned by the user running gyrojax
and not writable by its group or others (on POSIX systems; `folder_problem`). Otherwise the import warns once,
naming the folder and why, and runs without the cache; `compilation_cache(path)` refuses such a folder. The
warnings are `CacheWarning`s (a `RuntimeWarning`), each given once per process, and shown as
"gyrojax: warning: ..." rather than with Python's file and line.
"""

from __future__ import annotations

import enum
import os
import stat
import sys
import tempfile
import warnings
from typing import Any

import jax
from jax.experimental.compilation_cache import compilation_cache as _jax_cache


ENV_VAR = "GYROJAX_CACHE_DIR"
"""The environment variable that moves the cache (a path) or disables it (`off` or empty)."""

OFF_VALUES = ("", "off", "0", "false", "no", "none")
"""Values of `GYROJAX_CACHE_DIR` (case-insensitive) that disable the cache."""

MIN_COMPILE_TIME_S = 0.0
"""Every compiled program is written, however fast it compiled (JAX's default keeps only those over 1 s).
Measured on a 2-core CPU: one `settle` on the steady tier compiles 115 programs, one large root find and 114
small ones (eager array operations, about 20 ms each); with only the large one cached a second process still
spends 2.3 s compiling, with all of them 0.3 s (640 kB of cache)."""


def default_cache_dir() -> str:
    """The per-user cache folder for this platform (not created).

    **Returns:** the absolute path, ending in `gyrojax/jax` (`gyrojax/Cache/jax` on Windows).
    """
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.join(os.path.expanduser("~"), "AppData", "Local")
        return os.path.join(base, "gyrojax", "Cache", "jax")
    if sys.platform == "darwin":
        return os.path.join(os.path.expanduser("~"), "Library", "Caches", "gyrojax", "jax")
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):  # the XDG spec: a relative value is invalid and ignored
        base = os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "gyrojax", "jax")


class CacheWarning(RuntimeWarning):
    """A cache folder gyrojax does not use (it cannot be written, or others could change what is in it)."""


_given: set[str] = set()


def _format(message, category, filename, lineno, line=None, *, _python=warnings.formatwarning):
    # The cache's warnings come from the import, not from a line of the user's: shown in gyrojax's words.
    if issubclass(category, CacheWarning):
        return f"gyrojax: warning: {message}\n"
    return _python(message, category, filename, lineno, line)


if not getattr(warnings.formatwarning, "_gyrojax", False):
    _format._gyrojax = True
    warnings.formatwarning = _format


def warn_once(message: str) -> None:
    """Give `message` as a `CacheWarning`, once per process (the import and the exported programs check the
    same folder)."""
    if message not in _given:
        _given.add(message)
        warnings.warn(message, CacheWarning, stacklevel=3)


def folder_problem(path: str) -> str | None:
    """Why the existing folder `path` cannot be trusted to hold programs gyrojax runs, or None: owned by
    another user, or writable by its group or others (a symbolic link to it is followed: the folder is what is
    checked). Not checked on systems without POSIX owners (Windows)."""
    if not hasattr(os, "getuid"):
        return None
    st = os.stat(path)
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a folder"
    if st.st_uid != os.getuid():
        return f"it is owned by user id {st.st_uid}, not by the user running gyrojax (user id {os.getuid()})"
    who = [w for bit, w in ((stat.S_IWGRP, "its group"), (stat.S_IWOTH, "all users")) if st.st_mode & bit]
    if who:
        return f"it is writable by {' and '.join(who)} (mode 0o{stat.S_IMODE(st.st_mode):03o})"
    return None


def _writable(path: str) -> str | None:
    """Create `path` if needed and write a probe file in it; `None` if that worked, otherwise the reason.
    (`os.access` is not enough: it says yes to root on a read-only file system.)"""
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as e:
        return f"{type(e).__name__}: {e.strerror or e}"
    return None


def jax_flag(name: str) -> Any:
    """The value of JAX's configuration flag `name` (jax.config makes its flags attributes at run time, which
    type checkers cannot see)."""
    return getattr(jax.config, name)


def _use(path: str | None) -> None:
    """Point JAX's persistent cache at `path` (`None`: no cache) and make the change take effect even after
    a compilation (JAX opens its cache once, at the first compile)."""
    jax.config.update("jax_compilation_cache_dir", path)
    if path is not None:
        jax.config.update("jax_enable_compilation_cache", True)
    _jax_cache.reset_cache()


def _jax_already_configured() -> bool:
    """Whether JAX was given a cache folder, or told not to cache, before gyrojax was imported."""
    return bool(jax_flag("jax_compilation_cache_dir")) or not jax_flag("jax_enable_compilation_cache")


def _thresholds() -> None:
    # Only JAX's defaults are replaced: a value the user set (JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS, or
    # jax.config) stays.
    if ("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ
            and jax_flag("jax_persistent_cache_min_compile_time_secs") == 1.0):
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)


def enable_default() -> str | None:
    """Configure the cache as gyrojax's import does: `GYROJAX_CACHE_DIR`, else the per-user folder, unless
    JAX's own settings say otherwise. Called once, on import.

    **Returns:** the folder in use, or `None` (disabled, JAX's own settings kept, or not writable: then a
    `RuntimeWarning` says why).
    """
    if _jax_already_configured():
        return jax_flag("jax_compilation_cache_dir") or None
    value = os.environ.get(ENV_VAR)
    if value is not None and value.strip().lower() in OFF_VALUES:
        return None
    path = os.path.abspath(os.path.expanduser(value)) if value is not None else default_cache_dir()
    origin = f"{ENV_VAR}={value!r}" if value is not None else f"the default (set {ENV_VAR} to move it)"
    problem = _writable(path)
    if problem is not None:
        warn_once(f"the compilation cache folder {path} from {origin} cannot be written ({problem}); running "
                  "without the persistent compilation cache, so every new process compiles again.")
        return None
    untrusted = folder_problem(path)
    if untrusted is not None:
        warn_once(f"the compilation cache folder {path} from {origin} is not used: {untrusted}, so others could "
                  "change the programs gyrojax runs. Running without the persistent compilation cache; use a "
                  f"folder of your own that only you can write (chmod 700), or set {ENV_VAR} to one.")
        return None
    _thresholds()
    _use(path)
    return path


class _Unset(enum.Enum):
    UNSET = 0


_UNSET = _Unset.UNSET  # `path` omitted (None means no cache)


def compilation_cache(path: str | os.PathLike[str] | None | _Unset = _UNSET) -> str | None:
    """Where gyrojax's compiled programs are kept between processes; move the cache or switch it off.

    gyrojax turns JAX's persistent compilation cache on when it is imported (a per-user folder, e.g.
    `~/.cache/gyrojax/jax` on Linux; the environment variable `GYROJAX_CACHE_DIR` moves it, `off` disables
    it; a cache JAX was already given is left alone). A process that runs the same shapes as an earlier one
    loads the compiled programs instead of compiling them: the first `identify` of the demo lot took 21 s
    instead of 47 s on a 2-core CPU. Tracing is not cached, and is most of what is left, except for identify's
    largest program, which is exported into the same folder (`gyrojax_export`) and loaded untraced.

    **Arguments:**

    - `path`: a folder (created if needed, mode 0o700) to keep the cache in from now on, or `None` to stop
      using a persistent cache in this process. Omitted: change nothing, only report.

    **Returns:** the folder in use now, or `None` when no persistent cache is used.

    Raises `ValueError` if `path` is given and the folder cannot be created or written, or is owned by
    another user or writable by others (nothing is changed then), `TypeError` if it is not a path.

    The cache is trusted code: whoever can write to the folder can make your JAX processes run code of their
    choosing, so do not point it at a folder shared with users you do not trust.
    """
    if path is _UNSET:
        return jax_flag("jax_compilation_cache_dir") or None
    if path is None:
        _use(None)
        return None
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"compilation_cache: path must be a folder path (str or os.PathLike) or None, "
                        f"got {type(path).__name__}.")
    folder = os.path.abspath(os.path.expanduser(os.fspath(path)))
    problem = _writable(folder)
    if problem is None:
        problem = folder_problem(folder)
    if problem is not None:
        raise ValueError(f"compilation_cache: path {folder} cannot be used as a cache folder ({problem}).")
    _thresholds()
    _use(folder)
    return folder


enable_default()
