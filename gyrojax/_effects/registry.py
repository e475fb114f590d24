"""Effects by name, and `add_effect`."""

from .._gyroscope import Gyroscope
from .base import AbstractEffect
from .dac_inl import DacInl


EFFECTS: dict[str, type[AbstractEffect]] = {cls.name: cls for cls in (DacInl,)}


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
