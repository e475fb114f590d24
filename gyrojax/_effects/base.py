"""The effect interface: a small module holding its own parameters, nested at zero."""

import abc
from typing import ClassVar

import equinox as eqx

from .._gyroscope import Gyroscope


class AbstractEffect(eqx.Module):
    """A physical effect that can be added to a `Gyroscope`.

    An effect holds its own parameters (its array fields); with all of them zero, `apply` returns a device
    numerically identical to its input (nested at zero), so the gradient of a misfit with respect to them at
    zero measures how much the effect could explain (a score test). `apply` returns a new device
    (`eqx.tree_at`), never mutates one, adds to whatever the device already has in the slot it plugs into,
    and changes leaf values only, never the PyTree structure (or a leaf's shape): devices with and without
    the effect share jitted functions and can be stacked for `vmap`.

    **Class attributes:**

    - `name`: stable name (the registry key, the CLI's `--effect NAME`).
    - `description`: one physical line.
    - `plugs_into`: where in the device tree it acts (paths of the leaves it moves).
    - `revealed_by`: the measurement that sees it apart from the baseline's gains and biases; the diagnosis
      quotes it when the data at hand cannot (empty: not stated).
    """

    name: ClassVar[str]
    description: ClassVar[str]
    plugs_into: ClassVar[str]
    revealed_by: ClassVar[str] = ""

    @abc.abstractmethod
    def apply(self, gyro: Gyroscope) -> Gyroscope:
        """The device with this effect added on top of whatever it already has.

        Raises a `ValueError` naming the effect and the device when `supports(gyro)` is false.
        """

    @classmethod
    @abc.abstractmethod
    def typical(cls, scale: float = 1.0) -> "AbstractEffect":
        """The effect at a typical physical size for the preset devices, times `scale`."""

    @classmethod
    @abc.abstractmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        """Whether the effect can act on this kind of device (on the settled outputs of the tiers)."""
