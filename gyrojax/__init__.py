"""gyrojax: differentiable system identification of MEMS Coriolis vibratory gyroscopes.

The top level holds what a notebook uses daily (simulate, identify, diagnose, plan, compare, compensate, tables,
fits, models, presets, the lot strategies, results and the extension-point base classes); the families of
helpers live in public submodules that only re-export: `gyrojax.effects`, `gyrojax.sweeps`,
`gyrojax.identification`, `gyrojax.physics`, `gyrojax.temperature`, `gyrojax.io`, `gyrojax.metrics`,
`gyrojax.compensation`, `gyrojax.units` (docs/architecture.md, "Public layout"). Everything else is private.
"""

import warnings as _warnings

import jax as _jax


# ppm-level work needs float64, so importing gyrojax switches it on for the whole process (a JAX flag, not a
# per-call setting): a context manager would let float64 results meet float32 code outside it, and a check that
# raises would make every script start with the same line. Why, and what it means for other JAX code in the
# process: docs/architecture.md, "Float64 for the whole process".
_jax.config.update("jax_enable_x64", True)

from . import _units as units  # noqa: E402, F401  (the public gyrojax.units)
from . import compensation as compensation  # noqa: E402
from . import effects as effects  # noqa: E402
from . import identification as identification  # noqa: E402
from . import io as io  # noqa: E402  (importing it imports gyrojax._compile.cache, which turns the cache on)
from . import metrics as metrics  # noqa: E402
from . import physics as physics  # noqa: E402
from . import sweeps as sweeps  # noqa: E402
from . import temperature as temperature  # noqa: E402
from ._lots.campaign import (  # noqa: E402
    CAMPAIGN_TIER as CAMPAIGN_TIER,
    campaign_lot as campaign_lot,
    simulate_table as simulate_table,
)
from ._compensate.base import (  # noqa: E402
    AbstractCompensation as AbstractCompensation,
    AbstractCompensator as AbstractCompensator,
)
from ._compensate.compensate import CompensationResult as CompensationResult, compensate as compensate  # noqa: E402
from ._data.cells import DataError as DataError  # noqa: E402
from ._data.files import read_table as read_table, write_table as write_table  # noqa: E402
from ._data.table import Table as Table  # noqa: E402
from ._effects.base import AbstractEffect as AbstractEffect  # noqa: E402
from ._effects.registry import (  # noqa: E402
    EFFECTS as EFFECTS,
    add_effect as add_effect,
    effect as effect,
    supported_effects as supported_effects,
)
from ._gyroscope import Gyroscope as Gyroscope  # noqa: E402
from ._diagnose.compare import Comparison as Comparison, compare as compare  # noqa: E402
from ._diagnose import (  # noqa: E402
    Diagnosis as Diagnosis,
    Discrepancy as Discrepancy,
    LookAlike as LookAlike,
    Rejection as Rejection,
    diagnose as diagnose,
)
from ._identify.fitio import load_fit as load_fit, save_fit as save_fit  # noqa: E402
from ._distributed import DistributedSolve as DistributedSolve, identify_lot as identify_lot  # noqa: E402
from ._identify.report import fit_report as fit_report  # noqa: E402
from ._identify import (  # noqa: E402
    AbstractLotSolve as AbstractLotSolve,
    AbstractRecovery as AbstractRecovery,
    Coverage as Coverage,
    DecrementCertificate as DecrementCertificate,
    Fit as Fit,
    FitSpec as FitSpec,
    JointSolve as JointSolve,
    LoopSolve as LoopSolve,
    MultiStart as MultiStart,
    PopulationFit as PopulationFit,
    PopulationSolve as PopulationSolve,
    RestartRunoffs as RestartRunoffs,
    RetryWithSolver as RetryWithSolver,
    Unidentifiable as Unidentifiable,
    VmapSolve as VmapSolve,
    coverage as coverage,
    identify as identify,
)
from ._lots.stack import ProcessSpread as ProcessSpread, make_lot as make_lot  # noqa: E402
from ._metrics import fit_scale_factor as fit_scale_factor  # noqa: E402
from ._lots.noise import RateNoise as RateNoise  # noqa: E402
from ._lots.process import WaferProcess as WaferProcess  # noqa: E402
from ._model.parameters import PARAMETERS as PARAMETERS, Model as Model, Parameter as Parameter  # noqa: E402
from ._physics.thermal import AbstractTemperature as AbstractTemperature  # noqa: E402
from ._presets import PRESETS as PRESETS, paper_qmg as paper_qmg, preset as preset, vcf_2018 as vcf_2018  # noqa: E402
from ._sensitivity import nonlinearity_budget as nonlinearity_budget  # noqa: E402
from ._simulate.tiers import (  # noqa: E402
    AbstractTier as AbstractTier,
    Averaged as Averaged,
    FullWaveform as FullWaveform,
    Settled as Settled,
    Steady as Steady,
    settle as settle,
)
from ._effects.plugins import load_effects_module as load_effects_module  # noqa: E402
from ._describe import describe as describe  # noqa: E402
from ._device.file import load_device as load_device  # noqa: E402
from ._plan import (  # noqa: E402
    CandidateExperiment as CandidateExperiment,
    CandidatePlan as CandidatePlan,
    Plan as Plan,
    ScaleFactorDesign as ScaleFactorDesign,
    RateTablePlan as RateTablePlan,
    default_experiments as default_experiments,
    plan as plan,
    rate_table_plan as rate_table_plan,
)
from ._diagnose.probes import PROBES as PROBES, AbstractProbe as AbstractProbe  # noqa: E402
from ._solution import RESULTS as RESULTS  # noqa: E402
from ._terms import (  # noqa: E402
    AbstractFeedbackTerm as AbstractFeedbackTerm,
    AbstractOutputTerm as AbstractOutputTerm,
    AbstractRateTerm as AbstractRateTerm,
    AbstractTerm as AbstractTerm,
    PointConditions as PointConditions,
    TemperatureCoefficient as TemperatureCoefficient,
)
from ._sweeps.base import AbstractSweep as AbstractSweep  # noqa: E402
from ._sweeps.protocol import Protocol as Protocol  # noqa: E402
from ._sweeps.rate_table import (  # noqa: E402
    ding_zhou_2025_rates as ding_zhou_2025_rates,
    rate_sweep as rate_sweep,
    rate_table_points as rate_table_points,
)

from ._version import __version__ as __version__  # noqa: E402

# Names that lived at the top level before the submodules: still reachable for one release, with a warning that
# names the new home. `dir(gyrojax)` lists only the top level.
_MOVED = {
    "effects": (
        "AgcFiniteGain", "CombGap", "DacInl", "DampingCoupling", "DuffingDrive", "DuffingSense", "FeedbackCompression",
        "PushPullMismatch", "QuadraturePhase", "ThermalDrift", "VrefDrift", "ZroTempco", "load_effect_entry_points",
        "register_effect",
    ),
    "sweeps": (
        "AbstractSetpointSweep", "AbstractSettledSweep", "AbstractSteadySweep", "BRANCH_RATES_DPS", "BranchRatio",
        "CHAMBER_PLATEAUS_C", "DING_ZHOU_2025_RATES_DPS", "Dac", "DriveAmplitude", "DriveFrequency",
        "INJECTED_QUADRATURE_DPS", "LotCampaign", "QuadratureInjection", "RateTable", "RunWarmup", "SETPOINT_RATIOS",
        "SWEEP_KINDS", "SetpointReading", "SetpointZeroRate", "VCF_CARRIER_V", "VCF_DYNAMIC_AMPLITUDE_V",
        "VCF_DYNAMIC_FREQUENCIES_HZ", "VCF_STATIC_RATES_DPS", "VcfDynamic", "VcfStatic", "branch_ratio_points",
        "dac_points", "dac_sweep", "points_field", "register_sweep", "setpoint_points", "sweep_kind", "timing_field",
        "vcf_dynamic_points", "vcf_static_points",
    ),
    "physics": (
        "DAC", "DriveElectrode", "DriveLoop", "FTRExcitation", "FeedbackElectrode", "FrontEnd", "LeafRecord",
        "OpenLoopReadout", "RebalanceLoop", "Resonator", "StateSpace", "Stimulus", "VirtualCoriolisElectrode",
        "bandwidth", "design_drive_loop", "design_rebalance_loop", "frequency_response", "linearise",
    ),
    "temperature": (
        "ConstantTemperature", "PlateauTemperature", "WarmupTemperature",
    ),
    "io": (
        "DAC_WORD_BITS", "OPTIONAL_COLUMNS", "REQUIRED_COLUMNS", "SweepArrays", "aggregate_samples",
        "atomic_directory", "atomic_write_bytes", "atomic_write_json", "compilation_cache", "decode_dac_word",
    ),
    "metrics": (
        "EffectContribution", "FULL_SCALE_CONVENTIONS", "NonlinearityBudget", "RateBandwidth", "ScaleFactorFit",
        "asymmetry", "metrics_report", "rate_bandwidth", "repeatability",
    ),
    "identification": (
        "PopulationParameter",
    ),
    "compensation": (
        "COMPENSATORS", "CompositeCompensation", "CompositeCompensator", "ModelCompensation", "ModelCompensator",
        "PolynomialCompensation", "PolynomialCompensator", "RatePoints", "rate_points",
    ),
}
_HOME = {name: module for module, names in _MOVED.items() for name in names}


def __getattr__(name: str) -> object:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'gyrojax' has no attribute {name!r}")
    _warnings.warn(f"gyrojax.{name} is gyrojax.{home}.{name}; import it from there (the top-level name goes in "
                   "the next release).", DeprecationWarning, stacklevel=2)
    return getattr(globals()[home], name)


__all__ = sorted(name for name in globals() if not name.startswith("_"))


def __dir__() -> list[str]:
    return list(__all__)
