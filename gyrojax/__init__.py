"""gyrojax: differentiable system identification of MEMS Coriolis vibratory gyroscopes.

The public API is re-exported here; everything else is private.
"""

import jax as _jax


# ppm-level work needs float64, so importing gyrojax switches it on for the whole process (a JAX flag, not a
# per-call setting): a context manager would let float64 results meet float32 code outside it, and a check that
# raises would make every script start with the same line. Why, and what it means for other JAX code in the
# process: docs/architecture.md, "Float64 for the whole process".
_jax.config.update("jax_enable_x64", True)
from ._compile.cache import compilation_cache as compilation_cache  # noqa: E402  (importing it turns the cache on)

from . import _units as units  # noqa: E402, F401  (the public gyrojax.units)
from ._lots.campaign import (  # noqa: E402
    CAMPAIGN_TIER as CAMPAIGN_TIER,
    campaign_lot as campaign_lot,
    simulate_table as simulate_table,
)
from ._compensate.base import (  # noqa: E402
    AbstractCompensation as AbstractCompensation,
    AbstractCompensator as AbstractCompensator,
)
from ._compensate.compensate import (  # noqa: E402
    COMPENSATORS as COMPENSATORS,
    CompensationResult as CompensationResult,
    compensate as compensate,
    rate_points as rate_points,
)
from ._compensate.composite import (  # noqa: E402
    CompositeCompensation as CompositeCompensation,
    CompositeCompensator as CompositeCompensator,
)
from ._compensate.model import ModelCompensation as ModelCompensation, ModelCompensator as ModelCompensator  # noqa: E402
from ._compensate.points import RatePoints as RatePoints  # noqa: E402
from ._compensate.polynomial import (  # noqa: E402
    PolynomialCompensation as PolynomialCompensation,
    PolynomialCompensator as PolynomialCompensator,
)
from ._control.drive import DriveLoop as DriveLoop  # noqa: E402
from ._control.openloop import OpenLoopReadout as OpenLoopReadout  # noqa: E402
from ._control.rebalance import RebalanceLoop as RebalanceLoop  # noqa: E402
from ._data.arrays import SweepArrays as SweepArrays  # noqa: E402
from ._data.cells import (  # noqa: E402
    DAC_WORD_BITS as DAC_WORD_BITS,
    OPTIONAL_COLUMNS as OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS as REQUIRED_COLUMNS,
    DataError as DataError,
    decode_dac_word as decode_dac_word,
)
from ._data.files import read_table as read_table, write_table as write_table  # noqa: E402
from ._data.samples import aggregate_samples as aggregate_samples  # noqa: E402
from ._data.table import Table as Table  # noqa: E402
from ._effects.agc_finite_gain import AgcFiniteGain as AgcFiniteGain  # noqa: E402
from ._effects.base import AbstractEffect as AbstractEffect  # noqa: E402
from ._effects.comb_gap import CombGap as CombGap  # noqa: E402
from ._effects.dac_inl import DacInl as DacInl  # noqa: E402
from ._effects.damping_coupling import DampingCoupling as DampingCoupling  # noqa: E402
from ._effects.duffing_drive import DuffingDrive as DuffingDrive  # noqa: E402
from ._effects.duffing_sense import DuffingSense as DuffingSense  # noqa: E402
from ._effects.pushpull_mismatch import PushPullMismatch as PushPullMismatch  # noqa: E402
from ._effects.quadrature_phase import QuadraturePhase as QuadraturePhase  # noqa: E402
from ._effects.registry import (  # noqa: E402
    EFFECTS as EFFECTS,
    add_effect as add_effect,
    effect as effect,
    register_effect as register_effect,
    supported_effects as supported_effects,
)
from ._effects.feedback_compression import FeedbackCompression as FeedbackCompression  # noqa: E402
from ._effects.thermal_drift import ThermalDrift as ThermalDrift  # noqa: E402
from ._effects.vref_drift import VrefDrift as VrefDrift  # noqa: E402
from ._effects.zro_tempco import ZroTempco as ZroTempco  # noqa: E402
from ._electronics.dac import DAC as DAC  # noqa: E402
from ._electronics.excitation import FTRExcitation as FTRExcitation  # noqa: E402
from ._electronics.frontend import FrontEnd as FrontEnd  # noqa: E402
from ._gyroscope import (  # noqa: E402
    Gyroscope as Gyroscope,
    design_drive_loop as design_drive_loop,
    design_rebalance_loop as design_rebalance_loop,
)
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
    PopulationParameter as PopulationParameter,
    PopulationSolve as PopulationSolve,
    RestartRunoffs as RestartRunoffs,
    RetryWithSolver as RetryWithSolver,
    Unidentifiable as Unidentifiable,
    VmapSolve as VmapSolve,
    coverage as coverage,
    identify as identify,
)
from ._lots.stack import ProcessSpread as ProcessSpread, make_lot as make_lot  # noqa: E402
from ._data.io import (  # noqa: E402
    atomic_directory as atomic_directory,
    atomic_write_bytes as atomic_write_bytes,
    atomic_write_json as atomic_write_json,
)
from ._metrics import (  # noqa: E402
    FULL_SCALE_CONVENTIONS as FULL_SCALE_CONVENTIONS,
    RateBandwidth as RateBandwidth,
    ScaleFactorFit as ScaleFactorFit,
    asymmetry as asymmetry,
    fit_scale_factor as fit_scale_factor,
    metrics_report as metrics_report,
    rate_bandwidth as rate_bandwidth,
    repeatability as repeatability,
)
from ._lots.noise import RateNoise as RateNoise  # noqa: E402
from ._lots.process import WaferProcess as WaferProcess  # noqa: E402
from ._model.parameters import PARAMETERS as PARAMETERS, Model as Model, Parameter as Parameter  # noqa: E402
from ._physics.electrodes import (  # noqa: E402
    DriveElectrode as DriveElectrode,
    FeedbackElectrode as FeedbackElectrode,
    VirtualCoriolisElectrode as VirtualCoriolisElectrode,
)
from ._physics.resonator import Resonator as Resonator  # noqa: E402
from ._physics.thermal import (  # noqa: E402
    AbstractTemperature as AbstractTemperature,
    ConstantTemperature as ConstantTemperature,
    PlateauTemperature as PlateauTemperature,
    WarmupTemperature as WarmupTemperature,
)
from ._presets import PRESETS as PRESETS, paper_qmg as paper_qmg, preset as preset, vcf_2018 as vcf_2018  # noqa: E402
from ._sensitivity import (  # noqa: E402
    EffectContribution as EffectContribution,
    NonlinearityBudget as NonlinearityBudget,
    nonlinearity_budget as nonlinearity_budget,
)
from ._simulate.response import (  # noqa: E402
    StateSpace as StateSpace,
    bandwidth as bandwidth,
    frequency_response as frequency_response,
    linearise as linearise,
)
from ._simulate.tiers import (  # noqa: E402
    AbstractTier as AbstractTier,
    Averaged as Averaged,
    FullWaveform as FullWaveform,
    Settled as Settled,
    Steady as Steady,
    settle as settle,
)
from ._plugins import (  # noqa: E402
    load_effect_entry_points as load_effect_entry_points,
    load_effects_module as load_effects_module,
)
from ._describe import LeafRecord as LeafRecord, describe as describe  # noqa: E402
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
from ._physics.stimulus import Stimulus as Stimulus  # noqa: E402
from ._terms import (  # noqa: E402
    AbstractFeedbackTerm as AbstractFeedbackTerm,
    AbstractOutputTerm as AbstractOutputTerm,
    AbstractRateTerm as AbstractRateTerm,
    AbstractTerm as AbstractTerm,
    PointConditions as PointConditions,
    TemperatureCoefficient as TemperatureCoefficient,
)
from ._sweeps.base import (  # noqa: E402
    AbstractSweep as AbstractSweep,
    points_field as points_field,
    timing_field as timing_field,
)
from ._sweeps.branch_voltages import (  # noqa: E402
    BRANCH_RATES_DPS as BRANCH_RATES_DPS,
    BranchRatio as BranchRatio,
    branch_ratio_points as branch_ratio_points,
)
from ._sweeps.dac import Dac as Dac, dac_points as dac_points, dac_sweep as dac_sweep  # noqa: E402
from ._sweeps.drive_amplitude import DriveAmplitude as DriveAmplitude  # noqa: E402
from ._sweeps.drive_frequency import DriveFrequency as DriveFrequency  # noqa: E402
from ._sweeps.lot_campaign import LotCampaign as LotCampaign  # noqa: E402
from ._sweeps.protocol import (  # noqa: E402
    CHAMBER_PLATEAUS_C as CHAMBER_PLATEAUS_C,
    Protocol as Protocol,
    RunWarmup as RunWarmup,
)
from ._sweeps.quadrature_injection import (  # noqa: E402
    INJECTED_QUADRATURE_DPS as INJECTED_QUADRATURE_DPS,
    QuadratureInjection as QuadratureInjection,
)
from ._sweeps.rate_table import (  # noqa: E402
    DING_ZHOU_2025_RATES_DPS as DING_ZHOU_2025_RATES_DPS,
    RateTable as RateTable,
    ding_zhou_2025_rates as ding_zhou_2025_rates,
    rate_sweep as rate_sweep,
    rate_table_points as rate_table_points,
)
from ._sweeps.registry import (  # noqa: E402
    SWEEP_KINDS as SWEEP_KINDS,
    register_sweep as register_sweep,
    sweep_kind as sweep_kind,
)
from ._sweeps.setpoint import (  # noqa: E402
    SETPOINT_RATIOS as SETPOINT_RATIOS,
    AbstractSetpointSweep as AbstractSetpointSweep,
    SetpointReading as SetpointReading,
    setpoint_points as setpoint_points,
)
from ._sweeps.setpoint_zero_rate import SetpointZeroRate as SetpointZeroRate  # noqa: E402
from ._sweeps.steady import AbstractSettledSweep as AbstractSettledSweep  # noqa: E402
from ._sweeps.steady import AbstractSteadySweep as AbstractSteadySweep  # noqa: E402
from ._sweeps.vcf_dynamic import (  # noqa: E402
    VCF_DYNAMIC_AMPLITUDE_V as VCF_DYNAMIC_AMPLITUDE_V,
    VCF_DYNAMIC_FREQUENCIES_HZ as VCF_DYNAMIC_FREQUENCIES_HZ,
    VcfDynamic as VcfDynamic,
    vcf_dynamic_points as vcf_dynamic_points,
)
from ._sweeps.vcf_static import (  # noqa: E402
    VCF_CARRIER_V as VCF_CARRIER_V,
    VCF_STATIC_RATES_DPS as VCF_STATIC_RATES_DPS,
    VcfStatic as VcfStatic,
    vcf_static_points as vcf_static_points,
)

from ._version import __version__ as __version__  # noqa: E402
