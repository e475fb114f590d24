"""Effects written by users: from a Python file (`--effects-module FILE.py`) or from installed packages (the
`gyrojax.effects` entry-point group), registered in `gyrojax.EFFECTS` like the built-in ones.

Once registered, an effect is a name like any other: `gyrojax simulate --effect NAME=SCALE`,
`gyrojax identify --effect NAME`, and a candidate of `gyrojax diagnose` (`gyrojax.supported_effects`).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import inspect
import os
import re
import sys
import traceback
import types
import warnings

from ._effects.base import AbstractEffect
from ._effects.registry import EFFECTS, register_effect


ENTRY_POINT_GROUP = "gyrojax.effects"
"""The entry-point group an installed package names its effects in (each entry: a class or a module)."""

_loaded_files: dict[str, tuple[type[AbstractEffect], ...]] = {}
_entry_points_loaded = False


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
            if EFFECTS.get(getattr(cls, "name", None)) is cls:
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
    registered with `gyrojax.register_effect` (so the file may call `register_effect` itself, or just define
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
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses (equinox modules) look their module up while the class is built
    try:
        spec.loader.exec_module(module)
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
            elif isinstance(obj, type) and issubclass(obj, AbstractEffect):
                _register_all([obj], origin)
            else:
                raise TypeError(f"it loads {obj!r}, neither an effect class nor a module")
        except Exception as e:
            warnings.warn(f"gyrojax: {origin} was skipped: {type(e).__name__}: {e}", UserWarning, stacklevel=2)
    return tuple(n for n in EFFECTS if n not in before)
