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


STEADY_SWEEPS = ("rate_table", "vcf_static")
"""The sweeps read from settled points of the steady tier (a rate table and a static virtual-Coriolis sweep)."""


def steady_points(gyro: Gyroscope, requests, tier: AbstractTier = Steady(), carrier_v=VCF_CARRIER_V) -> tuple:
    """Settled points of several steady sweeps of one device in one call of the tier (one compiled settle
    for all of them: a static VCF point is the same equations as a rate point, at another input).

    **Arguments:**

    - `requests`: a sequence of `(sweep, inputs, temperatures, times)`: `sweep` one of `STEADY_SWEEPS`, the
      inputs in its data unit (deg/s, or V of V_ac at the fixed carrier `carrier_v`), one die temperature
      (deg C) and one time since power-on (s; None or NaN: not recorded) per point.

    **Returns:** a `Settled` per request, in order, with the device's readout terms applied.
    """
    parts, sizes, views = [], [], []
    for sweep, inputs, temperatures, times in requests:
        x = jnp.atleast_1d(jnp.asarray(inputs, dtype=float))
        temps = jnp.broadcast_to(jnp.asarray(temperatures, dtype=float), x.shape)
        t = _times(times, x)
        if sweep == "rate_table":
            def one(value, temp, time):
                return at_temperature(gyro, temp), Stimulus(rate=value * DEG, vcf_fc=0.0 * value, time=time)
        elif sweep == "vcf_static":
            def one(value, temp, time):
                return at_temperature(gyro, temp), Stimulus(rate=0.0 * value, vcf_ac=value, vcf_fc=carrier_v,
                                                            time=time)
        else:
            raise ValueError(f"steady_points: sweep must be one of {STEADY_SWEEPS}, got {sweep!r}.")
        parts.append(jax.vmap(one)(x, temps, t))
        sizes.append(x.shape[0])
        views.append((sweep, x, temps, t))
    gyros, stimuli = jax.tree.map(lambda *leaves: jnp.concatenate(leaves), *parts) if len(parts) > 1 else parts[0]
    settled = tier.settle_points(gyros, stimuli)
    out, start = [], 0
    for size, (sweep, x, temps, t) in zip(sizes, views):
        piece = jax.tree.map(lambda leaf, a=start, b=start + size: leaf[a:b], settled)
        out.append(_read_out(gyro, piece, sweep, x, temps, t))
        start += size
    return tuple(out)


def rate_table_points(gyro: Gyroscope, rates_dps: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                      tier: AbstractTier = Steady(), *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled rate-table points: table rates in deg/s, one die temperature (deg C) and optionally one time
    since power-on (s) per point."""
    return steady_points(gyro, [("rate_table", rates_dps, temperatures, times)], tier)[0]


def vcf_static_points(gyro: Gyroscope, amplitudes_v: Float[ArrayLike, " point"],
                      temperatures: Float[ArrayLike, " point"], tier: AbstractTier = Steady(), carrier_v=VCF_CARRIER_V,
                      *, times: Float[ArrayLike, "*#point"] | None = None) -> Settled:
    """Settled static virtual-Coriolis points (seed 003 Eq. 7): the virtual-rate voltage V_ac (V, signed)
    times the fixed carrier V_fc, one die temperature and optionally one time since power-on per point."""
    return steady_points(gyro, [("vcf_static", amplitudes_v, temperatures, times)], tier, carrier_v)[0]


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
