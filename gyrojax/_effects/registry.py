"""Effects by name, `add_effect`, and registering a new one."""

import jax
import numpy as np

from .._gyroscope import Gyroscope
from .agc_finite_gain import AgcFiniteGain
from .base import AbstractEffect
from .comb_gap import CombGap
from .dac_inl import DacInl
from .damping_coupling import DampingCoupling
from .duffing_drive import DuffingDrive
from .duffing_sense import DuffingSense
from .feedback_compression import FeedbackCompression
from .pushpull_mismatch import PushPullMismatch
from .quadrature_phase import QuadraturePhase
from .thermal_drift import ThermalDrift
from .vref_drift import VrefDrift
from .zro_tempco import ZroTempco


EFFECTS: dict[str, type[AbstractEffect]] = {cls.name: cls for cls in (
    DacInl, PushPullMismatch, CombGap, ThermalDrift, AgcFiniteGain, DuffingDrive, DuffingSense,
    QuadraturePhase, DampingCoupling, VrefDrift, ZroTempco, FeedbackCompression,
)}
"""The candidate effects by name: the physical effects of the model's sources, then the classic error sources
that need a term of their own (a temperature-dependent zero-rate output, compression after the DAC)."""


def register_effect(cls: type[AbstractEffect]) -> type[AbstractEffect]:
    """Add a user-written effect class to `EFFECTS` under `cls.name` (also usable as a class decorator).

    Checks the interface: a subclass of `AbstractEffect` with string `name`, `description` and `plugs_into`,
    whose `typical(0.0)` has all-zero array leaves. A name already taken by another class is refused.
    """
    if not (isinstance(cls, type) and issubclass(cls, AbstractEffect)):
        raise ValueError(f"register_effect expects a subclass of gyrojax.AbstractEffect, got {cls!r}.")
    for attr in ("name", "description", "plugs_into"):
        if not isinstance(getattr(cls, attr, None), str) or not getattr(cls, attr):
            raise ValueError(f"effect class {cls.__qualname__}: class attribute {attr!r} must be a non-empty "
                             f"string, got {getattr(cls, attr, None)!r}.")
    taken = EFFECTS.get(cls.name)
    if taken is not None and taken is not cls:
        raise ValueError(f"effect name {cls.name!r} is already registered by {taken.__qualname__}.")
    zero = cls.typical(0.0)
    if not isinstance(zero, cls) or any(np.any(np.asarray(x) != 0) for x in jax.tree.leaves(zero)):
        raise ValueError(f"effect class {cls.__qualname__}: typical(0.0) must be an instance with all-zero "
                         "parameters (the effect must be nested at zero).")
    EFFECTS[cls.name] = cls
    return cls


def effect(name: str, scale: float = 1.0) -> AbstractEffect:
    """The named effect at its typical size times `scale`."""
    try:
        cls = EFFECTS[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; expected one of {sorted(EFFECTS)}.") from None
    return cls.typical(scale)


def add_effect(gyro: Gyroscope, eff: AbstractEffect | str, scale: float = 1.0) -> Gyroscope:
    """A new device with `eff` (an effect, or its name at typical size times `scale`) added."""
    if isinstance(eff, str):
        eff = effect(eff, scale)
    return eff.apply(gyro)


def supported_effects(gyro: Gyroscope) -> tuple[str, ...]:
    """Names of the registered effects that can act on `gyro` (`supports`), in registry order."""
    return tuple(name for name, cls in EFFECTS.items() if cls.supports(gyro))
