"""False-discovery control across the candidates and steps of a diagnosis (Benjamini-Hochberg)."""

import numpy as np


def selection_p(p_value: float, candidates: int) -> float:
    """A step's p-value corrected for having picked the best of `candidates` (Bonferroni)."""
    return min(1.0, float(p_value) * max(int(candidates), 1))


def bh_q_values(p_values) -> np.ndarray:
    """Benjamini-Hochberg q-values of `p_values` (the smallest false-discovery rate at which each is a
    discovery), in the given order."""
    p = np.asarray(p_values, float)
    n = p.size
    if n == 0:
        return p
    order = np.argsort(p)
    ranked = p[order] * n / np.arange(1, n + 1)
    q = np.minimum.accumulate(ranked[::-1])[::-1]
    out = np.empty(n)
    out[order] = np.minimum(q, 1.0)
    return out
