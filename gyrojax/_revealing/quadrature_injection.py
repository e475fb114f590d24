r"""Quadrature injection: a virtual-Coriolis force in phase with the drive displacement, read on the rate
channel. Reveals `quadrature_phase`.

**Protocol.** At zero table rate the virtual-Coriolis electrode (seed 003 Eq. 5: a force K_svf V_ac V_fc at
the drive carrier) is driven with its carrier shifted by pi/2, so that its force is in phase with the drive
displacement instead of the velocity: a virtual *quadrature* (the force of a stiffness coupling). V_ac is
stepped through positive and negative values within one run; the rate and quadrature outputs are averaged
per point, as in a static VCF sweep.

**Model.** In the slow flow (phasor convention of `gyrojax/_simulate/_model.py`) the virtual force is
F_v = -j K_svf V_ac V_fc e^{j psi}, psi the carrier phase (`Stimulus.vcf_phase`; 0 for a virtual rate, pi/2
here). Closed loop, the rebalance loop nulls the sense motion: the rebalance force, rotated by the rate
channel's phase error phi (`RebalanceLoop.carrier_phase`, the `quadrature_phase` effect), balances F_v plus
the Coriolis and coupling forces, so

    rate word        R = SF [Om + Om_zro] cos(phi) + SF Q_v sin(phi) + ...
    quadrature word  Q = SF Q_v cos(phi) - ...,      Q_v = K_svf V_ac V_fc / (2 m Ag a w)

(Q_v the rate-equivalent of the injected quadrature). Open loop the demodulation reference is rotated by phi
(`OpenLoopReadout.phase_error`) and the rate channel reads sin(phi) of the injected quadrature response.
Readings, per point: `rate_lsb` and `quadrature_lsb` (rate output and quadrature word / channel, LSB).

**Why it sees the effect apart from the baseline.** At phi = 0 the baseline's rate output does not move with
the injection at all (closed loop exactly: the rate channel is the in-phase rebalance force), whatever K_vf,
K_svf or the DAC gain; a per-run bias takes only its mean. So dR/dV_ac = tan(phi) dQ/dV_ac measures phi
directly: at the typical 5 mrad with +/-100 deg/s of injected quadrature the rate output moves by
+/-0.5 deg/s, ~3000 sigma of a 2-min point. On the standard sweeps phi is a bias Q_0 sin(phi) (absorbed by the
run bias) and a gain loss 1 - cos(phi) (12.5 ppm). Open loop (vcf-2018) the baseline's rate channel does
read a little of the injection when the sense phase moves (`q_y`, `omega_y`: the demodulation reference is
fixed, the sense response's phase atan(g_y / d_y) is not), so a free `q_y` can take part of it.

**What the injection's own phase must be.** A phase error delta of the injection carrier puts
Q_v sin(delta) in phase with velocity, read exactly like phi: the experiment measures phi + delta. Taking
the carrier from the drive pick-off itself (a charge amplifier is in phase with the displacement; ~0.1 mrad
at a few kHz for a 10 MHz gain-bandwidth amplifier) keeps delta well below the 5 mrad to be found;
`QuadratureInjectionSettings.carrier_phase` models any other delta.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._gyroscope import Gyroscope
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._stimulus import Stimulus
from .._sweeps.base import at_temperature
from .._sweeps.vcf_static import VCF_CARRIER_V
from .._units import DEG


INJECTED_QUADRATURE_DPS = (-100.0, -50.0, 0.0, 50.0, 100.0)
"""Injected quadrature as the rate its force equals, deg/s, ASSUMPTION: half the rate full scale, so that the
rebalance word (quadrature and rate together) stays within the DAC range of the +/-200 deg/s sweep, and ten
times paper-qmg's residual quadrature. The voltages follow from seed 003 Eq. (7) with the design values, as
for the static VCF sweep (`QuadratureInjectionSettings.from_rates`)."""

DWELL_S = 120.0
"""s, the rate table's dwell (seed 000 §5: 2 min per point), so a point's noise is that of the rate table."""


class QuadratureInjectionSettings(eqx.Module):
    """The points of a quadrature injection.

    **Arguments:**

    - `amplitude_v`: V_ac of each point, V (signed).
    - `carrier_v`: V_fc, V (seed 003: 1 V).
    - `carrier_phase`: phase of the injection carrier, rad: pi/2 (default) is in phase with the drive
      displacement; anything else adds a virtual rate of Q_v cos(carrier_phase).
    - `temperature_c`: die temperature of each point, deg C (NaN: the device's own at power-on).
    """

    amplitude_v: Float[Array, " point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float))
    carrier_v: Float[Array, ""] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float), default=VCF_CARRIER_V)
    carrier_phase: Float[Array, ""] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                default=np.pi / 2)
    temperature_c: Float[Array, "*#point"] = eqx.field(converter=lambda x: jnp.asarray(x, dtype=float),
                                                       default=np.nan)

    @classmethod
    def from_rates(cls, gyro: Gyroscope, quadrature_dps=INJECTED_QUADRATURE_DPS, **kwargs):
        """Settings whose V_ac inject the given quadrature (deg/s of equivalent rate) on the nominal `gyro`,
        by seed 003 Eq. (7) inverted with its design values (as `Protocol.vcf_static_amplitudes` does)."""
        r = gyro.resonator
        k_svf = float(np.asarray(gyro.vcf_electrode.force_per_volt2))
        if k_svf == 0.0:
            raise ValueError(f"a quadrature injection needs a virtual-Coriolis electrode; {gyro.name!r} has "
                             "vcf_electrode.force_per_volt2 = 0.")
        carrier = float(kwargs.get("carrier_v", VCF_CARRIER_V))
        coriolis = 2.0 * r.mass * r.angular_gain * gyro.drive_amplitude(r.omega_x) * r.omega_x
        volts = np.asarray(quadrature_dps, dtype=float) * DEG * float(np.asarray(coriolis)) / (k_svf * carrier)
        return cls(amplitude_v=volts, **kwargs)


class QuadratureInjectionReading(eqx.Module):
    """What a quadrature injection reads, per point: `rate_lsb` (rate output) and `quadrature_lsb`
    (quadrature word or channel), LSB; `settled`: the tier's solution."""

    rate_lsb: Float[Array, " point"]
    quadrature_lsb: Float[Array, " point"]
    settled: Settled


def predict(gyro: Gyroscope, settings: QuadratureInjectionSettings, *,
            tier: AbstractTier = Steady()) -> QuadratureInjectionReading:
    """The quadrature injection of one device at zero rate (noise-free, without the run's bias).

    **Arguments:**

    - `gyro`: the device (a single one; vmap for a lot); needs a virtual-Coriolis electrode.
    - `settings`: a `QuadratureInjectionSettings`.
    - `tier`: `Steady()` (default), `Averaged()` or `FullWaveform()`.

    **Returns:** a `QuadratureInjectionReading`.
    """
    v = settings.amplitude_v
    temps = jnp.broadcast_to(settings.temperature_c, v.shape)

    def one(value, temp):
        return at_temperature(gyro, temp), Stimulus(rate=0.0 * value, vcf_ac=value, vcf_fc=settings.carrier_v,
                                                    vcf_phase=settings.carrier_phase)

    settled = tier.settle_points(*jax.vmap(one)(v, temps))
    return QuadratureInjectionReading(settled.rate, settled.quadrature, settled)
