"""The measurement model: what each sweep kind of the data format (docs/data_format.md) reads from a device.

One function per sweep, for one device and a vector of points, noise-free and without the per-run bias (the
turn-on bias belongs to the run, not to the device). The simulator (`simulate_table`) adds noise to these
predictions and identification fits them, so data and model can never disagree about what a column means.

Each point is evaluated at its own die temperature (the `temperature_c` column): the device's temperature
history is replaced by a constant at that temperature, since a settled point sees the temperature of its
dwell. A NaN temperature means "not recorded" and falls back to the device's own history at power-on. The
point's time since power-on (the `time_s` column; 0 when not recorded) reaches the device's terms that
depend on it (`gyrojax.AbstractRateTerm`, `AbstractOutputTerm`); the device's readout terms
(`AbstractOutputTerm`) act on the settled rate output of rate-table and static-VCF points.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Real

from ._gyroscope import Gyroscope
from ._physics.thermal import ConstantTemperature
from ._simulate.response import linearise
from ._simulate.tiers import AbstractTier, Settled, Steady
from ._stimulus import Stimulus
from ._sweeps import VCF_CARRIER_V, VCF_DYNAMIC_AMPLITUDE_V, dac_sweep
from ._terms import AbstractOutputTerm, PointConditions
from ._units import DEG


def at_temperature(gyro: Gyroscope, temperature) -> Gyroscope:
    """`gyro` held at `temperature` (deg C); NaN keeps the device's own temperature at power-on."""
    t = jnp.asarray(temperature, dtype=float)
    t = jnp.where(jnp.isnan(t), gyro.temperature(0.0), t)
    return eqx.tree_at(lambda g: g.temperature, gyro, ConstantTemperature(t))


def _times(times, like):
    """Times since power-on (s) per point; not recorded (None or NaN) is 0."""
    t = jnp.zeros_like(like) if times is None else jnp.broadcast_to(jnp.asarray(times, dtype=float), like.shape)
    return jnp.where(jnp.isnan(t), 0.0, t)


def _read_out(gyro: Gyroscope, settled: Settled, sweep: str, inputs, temperatures, times) -> Settled:
    """The settled rate output through the device's readout terms (`AbstractOutputTerm`)."""
    terms = gyro.terms_of(AbstractOutputTerm)
    if not terms:
        return settled
    temps = jnp.where(jnp.isnan(temperatures), gyro.temperature(0.0), temperatures)

    def one(output, x, temp, t):
        cond = PointConditions(sweep, x, temp, t)
        for term in terms:
            output = term(gyro, output, cond)
        return output

    return eqx.tree_at(lambda s: s.rate, settled, jax.vmap(one)(settled.rate, inputs, temps, times))


def rate_table_points(gyro: Gyroscope, rates_dps: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                      tier: AbstractTier = Steady(), *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled rate-table points: table rates in deg/s, one die temperature (deg C) and optionally one time
    since power-on (s) per point."""
    rates = jnp.asarray(rates_dps, dtype=float)
    temps = jnp.asarray(temperatures, dtype=float)
    t = _times(times, rates)

    def one(rate, temp, time):
        return at_temperature(gyro, temp), Stimulus(rate=rate * DEG, time=time)

    settled = tier.settle_points(*jax.vmap(one)(rates, temps, t))
    return _read_out(gyro, settled, "rate_table", rates, temps, t)


def vcf_static_points(gyro: Gyroscope, amplitudes_v: Float[ArrayLike, " point"],
                      temperatures: Float[ArrayLike, " point"], tier: AbstractTier = Steady(), carrier_v=VCF_CARRIER_V,
                      *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled static virtual-Coriolis points (seed 003 Eq. 7): the virtual-rate voltage V_ac (V, signed)
    times the fixed carrier V_fc, one die temperature and optionally one time since power-on per point."""
    volts = jnp.asarray(amplitudes_v, dtype=float)
    temps = jnp.asarray(temperatures, dtype=float)
    t = _times(times, volts)

    def one(v, temp, time):
        return at_temperature(gyro, temp), Stimulus(vcf_ac=v, vcf_fc=carrier_v, time=time)

    settled = tier.settle_points(*jax.vmap(one)(volts, temps, t))
    return _read_out(gyro, settled, "vcf_static", volts, temps, t)


def vcf_dynamic_points(gyro: Gyroscope, frequencies_hz: Float[ArrayLike, " point"],
                       temperatures: Float[ArrayLike, "*#point"], amplitude_v=VCF_DYNAMIC_AMPLITUDE_V,
                       carrier_v=VCF_CARRIER_V) -> tuple[Float[Array, " point"], Float[Array, " point"]]:
    """Dynamic virtual-Coriolis test (seed 003 Eq. 6): the rate output's amplitude (LSB) and phase (deg)
    for V_ac = `amplitude_v` modulated at each frequency (Hz), from the averaged model linearised at rest at
    the die temperature of each point (deg C; one value for every point linearises once). A lock-in reads
    the output at the modulation frequency: a zero-rate output and the readout terms do not reach it."""
    def response(f, temperature):
        ss = linearise(at_temperature(gyro, temperature), Stimulus(), input="vcf")
        h = ss.response(2.0 * jnp.pi * f) * (amplitude_v * carrier_v)
        return jnp.abs(h), jnp.rad2deg(jnp.angle(h))

    f, t = jnp.asarray(frequencies_hz, dtype=float), jnp.asarray(temperatures, dtype=float)
    if t.ndim == 0:
        return response(f, t)
    # Each point at its own temperature: the response follows the sense resonance's TCF.
    amp, phase = jax.vmap(lambda fi, ti: response(fi[None], ti))(f, t)
    return amp[:, 0], phase[:, 0]


def dac_points(gyro: Gyroscope, words: Real[ArrayLike, " word"]) -> Float[Array, " word"]:
    """Seed 000 Table 2's DAC sweep: signed carrier-fundamental amplitude (V) for each word (LSB)."""
    return dac_sweep(gyro, words)
