"""The dynamic virtual-Coriolis test (seed 003 Eq. 6): the rate output's response to a modulated virtual rate."""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._lots.noise import RateNoise
from .._physics.stimulus import Stimulus
from .._simulate.response import linearise
from .._simulate.tiers import AbstractTier
from .base import AbstractSweep, at_temperature, points_field, timing_field
from .lot_campaign import LotCampaign
from .protocol import Protocol
from .steady import per_run
from .vcf_static import VCF_CARRIER_V


VCF_DYNAMIC_AMPLITUDE_V = 0.02
"""V, seed 003 §3: "Vac = 20 mV", the virtual-rate voltage of the dynamic (swept-frequency) test."""

VCF_DYNAMIC_FREQUENCIES_HZ = tuple(10.0 * k for k in range(1, 51))
"""Hz, seed 003 §3: "we measured the dynamic response from 10Hz to 500Hz"; the 10 Hz step is an ASSUMPTION
(not printed), fine enough to place vcf-2018's 62 Hz peak and its -3 dB point by interpolation."""

VCF_DYNAMIC_DWELL_S = 10.0
"""s, ASSUMPTION: lock-in time per modulation frequency (not printed in seed 003); 100 whole cycles at the
lowest frequency."""

VCF_DYNAMIC_SAMPLE_RATE_HZ = 10_000.0
"""Hz, ASSUMPTION: output sampling of the dynamic test, 20x the highest modulation frequency; seed 003 §3
samples with an NI-DAQ 6366 (up to 2 MS/s), its rate is not printed."""


class VcfDynamic(AbstractSweep):
    """The dynamic virtual-Coriolis test: V_ac modulated at each frequency, the rate output's amplitude and
    phase read by a lock-in (seed 003 Eq. 6). No turn-on bias reaches a lock-in reading; the noise is the
    rate noise at the modulation frequency.

    **Arguments:**

    - `frequencies_hz`: the modulation frequencies, Hz, in order.
    - `amplitude_v`: V_ac, V (seed 003: 20 mV), applied by the simulator and the fitted measurement model.
    - `carrier_v`: the fixed carrier V_fc, V.
    - `lockin_dwell_s`, `lockin_sample_rate_hz`: averaging time and output sampling of one lock-in point.
    """

    frequencies_hz: tuple = points_field(VCF_DYNAMIC_FREQUENCIES_HZ, "frequencies (Hz)")
    amplitude_v: float = VCF_DYNAMIC_AMPLITUDE_V
    carrier_v: float = VCF_CARRIER_V
    lockin_dwell_s: float = timing_field(VCF_DYNAMIC_DWELL_S)
    lockin_sample_rate_hz: float = timing_field(VCF_DYNAMIC_SAMPLE_RATE_HZ)

    name = "vcf_dynamic"
    stream: ClassVar[int] = 2
    title = "dynamic-VCF"
    input_quantity = "modulation frequency"
    input_unit = "Hz"
    output_unit = "LSB"
    input_meaning = "the modulation frequency of V_ac, Hz (V_ac = 20 mV; seed 003's dynamic test)"
    output_meaning = ("the amplitude of the rate output at that frequency, LSB (a lock-in reading); its phase goes "
                      "in `phase_deg`")
    rate_output = True
    biased = False
    straight_line = False
    rate_noise = True
    # The static sweeps see the scale factor's ratio Ag m omega a / K_vf; the response to a modulated force
    # follows the rebalance loop's gain, K_vf / m, which sets the bandwidth and the peak: the two together
    # part K_vf from Ag (m stays degenerate with every force). Held, Ag leaves a lot's spread in the peak.
    reads = ("angular_gain",)

    def __check_init__(self):
        f = np.asarray(self.frequencies_hz)
        if np.any(f <= 0):
            raise ValueError(f"VcfDynamic.frequencies_hz must be > 0 Hz, got {f.tolist()}.")
        if self.amplitude_v == 0 or not np.isfinite(self.amplitude_v):
            raise ValueError(f"VcfDynamic.amplitude_v must be finite and non-zero, got {self.amplitude_v!r}.")
        if f.max() >= self.lockin_sample_rate_hz / 2:
            raise ValueError(f"VcfDynamic.lockin_sample_rate_hz = {self.lockin_sample_rate_hz} Hz does not sample the "
                             f"highest modulation frequency {f.max()} Hz (Nyquist: more than 2x).")
        if round(self.lockin_dwell_s * self.lockin_sample_rate_hz) < 1:
            raise ValueError(f"VcfDynamic: lockin_dwell_s x lockin_sample_rate_hz = "
                             f"{self.lockin_dwell_s * self.lockin_sample_rate_hz:g} gives no sample per point.")

    def inputs(self, gyro: Gyroscope | None = None) -> np.ndarray:
        return np.asarray(self.frequencies_hz)

    def n_points(self) -> int:
        return len(self.frequencies_hz)

    def dwell_s(self, protocol: Protocol) -> float:
        return self.lockin_dwell_s

    def sample_rate_hz(self, protocol: Protocol) -> float:
        return self.lockin_sample_rate_hz

    def reads_on(self, gyro: Gyroscope) -> tuple[str, ...]:
        # Open loop there is no rebalance loop: the response is the sense resonance's through sense_gain x K_svf,
        # and Ag reaches it only at second order (freed, a vcf-2018 device's fit crawled to max_steps).
        return tuple(self.reads) if gyro.closed_loop else ()

    def check_device(self, gyro: Gyroscope) -> None:
        if float(np.asarray(gyro.vcf_electrode.force_per_volt2)) == 0.0:
            raise ValueError(f"a vcf_dynamic sweep needs a virtual-Coriolis electrode; {gyro.name!r} has "
                             "vcf_electrode.force_per_volt2 = 0.")

    def predict(self, gyro: Gyroscope, inputs: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                times: Float[ArrayLike, " point"] | None, tier: AbstractTier | None = None
                ) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        # Each point at its own die temperature, as measured and simulated: one mean temperature per sweep
        # left ~1e-5 of amplitude, 10x the noise.
        pred, _ = vcf_dynamic_points(gyro, inputs, temperatures, self.amplitude_v, self.carrier_v)
        return pred, ~jnp.isfinite(pred)

    def point_sigmas(self, inputs: Float[ArrayLike, " point"], protocol: Protocol, noise: RateNoise, lsb_per_dps: float,
                     voltmeter_sigma_v: float) -> np.ndarray:
        # Lock-in over whole cycles: the rate noise at each modulation frequency (see RateNoise).
        return np.asarray(noise.amplitude_sigma_dps(np.asarray(inputs, dtype=float), self.dwell_s(protocol)),
                          dtype=float) * abs(float(lsb_per_dps))

    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        protocol = campaign.protocol
        inputs = campaign.applied(self, protocol.inputs(self))
        temps, full = campaign.temperatures(self), campaign.shape(self)
        amp, phase = _lot_vcf_dynamic(lot, jnp.asarray(inputs), jnp.asarray(temps), float(self.amplitude_v),
                                      float(self.carrier_v))
        amp, phase = np.asarray(amp, dtype=float), np.asarray(phase, dtype=float)
        if not (np.all(np.isfinite(amp)) and np.all(np.isfinite(phase))):
            raise RuntimeError("the vcf-dynamic response is not finite for some points; the device has no "
                               "stable equilibrium at rest (check its loop gains).")
        out = amp
        if campaign.noise_free:
            sigma = np.zeros(full)
        else:
            # Lock-in over whole cycles: each quadrature component carries sqrt(G(f) / T) (see RateNoise).
            sigma = (campaign.noise.amplitude_sigma_dps(inputs, self.lockin_dwell_s)[None, :, :]
                     * campaign.lsb_per_dps[:, None, None]) * np.ones(full)
            z = campaign.rng(self).standard_normal(full + (2,))
            reading = 1.0 + sigma * (z[..., 0] + 1j * z[..., 1]) / amp
            out = amp * np.abs(reading)
            phase = phase + np.rad2deg(np.angle(reading))
        return {"input": np.broadcast_to(inputs, full), "output": out, "output_sigma": sigma,
                "n_samples": np.full(full, float(protocol.n_samples(self))), "temperature_c": temps,
                "drive_freq_hz": np.full(full, np.nan), "phase_deg": phase,
                "time_s": np.broadcast_to(campaign.times(self), full)}


def vcf_dynamic_points(gyro: Gyroscope, frequencies_hz: Float[ArrayLike, " point"],
                       temperatures: Float[ArrayLike, "*#point"], amplitude_v: float = VCF_DYNAMIC_AMPLITUDE_V,
                       carrier_v: float = VCF_CARRIER_V) -> tuple[Float[Array, " point"], Float[Array, " point"]]:
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


@jit
def _lot_vcf_dynamic(lot, frequencies_hz, temperatures, amplitude_v, carrier_v):
    """`vcf_dynamic_points` for every device, run and point, each point at its own temperature; frequencies
    (point,) or (run, point)."""
    freqs = per_run(frequencies_hz, temperatures)

    def device(g, temps):
        return jax.vmap(lambda f, t_run: vcf_dynamic_points(g, f, t_run, amplitude_v, carrier_v))(freqs, temps)

    return eqx.filter_vmap(device)(lot, temperatures)
