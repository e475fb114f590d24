"""Open-loop sense readout of seed 003 Fig. 2 / Fig. 6: demodulation and low-pass filtering."""

import equinox as eqx
from jaxtyping import Array

from .._checks import check_finite, check_positive


class OpenLoopReadout(eqx.Module):
    """The sense pick-off demodulated with the drive reference and low-pass filtered.

    `demod_cutoff` is the corner of each of the `demod_order` first-order LPF stages (seed 003 uses an LPF "with stop
    frequency 2000 Hz"). `reference_phase` is the demodulation phase, chosen by the designer to align with
    the Coriolis response at zero rate; `phase_error` is an error on top (the `quadrature_phase` effect),
    which mixes quadrature into the output. The output is in sense-ADC LSB.
    """

    demod_cutoff: float | Array
    reference_phase: float | Array = 0.0
    phase_error: float | Array = 0.0

    demod_order: int = eqx.field(static=True, default=4)

    def __check_init__(self):
        if not isinstance(self.demod_order, int) or self.demod_order < 1:
            raise ValueError(f"OpenLoopReadout.demod_order must be an integer >= 1, got {self.demod_order!r}.")
        check_positive("OpenLoopReadout", "demod_cutoff", self.demod_cutoff)
        check_finite("OpenLoopReadout", "reference_phase", self.reference_phase)
        check_finite("OpenLoopReadout", "phase_error", self.phase_error)
