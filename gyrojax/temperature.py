"""Temperature histories: what die temperature a device sees over a run (`AbstractTemperature` and the constant,
plateau and warm-up histories).

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._physics.thermal import (
    AbstractTemperature as AbstractTemperature,
    ConstantTemperature as ConstantTemperature,
    PlateauTemperature as PlateauTemperature,
    WarmupTemperature as WarmupTemperature,
)


__all__ = [
    "AbstractTemperature",
    "ConstantTemperature",
    "PlateauTemperature",
    "WarmupTemperature",
]
