r"""`diagnose`: see where a model fails, learn which physical effect is missing, add it, watch the error fall.

Every candidate effect is in the model from the start, nested at zero and held there, so the baseline fit
already carries the Jacobian of the residuals with respect to every candidate's parameters (one compiled
model for the whole loop). At a fitted model, a candidate with parameters psi is ranked by the score
(Lagrange-multiplier) test, per device d and summed over the lot:

    J_e' = (I - P_b) J_e,   s = J_e'^T r,   S = sum_d s^T (J_e'^T J_e')^+ s  ~  chi2(sum_d rank)

where r are the standardised residuals, J_b the Jacobian of the free baseline parameters (P_b its
projector: what the baseline could already absorb is removed) and J_e that of the candidate. The predicted
residual change J_e' (J_e'^T J_e')^+ s is the candidate's fingerprint on this data. Effect parameters are
in units of their typical size, so the largest eigenvalue of J_e'^T J_e', summed over devices, is the chi2
that the most visible typical-size combination of the candidate would leave after the baseline took up what
it could (`typical_chi2`). A candidate whose projected Jacobian is empty, or whose `typical_chi2` is below
`min_typical_chi2` (a typical-size effect changes the lot's chi2 by less than the noise does) while its
score is not significant, is reported as not testable (the baseline absorbs it, or this data cannot see
it at a plausible size); it stays in the ranking and is still selected if significant. The best candidate with p below
alpha / (number of candidates) is refitted; the likelihood-ratio test
(chi2 drop ~ chi2(df)) and BIC confirm it, and the loop repeats until no candidate is significant.
Significant candidates whose fingerprints are nearly collinear (|cos| > `ambiguity`) are reported together,
with the sweep of the data on which their fingerprints differ most, if any.
"""

from .candidates import (
    baseline_model as baseline_model,
    candidate_effects as candidate_effects,
    first_device as first_device,
    full_key as full_key,
    is_lot as is_lot,
)
from .diagnose import diagnose as diagnose
from .discrepancy import Discrepancy as Discrepancy, LookAlike as LookAlike, score_probes as score_probes
from .guards import MAX_TYPICAL_MULTIPLE as MAX_TYPICAL_MULTIPLE, Rejection as Rejection
from .report import write_report as write_report
from .score import CandidateScore as CandidateScore, score_candidates as score_candidates
from .solution import (
    IMPLAUSIBLE_MULTIPLE as IMPLAUSIBLE_MULTIPLE,
    VERDICTS as VERDICTS,
    Diagnosis as Diagnosis,
    Step as Step,
)
