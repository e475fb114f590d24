"""Compensation: correcting a device's rate output from its rate-table points (`compensate`, `rate_points`) with a
polynomial, the identified model, or both (`COMPENSATORS` names them); `AbstractCompensator` is the extension
point for a new method.

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._compensate.base import AbstractCompensation as AbstractCompensation, AbstractCompensator as AbstractCompensator
from ._compensate.compensate import (
    COMPENSATORS as COMPENSATORS,
    CompensatedDevice as CompensatedDevice,
    CompensatedRun as CompensatedRun,
    CompensationResult as CompensationResult,
    compensate as compensate,
    rate_points as rate_points,
)
from ._compensate.composite import (
    CompositeCompensation as CompositeCompensation,
    CompositeCompensator as CompositeCompensator,
)
from ._compensate.model import ModelCompensation as ModelCompensation, ModelCompensator as ModelCompensator
from ._compensate.points import RatePoints as RatePoints
from ._compensate.polynomial import (
    PolynomialCompensation as PolynomialCompensation,
    PolynomialCompensator as PolynomialCompensator,
)


__all__ = [
    "AbstractCompensation",
    "AbstractCompensator",
    "COMPENSATORS",
    "CompensatedDevice",
    "CompensatedRun",
    "CompensationResult",
    "CompositeCompensation",
    "CompositeCompensator",
    "ModelCompensation",
    "ModelCompensator",
    "PolynomialCompensation",
    "PolynomialCompensator",
    "RatePoints",
    "compensate",
    "rate_points",
]
