"""Numerical building blocks: small dense solves in XLA operations (`linsolve.py`), the Levenberg-Marquardt
solver (`lm.py`), chi-squared tails and quantiles (`stats.py`) and the one testability rule (`testability.py`)."""
