"""The verbs' one argument order, `(model, data)` as `identify` takes them: `diagnose` and `plan` called in the
old `(data, model)` order are swapped with a `DeprecationWarning`; a pair that is neither raises a `TypeError`
naming the argument and what it expects."""

import os
import warnings

from .._data.table import Table
from .._device.file import is_device_file
from .._gyroscope import Gyroscope
from .._model.fitdata import FitData
from .._model.parameters import Model
from .._presets import PRESETS


DEFAULT_MODEL = "paper-qmg"  # the model `diagnose` and `plan` fit when none is given
_MODEL = "a preset name (" + ", ".join(repr(p) for p in PRESETS) + "), a device file (.toml), a Gyroscope or a Model"
_DATA = "a gyrojax.Table or FitData (read a file with gyrojax.read_table)"


def _is_data(x) -> bool:
    return isinstance(x, (Table, FitData))


def _is_model(x) -> bool:
    return isinstance(x, (Model, Gyroscope)) or is_device_file(x) or (isinstance(x, str) and x in PRESETS)


def _named(x) -> str:
    return f"{type(x).__name__} {os.fspath(x)!r}" if isinstance(x, (str, os.PathLike)) else type(x).__name__


def model_and_data(verb: str, model, data, *, data_required: bool) -> tuple:
    """`(model, data)` of a call to `verb` (`"diagnose"` or `"plan"`) in the order `(model, data)`. A call in
    the old order (data first, then a model or nothing) is swapped, with a `DeprecationWarning`; two data, data
    that are not data, or no data where `data_required`, raise a `TypeError`."""
    if _is_data(model):
        if _is_data(data):
            raise TypeError(f"{verb}(model, data): model must be {_MODEL}; got a {type(model).__name__} as model "
                            f"and a {type(data).__name__} as data.")
        if data is not None and not isinstance(data, str) and not _is_model(data):
            raise TypeError(f"{verb}(model, data): model must be {_MODEL}, and data {_DATA}; got a "
                            f"{type(model).__name__} as model and {_named(data)} as data.")
        warnings.warn(f"{verb}(data, model) is now {verb}(model, data): pass the model first, e.g. "
                      f"gj.{verb}('{DEFAULT_MODEL}', table)", DeprecationWarning, stacklevel=3)
        return (DEFAULT_MODEL if data is None else data), model
    if data is None:
        if data_required:
            raise TypeError(f"{verb}(model, data): data must be {_DATA}; got none.")
        return model, data
    if not _is_data(data):
        raise TypeError(f"{verb}(model, data): data must be {_DATA}; got {_named(data)}.")
    return model, data
