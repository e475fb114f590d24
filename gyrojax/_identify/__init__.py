"""Identification: `identify` fits a model's parameters to every sweep of a lot, with uncertainties, and
returns a `Fit`. One concept per file:

- `identify.py`: the entry point, which composes the pieces below.
- `problem.py`: the problem of one device (parameters, masks, priors) and its residuals.
- `evaluation.py`: `Evaluation` (residuals, Jacobian over every entry, the scale factor and its gradient) and the
  residual function the solvers run, which carries it as aux.
- `strategies.py`: how a lot's devices are solved (vmapped in chunks, sharded, one after another, or jointly), in one
  compiled program per fit that also evaluates at the start (stopped after one step).
- `recovery.py`: what is tried when a solve ends badly (multi-start, a retry with another solver, the restart of
  a run-off fit, the decrement certificate).
- `identifiability.py`: what the data cannot fix (hold rules, weak directions, the scale factor's determinacy).
- `covariance.py`: covariance, the Gauss-Newton decrement, the chi2 test's p-values.
- `noise.py`: the noise of data without `output_sigma`, estimated from a first fit's residuals.
- `plausibility.py`: data no fit can mean anything with (refused), and implausible fitted values (flagged).
- `assemble.py`: from a solution to a `Fit` (statuses and warnings).
- `coverage.py`: the coverage audit of a fit's intervals (`coverage`, `Coverage`): simulated draws refitted.
- `population/`: the lot as a population (`PopulationSolve`, `PopulationFit`): random effects, empirical Bayes,
  one concept per file.
- `fit.py`: `Fit`, `Unidentifiable`, statuses and exit codes.
- `fitio.py`, `fitmatch.py`, `report.py`: fit files, whether a fit belongs to the data it is given, the identify report.
- `spec.py`: `FitSpec`, how a fit is made, which `identify`, `diagnose` and `plan` accept whole.
- `shortcuts.py`: the strings accepted for strategy objects (`solver="levenberg-marquardt"`), in one place.
"""

from .covariance import chi2_p_value as chi2_p_value
from .coverage import Coverage as Coverage, coverage as coverage
from .fit import (
    EXIT_CODES as EXIT_CODES,
    EXIT_PRECEDENCE as EXIT_PRECEDENCE,
    HELD_LABEL as HELD_LABEL,
    STATUSES as STATUSES,
    Fit as Fit,
    Unidentifiable as Unidentifiable,
)
from .identify import identify as identify
from .population import (
    PopulationFit as PopulationFit,
    PopulationParameter as PopulationParameter,
    PopulationSolve as PopulationSolve,
)
from .recovery import (
    AbstractRecovery as AbstractRecovery,
    DecrementCertificate as DecrementCertificate,
    MultiStart as MultiStart,
    RestartRunoffs as RestartRunoffs,
    RetryWithSolver as RetryWithSolver,
)
from .spec import FitSpec as FitSpec
from .strategies import (
    AbstractLotSolve as AbstractLotSolve,
    JointSolve as JointSolve,
    LoopSolve as LoopSolve,
    VmapSolve as VmapSolve,
)
