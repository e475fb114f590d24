"""The measurement planner: which experiments make each candidate effect testable, and the scale factor's
design within a time budget."""

from .experiment import (
    CandidateExperiment as CandidateExperiment,
    NoiseLevel as NoiseLevel,
    default_experiments as default_experiments,
)
from .plan import plan as plan
from .power import ncx2_sf as ncx2_sf, power as power, required_noncentrality as required_noncentrality
from .rate_table import RateTablePlan as RateTablePlan, rate_table_plan as rate_table_plan
from .results import (
    CandidatePlan as CandidatePlan,
    Plan as Plan,
    Recommendation as Recommendation,
    ScaleFactorDesign as ScaleFactorDesign,
)
