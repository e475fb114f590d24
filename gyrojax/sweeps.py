"""Sweeps: the kinds of measurement a campaign runs (each an `AbstractSweep` whose `predict` is what the simulator
and the fit both use), the functions that give each kind's points, the protocol constants of the source papers
(rates, setpoint ratios, VCF voltages, chamber plateaus), and the registry through which a new kind is added
(`register_sweep`, `points_field`, `timing_field`; see the sweep-kind page of the API reference).

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._sweeps.base import AbstractSweep as AbstractSweep, points_field as points_field, timing_field as timing_field
from ._sweeps.branch_voltages import (
    BRANCH_RATES_DPS as BRANCH_RATES_DPS,
    BranchRatio as BranchRatio,
    branch_ratio_points as branch_ratio_points,
)
from ._sweeps.dac import Dac as Dac, dac_points as dac_points, dac_sweep as dac_sweep
from ._sweeps.drive_amplitude import DriveAmplitude as DriveAmplitude
from ._sweeps.drive_frequency import DriveFrequency as DriveFrequency
from ._sweeps.lot_campaign import LotCampaign as LotCampaign
from ._sweeps.protocol import CHAMBER_PLATEAUS_C as CHAMBER_PLATEAUS_C, Protocol as Protocol, RunWarmup as RunWarmup
from ._sweeps.quadrature_injection import (
    INJECTED_QUADRATURE_DPS as INJECTED_QUADRATURE_DPS,
    QuadratureInjection as QuadratureInjection,
)
from ._sweeps.rate_table import (
    DING_ZHOU_2025_RATES_DPS as DING_ZHOU_2025_RATES_DPS,
    RateTable as RateTable,
    ding_zhou_2025_rates as ding_zhou_2025_rates,
    rate_sweep as rate_sweep,
    rate_table_points as rate_table_points,
)
from ._sweeps.registry import SWEEP_KINDS as SWEEP_KINDS, register_sweep as register_sweep, sweep_kind as sweep_kind
from ._sweeps.setpoint import (
    SETPOINT_RATIOS as SETPOINT_RATIOS,
    AbstractSetpointSweep as AbstractSetpointSweep,
    SetpointReading as SetpointReading,
    setpoint_points as setpoint_points,
)
from ._sweeps.setpoint_zero_rate import SetpointZeroRate as SetpointZeroRate
from ._sweeps.steady import AbstractSettledSweep as AbstractSettledSweep, AbstractSteadySweep as AbstractSteadySweep
from ._sweeps.vcf_dynamic import (
    VCF_DYNAMIC_AMPLITUDE_V as VCF_DYNAMIC_AMPLITUDE_V,
    VCF_DYNAMIC_FREQUENCIES_HZ as VCF_DYNAMIC_FREQUENCIES_HZ,
    VcfDynamic as VcfDynamic,
    vcf_dynamic_points as vcf_dynamic_points,
)
from ._sweeps.vcf_static import (
    VCF_CARRIER_V as VCF_CARRIER_V,
    VCF_STATIC_RATES_DPS as VCF_STATIC_RATES_DPS,
    VcfStatic as VcfStatic,
    vcf_static_points as vcf_static_points,
)


__all__ = [
    "AbstractSetpointSweep",
    "AbstractSettledSweep",
    "AbstractSteadySweep",
    "AbstractSweep",
    "BRANCH_RATES_DPS",
    "BranchRatio",
    "CHAMBER_PLATEAUS_C",
    "DING_ZHOU_2025_RATES_DPS",
    "Dac",
    "DriveAmplitude",
    "DriveFrequency",
    "INJECTED_QUADRATURE_DPS",
    "LotCampaign",
    "Protocol",
    "QuadratureInjection",
    "RateTable",
    "RunWarmup",
    "SETPOINT_RATIOS",
    "SWEEP_KINDS",
    "SetpointReading",
    "SetpointZeroRate",
    "VCF_CARRIER_V",
    "VCF_DYNAMIC_AMPLITUDE_V",
    "VCF_DYNAMIC_FREQUENCIES_HZ",
    "VCF_STATIC_RATES_DPS",
    "VcfDynamic",
    "VcfStatic",
    "branch_ratio_points",
    "dac_points",
    "dac_sweep",
    "ding_zhou_2025_rates",
    "points_field",
    "rate_sweep",
    "rate_table_points",
    "register_sweep",
    "setpoint_points",
    "sweep_kind",
    "timing_field",
    "vcf_dynamic_points",
    "vcf_static_points",
]
