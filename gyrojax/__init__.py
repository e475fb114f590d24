"""gyrojax: differentiable system identification of MEMS Coriolis vibratory gyroscopes.

The public API is re-exported here; everything else is private.
"""

import jax as _jax


# ppm-level work needs float64; gyrojax switches it on at import.
_jax.config.update("jax_enable_x64", True)

from . import _units as units  # noqa: E402
from ._control.drive import DriveLoop as DriveLoop  # noqa: E402
from ._control.openloop import OpenLoopReadout as OpenLoopReadout  # noqa: E402
from ._control.rebalance import RebalanceLoop as RebalanceLoop  # noqa: E402
from ._effects.base import AbstractEffect as AbstractEffect  # noqa: E402
from ._effects.dac_inl import DacInl as DacInl  # noqa: E402
from ._effects.registry import EFFECTS as EFFECTS, add_effect as add_effect, effect as effect  # noqa: E402
from ._electronics.dac import DAC as DAC  # noqa: E402
from ._electronics.excitation import FTRExcitation as FTRExcitation  # noqa: E402
from ._electronics.frontend import FrontEnd as FrontEnd  # noqa: E402
from ._gyroscope import (  # noqa: E402
    Gyroscope as Gyroscope,
    design_drive_loop as design_drive_loop,
    design_rebalance_loop as design_rebalance_loop,
)
from ._physics.electrodes import (  # noqa: E402
    DriveElectrode as DriveElectrode,
    FeedbackElectrode as FeedbackElectrode,
    VirtualCoriolisElectrode as VirtualCoriolisElectrode,
)
from ._physics.resonator import Resonator as Resonator  # noqa: E402
from ._physics.thermal import (  # noqa: E402
    AbstractTemperature as AbstractTemperature,
    ConstantTemperature as ConstantTemperature,
    WarmupTemperature as WarmupTemperature,
)
from ._presets import PRESETS as PRESETS, paper_qmg as paper_qmg, preset as preset, vcf_2018 as vcf_2018  # noqa: E402
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
from ._solution import RESULTS as RESULTS  # noqa: E402
from ._stimulus import Stimulus as Stimulus  # noqa: E402
from ._sweeps import SEED000_RATES_DPS as SEED000_RATES_DPS, rate_sweep as rate_sweep, seed000_rates as seed000_rates  # noqa: E402

__version__ = "0.1.0"
