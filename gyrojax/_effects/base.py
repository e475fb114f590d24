"""The effect interface: a small module holding its own parameters, nested at zero."""

import abc
from typing import ClassVar

import equinox as eqx

from .._gyroscope import Gyroscope


class AbstractEffect(eqx.Module):
    """A physical effect that can be added to a `Gyroscope`.

    An effect holds its own parameters; with all of them zero, `apply` returns the device unchanged
    (nested at zero), so the gradient of a misfit with respect to them at zero measures how much the
    effect could explain. `apply` returns a new device (`eqx.tree_at`), never mutates one.
    """

    name: ClassVar[str]
    description: ClassVar[str]

    @abc.abstractmethod
    def apply(self, gyro: Gyroscope) -> Gyroscope:
        """The device with this effect added on top of whatever it already has."""

    @classmethod
    @abc.abstractmethod
    def typical(cls, scale: float = 1.0) -> "AbstractEffect":
        """The effect at a typical size for the preset devices, times `scale`."""
