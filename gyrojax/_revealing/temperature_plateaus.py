r"""Rate-table and static-VCF sweeps at chamber-temperature plateaus within one run. Separates `vref_drift`,
`thermal_drift` and `zro_tempco`.

**Protocol.** One power-on run in a thermal chamber on the rate table: at each chamber plateau T_k the die
soaks, then a rate table and a static virtual-Coriolis sweep are taken back to back; the chamber then steps
to the next plateau. What the standard protocol needs added: a chamber set-point per plateau, a soak time,
and the two sweeps repeated per plateau *within the same run* (one turn-on bias for all plateaus), with each
point's die temperature recorded (`temperature_c`) from the die's own sensor or, as modelled here, from the
plateau history below.

**Die temperature.** `PlateauTemperature`: the chamber steps at the start of each plateau, the die follows
it with a first-order lag (package time constant tau_p) on top of its self-heating after power-on:

    T(t) = T_0 + sum_k (T_k - T_{k-1}) (1 - exp(-(t - t_k) / tau_p)) H(t - t_k) + rise (1 - exp(-t / tau_w)),

t_k the start of plateau k (T_{-1} = T_0, the chamber at power-on).

**Model.** Each point is the steady rate-table or static-VCF point at its own die temperature
(`gyrojax.rate_table_points`, `vcf_static_points`), so every temperature coefficient of the device acts:

    rate table:  R = SF_r(T) Om + SF_r(T) b_T (T - t_ref) + b_run,    SF_r ~ w(T) / (K_vf (1 + tc_v dT))
    static VCF:  V = SF_v(T) V_ac + SF_r(T) b_T (T - t_ref) + b_run',  SF_v ~ 1 / (K_vf (1 + tc_v dT))

with w(T) = w_x (1 + (tcf + tcf_extra) dT) (`thermal_drift`), tc_v the feedback bias's coefficient
(`vref_drift`) and b_T the zero-rate output's (`zro_tempco`). Readings: `rate_lsb` (plateau x rate) and
`vcf_lsb` (plateau x voltage), LSB.

**Why it sees the effects apart from the baseline and from each other.** At one temperature each is absorbed:
tc_v and the extra tcf by `k_vf`, b_T by the run bias. Across plateaus within one run the baseline's constant
K_vf, K_svf and run biases cannot follow: `vref_drift` moves both scale factors alike, `thermal_drift` only
the rate table's (the virtual force does not scale with w), `zro_tempco` only the intercepts. Their
fingerprints are three different patterns over (plateau, sweep), so they also separate from each other.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._checks import check_finite, check_positive
from .._gyroscope import Gyroscope
from .._physics.thermal import AbstractTemperature
from .._simulate.tiers import AbstractTier, Steady
from .._sweeps.protocol import WARMUP_RISE_K, WARMUP_TIME_CONSTANT_S, Protocol
from .._sweeps.rate_table import RateTable
from .._sweeps.steady import steady_points
from .._sweeps.vcf_static import VcfStatic


PLATEAUS_C = (10.0, 25.0, 40.0)
"""deg C, ASSUMPTION: three plateaus 15 K apart around room temperature. Three (not two) so that a linear
temperature coefficient is checked on a third point; a +/-15 K span keeps inside the range where the
library's linear coefficients hold (silicon's TCF is linear to a few percent over +/-15 K) and gives the
effects' typical sizes 300 ppm (`vref_drift`), 45 ppm (`thermal_drift`) and 0.015 deg/s (`zro_tempco`) of
swing."""

PACKAGE_TIME_CONSTANT_S = 300.0
"""s, ASSUMPTION: die-to-chamber thermal time constant of a ceramic LCC-packaged MEMS gyroscope on a fixture
(minutes: the fixture's and package's heat capacity through convection in the chamber)."""

SOAK_S = 1800.0
"""s, ASSUMPTION: soak per plateau, six package time constants: the die within 0.25 % of the step
(0.04 K of 15 K) before the first point."""

RATES_DPS = (-200.0, -100.0, -20.0, 20.0, 100.0, 200.0)
"""deg/s, ASSUMPTION: six of seed 000's rates per plateau (its 22 would take 44 min per sweep and plateau);
the static VCF sweep uses the same values as virtual rates."""

DWELL_S = 120.0
"""s, seed 000 §5: 2 min per point."""


class PlateauTemperature(AbstractTemperature):
    """Die temperature in a chamber that steps through plateaus, with self-heating after power-on (see the
    module docstring).

    **Arguments:**

    - `plateaus_c`: chamber temperature of each plateau, deg C.
    - `starts_s`: time since power-on at which the chamber steps to each plateau, s.
    - `initial_c`: chamber (and die) temperature at power-on, deg C.
    - `package_time_constant_s`: the die's lag behind the chamber, s.
    - `rise_k`, `heating_time_constant_s`: self-heating after power-on, K and s.
    """

    plateaus_c: tuple = eqx.field(converter=lambda x: tuple(float(v) for v in x))
    starts_s: tuple = eqx.field(converter=lambda x: tuple(float(v) for v in x))
    initial_c: float = 25.0
    package_time_constant_s: float = PACKAGE_TIME_CONSTANT_S
    rise_k: float = WARMUP_RISE_K
    heating_time_constant_s: float = WARMUP_TIME_CONSTANT_S

    def __check_init__(self):
        if len(self.plateaus_c) != len(self.starts_s) or not self.plateaus_c:
            raise ValueError(f"PlateauTemperature: plateaus_c and starts_s need one entry per plateau, got "
                             f"{len(self.plateaus_c)} and {len(self.starts_s)}.")
        if any(b <= a for a, b in zip(self.starts_s, self.starts_s[1:])) or self.starts_s[0] < 0:
            raise ValueError(f"PlateauTemperature.starts_s must be >= 0 and increasing, got {list(self.starts_s)}.")
        check_finite("PlateauTemperature", "initial_c", self.initial_c)
        check_finite("PlateauTemperature", "rise_k", self.rise_k)
        check_positive("PlateauTemperature", "package_time_constant_s", self.package_time_constant_s)
        check_positive("PlateauTemperature", "heating_time_constant_s", self.heating_time_constant_s)

    def __call__(self, t):
        t = jnp.asarray(t, dtype=float)
        temp = self.initial_c + self.rise_k * (1.0 - jnp.exp(-t / self.heating_time_constant_s))
        previous = self.initial_c
        for start, plateau in zip(self.starts_s, self.plateaus_c):
            since = jnp.maximum(t - start, 0.0)
            temp = temp + (plateau - previous) * (-jnp.expm1(-since / self.package_time_constant_s))
            previous = plateau
        return temp


class PlateauSettings(eqx.Module):
    """The schedule of a plateau run: per plateau a soak, then `rates_dps` on the rate table, then the same
    values as virtual rates on the static VCF sweep, each point `dwell_s` long.

    **Arguments:**

    - `vcf_amplitudes_v`: V_ac of the static VCF points, V (one per rate); `for_device` sets them from
      `rates_dps` as virtual rates with the design device's values (seed 003 Eq. 7, as
      `Protocol.vcf_static_amplitudes`).
    - `plateaus_c`, `soak_s`, `rates_dps`, `dwell_s`: see the module's constants for the defaults.
    - `initial_c`: the chamber at power-on, deg C (default: the first plateau, so the run starts soaked).
    """

    vcf_amplitudes_v: tuple = eqx.field(converter=lambda x: tuple(float(v) for v in x))

    plateaus_c: tuple = eqx.field(converter=lambda x: tuple(float(v) for v in x), default=PLATEAUS_C)
    soak_s: float = SOAK_S
    rates_dps: tuple = eqx.field(converter=lambda x: tuple(float(v) for v in x), default=RATES_DPS)
    dwell_s: float = DWELL_S
    initial_c: float | None = None

    def __check_init__(self):
        if len(self.plateaus_c) < 2:
            raise ValueError(f"PlateauSettings.plateaus_c needs at least 2 plateaus, got {list(self.plateaus_c)}.")
        check_positive("PlateauSettings", "soak_s", self.soak_s)
        check_positive("PlateauSettings", "dwell_s", self.dwell_s)
        if len(self.vcf_amplitudes_v) != len(self.rates_dps):
            raise ValueError(f"PlateauSettings.vcf_amplitudes_v needs one voltage per rate ({len(self.rates_dps)}), "
                             f"got {len(self.vcf_amplitudes_v)}.")

    @classmethod
    def for_device(cls, gyro: Gyroscope, **kwargs) -> "PlateauSettings":
        """Settings whose VCF voltages stand for `rates_dps` on the design device `gyro`."""
        rates = kwargs.get("rates_dps", RATES_DPS)
        return cls(Protocol(vcf_rates_dps=rates).vcf_static_amplitudes(gyro), **kwargs)

    @property
    def plateau_s(self) -> float:
        """Length of one plateau, s: the soak and both sweeps."""
        return self.soak_s + 2 * len(self.rates_dps) * self.dwell_s

    def history(self) -> PlateauTemperature:
        """The die-temperature history of the run."""
        starts = tuple(k * self.plateau_s for k in range(len(self.plateaus_c)))
        initial = self.plateaus_c[0] if self.initial_c is None else self.initial_c
        return PlateauTemperature(self.plateaus_c, starts, initial_c=initial)

    def point_times(self) -> tuple[np.ndarray, np.ndarray]:
        """Middle of each point's dwell, s since power-on: `(rate table, static VCF)`, shape (plateau, point)."""
        n, k = len(self.rates_dps), np.arange(len(self.plateaus_c))[:, None]
        first = k * self.plateau_s + self.soak_s + (np.arange(n)[None, :] + 0.5) * self.dwell_s
        return first, first + n * self.dwell_s


class PlateauReading(eqx.Module):
    """The rate-table output `rate_lsb` and the static-VCF output `vcf_lsb` (LSB, shape (plateau, point)),
    and the die temperature of each point (`rate_temperature_c`, `vcf_temperature_c`, deg C)."""

    rate_lsb: Float[Array, "plateau point"]
    vcf_lsb: Float[Array, "plateau point"]
    rate_temperature_c: Float[Array, "plateau point"]
    vcf_temperature_c: Float[Array, "plateau point"]


def predict(gyro: Gyroscope, settings: PlateauSettings, *, tier: AbstractTier = Steady()) -> PlateauReading:
    """The plateau run of one device (noise-free, without the run's bias).

    **Arguments:**

    - `gyro`: the device (a single one), with a virtual-Coriolis electrode.
    - `settings`: a `PlateauSettings`.
    - `tier`: `Steady()` (default) or `Averaged()`.

    **Returns:** a `PlateauReading`.
    """
    volts = np.asarray(settings.vcf_amplitudes_v)
    history = settings.history()
    t_rate, t_vcf = settings.point_times()
    temp_rate, temp_vcf = history(t_rate), history(t_vcf)
    shape = t_rate.shape
    rate, vcf = steady_points(gyro, [
        (RateTable(), np.tile(settings.rates_dps, shape[0]), jnp.ravel(temp_rate), t_rate.ravel()),
        (VcfStatic(), np.tile(volts, shape[0]), jnp.ravel(temp_vcf), t_vcf.ravel()),
    ], tier)
    return PlateauReading(rate.rate.reshape(shape), vcf.rate.reshape(shape), temp_rate, temp_vcf)
