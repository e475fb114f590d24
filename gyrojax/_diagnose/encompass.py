"""Guards that do not depend on the list of shapes: a candidate must stay significant beyond the flexible
description of the misfit it does not explain (an encompassing test).

The test uses the candidate's refit (its real, nonlinear effect) and the flexible descriptions linearly, as the
score test does: the misfit the candidate does not explain, F, is the localisation at the refit
(`gyrojax._diagnose.locate`, described afresh) with the locations before the step that stay significant after the
refit and beyond it (a location before the step that kept significance only through a second misfit the fresh
localisation says along another shape is taken). What the candidate removes beyond F is

    D = (chi2_before - S_F(before)) - (chi2_after - S_F(after)) ~ chi2(df of the step)

with S_F(fit) the chi2 that F's columns remove beyond the fit's own span. A candidate that only takes part of a
misfit of another shape (a bias that jumps partway through a run, taken for a compression of the feedback
amplifier) removes nothing that F would not."""

import numpy as np

from .._identify import Fit
from .._numerics.stats import chi2_sf
from .locate import locate
from .space import EXPLAINED_SHARE_LEFT, ResidualSpace


def encompassing_guard(before: Fit, after: Fit, effect: str, localisation, df: int, alpha: float,
                       located_after=None) -> str | None:
    """A reason not to confirm `effect` (refitted from `before` to `after` with `df` new parameters over the lot),
    or None: what it removes beyond the locations it leaves (see the module docstring) is not significant at
    `alpha`."""
    if not localisation.locations:
        return None
    space_after = ResidualSpace(after)
    # What the refit leaves: the locations before it that it leaves, and the misfit described afresh at the
    # refit. A location before it that holds a right candidate and a second misfit in one flexible shape (an
    # offset along the input growing with temperature: a bias in temperature and a gain from run to run) keeps
    # significance after the refit only through the second misfit, which the fresh description says alone
    # (a gain per run): that location is taken. One that holds a misfit of another shape the candidate took part
    # of keeps what the fresh description of the rest does not say.
    fresh = list((located_after if located_after is not None else locate(after, alpha=alpha, pooled=False)).locations)
    left = left_locations(space_after, localisation, alpha)
    if fresh and left:
        joined = space_after.with_columns(np.concatenate([f.columns for f in fresh], axis=-1))
        cut = alpha / len(localisation.locations)
        left = [loc for loc in left if _keeps(joined.score(loc.columns), loc, cut)]
    left = fresh + left
    if not left:
        return None
    cols = np.concatenate([loc.columns for loc in left], axis=-1)
    d = (before.chi2_total - ResidualSpace(before).score(cols).statistic) - (
        after.chi2_total - space_after.score(cols).statistic)
    p = chi2_sf(max(d, 0.0), max(df, 1))
    if p < alpha:
        return None
    where = "; ".join(f"{loc.shape} on {'+'.join(loc.located_on)}" for loc in left)
    return (f"it is not significant beyond the flexible description of the misfit it leaves ({where}): it removes "
            f"chi2 {d:.4g} beyond it (df {df}, p = {p:.2g}); what it takes is part of a misfit of another shape")


def left_locations(space_after: ResidualSpace, localisation, alpha: float) -> list:
    """The locations of `localisation` (before a refit) that the refit (`space_after`) leaves: still significant
    after it, keeping more than `EXPLAINED_SHARE_LEFT` of their chi2, and beyond the other locations left."""
    locations = localisation.locations
    if not locations:
        return []
    cut = alpha / len(locations)
    left = []
    for loc in locations:
        now = space_after.score(loc.columns)
        if not _keeps(now, loc, cut):
            continue  # the candidate took this misfit
        left.append((now.statistic, loc))
    return _beyond_each_other(space_after, left, cut)


def _beyond_each_other(space, left, cut) -> list:
    """Of the locations left after the refit ((chi2 left, location) pairs), those that stay significant beyond the
    others: a flexible description along the candidate's own coordinate (an offset along temperature around a
    bias linear in it) keeps significance after the refit only through a second misfit it partly overlaps (a
    step partway through a run, located on its own), which the other location says; with it, that is taken.
    The weakest is tested first, so that of two descriptions of one misfit one stays."""
    kept = [loc for _, loc in sorted(left, key=lambda x: x[0])]
    for loc in list(kept):
        others = [o.columns for o in kept if o is not loc]
        if not others:
            break
        now = space.with_columns(np.concatenate(others, axis=-1)).score(loc.columns)
        if not _keeps(now, loc, cut):
            kept = [o for o in kept if o is not loc]
    return kept


def _keeps(now, loc, cut) -> bool:
    """Whether location `loc`, scored `now` beyond some columns, keeps its misfit there: still significant at
    `cut` and more than `EXPLAINED_SHARE_LEFT` of its chi2."""
    return now.p_value < cut and now.statistic > EXPLAINED_SHARE_LEFT * loc.chi2_explained
