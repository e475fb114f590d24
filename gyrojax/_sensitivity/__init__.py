"""Sensitivity studies of the nonlinearity sources: how many ppm of scale-factor nonlinearity each effect causes,
alone and jointly, and its gradients (`budget.py`: `nonlinearity_budget` and the `NonlinearityBudget` it returns)."""

from .budget import (
    EffectContribution as EffectContribution,
    NonlinearityBudget as NonlinearityBudget,
    nonlinearity_budget as nonlinearity_budget,
)
