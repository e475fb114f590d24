"""Effects by name, and `add_effect`."""

from .._gyroscope import Gyroscope
from .agc_finite_gain import AgcFiniteGain
from .base import AbstractEffect
from .comb_gap import CombGap
from .dac_inl import DacInl
from .damping_coupling import DampingCoupling
from .duffing_drive import DuffingDrive
from .duffing_sense import DuffingSense
from .pushpull_mismatch import PushPullMismatch
from .quadrature_phase import QuadraturePhase
from .thermal_drift import ThermalDrift
from .vref_drift import VrefDrift


EFFECTS: dict[str, type[AbstractEffect]] = {cls.name: cls for cls in (
    DacInl, PushPullMismatch, CombGap, ThermalDrift, AgcFiniteGain, DuffingDrive, DuffingSense,
    QuadraturePhase, DampingCoupling, VrefDrift,
)}
"""The candidate effects by name, in the order of DESIGN.md §2's table."""


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
