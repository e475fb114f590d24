"""Sweep kinds by name, and registering a new one."""

import difflib

from .base import AbstractSweep
from .branch_voltages import BranchRatio
from .dac import Dac
from .drive_amplitude import DriveAmplitude
from .drive_frequency import DriveFrequency
from .quadrature_injection import QuadratureInjection
from .rate_table import RateTable
from .setpoint_zero_rate import SetpointZeroRate
from .vcf_dynamic import VcfDynamic
from .vcf_static import VcfStatic


SWEEP_KINDS: dict[str, type[AbstractSweep]] = {cls.name: cls for cls in (
    RateTable, VcfStatic, VcfDynamic, Dac, QuadratureInjection, DriveAmplitude, DriveFrequency, SetpointZeroRate,
    BranchRatio)}
"""The sweep kinds by their `sweep` name, in the data format's order: the one list of the kinds a table may
hold, `simulate_table` simulates, identification fits and the planner proposes (`register_sweep` adds to it).
A kind's random streams are its own `stream`, not its position here."""

_CLASS_ATTRIBUTES = {"name": str, "title": str, "input_quantity": str, "input_unit": str, "output_unit": str,
                     "input_meaning": str, "output_meaning": str, "biased": bool, "straight_line": bool,
                     "word_input": bool, "rate_input": bool, "timed": bool, "rate_noise": bool,
                     "fit_against_rate": bool, "sign_definite": bool, "stream": int, "reads": tuple}


def register_sweep(cls: type[AbstractSweep]) -> type[AbstractSweep]:
    """Add a sweep kind to `SWEEP_KINDS` under `cls.name` (also usable as a class decorator). From then on
    tables may hold it, `simulate_table` simulates it and identification fits it.

    Checks the interface: a concrete subclass of `gyrojax.AbstractSweep` with every class attribute set
    (strings non-empty, `stream` a non-negative integer, `reads` a tuple of parameter names), and constructible
    without arguments. A name or a `stream` already taken by another class is refused.
    """
    if not (isinstance(cls, type) and issubclass(cls, AbstractSweep)):
        raise ValueError(f"register_sweep expects a subclass of gyrojax.AbstractSweep, got {cls!r}.")
    for attr, kind in _CLASS_ATTRIBUTES.items():
        value = getattr(cls, attr, None)
        if (not isinstance(value, kind) or (isinstance(value, str) and not value.strip())
                or (kind is int and isinstance(value, int) and (isinstance(value, bool) or value < 0))
                or (isinstance(value, tuple) and not all(isinstance(v, str) for v in value))):
            what = {str: "non-empty string", bool: "bool", int: "non-negative integer (its own random stream)",
                    tuple: "tuple of parameter names"}[kind]
            raise ValueError(f"sweep class {cls.__qualname__}: class attribute {attr!r} must be a {what}, got "
                             f"{value!r}.")
    if cls.name != cls.name.strip() or "," in cls.name:
        raise ValueError(f"sweep class {cls.__qualname__}: name {cls.name!r} must not contain commas or start "
                         "or end with spaces (it is a cell of a CSV file and an item of --sweeps).")
    taken = SWEEP_KINDS.get(cls.name)
    if taken is not None and taken is not cls:
        raise ValueError(f"sweep name {cls.name!r} is already registered by {taken.__qualname__}.")
    same = next((k for k in SWEEP_KINDS.values() if k.stream == cls.stream and k.name != cls.name), None)
    if same is not None:
        raise ValueError(f"sweep class {cls.__qualname__}: stream {cls.stream} is already the random stream of "
                         f"{same.name!r} ({same.__qualname__}); give the kind a stream number of its own.")
    try:
        cls()
    except TypeError as e:
        raise ValueError(f"sweep class {cls.__qualname__} must be concrete and constructible without "
                         f"arguments: {e}") from None
    SWEEP_KINDS[cls.name] = cls
    return cls


def sweep_kind(sweep: str | AbstractSweep) -> AbstractSweep:
    """The sweep kind named `sweep` with its default settings (an `AbstractSweep` is returned as it is).

    Raises a `ValueError` for an unknown name, with the closest registered name if there is one.
    """
    if isinstance(sweep, AbstractSweep):
        return sweep
    try:
        return SWEEP_KINDS[sweep]()
    except (KeyError, TypeError):
        close = difflib.get_close_matches(str(sweep).lower(), SWEEP_KINDS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"unknown sweep {sweep!r}{hint}; expected one of {', '.join(SWEEP_KINDS)}.") from None
