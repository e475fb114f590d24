"""Identification: how a fit is made, beside `gyrojax.identify` itself. `FitSpec` (the whole specification), the
baseline's free parameters (`DEFAULT_FREE`, and `default_free(gyro, data)` with those the data's sweeps read), the
first solve (`MultiStart`), the recovery policies tried after it (`AbstractRecovery`, the built-in ones and their
default tuple `RECOVERY`) with what a policy receives and returns (`Solving`, `Solution`, its `Evaluation`, the
integer codes of `result_code`), the lot strategies (`AbstractLotSolve` and its kinds) and the population records
(`PopulationParameter`), and `IdentifyReport` (what `gyrojax identify` prints and writes: the fit, where the
model fails, the population). A new recovery policy is one `AbstractRecovery` (docs: "Extending", "A recovery policy").

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._identify.evaluation import Evaluation as Evaluation
from ._identify.population import (
    PopulationFit as PopulationFit,
    PopulationParameter as PopulationParameter,
    PopulationSolve as PopulationSolve,
)
from ._identify.recovery import (
    RECOVERY as RECOVERY,
    AbstractRecovery as AbstractRecovery,
    DecrementCertificate as DecrementCertificate,
    MultiStart as MultiStart,
    RestartRunoffs as RestartRunoffs,
    RetryWithSolver as RetryWithSolver,
    Solution as Solution,
    Solving as Solving,
)
from ._identify.report import IdentifyReport as IdentifyReport
from ._identify.spec import FitSpec as FitSpec, default_free as default_free
from ._identify.strategies import (
    AbstractLotSolve as AbstractLotSolve,
    JointSolve as JointSolve,
    LoopSolve as LoopSolve,
    VmapSolve as VmapSolve,
)
from ._model.catalog import DEFAULT_FREE as DEFAULT_FREE
from ._solution import result_code as result_code


__all__ = [
    "AbstractLotSolve",
    "DEFAULT_FREE",
    "AbstractRecovery",
    "DecrementCertificate",
    "Evaluation",
    "FitSpec",
    "IdentifyReport",
    "JointSolve",
    "LoopSolve",
    "MultiStart",
    "PopulationFit",
    "PopulationParameter",
    "PopulationSolve",
    "RECOVERY",
    "RestartRunoffs",
    "RetryWithSolver",
    "Solution",
    "Solving",
    "VmapSolve",
    "default_free",
    "result_code",
]
