"""Effects written by users: from a Python file (`--effects-module FILE.py`) or from installed packages (the
`gyrojax.effects` entry-point group), registered in `gyrojax.EFFECTS` like the built-in ones.

Once registered, an effect is a name like any other: `gyrojax simulate --effect NAME=SCALE`,
`gyrojax identify --effect NAME`, and a candidate of `gyrojax diagnose` (`gyrojax.supported_effects`).

Checks made here: the methods a user's class overrides have the signatures of `AbstractEffect`'s (at
registration); a file that registers nothing is warned about; `sys.exit` while importing a file is an error;
`nonfinite_effect` says when an effect gives a device with NaN or infinite values (the commands refuse such an
effect by name, `diagnose` drops such a candidate with a note). The source of every user effect module, and of
the modules it imports from outside the installed packages and the standard library, is hashed when it is
loaded: `user_code_digest` keys the exported programs (`gyrojax/_compile/export.py`) and `user_effect_code` is recorded
in a saved fit (`gyrojax/_identify/fitio.py`), so that a helper module edited since is never served from an old program
and a fit loaded with other code says so.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import inspect
import json
import os
import re
import sys
import sysconfig
import traceback
import types
import warnings
from collections.abc import Mapping

from .base import AbstractEffect
from .registry import EFFECTS, register_effect


ENTRY_POINT_GROUP = "gyrojax.effects"
"""The entry-point group an installed package names its effects in (each entry: a class or a module)."""

_loaded_files: dict[str, tuple[type[AbstractEffect], ...]] = {}
_entry_points_loaded = False
_sources: dict[str, dict[str, str]] = {}  # user module name -> {source file: SHA-256}, itself and its imports
_origins: dict[str, str] = {}  # user module name -> the file (or entry point) it was loaded from, as given


def _install_folders() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    folders = {os.path.realpath(paths[k]) for k in ("purelib", "platlib", "stdlib", "platstdlib")}
    folders.add(os.path.dirname(os.path.realpath(__file__)))  # gyrojax itself: versioned by its own hash
    return tuple(os.path.join(f, "") for f in sorted(folders))


def _user_source(module) -> str | None:
    """The source file of `module` when it is a user's (not the standard library, an installed package or
    gyrojax), else None."""
    path = getattr(module, "__file__", None)
    if not isinstance(path, str) or not path.endswith(".py") or not os.path.isfile(path):
        return None
    real = os.path.realpath(path)
    return None if real.startswith(_install_folders()) else real


def _referenced_modules(module) -> list:
    """The modules `module`'s globals are or come from (`import helper`, `from helper import f`)."""
    out = []
    for value in list(vars(module).values()):
        if isinstance(value, types.ModuleType):
            out.append(value)
        elif isinstance(value, (type, types.FunctionType)):
            out.append(sys.modules.get(getattr(value, "__module__", None) or ""))
    return [m for m in out if m is not None]


def _hash_sources(module, extra=()) -> dict[str, str]:
    """{source file: SHA-256} of a user module and of every user module it reaches through its globals (and
    `extra`, the user modules first imported while it ran)."""
    found: dict[str, str] = {}
    stack = [module, *extra]
    while stack:
        m = stack.pop()
        path = _user_source(m)
        if path is None or path in found:
            continue
        with open(path, "rb") as f:
            found[path] = hashlib.sha256(f.read()).hexdigest()
        stack.extend(_referenced_modules(m))
    return dict(sorted(found.items()))


def _record_sources(module, origin: str, extra=()) -> None:
    if _user_source(module) is not None:
        _sources[module.__name__] = _hash_sources(module, extra)
        _origins[module.__name__] = origin


def _digest(sources: Mapping[str, object]) -> str:
    return hashlib.sha256(json.dumps(sources, sort_keys=True).encode()).hexdigest()


def user_code_digest() -> str:
    """A SHA-256 of the source of every user effect module loaded in this process and of the user modules each
    imports (read when it was loaded; installed packages and the standard library are versioned elsewhere);
    the empty string when no user code is loaded. Part of the key of every exported program."""
    if not _sources:
        return ""
    return _digest({name: _sources[name] for name in sorted(_sources)})


def _class_module(name: str) -> str | None:
    cls = EFFECTS.get(name)
    module = getattr(cls, "__module__", None)
    return module if module in _sources else None


def user_effect_code(effect_names) -> dict[str, dict]:
    """For each of `effect_names` defined by a loaded user module: `{"module": the file it was loaded from,
    "sha256": the digest of its source and its user imports}` (what a saved fit records)."""
    out = {}
    for name in effect_names:
        module = _class_module(name)
        if module is not None:
            out[name] = {"module": _origins[module], "sha256": _digest(_sources[module])}
    return out


def user_code_changes(recorded: dict, effect_names) -> list[str]:
    """What differs between the user effect code `recorded` (by `user_effect_code`) and that loaded now, for
    `effect_names`: one sentence per effect, naming its module."""
    now = user_effect_code(effect_names)
    out = []
    for name in effect_names:
        was, is_ = recorded.get(name), now.get(name)
        if was == is_ or (was and is_ and was["sha256"] == is_["sha256"]):
            continue
        if was is None:
            if is_ is not None:  # (both None are equal: skipped above)
                out.append(f"effect {name!r} comes now from the user module {is_['module']}; the fit recorded no "
                           "user code for it")
        elif is_ is None:
            out.append(f"effect {name!r} came from the user module {was['module']}; it is not loaded from it now")
        else:
            out.append(f"effect {name!r}: the code of its module {is_['module']} (or of a module it imports) "
                       f"differs from that of {was['module']} when the fit was made")
    return out


def effect_origin(cls: type) -> str:
    """Where an effect class comes from, for messages: `class X in FILE` for a user's, else its import path."""
    module = cls.__module__
    if module in _origins:
        return f"class {cls.__qualname__} in {_origins[module]}"
    return f"{module}.{cls.__qualname__}"


def nonfinite_effect(name: str, gyro, scale: float = 1.0) -> str | None:
    """Why effect `name` cannot be used on the device `gyro`: the first parameter of the device that it makes
    NaN or infinite, at zero or at `scale` times its typical size (or the exception its `apply` raised); None
    when it gives finite devices or does not act on `gyro`. `gyro` is one device (no lot axis)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .registry import effect

    typical = effect(name, scale)  # an unknown name: the registry's error
    cls = type(typical)
    if not cls.supports(gyro):
        return None  # not this effect's device: `apply` says so where it is used
    zero = jax.tree.map(lambda x: jnp.zeros_like(jnp.asarray(x, dtype=float)), typical)
    size = "at its typical size" if scale == 1.0 else f"at {scale:g} times its typical size"
    def bad(leaf):  # an inexact array with a NaN or an infinity
        value = np.asarray(leaf) if eqx.is_array(leaf) or isinstance(leaf, float) else None
        return value is not None and np.issubdtype(value.dtype, np.inexact) and not np.all(np.isfinite(value))

    before = [bad(leaf) for leaf in jax.tree.leaves(gyro)]
    for size, eff in (("at zero", zero), (size, typical)):
        try:
            out = eff.apply(gyro)
        except Exception as e:
            return f"effect {name!r} ({effect_origin(cls)}): apply() {size} raised {type(e).__name__}: {e}"
        leaves = jax.tree_util.tree_flatten_with_path(out)[0]
        for (path, leaf), was_bad in zip(leaves, before + [False] * (len(leaves) - len(before))):
            if bad(leaf) and not was_bad:  # a leaf the device holds non-finite by design (inf: none) is its own
                value = np.asarray(leaf).ravel()
                shown = value[~np.isfinite(value)][0]
                return (f"effect {name!r} ({effect_origin(cls)}) gives the device a non-finite value {size}: "
                        f"{jax.tree_util.keystr(path).lstrip('.')} = {float(np.real(shown))}")
    return None


def _check_signatures(cls: type, origin: str) -> None:
    """Refuse a class whose `apply`, `typical` or `supports` cannot be called as `AbstractEffect` calls them,
    naming `origin`, the class and the method."""
    expected = {"apply": (False, ("gyro",), "gyro"), "typical": (True, (1.0,), "scale"),
                "supports": (True, ("gyro",), "gyro")}
    for method, (is_classmethod, call_args, shown) in expected.items():
        static = inspect.getattr_static(cls, method)
        abstract = inspect.getattr_static(AbstractEffect, method)
        want = inspect.signature(abstract.__func__ if isinstance(abstract, classmethod) else abstract)
        where = f"{origin}: effect class {cls.__qualname__}, method {method}"
        if isinstance(static, staticmethod) or isinstance(static, classmethod) != is_classmethod:
            kind = "a classmethod" if is_classmethod else "a plain method (not a classmethod or staticmethod)"
            raise ValueError(f"{where}: must be {kind}, as AbstractEffect.{method}{want}.")
        func = static.__func__ if isinstance(static, classmethod) else static
        try:
            got = inspect.signature(func)
        except (TypeError, ValueError):
            continue  # a builtin or a wrapped callable: nothing to read
        try:
            got.bind(cls, *call_args)
        except TypeError as e:
            raise ValueError(f"{where}{got}: does not match AbstractEffect.{method}{want}: gyrojax calls it as "
                             f"{method}({shown}) with one positional argument, which fails ({e}).") from None


def _effect_classes(module: types.ModuleType) -> list[type[AbstractEffect]]:
    """The concrete effect classes a module defines itself (not those it imports)."""
    return [obj for obj in vars(module).values()
            if isinstance(obj, type) and issubclass(obj, AbstractEffect) and obj.__module__ == module.__name__
            and not inspect.isabstract(obj)]


def _register_all(classes, origin: str) -> tuple[type[AbstractEffect], ...]:
    """Register every class not yet registered, all or none; errors name `origin` and the class."""
    added = []
    try:
        for cls in classes:
            _check_signatures(cls, origin)
        for cls in classes:
            if EFFECTS.get(getattr(cls, "name", "")) is cls:
                continue  # registered already (e.g. the module called register_effect itself)
            try:
                register_effect(cls)
            except Exception as e:
                raise ValueError(f"{origin}: effect class {cls.__qualname__} cannot be registered: {e}") from None
            added.append(cls)
    except BaseException:
        for cls in added:  # all or none: a half-registered file would make names depend on class order
            EFFECTS.pop(cls.name, None)
        raise
    return tuple(classes)


def load_effects_module(path: str | os.PathLike) -> tuple[type[AbstractEffect], ...]:
    """Import a Python file and register every effect class it defines.

    Every concrete subclass of `gyrojax.AbstractEffect` defined in the file that is not registered yet is
    registered with `gyrojax.effects.register_effect` (so the file may call `register_effect` itself, or just define
    the classes). Loading the same file again returns the same classes without running it again (registering
    any of them that was removed from `gyrojax.EFFECTS` meanwhile).

    **Arguments:**

    - `path`: a `.py` file.

    **Returns:**

    The effect classes the file defines, in the order it defines them.

    Raises `ValueError` naming the file when it does not exist, is not a `.py` file, has a syntax error (with
    its line), fails while running (with the line in the file), or defines an effect class that
    `register_effect` refuses (then none of the file's classes is registered).
    """
    given = os.fspath(path)
    if not os.path.exists(given):
        raise ValueError(f"{given}: no such file; --effects-module expects a Python file defining effects.")
    if os.path.isdir(given):
        raise ValueError(f"{given} is a directory; --effects-module expects a Python file (.py).")
    if not given.endswith(".py"):
        raise ValueError(f"{given}: not a .py file; --effects-module expects a Python file defining effects.")
    real = os.path.realpath(given)
    if real in _loaded_files:  # not run again; its classes registered again if they were removed meanwhile
        classes = _loaded_files[real]
        _register_all([c for c in classes if EFFECTS.get(c.name) is not c], given)
        return classes
    stem = re.sub(r"\W", "_", os.path.splitext(os.path.basename(real))[0])
    name = f"gyrojax_user_effects_{stem}_{hashlib.sha256(real.encode()).hexdigest()[:12]}"
    spec = importlib.util.spec_from_file_location(name, real)
    if spec is None or spec.loader is None:
        raise ValueError(f"{given}: Python cannot load it as a module.")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses (equinox modules) look their module up while the class is built
    before = set(sys.modules)
    try:
        spec.loader.exec_module(module)
    except SystemExit as e:
        del sys.modules[name]
        lines = [f.lineno for f in traceback.extract_tb(e.__traceback__) if os.path.realpath(f.filename) == real]
        at = f"line {lines[-1]}: " if lines else ""
        raise ValueError(f"{given}: {at}the file called sys.exit({e.code!r}) while being imported; an effects "
                         "module must only define (and may register) effect classes.") from None
    except SyntaxError as e:
        del sys.modules[name]
        raise ValueError(f"{given}: line {e.lineno}: syntax error: {e.msg}.") from None
    except Exception as e:
        del sys.modules[name]
        lines = [f.lineno for f in traceback.extract_tb(e.__traceback__) if os.path.realpath(f.filename) == real]
        at = f"line {lines[-1]}: " if lines else ""
        raise ValueError(f"{given}: {at}importing it failed: {type(e).__name__}: {e}") from None
    try:
        classes = _register_all(_effect_classes(module), given)
    except BaseException:
        del sys.modules[name]
        raise
    if not classes:
        warnings.warn(f"{given}: defines no effect class (no concrete subclass of gyrojax.AbstractEffect); "
                      "nothing was registered.", UserWarning, stacklevel=2)
    _record_sources(module, given, [sys.modules[m] for m in set(sys.modules) - before if m in sys.modules])
    _loaded_files[real] = classes
    return classes


def load_effect_entry_points() -> tuple[str, ...]:
    """Register the effects installed packages declare in the `gyrojax.effects` entry-point group (once).

    Each entry point loads an effect class (registered) or a module (every effect class it defines is
    registered, as for [`load_effects_module`][]). The group is read on the first call only; later calls do
    nothing. An entry point that fails to load or register gives a `UserWarning` naming it and its package,
    and is skipped: a broken plugin never stops gyrojax.

    **Returns:**

    The names of the effects registered by this call.
    """
    global _entry_points_loaded
    if _entry_points_loaded:
        return ()
    _entry_points_loaded = True
    before = set(EFFECTS)
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        dist = getattr(ep, "dist", None)
        origin = (f"entry point {ep.name!r} = {ep.value!r} in group {ENTRY_POINT_GROUP!r}"
                  + (f" (package {dist.name})" if dist is not None else ""))
        try:
            obj = ep.load()
            if isinstance(obj, types.ModuleType):
                _register_all(_effect_classes(obj), origin)
                _record_sources(obj, origin)
            elif isinstance(obj, type) and issubclass(obj, AbstractEffect):
                _register_all([obj], origin)
                _record_sources(sys.modules[obj.__module__], origin)
            else:
                raise TypeError(f"it loads {obj!r}, neither an effect class nor a module")
        except Exception as e:
            warnings.warn(f"gyrojax: {origin} was skipped: {type(e).__name__}: {e}", UserWarning, stacklevel=2)
    return tuple(n for n in EFFECTS if n not in before)
