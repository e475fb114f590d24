r"""Slots for new physics: terms a device carries beside its fixed parts, evaluated where they act.

A `Gyroscope` holds a tuple `terms`. Each term is an `eqx.Module` of one of four kinds, and the tiers and
the measurement model call every term of a kind at the place where that kind acts:

| kind | what it adds | where it acts |
|---|---|---|
| `AbstractRateTerm` | a rate-equivalent sense force Om_eq(T, t, Om), rad/s: a force in phase with the Coriolis force, like a zero-rate output | the sense equation of every tier, beside Ag Om |
| `AbstractFeedbackTerm` | a memoryless map of the feedback voltage after the DAC (amplifier, electrodes) | the instantaneous carrier samples of the force-to-rebalance path; the DAC sweep reads before it |
| `AbstractOutputTerm` | a map of the settled rate output (LSB) given the point's conditions | the readout of rate-table and static-VCF points |
| `TemperatureCoefficient` | a linear temperature coefficient on any array leaf | the device at the die temperature of each instant |

An effect that needs a term the fixed parts cannot express is itself a term: it subclasses its kind as well
as `AbstractEffect`, and its `apply` is `gyro.with_term(self)`. A term with all its parameters zero must
leave every output unchanged (nested at zero), so that the diagnosis can score it at zero.

Adding a term adds leaves to the device (the devices with the term at zero and at any size share one
structure and every compiled function; the device without it has another).
"""

import abc
import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


Device = Any
"""A `gyrojax.Gyroscope`, which holds the terms (its module imports this one, so this one cannot import it)."""


class AbstractTerm(eqx.Module):
    """A term carried by a `Gyroscope` in its `terms` slot. Subclass one of the four kinds, not this."""


class AbstractRateTerm(AbstractTerm):
    r"""A rate-equivalent sense force: the sense mode feels the Coriolis force of Om + Om_eq.

    In the averaged equations this is `dY/dt -= Ag Om_eq X` beside the Coriolis term (full waveform:
    `y'' += -2 Ag Om_eq x'`); the force-to-rebalance loop then balances it, and an open-loop readout sees it,
    exactly like a rate. A zero-rate output that depends on the die temperature or on the time since
    power-on (anisodamping that drifts, electrical crosstalk) is a term of this kind.
    """

    @abc.abstractmethod
    def rate(self, gyro: Device, temperature: Float[Array, ""], time: Float[Array, ""], rate: Float[Array, ""]
             ) -> Float[Array, ""]:
        """Om_eq in rad/s at die `temperature` (deg C), `time` since power-on (s) and input `rate` (rad/s)."""


class AbstractFeedbackTerm(AbstractTerm):
    """A memoryless nonlinearity (or gain) of the feedback path after the DAC: the amplifier output V_fa
    (V, instantaneous carrier samples) goes in, the voltage split onto the + and - branches comes out."""

    @abc.abstractmethod
    def __call__(self, gyro: Device, voltage: Float[Array, "*sample"]) -> Float[Array, "*sample"]:
        """The voltage after this term, for instantaneous samples `voltage` (V, any shape)."""


class PointConditions(eqx.Module):
    """What an output term may depend on besides the output: the point's sweep kind, its `input` (the data
    column: deg/s for a rate table, V for a static VCF sweep), die `temperature` (deg C) and `time` since
    power-on (s; 0 when not recorded)."""

    sweep: str = eqx.field(static=True)
    input: jax.Array
    temperature: jax.Array
    time: jax.Array


class AbstractOutputTerm(AbstractTerm):
    """A term of the readout path: maps the settled rate output (LSB) of a rate-table or static-VCF point,
    e.g. an additive offset that drifts with temperature or time, or an output nonlinearity."""

    @abc.abstractmethod
    def __call__(self, gyro: Device, output: Float[Array, ""], conditions: PointConditions) -> Float[Array, ""]:
        """The output (LSB) after this term."""


def _leaf(path: str):
    return lambda g: functools.reduce(getattr, path.split("."), g)


class TemperatureCoefficient(AbstractTerm):
    """A linear temperature coefficient on any array leaf of the device: at die temperature T the leaf at
    `path` (dotted, e.g. `"drive_frontend.gain"`) is its value times (1 + tc (T - t_ref)), with t_ref the
    resonator's reference temperature. Several coefficients on one leaf multiply."""

    path: str = eqx.field(static=True)
    tc: jax.Array = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))

    def scaled(self, gyro: Device, temperature: Float[ArrayLike, ""]) -> Device:
        dt = jnp.asarray(temperature, dtype=float) - gyro.resonator.t_ref
        where = _leaf(self.path)
        return eqx.tree_at(where, gyro, where(gyro) * (1.0 + self.tc * dt))


def check_path(gyro: Device, path: str) -> None:
    """Raise a ValueError unless `path` names an array leaf of `gyro`."""
    try:
        leaf = _leaf(path)(gyro)
    except AttributeError:
        raise ValueError(f"TemperatureCoefficient.path {path!r} is not a leaf of device {gyro.name!r} "
                         "(a dotted path of attributes, e.g. 'drive_frontend.gain').") from None
    if not (eqx.is_array(leaf) or isinstance(leaf, float)):
        raise ValueError(f"TemperatureCoefficient.path {path!r} of device {gyro.name!r} is a "
                         f"{type(leaf).__name__}, not a number: a coefficient scales an array leaf.")
