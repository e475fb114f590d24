"""Guards that do not depend on the list of shapes: a candidate must stay significant beyond the flexible
description of the misfit along the coordinates it does not explain (an encompassing test)."""

import numpy as np

from .._identify import Fit
from .columns import effect_columns
from .score import TYPICAL_RANK_TOL, CandidateScore
from .space import ResidualSpace


# A candidate "explains" a location when the location's description, beyond the fit and the candidate, keeps
# less than this share of its chi2 (or nothing significant): the same rule as the probes' (`SHAPE_SHARE_LEFT`),
# since the candidate's Jacobian is taken at the baseline, not at the truth.
EXPLAINED_SHARE_LEFT = 0.1


def encompassing_guard(fit: Fit, candidate: CandidateScore, localisation, candidate_cut: float,
                       alpha: float) -> str | None:
    """A reason not to confirm `candidate`, or None: the locations of the misfit it does not explain (their
    flexible descriptions, `gyrojax._diagnose.locate`), taken into the fit's span, leave it nothing significant
    (not at `candidate_cut`)."""
    locations = localisation.locations
    if not locations:
        return None
    je = np.asarray(fit.jacobian)[:, :, effect_columns(fit, candidate.effect)]
    space = ResidualSpace(fit)
    with_candidate = space.with_columns(je)
    cut = alpha / len(locations)
    foreign = []
    for loc in locations:
        left = with_candidate.score(loc.columns)
        if left.p_value >= cut or left.statistic <= EXPLAINED_SHARE_LEFT * loc.chi2_explained:
            continue  # the candidate has this misfit's shape
        foreign.append(loc)
    if not foreign:
        return None
    beyond = space.with_columns(np.concatenate([loc.columns for loc in foreign], axis=-1))
    own = beyond.score(je)
    # the candidate's directions that carry information at its typical size (as the score test counts them)
    if own.df and own.p_value < candidate_cut and own.statistic > TYPICAL_RANK_TOL:
        return None
    where = "; ".join(f"{loc.shape} on {'+'.join(loc.located_on)}" for loc in foreign)
    return (f"it is not significant beyond the flexible description of the misfit it does not explain ({where}): "
            f"S = {own.statistic:.3g}, df {own.df}, p = {own.p_value:.2g} beyond it; what it would take is part of "
            "a misfit of another shape")
