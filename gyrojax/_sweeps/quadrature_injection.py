r"""The quadrature injection: a virtual-Coriolis force in phase with the drive displacement, read on the rate
output. Reveals `quadrature_phase`.

**Protocol.** At zero table rate the virtual-Coriolis electrode (seed 003 Eq. 5: a force K_svf V_ac V_fc at
the drive carrier) is driven with its carrier shifted by pi/2, so that its force is in phase with the drive
displacement instead of the velocity: a virtual *quadrature* (the force of a stiffness coupling). V_ac is
stepped through positive and negative values within one run; the rate output is averaged per point, as in a
static VCF sweep.

**Model.** In the slow flow the virtual force is F_v = -j K_svf V_ac V_fc e^{j psi}, psi the carrier phase
(`Stimulus.vcf_phase`; 0 for a virtual rate, pi/2 here). Closed loop, the rebalance loop nulls the sense
motion: the rebalance force, rotated by the rate channel's phase error phi (`RebalanceLoop.carrier_phase`,
the `quadrature_phase` effect), balances F_v plus the Coriolis and coupling forces, so

    rate word        R = SF [Om + Om_zro] cos(phi) + SF Q_v sin(phi) + ...
    quadrature word  Q = SF Q_v cos(phi) - ...,      Q_v = K_svf V_ac V_fc / (2 m Ag a w)

(Q_v the rate-equivalent of the injected quadrature). Open loop the demodulation reference is rotated by phi
(`OpenLoopReadout.phase_error`) and the rate channel reads sin(phi) of the injected quadrature response.

**Why it sees the effect apart from the baseline.** At phi = 0 the baseline's rate output does not move with
the injection at all (closed loop exactly: the rate channel is the in-phase rebalance force), whatever K_vf,
K_svf or the DAC gain; a per-run bias takes only its mean. So dR/dV_ac = tan(phi) dQ/dV_ac measures phi
directly: at the typical 5 mrad with +/-100 deg/s of injected quadrature the rate output moves by
+/-0.5 deg/s, thousands of sigma of a 2-min point. On the standard sweeps phi is a bias Q_0 sin(phi) (taken
by the run bias) and a gain loss 1 - cos(phi) (12.5 ppm). Open loop (vcf-2018) the baseline's rate channel
does read a little of the injection when the sense phase moves (`q_y`, `omega_y`), so a free `q_y` can take
part of it unless a dynamic VCF sweep pins the sense resonance.

**The injection's own phase.** A phase error delta of the injection carrier puts Q_v sin(delta) in phase with
velocity, read exactly like phi: the experiment measures phi + delta. Taking the carrier from the drive
pick-off itself (a charge amplifier is in phase with the displacement; ~0.1 mrad at a few kHz for a 10 MHz
gain-bandwidth amplifier) keeps delta well below the 5 mrad to be found; `QuadratureInjection.carrier_phase`
models any other delta.
"""

from typing import ClassVar

import numpy as np
from jaxtyping import Array, Float

from .._gyroscope import Gyroscope
from .._physics.stimulus import Stimulus
from .base import points_field
from .steady import AbstractSteadySweep
from .vcf_static import VCF_CARRIER_V, virtual_rate_volts


INJECTED_QUADRATURE_DPS = (-100.0, -50.0, 0.0, 50.0, 100.0)
"""Injected quadrature as the rate its force equals, deg/s, ASSUMPTION: half the rate full scale, so that the
rebalance word (quadrature and rate together) stays within the DAC range of the +/-200 deg/s sweep, and ten
times paper-qmg's residual quadrature. The voltages follow from seed 003 Eq. (7) with the design values, as
for the static VCF sweep (`virtual_rate_volts`)."""


class QuadratureInjection(AbstractSteadySweep):
    """A quadrature injection: V_ac on the virtual-Coriolis electrode with its carrier in phase with the drive
    displacement, the settled rate output read, zero table rate. The rate table's timing; the output carries
    the run's turn-on bias and rate noise, as a static VCF point.

    **Arguments:**

    - `quadrature_rates_dps`: the injected quadrature as the rate its force equals, deg/s, in order: V_ac is
      set from them with the device's design values (`virtual_rate_volts`).
    - `amplitudes_v`: explicit injection voltages V_ac, V, in order; when given they replace
      `quadrature_rates_dps`.
    - `carrier_v`: the fixed carrier V_fc, V.
    - `carrier_phase`: phase of the injection carrier, rad: pi/2 (default) is in phase with the drive
      displacement; anything else adds a virtual rate of Q_v cos(carrier_phase).
    """

    quadrature_rates_dps: tuple = points_field(INJECTED_QUADRATURE_DPS, "virtual quadratures (deg/s)")
    amplitudes_v: tuple | None = points_field(None, "voltages (V)", optional=True)
    carrier_v: float = VCF_CARRIER_V
    carrier_phase: float = np.pi / 2

    name = "quadrature_injection"
    stream: ClassVar[int] = 4
    title = "quadrature-injection"
    input_quantity = "injection voltage V_ac"
    input_unit = "V"
    output_unit = "LSB"
    input_meaning = ("the voltage V_ac on the virtual-Coriolis electrode, V, signed, with the carrier (V_fc = 1 V) "
                     "in phase with the drive displacement: a virtual quadrature, at zero table rate")
    output_meaning = "the gyro's rate output, LSB"
    sign_definite = False  # the slope is the rate channel's phase error on the quadrature, of either sign

    def applicable_metrics(self) -> tuple[str, ...]:
        return ("scale_factor", "bias")  # the rate output per injected quadrature volt: the quadrature leakage

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        if self.amplitudes_v is not None:
            return np.asarray(self.amplitudes_v)
        if gyro is None:
            raise ValueError("QuadratureInjection.inputs needs the device to turn quadrature_rates_dps into volts; "
                             "pass gyro=.")
        return virtual_rate_volts(gyro, self.quadrature_rates_dps, self.carrier_v)

    def n_points(self) -> int:
        return len(self.amplitudes_v if self.amplitudes_v is not None else self.quadrature_rates_dps)

    def check_device(self, gyro: Gyroscope) -> None:
        if float(np.asarray(gyro.vcf_electrode.force_per_volt2)) == 0.0:
            raise ValueError(f"a quadrature_injection sweep needs a virtual-Coriolis electrode; {gyro.name!r} has "
                             "vcf_electrode.force_per_volt2 = 0.")

    def stimulus(self, value: Float[Array, " point"], time: Float[Array, " point"]) -> Stimulus:
        return Stimulus(rate=0.0 * value, vcf_ac=value, vcf_fc=self.carrier_v + 0.0 * value,
                        vcf_phase=self.carrier_phase + 0.0 * value, time=time)
