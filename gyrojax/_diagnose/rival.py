r"""A guard that does not depend on the list of shapes: a library effect is compared with the closed form the
data themselves propose for the misfit it takes (`gyrojax._diagnose.formula`), a rival outside the library.

The two explanations are not nested, so neither likelihood-ratio test decides between them. As in Vuong's and
Cox's tests, the difference of their chi2 (each with an information-criterion penalty of 2 per parameter),

    Delta = (chi2_effect + 2 k_effect) - (chi2_formula + 2 k_formula),

is compared with its own noise: if the effect's refit changes the standardised predictions by f_E and the
formula (fitted to the residuals beyond the same baseline) by f_F, noise moves Delta by 2 |f_E - f_F| (one
standard deviation), so z = Delta / (2 |f_E - f_F|) ~ N(0, 1) when both describe the data equally well.

- The formula is the effect's own shape in the dictionary's words (the effect's change lies in the span of the
  formula's terms to `SAME_SHAPE` of its norm squared): no rival, the effect stands.
- z above 0: a shape outside the library fits the data as well or better, after paying for its choice among
  the dictionary's terms (2 ln N per term: the risk inflation of a best-of-N selection); the effect is not
  confirmed.
- z between -`Z_CRIT` (1 - inside) and 0, with `inside` the share of the effect's change inside the formula's
  span: the effect fits better, but not by the margin the difference of the two shapes asks for. A rival of
  nearly the effect's shape (inside near 1: a quadratic in temperature against a linear one over a ramp) predicts
  what the effect predicts, so choosing between them is no claim about physics and needs no margin; a rival of
  another shape (inside near 0) predicts differently, and naming the library effect is a claim the data must
  support by the full `Z_CRIT`. Not confirmed: the data do not tell the two apart.
- z between -`Z_CRIT` and that margin: confirmed, and the closed form is reported as a look-alike the data cannot
  tell from it.
- z below -`Z_CRIT`: the effect fits better than every closed form the dictionary offers.
"""

import dataclasses
import math

import numpy as np

from .._identify import Fit
from .discrepancy import LookAlike
from .formula import Formula, formula_columns, propose
from .locate import locate
from .space import ResidualSpace


SAME_SHAPE = 0.99  # share of the effect's change (norm squared) inside the formula's span: the same shape
Z_CRIT = 1.96  # a rival closer than this many standard deviations is a look-alike


@dataclasses.dataclass(frozen=True)
class Rivalry:
    """The comparison of an effect's refit with the formula of the misfit it takes."""

    formula: Formula  # the rival
    z: float  # > 0: the formula fits better
    delta: float  # the penalised chi2 difference (effect - formula)
    distance: float  # |f_E - f_F|, standardised
    inside: float  # share of the effect's change inside the formula's span

    @property
    def verdict(self) -> str:
        if self.inside >= SAME_SHAPE:
            return "same shape"
        if self.z > 0.0:
            return "rival fits as well"
        if self.z > -Z_CRIT * (1.0 - self.inside):
            return "not told apart"
        if self.z > -Z_CRIT:
            return "look-alike"
        return "effect fits better"


def rival(before: Fit, after: Fit, df_effect: int, localisation, *, alpha: float,
          located_after=None) -> Rivalry | None:
    """The closed form of the misfit that the refit from `before` to `after` (`df_effect` new parameters over
    the lot) takes most of, compared with the refit (see the module docstring); None when no location of
    `localisation` (at `before`) loses chi2 in the refit or no term is significant there."""
    if not localisation.locations:
        return None
    space_b, space_a = ResidualSpace(before), ResidualSpace(after)
    taken = [(space_b.score(loc.columns).statistic - space_a.score(loc.columns).statistic, loc)
             for loc in localisation.locations]
    gain, loc = max(taken, key=lambda x: x[0])
    if gain <= 0:
        return None
    # A second misfit, what the refit leaves along other coordinates than the misfit the effect takes, is credited
    # to both sides: the rival's formula is not credited with a term for it (a step beside a bias in temperature),
    # nor the effect blamed for leaving it. (The rest of the effect's own misfit is what a rival may explain better.)
    chi2_before, chi2_after = float(before.chi2_total), float(after.chi2_total)
    f_effect = np.asarray(before.residual_vector, float) - np.asarray(after.residual_vector, float)
    left = (located_after if located_after is not None else locate(after, alpha=alpha, pooled=False)).locations
    other = [o.columns for o in left if o.coordinate != loc.coordinate]
    if other:
        oc = np.concatenate(other, axis=-1)
        for d in range(oc.shape[0]):  # without the effect's own change: the other misfit only
            norm = float(f_effect[d] @ f_effect[d])
            if norm > 0:
                oc[d] -= np.outer(f_effect[d], f_effect[d] @ oc[d]) / norm
        chi2_before -= space_b.score(oc).statistic
        chi2_after -= space_a.score(oc).statistic
        space_b, space_a = space_b.with_columns(oc), space_a.with_columns(oc)
    # the rival is the best closed form of another shape: terms that alone reproduce the effect's change are
    # its own shape in the dictionary's words, not a rival
    formula = propose(before, loc, step_at=localisation.step_at, periods=localisation.periods, alpha=alpha,
                      space=space_b, allowed=lambda _, c: _inside(space_b, c, f_effect) < SAME_SHAPE)
    if formula is None:
        return None
    cols = formula_columns(space_b, formula)
    sc = space_b.score(cols)
    f_formula = sc.fingerprint
    inside = _inside(space_b, cols, f_effect)
    chi2_effect = chi2_after + 2.0 * df_effect
    rest = _closed_rest(after, space_a, [o for o in left if o.coordinate == loc.coordinate], located_after, alpha)
    if rest is not None:
        # what the refit leaves along the misfit's own coordinate has a closed form of its own (a bias quadratic in
        # time beside a tempco, where the input and the time move together): the effect with that form, both paying
        # as the rival does, is one complete explanation, the rival another
        rest_sc, rest_formula = rest
        chi2_effect += (-rest_sc.statistic + 2.0 * rest_sc.df
                        + 2.0 * math.log(max(rest_formula.dictionary_size, 1)) * len(rest_formula.terms))
        f_effect = f_effect + rest_sc.fingerprint
    # the formula's terms were chosen among the dictionary's: each pays 2 ln(size) for that choice (the risk
    # inflation of a best-of-N selection), beside 2 per coefficient
    chi2_formula = (chi2_before - sc.statistic + 2.0 * sc.df
                    + 2.0 * math.log(max(formula.dictionary_size, 1)) * len(formula.terms))
    delta = chi2_effect - chi2_formula
    distance = float(np.sqrt(np.sum((f_effect - f_formula) ** 2)))
    z = delta / (2.0 * distance) if distance > 0 else (math.inf if delta > 0 else -math.inf if delta < 0 else 0.0)
    return Rivalry(formula, float(z), float(delta), distance, float(inside))


def _closed_rest(after: Fit, space_a: ResidualSpace, same, located_after, alpha):
    """(its score at `after`, the formula) of the strongest misfit `same` the refit leaves along the effect's own
    coordinate, where the dictionary describes it completely; None otherwise (a shape no term has: what is left
    may be the effect's own misfit, which the rival may explain better)."""
    if not same or located_after is None:
        return None
    top = max(same, key=lambda o: space_a.score(o.columns, o.pooled).statistic)
    f = propose(after, top, step_at=located_after.step_at, periods=located_after.periods, alpha=alpha,
                space=space_a)
    if f is None or not f.complete:
        return None
    return space_a.score(formula_columns(space_a, f)), f


def _inside(space, cols, f):
    """The share of `f` (device, rows; norm squared) inside the span of `cols` beyond the fit's own span, each
    device its own coefficients."""
    within = space.project(cols)
    num, norm = 0.0, float(np.sum(f**2))
    for d in range(within.shape[0]):
        if not np.any(within[d]):
            continue
        u, sv, _ = np.linalg.svd(within[d], full_matrices=False)
        u = u[:, sv > 1e-9 * sv.max()]
        num += float(np.sum((u.T @ f[d]) ** 2))
    return num / norm if norm > 0 else 1.0


def rival_guard(before: Fit, after: Fit, effect: str, df_effect: int, localisation, *, alpha: float,
                located_after=None):
    """(a reason not to confirm `effect` and its kind in a few words, or None; a `LookAlike` naming the rival
    the data cannot tell from it, or None). `located_after`: the localisation at `after`, the misfit it leaves."""
    r = rival(before, after, df_effect, localisation, alpha=alpha, located_after=located_after)
    if r is None or r.verdict in ("same shape", "effect fits better"):
        return None, None
    terms = " + ".join(f"{t.name} on {'+'.join(t.sweeps)}" for t in r.formula.terms)
    if r.verdict == "rival fits as well":
        return (f"a closed form of another shape outside the library fits the misfit it takes as well or better: "
                f"{terms} (chi2 + 2k, the closed form also paying 2 ln {r.formula.dictionary_size} per term chosen "
                f"from the dictionary: {effect} {r.delta:+.4g} against it, z = {r.z:.2g}; the two differ by "
                f"{r.distance:.3g} sigma in the predictions)", "a closed form of another shape as good"), None
    if r.verdict == "not told apart":
        return (f"the data do not tell it from a closed form of another shape outside the library: {terms} "
                f"({100 * (1 - r.inside):.0f} % of what {effect} changes lies outside that form's span, so naming "
                f"{effect} asks for a margin of {Z_CRIT * (1 - r.inside):.2g} standard deviations; it fits better "
                f"by z = {-r.z:.2g} (chi2 + 2k {r.delta:+.4g}); a longer or wider sweep along the coordinate they "
                f"differ on would decide)", "not told from a closed form of another shape"), None
    factor = (Z_CRIT / abs(r.z)) ** 2 if r.z != 0 else math.inf
    return None, LookAlike(probe=" + ".join(t.name for t in r.formula.terms),
                           shape=f"a closed form outside the library ({terms}), which fits {-r.delta:.3g} worse in "
                                 f"chi2 + 2k (z = {r.z:.2g})", sweeps=(), separation_sigma=r.distance,
                           information_factor=factor)
