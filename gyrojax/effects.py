"""Effects: the parasitic and non-ideal behaviours a device can carry, each an `AbstractEffect` that is nested at
zero (all parameters zero gives back the device unchanged), and the registry that names them.

`EFFECTS`/`effect`/`add_effect`/`supported_effects` look effects up by name and add them to a device;
`register_effect` adds a user's own class (docs: "Adding an effect");
`load_effects_module`/`load_effect_entry_points` load effects from a Python file or from installed packages.

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._effects.agc_finite_gain import AgcFiniteGain as AgcFiniteGain
from ._effects.base import AbstractEffect as AbstractEffect
from ._effects.comb_gap import CombGap as CombGap
from ._effects.dac_inl import DacInl as DacInl
from ._effects.damping_coupling import DampingCoupling as DampingCoupling
from ._effects.duffing_drive import DuffingDrive as DuffingDrive
from ._effects.duffing_sense import DuffingSense as DuffingSense
from ._effects.feedback_compression import FeedbackCompression as FeedbackCompression
from ._effects.plugins import (
    load_effect_entry_points as load_effect_entry_points,
    load_effects_module as load_effects_module,
)
from ._effects.pushpull_mismatch import PushPullMismatch as PushPullMismatch
from ._effects.quadrature_phase import QuadraturePhase as QuadraturePhase
from ._effects.registry import (
    EFFECTS as EFFECTS,
    add_effect as add_effect,
    effect as effect,
    register_effect as register_effect,
    supported_effects as supported_effects,
)
from ._effects.thermal_drift import ThermalDrift as ThermalDrift
from ._effects.vref_drift import VrefDrift as VrefDrift
from ._effects.zro_tempco import ZroTempco as ZroTempco


__all__ = [
    "AbstractEffect",
    "AgcFiniteGain",
    "CombGap",
    "DacInl",
    "DampingCoupling",
    "DuffingDrive",
    "DuffingSense",
    "EFFECTS",
    "FeedbackCompression",
    "PushPullMismatch",
    "QuadraturePhase",
    "ThermalDrift",
    "VrefDrift",
    "ZroTempco",
    "add_effect",
    "effect",
    "load_effect_entry_points",
    "load_effects_module",
    "register_effect",
    "supported_effects",
]
