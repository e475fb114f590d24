"""Physics: the parts a `Gyroscope` is built from (resonator, electrodes, drive and rebalance loops, open-loop
readout, front end, DAC, FTR excitation, stimulus), the loop design helpers, and the small-signal linearisation
of a settled device (`linearise`, `frequency_response`, `bandwidth`). `describe` lists a device's leaves as
`LeafRecord`s.

This module only re-exports; the code lives in the private modules it imports from.
"""

from ._control.drive import DriveLoop as DriveLoop
from ._control.openloop import OpenLoopReadout as OpenLoopReadout
from ._control.rebalance import RebalanceLoop as RebalanceLoop
from ._describe import LeafRecord as LeafRecord, describe as describe
from ._electronics.dac import DAC as DAC
from ._electronics.excitation import FTRExcitation as FTRExcitation
from ._electronics.frontend import FrontEnd as FrontEnd
from ._gyroscope import (
    Gyroscope as Gyroscope,
    design_drive_loop as design_drive_loop,
    design_rebalance_loop as design_rebalance_loop,
)
from ._physics.electrodes import (
    DriveElectrode as DriveElectrode,
    FeedbackElectrode as FeedbackElectrode,
    VirtualCoriolisElectrode as VirtualCoriolisElectrode,
)
from ._physics.resonator import Resonator as Resonator
from ._physics.stimulus import Stimulus as Stimulus
from ._simulate.response import (
    StateSpace as StateSpace,
    bandwidth as bandwidth,
    frequency_response as frequency_response,
    linearise as linearise,
)


__all__ = [
    "DAC",
    "DriveElectrode",
    "DriveLoop",
    "FTRExcitation",
    "FeedbackElectrode",
    "FrontEnd",
    "Gyroscope",
    "LeafRecord",
    "OpenLoopReadout",
    "RebalanceLoop",
    "Resonator",
    "StateSpace",
    "Stimulus",
    "VirtualCoriolisElectrode",
    "bandwidth",
    "describe",
    "design_drive_loop",
    "design_rebalance_loop",
    "frequency_response",
    "linearise",
]
