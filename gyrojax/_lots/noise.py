r"""Noise of the gyro's rate output during a run, and the standard uncertainty it gives each point.

The rate-equivalent output noise (deg/s) of one power-on run is

    n(t) = b0 + b(t) + w(t)

- `b0`: the turn-on bias, constant within the run, N(0, turn_on_bias^2) from run to run;
- `b(t)`: bias wander, a first-order Gauss-Markov (Ornstein-Uhlenbeck) process with stationary standard
  deviation q and correlation time tau, autocovariance q^2 exp(-|u| / tau); it makes the bias-instability
  floor of the Allan deviation (peak `ALLAN_PEAK_FACTOR` q at T = `ALLAN_PEAK_TIME_FACTOR` tau);
- `w(t)`: white rate noise, the angle random walk N (deg/sqrt(s)): a mean over T has standard deviation
  N / sqrt(T), whatever the sampling rate.

A settled point is the mean of its dwell window [t, t + T]. Its standard uncertainty about the run's constant
bias b0 is

    sigma^2 = N^2 / T + Var(mean of b over T),   Var = 2 q^2 (tau/T)^2 (T/tau - 1 + exp(-T/tau)),

which is what `output_sigma` reports. Consecutive windows share part of the wander: their correlation is
q^2 (tau/T)^2 (1 - exp(-T/tau))^2 / Var (0.16 of the wander share at the defaults, T = 120 s, tau = 30 s),
so a fit with one constant bias per run and these diagonal weights gives a reduced chi^2 near 1 as long as
tau is short against the dwell. With tau comparable to a whole run the wander acts as a second turn-on
bias: the fitted per-run biases absorb it and the reduced chi^2 falls below 1 (the points are then
correlated, which one sigma per point cannot say).

A dynamic (lock-in) point measures the amplitude of the output at the modulation frequency f over T whole
cycles: the turn-on bias is rejected, and each quadrature component carries the noise within the lock-in's
band, variance G(f) / T with G the one-sided noise PSD, G(f) = 2 N^2 + 4 q^2 tau / (1 + (2 pi f tau)^2).
"""

import math

import equinox as eqx
import numpy as np
from jaxtyping import ArrayLike, Float

from .._checks import check_nonnegative, check_positive


def _allan_gm(x):
    """Allan variance of a unit Gauss-Markov process at T = x tau (IEEE 952-style two-window definition)."""
    e = np.exp(-x)
    return (2.0 * (x - 1.0 + e) - (1.0 - e) ** 2) / x**2


def _allan_peak():
    x = np.geomspace(0.1, 20.0, 20001)
    v = _allan_gm(x)
    i = int(np.argmax(v))
    return float(np.sqrt(v[i])), float(x[i])


ALLAN_PEAK_FACTOR, ALLAN_PEAK_TIME_FACTOR = _allan_peak()
"""The Allan deviation of a Gauss-Markov wander peaks at 0.6174 q when T = 1.893 tau (computed above from the
exact Allan variance of the process); the bias instability read off that peak sets q."""


class RateNoise(eqx.Module):
    """Noise of the gyro's rate output (in deg/s of rate; each device converts it to LSB with its own
    rate-table scale factor).

    **Arguments:**

    - `arw_dps_per_sqrt_h`: angle random walk, deg/sqrt(h) (white rate noise).
    - `bias_instability_dph`: bias instability, deg/h: the peak of the Allan deviation of the Gauss-Markov
      bias wander (so its stationary standard deviation is this / `ALLAN_PEAK_FACTOR`).
    - `bias_correlation_s`: correlation time of the wander, s.
    - `turn_on_bias_dps`: 1-sigma bias change from run to run (turn-on repeatability), deg/s.

    Defaults are ASSUMPTIONS for a tactical-grade MEMS gyro (seeds 000 and 003 give no noise figures):
    0.05 deg/sqrt(h), 0.5 deg/h with its Allan floor near 1 min (tau = 30 s, peak at 57 s: MEMS gyros
    typically reach their bias-instability floor at 10-100 s of averaging), 0.01 deg/s turn-on bias.
    """

    arw_dps_per_sqrt_h: float = 0.05
    bias_instability_dph: float = 0.5
    bias_correlation_s: float = 30.0
    turn_on_bias_dps: float = 0.01

    def __check_init__(self):
        check_nonnegative("RateNoise", "arw_dps_per_sqrt_h", self.arw_dps_per_sqrt_h)
        check_nonnegative("RateNoise", "bias_instability_dph", self.bias_instability_dph)
        check_positive("RateNoise", "bias_correlation_s", self.bias_correlation_s)
        check_nonnegative("RateNoise", "turn_on_bias_dps", self.turn_on_bias_dps)

    @property
    def arw_dps_per_sqrt_s(self) -> float:
        """Angle random walk N in deg/sqrt(s): the white-noise mean over T seconds has sigma N / sqrt(T)."""
        return self.arw_dps_per_sqrt_h / 60.0

    @property
    def wander_sigma_dps(self) -> float:
        """Stationary standard deviation q of the bias wander, deg/s."""
        return self.bias_instability_dph / 3600.0 / ALLAN_PEAK_FACTOR

    def wander_mean_variance(self, dwell_s: float) -> float:
        """Variance of the wander's mean over `dwell_s` seconds, (deg/s)^2."""
        x = dwell_s / self.bias_correlation_s
        # 2 (x - 1 + e^-x) / x^2 with expm1 against cancellation at small x
        return self.wander_sigma_dps**2 * 2.0 * (x + math.expm1(-x)) / x**2

    def point_sigma_dps(self, dwell_s: float) -> float:
        """Standard uncertainty (deg/s) of one settled point's mean over `dwell_s` about the run's bias."""
        check_positive("RateNoise.point_sigma_dps", "dwell_s", dwell_s)
        return math.sqrt(self.arw_dps_per_sqrt_s**2 / dwell_s + self.wander_mean_variance(dwell_s))

    def amplitude_sigma_dps(self, frequency_hz: Float[ArrayLike, "*f"], dwell_s: float) -> Float[np.ndarray, "*f"]:
        """Standard uncertainty (deg/s) of each quadrature component of a lock-in reading at
        `frequency_hz` (array) over `dwell_s` seconds: sqrt(G(f) / T)."""
        check_positive("RateNoise.amplitude_sigma_dps", "dwell_s", dwell_s)
        f = np.asarray(frequency_hz, dtype=float)
        tau, q = self.bias_correlation_s, self.wander_sigma_dps
        psd = 2.0 * self.arw_dps_per_sqrt_s**2 + 4.0 * q**2 * tau / (1.0 + (2.0 * np.pi * f * tau) ** 2)
        return np.sqrt(psd / dwell_s)

    def sample_point_means(self, rng: np.random.Generator, shape: tuple[int, ...], n_points: int, dwell_s: float
                           ) -> tuple[np.ndarray, np.ndarray]:
        """Noise (deg/s) of `n_points` consecutive settled points of `dwell_s` each, per run.

        **Arguments:**

        - `rng`: a NumPy random generator.
        - `shape`: batch shape of the runs, e.g. `(devices, runs)`.
        - `n_points`, `dwell_s`: the sweep; windows are back to back.

        **Returns:** `(bias, noise)`: the turn-on bias, shape `shape`, and the zero-mean noise of each point's
        mean (white plus wander), shape `shape + (n_points,)`. The wander is drawn exactly: the window
        integral and the end state of an Ornstein-Uhlenbeck process are jointly Gaussian given the start
        state, which is drawn from the stationary law (the run has been on since its warm-up).
        """
        shape = tuple(shape)
        bias = self.turn_on_bias_dps * rng.standard_normal(shape)
        white = self.arw_dps_per_sqrt_s / math.sqrt(dwell_s) * rng.standard_normal(shape + (n_points,))
        q, tau = self.wander_sigma_dps, self.bias_correlation_s
        x = dwell_s / tau
        e = math.exp(-x)
        em = math.expm1(-x)
        var_end = q**2 * -math.expm1(-2.0 * x)  # Var(b_end | b_start)
        var_int = q**2 * tau**2 * (2.0 * (x + em) - em**2)  # Var(integral | b_start) = q^2 tau^2 (2x-3+4e-e^2)
        cov = q**2 * tau * em**2  # Cov(integral, b_end | b_start)
        state = q * rng.standard_normal(shape)
        wander = np.empty(shape + (n_points,))
        for i in range(n_points):
            z1, z2 = rng.standard_normal(shape), rng.standard_normal(shape)
            end = state * e + math.sqrt(var_end) * z1
            if var_end > 0:
                mean_int = state * tau * -em + cov / var_end * (end - state * e)
                var_cond = max(var_int - cov**2 / var_end, 0.0)
            else:
                mean_int, var_cond = state * tau * -em, 0.0
            wander[..., i] = (mean_int + math.sqrt(var_cond) * z2) / dwell_s
            state = end
        return bias, white + wander


DAC_VOLTMETER_SIGMA_V = 2e-5
"""V, ASSUMPTION: 1-sigma reading noise of the AC voltmeter in a DAC sweep (seed 000 Table 2 prints
amplitudes to 1 mV; a 6.5-digit meter on its 10 V AC range reads to a few 10 uV)."""
