"""The score test of each candidate effect at a fitted model, its fingerprint, what makes it testable, and
the sweep on which two fingerprints differ most."""

import math

import equinox as eqx
import numpy as np

from .._effects.registry import EFFECTS
from .._identify import Fit
from .._model.fitdata import FitData
from .._numerics.testability import MIN_TYPICAL_CHI2, is_testable, separates
from .columns import effect_columns, row_blocks
from .probes import score_columns


class CandidateScore(eqx.Module):
    """One candidate effect scored against a fitted model (no refit)."""

    effect: str
    statistic: float
    df: int
    p_value: float
    testable: bool
    fingerprint: np.ndarray  # (device, residual): predicted residual change
    description: str
    typical_chi2: float = 0.0  # chi2 left by the most visible typical-size combination, summed over devices
    # The same before the baseline's free parameters take their share (after the run biases), and the free
    # parameters that take it: what hides the candidate when it is not testable.
    visible_chi2: float = 0.0
    absorbed_by: tuple[str, ...] = ()

    @property
    def implied_multiple(self) -> float:
        """The size, in units of its typical size, at which the candidate would explain what its score
        credits it with: sqrt(S / typical_chi2) (its most visible combination)."""
        if self.typical_chi2 <= 0:
            return math.inf
        return math.sqrt(max(self.statistic, 0.0) / self.typical_chi2)

    @property
    def absorption(self) -> str:
        """Why the data cannot test it, in words: what takes up its fingerprint, and what would reveal it."""
        if self.visible_chi2 < 1.0:
            what = (f"a typical size changes the chi2 by {self.visible_chi2:.2g} once the run biases are "
                    "out: the run biases take it up, or this data barely sees it")
        else:
            share = 1.0 - self.typical_chi2 / self.visible_chi2
            who = ", ".join(self.absorbed_by) or "the free parameters together"
            what = (f"a typical size would change the chi2 by {self.visible_chi2:.3g}; {who} "
                    f"{'absorbs' if len(self.absorbed_by) == 1 else 'absorb'} {100 * share:.4g} % of it, "
                    f"leaving {_left(self.typical_chi2, self.visible_chi2)}")
        reveal = EFFECTS[self.effect].revealed_by
        return what + (f". Revealed by: {reveal}" if reveal else "")


def _left(typical_chi2: float, visible_chi2: float) -> str:
    # What a fully absorbed direction leaves is round-off (~1e-23, a tiny negative too), which differs between
    # machines: printed as 0, not as a number the data determined.
    return "0" if typical_chi2 <= 1e-12 * max(visible_chi2, 1.0) else f"{typical_chi2:.2g}"


# A candidate direction counts in the score test when a typical size of it changes the chi2 by more than this
# (its columns are per typical size): below, the data do not see it.
TYPICAL_RANK_TOL = 1e-4


def score_candidates(fit: Fit, candidates, *, rank_tol: float = TYPICAL_RANK_TOL,
                     min_typical_chi2: float = MIN_TYPICAL_CHI2) -> tuple[CandidateScore, ...]:
    """Score test of each candidate (effect name held at zero in `fit.model`) against the fitted model. A
    candidate is testable by `gyrojax._numerics.testability`'s rule: its typical size leaves chi2 `min_typical_chi2`."""
    jac = np.asarray(fit.jacobian)
    res = np.asarray(fit.residual_vector)
    free = np.asarray(fit.free)
    names_free = [nm for nm, f in zip(fit.names, free) if f]
    out = []
    for name in candidates:
        cols = effect_columns(fit, name)
        visible = 0.0
        share = np.zeros(len(names_free))  # of the most visible fingerprint's chi2, per free parameter
        for d in range(jac.shape[0]):
            jb, je = jac[d][:, free], jac[d][:, cols]
            if je.shape[1]:
                evals, evecs = np.linalg.eigh(je.T @ je)
                visible += max(float(evals[-1]), 0.0)
                if jb.shape[1]:
                    # |P f|^2 = sum_k c_k (b_k . f) with c the least-squares coefficients of f on the columns
                    f = je @ evecs[:, -1]
                    c = np.linalg.lstsq(jb, f, rcond=None)[0]
                    share += c * (jb.T @ f)
        scored = score_columns(jac[:, :, free], jac[:, :, cols], res, rank_tol=rank_tol)
        order = np.argsort(-share)
        absorbed_by = tuple(names_free[k] for k in order if share[k] > 0.1 * max(np.sum(share), 0.0))
        testable = scored.df > 0 and is_testable(scored.information, min_typical_chi2)
        out.append(CandidateScore(effect=name, statistic=scored.statistic, df=scored.df, p_value=scored.p_value,
                                  testable=testable, fingerprint=scored.fingerprint,
                                  description=EFFECTS[name].description, typical_chi2=scored.information,
                                  visible_chi2=visible, absorbed_by=absorbed_by))
    return tuple(sorted(out, key=lambda c: (not c.testable, c.p_value, -c.statistic)))


def cosine(a, b):
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return 0.0 if na == 0 or nb == 0 else float(np.sum(a * b) / (na * nb))


def separating_sweep(a, b, data: FitData, ambiguity):
    """The sweep of `data` on whose rows the fingerprints `a` and `b` (at their fitted sizes) differ most, among
    those that separate them by `gyrojax._numerics.testability.separates` (what one leaves after the other is
    testable); None when no sweep does."""
    best, best_cos = None, ambiguity
    for sweep, i, j in row_blocks(data):
        c = abs(cosine(a[:, i:j], b[:, i:j]))
        if separates(a[:, i:j], b[:, i:j]) and c < best_cos:
            best, best_cos = sweep, c
    return best
