"""Testability: one rule for whether data can test a candidate effect, and whether a sweep tells two apart,
used by `gyrojax.diagnose` (its ranking and what separates look-alikes) and `gyrojax.plan` (its candidates).

A candidate is *testable* on some data when a typical-size effect leaves an expected chi2 of at least
`MIN_TYPICAL_CHI2` once what can take it up (the baseline's free parameters, each run's bias) has taken its
share. Below that, a typical-size effect changes the chi2 by less than one point's noise does: the data cannot
test it, however small its p-value at some other size. The planner's power (at `target_power`) is a stronger
demand on the same number: a testable effect may still need more runs to be detected reliably.

A sweep *separates* two fingerprints (the residual changes two effects predict) when, on its rows, what one
leaves after the other took the share it can explains at least `MIN_TYPICAL_CHI2` (the same rule, applied to
the part of one effect the other cannot imitate)."""

import math

import numpy as np


MIN_TYPICAL_CHI2 = 1.0
"""The expected chi2 a typical-size effect must leave (after the baseline absorbed what it can) for the data to
test it: one point's worth of noise."""


def is_testable(typical_chi2: float, threshold: float = MIN_TYPICAL_CHI2) -> bool:
    """Whether an effect leaving expected chi2 `typical_chi2` at its typical size is testable (see the module
    notes)."""
    return bool(math.isfinite(typical_chi2) and typical_chi2 >= threshold)


def unseparated_chi2(a, b) -> float:
    """The chi2 of fingerprint `a` (standardised residual changes, any shape) that fingerprint `b` cannot
    take at any size: |a - b (a.b / b.b)|^2 (all of a when b is zero)."""
    a, b = np.ravel(np.asarray(a, dtype=float)), np.ravel(np.asarray(b, dtype=float))
    bb = float(b @ b)
    r = a - b * (float(a @ b) / bb) if bb > 0 else a
    return float(r @ r)


def separates(a, b, threshold: float = MIN_TYPICAL_CHI2) -> bool:
    """Whether rows on which the fingerprints are `a` and `b` tell the two effects apart: what either leaves
    after the other took its share is testable."""
    return is_testable(max(unseparated_chi2(a, b), unseparated_chi2(b, a)), threshold)
