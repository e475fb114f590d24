#!/usr/bin/env python
"""Benchmark of gyrojax's simulation tiers, and of the full-waveform tier against scipy (a script, not a test).

    python benchmarks/bench_tiers.py [--quick] [--json PATH] [--repeats N] [--skip-part1/2/3]

Everything runs on `paper_qmg()` (seed 000, closed loop) at settle 0.12 s + 40 carrier periods (quick
mode: 0.02 s + 40 periods everywhere, for a smoke run; its figures are not the README's).

Part 1 - the tiers on the 22-point rate sweep (+/-0.1 ... +/-200 deg/s), each `eqx.filter_jit(vmap)`ed
with the device as an argument, on the ideal device and with the typical DAC INL: time per point, scale
factor (SF) and nonlinearity (NL) against the steady tier, and the numerical error of each full-tier
setting against a full-tier solve at rtol = atol = 1e-12 (the "accuracy" E of that setting: its largest
deviation over the sweep and both devices, ppm of full scale).

Part 2 - one point at +200 deg/s: the full tier against scipy on the *same* ODE (the scaled, flattened
state of `FullWaveform`: WaveState / wave_scales plus the three output integrals / output_scales; same
initial state, span, first step and averaging window), at EQUAL ACCURACY: for each scipy method its
tolerance (rtol = atol) is tightened in half-decade steps from 1e-5 until its error against the 1e-12
reference is within the E of the gyrojax setting it is compared with (part 1); that run's time is its time.
scipy's right-hand side is a NumPy / Python-scalar mirror of `full_field` for the ideal device (linear
DAC), checked against the JAX field at random states before anything is timed. Methods: solve_ivp RK45,
DOP853, LSODA and scipy.integrate.odeint (LSODA driven from Fortran, the leanest scipy path).

Part 3 - the whole sweep (ideal device) at the default tier's accuracy: scipy DOP853, LSODA and odeint with
all 22 points stacked into one 616-state system and a NumPy right-hand side vectorised over the points,
and part 2's best method point by point with the scalar mirror; against gyrojax's vmapped sweep and a
Python loop over one compiled point. Tolerances searched as in part 2 (starting from part 2's choice).

Timings are wall clock after compilation (compile time reported on its own), with `jax.block_until_ready`.
The times compared in parts 2 and 3 are the best of 3 interleaved rounds (1 in quick mode): in each round
every contender (gyrojax settings and scipy methods at their chosen tolerances) runs once in turn, so that
the load of a shared machine hits all of them alike; the load average is printed at start and end.
"""

import argparse
import cmath
import datetime
import math
import os
import platform
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jaxlib  # noqa: E402
import numpy as np  # noqa: E402
import optimistix  # noqa: E402
import scipy  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402
from scipy.integrate import odeint, solve_ivp  # noqa: E402

from gyrojax import (  # noqa: E402
    RESULTS,
    Averaged,
    FullWaveform,
    Steady,
    add_effect,
    make_lot,
    paper_qmg,
    settle,
    units,
)
from gyrojax._data.io import atomic_write_json  # noqa: E402
from gyrojax._simulate._model import (  # noqa: E402
    Outputs,
    full_field,
    operating_point,
    output_scales,
    wave_from_slow,
    wave_scales,
)
from gyrojax.effects import DacInl  # noqa: E402
from gyrojax.physics import Stimulus  # noqa: E402
from gyrojax.temperature import ConstantTemperature  # noqa: E402


DEG = units.DEG


SWEEP_DPS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
TARGET_FULL_VS_SCIPY = 20.0
TARGET_STEADY_VS_FULL = 1000.0
TARGET_STEADY_PPM = 1.0
DEFAULT = "full (default: DOP853, 1e-8)"
FAST = "full DOP853 1e-6"
TOLERANCES = tuple(10.0 ** (-k / 2) for k in range(10, 27))  # 1e-5, 3.2e-6, ..., 1e-13


# --------------------------------------------------------------------------------------------- helpers


def _print(*args):
    print(*args, flush=True)


def _versions():
    return {
        "python": sys.version.split()[0],
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "diffrax": diffrax.__version__,
        "equinox": eqx.__version__,
        "optimistix": optimistix.__version__,
        "scipy": scipy.__version__,
        "numpy": np.__version__,
    }


def _machine():
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "jax_backend": jax.default_backend(),
        "jax_devices": [str(d) for d in jax.devices()],
        "load_average": os.getloadavg(),
    }


def _best_of(fn, repeats, budget_s=0.5, max_repeats=500):
    """Best wall-clock time (s) over calls of `fn` (which must block), and the last result.

    At least `repeats` calls; cheap calls are repeated further until `budget_s` seconds have been spent
    (at most `max_repeats` calls), so that a first call's one-off costs never set a millisecond figure.
    """
    best = math.inf
    out = None
    spent = 0.0
    count = 0
    while count < repeats or (spent < budget_s and count < max_repeats):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        spent += dt
        count += 1
    return best, out


def _compile(fn, *args):
    """AOT-compile a jitted `fn` for `args`; returns (compiled, seconds for trace + lower + compile)."""
    t0 = time.perf_counter()
    compiled = fn.lower(*args).compile()
    return compiled, time.perf_counter() - t0


def _write_json(path, payload):
    """Atomic write (gyrojax's own helper): a temporary file in the target folder, then os.replace."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    atomic_write_json(payload, path)


def _table(rows, headers):
    cells = [[str(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) for i, h in enumerate(headers)]
    line = "  ".join(h.rjust(w) for h, w in zip(headers, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join(out)


def _mul(a, b):
    return jax.tree.map(lambda x, y: x * y, a, b)


def _div(a, b):
    return jax.tree.map(lambda x, y: x / y, a, b)


# ------------------------------------------------------------------ the flattened closed-loop problem


class FlatProblem:
    """The full tier's ODE as `_ode_settle` sets it up, flattened to a vector for scipy.

    State z = (WaveState / wave_scales, integral of Outputs / output_scales); the same initial state
    (ideal operating point, carrier phase 0, zero integrals), span [0, settle_time + average_periods T],
    and the rate output = (integral(t1) - integral(settle_time)) / average_time * output scale.
    """

    def __init__(self, gyro, rate, settle_time, average_periods):
        self.gyro = gyro
        self.stim = Stimulus(rate=rate)
        self.settle_time = float(settle_time)
        self.average_periods = int(average_periods)
        omega = float(gyro.drive_loop.center_frequency)
        self.average_time = self.average_periods * 2.0 * math.pi / omega
        self.t1 = self.settle_time + self.average_time
        self.scales = wave_scales(gyro)
        self.out_scales = output_scales(gyro)
        slow = operating_point(gyro, self.stim)
        zero = Outputs(jnp.zeros(()), jnp.zeros(()), jnp.zeros(()))
        z0 = (_div(wave_from_slow(slow, omega), self.scales), zero)
        y0, self.unravel = ravel_pytree(z0)
        self.y0 = np.asarray(y0)
        self.n = self.y0.size
        # Where each field sits in the flat vector: unravel the indices themselves.
        self.index = self.unravel(jnp.arange(self.n, dtype=float))
        scale_vec, _ = ravel_pytree((self.scales, self.out_scales))
        self.scale_vec = np.asarray(scale_vec)
        self.rate_index = int(self.index[1].rate)
        self.rate_scale = float(self.out_scales.rate)

        gyro_, stim_, scales, out_scales, unravel = gyro, self.stim, self.scales, self.out_scales, self.unravel

        def flat_field(t, y):
            state, _ = unravel(y)
            d, out = full_field(t, _mul(state, scales), gyro_, stim_)
            flat, _ = ravel_pytree((_div(d, scales), _div(out, out_scales)))
            return flat

        self.flat_field = flat_field
        self.jax_rhs = jax.jit(flat_field)

    def rate_from(self, y_settle, y_end):
        """Mean rate output (LSB) over the averaging window from the two saved flat states."""
        return (y_end[self.rate_index] - y_settle[self.rate_index]) / self.average_time * self.rate_scale


class NumpyFullField:
    """A NumPy / Python-scalar mirror of `full_field` for the ideal closed-loop device, on the flat scaled
    state of `FlatProblem` (what a user would write to hand the ODE to scipy).

    Ideal device: linear DAC (no INL, DNL or quantiser), constant temperature, closed loop. Everything
    else (Duffing terms, couplings, gain/offset errors, branch mismatch, gap nonlinearity of the feedback
    combs, VCF force, modulated rate) is mirrored term by term.
    """

    def __init__(self, problem: FlatProblem):
        g = problem.gyro
        if not g.closed_loop:
            raise ValueError("NumpyFullField mirrors the closed-loop field only.")
        dac = g.excitation.dac
        if np.any(np.asarray(dac.inl) != 0.0) or float(dac.dnl_amplitude) != 0.0 or dac.quantize:
            raise ValueError("NumpyFullField mirrors the ideal (linear) DAC only.")
        if not isinstance(g.temperature, ConstantTemperature):
            raise ValueError("NumpyFullField mirrors a constant temperature only.")
        f = float
        r = g.resonator
        temperature = g.temperature(0.0)
        wx, wy, qx, qy = (f(v) for v in r.at_temperature(temperature))
        self.wx, self.wy, self.qx, self.qy = wx, wy, qx, qy
        self.m = f(r.mass)
        self.c, self.kap, self.ag = f(r.damping_coupling), f(r.stiffness_coupling), f(r.angular_gain)
        self.bx, self.by = f(r.duffing_x), f(r.duffing_y)
        dl = g.drive_loop
        self.rot_d = cmath.exp(-1j * f(dl.reference_phase))
        self.setpoint, self.wc = f(dl.amplitude_setpoint), f(dl.center_frequency)
        self.pll_kp, self.pll_ki = f(dl.pll_kp), f(dl.pll_ki)
        self.agc_kp, self.agc_ki, self.agc_leak = f(dl.agc_kp), f(dl.agc_ki), f(dl.agc_leak)
        self.cut_d = f(dl.demod_cutoff)
        rl = g.rebalance_loop
        self.rot_s = cmath.exp(-1j * f(rl.reference_phase))
        self.rkp, self.rki, self.rleak = f(rl.kp), f(rl.ki), f(rl.leak)
        self.cut_s = f(rl.demod_cutoff)
        self.carrier_phase = f(rl.carrier_phase)
        self.kdx = f(g.drive_electrode.force_per_volt)
        self.update_rate = f(dac.update_rate)
        self.code_scale = f(dac.code_scale)
        self.half = 2.0 ** (dac.bits - 1)
        self.dac_gain = f(dac.full_scale) * (1.0 + f(dac.gain_error))
        self.dac_offset = f(dac.offset)
        ex = g.excitation
        self.ka, self.ep, self.em = f(ex.amplifier_gain), f(ex.branch_gain_error_plus), f(ex.branch_gain_error_minus)
        fb = g.feedback_electrode
        self.fb_a = f(fb.k_vf) / (2.0 * f(fb.v_dc))
        self.vdc, self.d0, self.rho = f(fb.v_dc), f(fb.gap), f(fb.gap_fraction)
        self.spring = 2.0 * self.fb_a * self.vdc**2 * self.rho / self.d0  # at the nominal bias
        self.bias = f(fb.bias(temperature - r.t_ref))  # the bias the force sees at the die temperature
        self.gd = f(g.drive_frontend.gain * g.drive_frontend.current_per_velocity / g.drive_frontend.adc_lsb)
        self.gs = f(g.sense_frontend.gain * g.sense_frontend.current_per_velocity / g.sense_frontend.adc_lsb)
        self.d_charge = g.drive_frontend.kind == "charge"
        self.s_charge = g.sense_frontend.kind == "charge"
        self.kvcf = f(g.vcf_electrode.force_per_volt2)
        st = problem.stim
        self.rate, self.rate_freq = f(st.rate), f(st.rate_frequency)
        self.vcf = f(st.vcf_ac) * f(st.vcf_fc)
        self.vcf_freq = f(st.vcf_frequency)

        ix = problem.index
        w, o = ix[0], ix[1]
        as_int = lambda a: [int(v) for v in np.asarray(a).reshape(-1)]  # noqa: E731
        self.i_x, self.i_vx = as_int(w.drive)
        self.i_y, self.i_vy = as_int(w.sense)
        (self.i_ph,) = as_int(w.phase)
        (self.i_pll,) = as_int(w.loops.pll)
        (self.i_agc,) = as_int(w.loops.agc)
        self.i_dlpf = [tuple(as_int(row)) for row in np.asarray(w.loops.drive_lpf)]
        self.i_slpf = [tuple(as_int(row)) for row in np.asarray(w.loops.sense_lpf)]
        self.i_reb = tuple(as_int(w.loops.rebalance))
        self.i_out = (int(o.rate), int(o.quadrature), int(o.frequency))
        self.n = problem.n
        self.scale = problem.scale_vec
        self.inv_scale = 1.0 / problem.scale_vec

    def __call__(self, t, z):
        u = (z * self.scale).tolist()
        x, vx, y, vy = u[self.i_x], u[self.i_vx], u[self.i_y], u[self.i_vy]
        theta = u[self.i_ph]
        dlpf = [complex(u[i], u[j]) for i, j in self.i_dlpf]
        slpf = [complex(u[i], u[j]) for i, j in self.i_slpf]
        zr = complex(u[self.i_reb[0]], u[self.i_reb[1]])

        # Drive loop (PLL + AGC) and rebalance loop (complex PI).
        e_d = dlpf[-1] * self.rot_d
        phase = cmath.phase(e_d)
        err = self.setpoint - abs(e_d)
        omega = self.wc + self.pll_kp * phase + u[self.i_pll]
        v_d = self.agc_kp * err + u[self.i_agc]
        d_pll = self.pll_ki * phase
        d_agc = self.agc_ki * err - self.agc_leak * u[self.i_agc]
        e_s = slpf[-1] * self.rot_s
        word = -(self.rkp * e_s + zr)
        d_reb = self.rki * e_s - self.rleak * zr

        m = self.m
        om = self.rate * math.cos(self.rate_freq * t)
        sin_t = math.sin(theta)
        f_x = self.kdx * v_d * (-sin_t) - m * self.bx * x**3

        # FTR chain: word on the carrier -> ZOH (fundamental gain and delay) -> DAC -> K_a -> branches.
        h = 0.5 * omega / self.update_rate
        hold_gain = math.sin(h) / h if h > 0 else 1.0
        sample = (1j * word * cmath.exp(1j * (theta + self.carrier_phase - h))).real
        v_dac = (self.dac_gain * (sample * self.code_scale) / self.half + self.dac_offset) * hold_gain
        v = self.ka * v_dac
        vp, vm = v * (1.0 + self.ep), v * (1.0 + self.em)
        rho, d0 = self.rho, self.d0
        plus = (1.0 - rho) + rho * d0**2 / (d0 - y) ** 2
        minus = (1.0 - rho) + rho * d0**2 / (d0 + y) ** 2
        f_fb = 0.5 * self.fb_a * (plus * (self.bias + vp) ** 2 - minus * (self.bias - vm) ** 2) - self.spring * y
        f_y = (-m * self.by * y**3 + f_fb
               + self.kvcf * self.vcf * math.cos(self.vcf_freq * t) * sin_t)

        wx, wy, c, kap, ag = self.wx, self.wy, self.c, self.kap, self.ag
        ax = f_x / m - (wx / self.qx) * vx - wx**2 * x - c * vy - kap * y + 2 * ag * om * vy
        ay = f_y / m - (wy / self.qy) * vy - wy**2 * y - c * vx - kap * x - 2 * ag * om * vx

        carrier = 2.0 * cmath.exp(-1j * theta)
        drive_demod = self.gd * (x if self.d_charge else vx) * carrier
        sense_demod = self.gs * (y if self.s_charge else vy) * carrier

        d = [0.0] * self.n
        d[self.i_x], d[self.i_vx], d[self.i_y], d[self.i_vy] = vx, ax, vy, ay
        d[self.i_ph] = omega
        d[self.i_pll], d[self.i_agc] = d_pll, d_agc
        prev = drive_demod
        for (i, j), zk in zip(self.i_dlpf, dlpf):
            dk = self.cut_d * (prev - zk)
            d[i], d[j] = dk.real, dk.imag
            prev = zk
        prev = sense_demod
        for (i, j), zk in zip(self.i_slpf, slpf):
            dk = self.cut_s * (prev - zk)
            d[i], d[j] = dk.real, dk.imag
            prev = zk
        d[self.i_reb[0]], d[self.i_reb[1]] = d_reb.real, d_reb.imag
        d[self.i_out[0]], d[self.i_out[1]], d[self.i_out[2]] = word.real, word.imag, omega
        return np.array(d) * self.inv_scale


def check_numpy_field(problem, np_field, samples=8, seed=0):
    """How far the NumPy mirror is from the JAX field at random scaled states: (max |diff| / max |f| over
    everything, and the worst component's max |diff| / that component's largest |f| over the samples).

    The first sample is the operating point itself, where some derivatives are sums of large terms that
    cancel to round-off; each component is therefore measured against its own size over all samples.
    """
    rng = np.random.default_rng(seed)
    refs, diffs = [], []
    for k in range(samples):
        z = problem.y0 + (0.0 if k == 0 else 0.3) * rng.standard_normal(problem.n)
        z[np.asarray(problem.index[0].phase, dtype=int)] = rng.uniform(0, 2 * math.pi) if k else 0.0
        t = 0.0 if k == 0 else rng.uniform(0.0, problem.t1)
        ref = np.asarray(problem.jax_rhs(t, z))
        refs.append(np.abs(ref))
        diffs.append(np.abs(np.asarray(np_field(t, z)) - ref))
    refs, diffs = np.array(refs), np.array(diffs)
    worst_norm = float(np.max(diffs) / np.max(refs))
    size = np.max(refs, axis=0)
    worst_comp = float(np.max(np.max(diffs, axis=0) / np.where(size > 0, size, 1.0)))
    return worst_norm, worst_comp


# -------------------------------------------------------------------------------------------- part 1


class NumpyFullFieldBatch:
    """The NumPy mirror vectorised over a batch of points (one table rate each), for scipy on a whole sweep
    as one ODE: the state is (n states, B points) flattened row-major, so each state is a contiguous
    length-B vector and every operation is one NumPy call on B values.
    """

    def __init__(self, problems):
        self.base = NumpyFullField(problems[0])  # constants and indices (the same device for all points)
        self.n, self.b = problems[0].n, len(problems)
        self.rate = np.array([float(p.stim.rate) for p in problems])
        self.y0 = np.stack([p.y0 for p in problems], axis=1).reshape(-1)
        self.scale = problems[0].scale_vec[:, None]
        self.inv_scale = 1.0 / self.scale

    def rates_from(self, problem, y_settle, y_end):
        """Mean rate outputs (LSB) of all points from the two saved flat states."""
        i = problem.rate_index
        ys, ye = y_settle.reshape(self.n, self.b)[i], y_end.reshape(self.n, self.b)[i]
        return (ye - ys) / problem.average_time * problem.rate_scale

    def __call__(self, t, z):
        b = self.base
        u = z.reshape(self.n, self.b) * self.scale
        x, vx, y, vy = u[b.i_x], u[b.i_vx], u[b.i_y], u[b.i_vy]
        theta = u[b.i_ph]
        dlpf = [u[i] + 1j * u[j] for i, j in b.i_dlpf]
        slpf = [u[i] + 1j * u[j] for i, j in b.i_slpf]
        zr = u[b.i_reb[0]] + 1j * u[b.i_reb[1]]

        e_d = dlpf[-1] * b.rot_d
        phase = np.angle(e_d)
        err = b.setpoint - np.abs(e_d)
        omega = b.wc + b.pll_kp * phase + u[b.i_pll]
        v_d = b.agc_kp * err + u[b.i_agc]
        d_pll = b.pll_ki * phase
        d_agc = b.agc_ki * err - b.agc_leak * u[b.i_agc]
        e_s = slpf[-1] * b.rot_s
        word = -(b.rkp * e_s + zr)
        d_reb = b.rki * e_s - b.rleak * zr

        m = b.m
        om = self.rate * math.cos(b.rate_freq * t)
        sin_t = np.sin(theta)
        f_x = b.kdx * v_d * (-sin_t) - m * b.bx * x**3

        h = 0.5 * omega / b.update_rate
        hold_gain = np.where(h > 0, np.sin(h) / np.where(h > 0, h, 1.0), 1.0)
        sample = (1j * word * np.exp(1j * (theta + b.carrier_phase - h))).real
        v_dac = (b.dac_gain * (sample * b.code_scale) / b.half + b.dac_offset) * hold_gain
        v = b.ka * v_dac
        vp, vm = v * (1.0 + b.ep), v * (1.0 + b.em)
        plus = (1.0 - b.rho) + b.rho * b.d0**2 / (b.d0 - y) ** 2
        minus = (1.0 - b.rho) + b.rho * b.d0**2 / (b.d0 + y) ** 2
        f_fb = 0.5 * b.fb_a * (plus * (b.bias + vp) ** 2 - minus * (b.bias - vm) ** 2) - b.spring * y
        f_y = -m * b.by * y**3 + f_fb + b.kvcf * b.vcf * math.cos(b.vcf_freq * t) * sin_t

        ax = f_x / m - (b.wx / b.qx) * vx - b.wx**2 * x - b.c * vy - b.kap * y + 2 * b.ag * om * vy
        ay = f_y / m - (b.wy / b.qy) * vy - b.wy**2 * y - b.c * vx - b.kap * x - 2 * b.ag * om * vx

        carrier = 2.0 * np.exp(-1j * theta)
        drive_demod = b.gd * (x if b.d_charge else vx) * carrier
        sense_demod = b.gs * (y if b.s_charge else vy) * carrier

        d = np.empty((self.n, self.b))
        d[b.i_x], d[b.i_vx], d[b.i_y], d[b.i_vy] = vx, ax, vy, ay
        d[b.i_ph] = omega
        d[b.i_pll], d[b.i_agc] = d_pll, d_agc
        for indices, stages, cutoff, signal in ((b.i_dlpf, dlpf, b.cut_d, drive_demod),
                                                (b.i_slpf, slpf, b.cut_s, sense_demod)):
            prev = signal
            for (i, j), zk in zip(indices, stages):
                dk = cutoff * (prev - zk)
                d[i], d[j] = dk.real, dk.imag
                prev = zk
        d[b.i_reb[0]], d[b.i_reb[1]] = d_reb.real, d_reb.imag
        d[b.i_out[0]], d[b.i_out[1]], d[b.i_out[2]] = word.real, word.imag, omega
        return (d * self.inv_scale).reshape(-1)


def check_batch_field(problems, batch_field, samples=4, seed=1):
    """Worst componentwise difference of the vectorised mirror from the JAX field, point by point."""
    rng = np.random.default_rng(seed)
    n, nb = batch_field.n, batch_field.b
    refs, diffs = [], []
    for _ in range(samples):
        z = batch_field.y0.reshape(n, nb) + 0.3 * rng.standard_normal((n, nb))
        t = rng.uniform(0.0, problems[0].t1)
        got = batch_field(t, z.reshape(-1)).reshape(n, nb)
        for k, p in enumerate(problems):
            ref = np.asarray(p.jax_rhs(t, z[:, k]))
            refs.append(np.abs(ref))
            diffs.append(np.abs(got[:, k] - ref))
    refs, diffs = np.array(refs), np.array(diffs)
    size = np.max(refs, axis=0)
    return float(np.max(np.max(diffs, axis=0) / np.where(size > 0, size, 1.0)))


def _field_cost_in_xla(problem, evaluations=10_000):
    """Seconds per evaluation of the flattened JAX field inside one XLA loop (no dispatch, no solver)."""
    f = problem.flat_field

    @jax.jit
    def loop(y):
        return jax.lax.fori_loop(0, evaluations, lambda i, y: y + 1e-12 * f(i * 1e-7, y), y)

    y0 = jnp.asarray(problem.y0)
    compiled, _ = _compile(loop, y0)
    t, _ = _best_of(lambda: jax.block_until_ready(compiled(y0)), 3)
    return t / evaluations


# ---------------------------------------------------------------------------------------- scipy runs


def _scipy_run(method, rhs, y0, settle_time, t1, tol):
    """One scipy solve from 0 to t1 saving at settle_time and t1: (seconds, y(settle), y(t1), nfev)."""
    t0 = time.perf_counter()
    if method == "odeint":
        ys, info = odeint(rhs, y0, [0.0, settle_time, t1], rtol=tol, atol=tol, tfirst=True, full_output=True,
                          mxstep=10**8, h0=FullWaveform().dt0)
        seconds = time.perf_counter() - t0
        if info["message"] != "Integration successful.":
            raise RuntimeError(f"odeint: {info['message']}")
        return seconds, ys[1], ys[2], int(info["nfe"][-1])
    res = solve_ivp(rhs, (0.0, t1), y0, method=method, t_eval=[settle_time, t1], rtol=tol, atol=tol,
                    first_step=FullWaveform().dt0)
    seconds = time.perf_counter() - t0
    if res.status != 0:
        raise RuntimeError(f"solve_ivp {method}: {res.message}")
    return seconds, res.y[:, 0], res.y[:, 1], int(res.nfev)


def _tolerance_search(run, error_of, targets, budget_s):
    """Tighten rtol = atol over TOLERANCES until each target (ppm, loosest first) is met.

    `run(tol)` returns (seconds, result, nfev); `error_of(result)` the error in ppm. Returns
    (tried: list of dicts, chosen: {target: the first tried entry meeting it, or None}). Stops when every
    target is met, or when one run took longer than `budget_s` without meeting the remaining targets.
    """
    tried, chosen = [], {t: None for t in targets}
    for tol in TOLERANCES:
        seconds, result, nfev = run(tol)
        err = float(error_of(result))
        entry = {"tol": tol, "seconds": seconds, "error_ppm": err, "nfev": nfev, "result": result}
        tried.append(entry)
        for target in targets:
            if chosen[target] is None and abs(err) <= target:
                chosen[target] = entry
        if all(v is not None for v in chosen.values()) or seconds > budget_s:
            break
    return tried, chosen


# -------------------------------------------------------------------------------------------- part 1


def _sweep_program(tier):
    @eqx.filter_jit
    def run(gyro, rates):
        s = tier.settle_points(*jax.vmap(lambda r: (gyro, Stimulus(rate=r)))(rates))
        return s.rate, s.result == RESULTS.successful, s.num_steps

    return run


def _fit(x, y):
    """Least-squares line; (slope, max |residual| / (|slope| max |x|) in ppm)."""
    a = np.stack([x, np.ones_like(x)], 1)
    coef = np.linalg.lstsq(a, y, rcond=None)[0]
    res = y - a @ coef
    return coef[0], float(np.max(np.abs(res)) / (abs(coef[0]) * np.max(np.abs(x))) * 1e6)


def part1(devices, args):
    dps = np.array(sorted([-v for v in SWEEP_DPS] + list(SWEEP_DPS)))
    rates = jnp.asarray(dps * DEG)
    x = dps * DEG
    npts = dps.size
    st, periods = args.settle, args.average_periods

    def full(**kw):
        return FullWaveform(settle_time=st, average_periods=periods, **kw)

    tiers = [("reference: full Dopri8 rtol 1e-12", full(solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12)),
             ("steady", Steady()),
             ("averaged", Averaged(settle_time=st)),
             (DEFAULT, full())]
    if not args.quick:
        tiers += [(FAST, full(rtol=1e-6, atol=1e-6))]
    if not (args.quick or args.tiers_only):
        tiers += [("full Dopri8 unrolled 1e-8", full(solver=diffrax.Dopri8(), rtol=1e-8, atol=1e-8)),
                  ("full Dopri8 diffrax loop 1e-8", full(solver=diffrax.Dopri8(), rtol=1e-8, atol=1e-8,
                                                         unroll_stages=False)),
                  ("full Tsit5 diffrax loop 1e-10", full(solver=diffrax.Tsit5(), rtol=1e-10, atol=1e-10,
                                                         unroll_stages=False))]
    _print(f"\n== Part 1: tiers on a {npts}-point rate sweep (+/-{', '.join(f'{v:g}' for v in SWEEP_DPS)} deg/s), "
           f"eqx.filter_jit(vmap(settle)) with the device as an argument, settle {st:g} s (full: + {periods} "
           f"carrier periods), devices: ideal and with the typical DAC INL ==")
    results = {}
    for name, tier in tiers:
        fn = _sweep_program(tier)
        out = {}
        t0 = time.perf_counter()
        jax.block_until_ready(fn(devices["ideal"], rates))
        first = time.perf_counter() - t0
        for label, dev in devices.items():
            t_batch, (rate, ok, steps) = _best_of(lambda dev=dev: jax.block_until_ready(fn(dev, rates)),
                                                  args.sweep_repeats)
            if not bool(np.all(np.asarray(ok))):
                raise SystemExit(f"{name} / {label}: some sweep points did not settle: {np.asarray(ok)}")
            out[label] = {"rate": np.asarray(rate), "t_batch": t_batch, "steps": int(np.max(np.asarray(steps)))}
        out["compile_s"] = max(first - out["ideal"]["t_batch"], 0.0)
        results[name] = out
        _print(f"{name:40s}: compile ~{out['compile_s']:5.1f} s, batch {out['ideal']['t_batch']:8.3f} s "
               f"({out['ideal']['t_batch'] / npts * 1e3:8.3f} ms/point), max steps {out['ideal']['steps']}")

    ref = results[tiers[0][0]]
    steady = results["steady"]
    fs = {label: abs(float(steady[label]["rate"][dps == 200.0][0])) for label in devices}
    sf_s, nl_s = _fit(x, steady["inl"]["rate"])
    rows, table = {}, []
    default_name = DEFAULT
    t_default = results[default_name]["ideal"]["t_batch"]
    for name, _ in tiers:
        r = results[name]
        sf, nl = _fit(x, r["inl"]["rate"])
        vs_steady = max(float(np.max(np.abs(r[lb]["rate"] - steady[lb]["rate"]))) / fs[lb] * 1e6 for lb in devices)
        err = max(float(np.max(np.abs(r[lb]["rate"] - ref[lb]["rate"]))) / fs[lb] * 1e6 for lb in devices)
        is_full = name.startswith(("full", "reference"))
        row = {"compile_s": r["compile_s"], "batch_s": r["ideal"]["t_batch"],
               "per_point_ms": r["ideal"]["t_batch"] / npts * 1e3, "max_steps": r["ideal"]["steps"],
               "speedup_vs_default_full": t_default / r["ideal"]["t_batch"],
               "sf_vs_steady_ppm": (sf / sf_s - 1) * 1e6, "nl_ppm": nl, "nl_minus_steady_ppm": nl - nl_s,
               "max_vs_steady_ppm_fs": vs_steady, "numerical_error_ppm_fs": err if is_full else None,
               "rate_lsb_ideal": r["ideal"]["rate"].tolist(), "rate_lsb_inl": r["inl"]["rate"].tolist()}
        rows[name] = row
        table.append([name, f"{row['compile_s']:.1f}", f"{row['per_point_ms']:.3f}",
                      f"{row['speedup_vs_default_full']:.2f}", row["max_steps"], f"{row['sf_vs_steady_ppm']:+.4f}",
                      f"{row['nl_minus_steady_ppm']:+.4f}", f"{vs_steady:.4f}", "" if not is_full else f"{err:.5f}"])
    _print()
    _print(_table(table, ["tier", "compile s", "ms/point", "x default full", "max steps", "SF vs steady ppm",
                          "NL - NL steady ppm", "max |diff| vs steady ppm FS", "E: vs 1e-12 ppm FS"]))
    _print(f"(INL device: NL of the steady tier {nl_s:.3f} ppm. SF/NL on the INL device; 'max |diff|' and E over "
           "both devices, ppm of each device's full-scale output)")
    st_row = rows["steady"]
    ok_speed = st_row["speedup_vs_default_full"] >= TARGET_STEADY_VS_FULL
    ok_ppm = st_row["max_vs_steady_ppm_fs"] == 0.0 or rows[default_name]["max_vs_steady_ppm_fs"] <= TARGET_STEADY_PPM
    _print(f"\nsteady tier: {st_row['speedup_vs_default_full']:.0f}x faster per point than the default full tier "
           f"(target >= {TARGET_STEADY_VS_FULL:g}x: {'meets' if ok_speed else 'MISSES'}); full vs steady "
           f"{rows[default_name]['max_vs_steady_ppm_fs']:.3f} ppm of full scale (target <= {TARGET_STEADY_PPM:g} ppm: "
           f"{'meets' if ok_ppm else 'MISSES'})")
    inl_ratio = results[default_name]["inl"]["t_batch"] / results["steady"]["inl"]["t_batch"]
    _print(f"on the INL device alone: steady {results['steady']['inl']['t_batch'] / npts * 1e3:.4f} vs full "
           f"{results[default_name]['inl']['t_batch'] / npts * 1e3:.3f} ms/point: {inl_ratio:.0f}x "
           f"(steady max steps {results['steady']['inl']['steps']})")
    lot = lot_scale(devices["inl"], rates, args)
    return {"lot_scale": lot, "speedup_inl_vs_default_full": inl_ratio, "rates_dps": dps.tolist(),
            "settle_time_s": st, "average_periods": periods,
            "full_scale_lsb": fs, "steady_nl_ppm_inl": nl_s, "tiers": rows, "reference": tiers[0][0],
            "default": default_name, "steady_meets_speed_target": ok_speed, "steady_meets_ppm_target": ok_ppm}


def lot_scale(gyro, rates, args, devices=8):
    """Steady against the default full tier per point at lot scale: one compiled call settles the whole sweep
    of every device of a simulated lot (`make_lot`, default process spread, INL device), as identify and
    simulate_table do. A 22-point sweep alone leaves the steady tier's few-hundred small XLA operations
    overhead-bound (~1 ms per call however few points); at lot scale both tiers are compute-bound."""
    lot = make_lot(gyro, devices, jax.random.PRNGKey(0))
    _print(f"\n-- lot scale: {devices} devices x {rates.size} points = {devices * rates.size} points per call --")

    out = {}
    for name, tier in (("steady", Steady()), (DEFAULT, FullWaveform(settle_time=args.settle,
                                                                     average_periods=args.average_periods))):
        # part 1's sweep program, vmapped over the lot's devices
        fn = eqx.filter_jit(eqx.filter_vmap(_sweep_program(tier), in_axes=(eqx.if_array(0), None)))
        jax.block_until_ready(fn(lot, rates))
        t, (rate, ok, _) = _best_of(lambda: jax.block_until_ready(fn(lot, rates)), args.sweep_repeats)
        if not bool(np.all(np.asarray(ok))):
            raise SystemExit(f"lot scale, {name}: some points did not settle")
        out[name] = {"t_batch": t, "per_point_ms": t / rate.size * 1e3, "rate": np.asarray(rate)}
        _print(f"{name:40s}: batch {t:8.3f} s ({t / rate.size * 1e3:8.4f} ms/point)")
    full_scale = np.max(np.abs(out["steady"]["rate"]), axis=1, keepdims=True)
    diff = float(np.max(np.abs(out[DEFAULT]["rate"] - out["steady"]["rate"]) / full_scale) * 1e6)
    ratio = out[DEFAULT]["t_batch"] / out["steady"]["t_batch"]
    _print(f"steady tier at lot scale: {ratio:.0f}x faster per point than the default full tier (target >= "
           f"{TARGET_STEADY_VS_FULL:g}x: {'meets' if ratio >= TARGET_STEADY_VS_FULL else 'MISSES'}); the two "
           f"{diff:.3f} ppm of full scale apart at most")
    return {"devices": devices, "points": int(devices * rates.size), "speedup": ratio, "max_diff_ppm_fs": diff,
            **{k: {"t_batch_s": v["t_batch"], "per_point_ms": v["per_point_ms"]} for k, v in out.items()}}


# -------------------------------------------------------------------------------------------- part 2


SCIPY_METHODS = ("RK45", "DOP853", "LSODA", "odeint")


def _interleaved(contenders, rounds):
    """Best time of each `(name, fn)` over `rounds` rounds in which every contender runs once in turn, so
    that a change of load on a shared machine hits all of them alike. `fn()` must block and return its
    wall time (or None to time it here)."""
    best = {name: math.inf for name, _ in contenders}
    for _ in range(rounds):
        for name, fn in contenders:
            t0 = time.perf_counter()
            got = fn()
            best[name] = min(best[name], got if got is not None else time.perf_counter() - t0)
    return best


def part2(gyro, args, accuracy):
    """`accuracy`: {label: (tier, E ppm)} of the gyrojax settings to compare at ("reference" included)."""
    rate = 200.0 * DEG
    problem = FlatProblem(gyro, rate, args.settle, args.average_periods)
    _print(f"\n== Part 2: one point at +200 deg/s, span 0 .. {args.settle:g} s + {args.average_periods} periods = "
           f"{problem.t1:.6f} s, {problem.n} scaled states; scipy at equal accuracy ==")
    np_field = NumpyFullField(problem)
    norm_err, comp_err = check_numpy_field(problem, np_field)
    ok = comp_err <= 1e-12
    _print(f"NumPy RHS vs JAX full_field at 8 random states: max |diff| / max |f| = {norm_err:.2e}, worst "
           f"component {comp_err:.2e} of its size  [{'OK' if ok else 'FAILED'} at 1e-12]")
    if not ok:
        raise SystemExit("The NumPy mirror of full_field disagrees with the JAX field; not timing it.")
    batch1 = NumpyFullFieldBatch([problem])
    t_np, _ = _best_of(lambda: [np_field(0.01, problem.y0) for _ in range(1000)], 3)
    t_vec, _ = _best_of(lambda: [batch1(0.01, problem.y0) for _ in range(1000)], 3)
    t_xla = _field_cost_in_xla(problem)
    rhs_us = {"numpy_scalar": t_np / 1e3 * 1e6, "numpy_vectorised_batch1": t_vec / 1e3 * 1e6, "jax_in_xla": t_xla * 1e6}
    _print(f"one RHS evaluation: NumPy on Python scalars {rhs_us['numpy_scalar']:.1f} us (used for one point), "
           f"NumPy arrays (vectorised mirror, 1 point) {rhs_us['numpy_vectorised_batch1']:.1f} us, the JAX field "
           f"inside XLA {rhs_us['jax_in_xla']:.2f} us")

    # the reference and the gyrojax settings, one unbatched jitted point each
    compiled, rows = {}, []
    for label, (tier, _) in accuracy.items():
        fn = jax.jit(lambda r, tier=tier: settle(gyro, Stimulus(rate=r), tier))
        compiled[label], t_compile = _compile(fn, rate)
        sol = compiled[label](rate)
        if sol.result != RESULTS.successful:
            raise SystemExit(f"{label} failed: {sol.result}")
        if label == "reference":
            ref_rate = float(sol.rate)
            continue
        rows.append({"method": f"gyrojax {label}", "accuracy": label, "tol": float(tier.rtol), "compile_s": t_compile,
                     "steps": int(sol.num_steps), "nfev": None, "rate_lsb": float(sol.rate),
                     "error_ppm": (float(sol.rate) / ref_rate - 1) * 1e6})
    steady_rate = float(settle(gyro, Stimulus(rate=rate)).rate)
    _print(f"reference (full tier, Dopri8 rtol 1e-12): {ref_rate:.6f} LSB; steady tier {steady_rate:.6f} LSB "
           f"({(ref_rate / steady_rate - 1) * 1e6:+.4f} ppm: the tiers' physical difference)")

    labels = [k for k in accuracy if k != "reference"]
    targets = {label: accuracy[label][1] for label in labels}
    searches, chosen_runs = {}, {}
    for method in SCIPY_METHODS:
        def run(tol, method=method):
            seconds, ys, ye, nfev = _scipy_run(method, np_field, problem.y0, problem.settle_time, problem.t1, tol)
            return seconds, float(problem.rate_from(ys, ye)), nfev

        tried, chosen = _tolerance_search(run, lambda r: (r / ref_rate - 1) * 1e6,
                                          sorted(set(targets.values()), reverse=True), args.scipy_budget)
        searches[method] = [{k: v for k, v in e.items() if k != "result"} for e in tried]
        _print(f"scipy {method:6s} (tol: error, s): " + ", ".join(
            f"{e['tol']:.1e}: {e['error_ppm']:+.5f} ppm {e['seconds']:.2f}" for e in tried))
        for label in labels:
            e = chosen[targets[label]]
            row = {"method": f"scipy {method}", "accuracy": label, "tol": None if e is None else e["tol"],
                   "compile_s": None, "steps": None, "nfev": None if e is None else e["nfev"],
                   "rate_lsb": None if e is None else e["result"], "error_ppm": None if e is None else e["error_ppm"]}
            rows.append(row)
            if e is not None:
                chosen_runs[(method, e["tol"])] = lambda method=method, tol=e["tol"]: run(tol, method)[0]

    # the timings: every contender once per round, rounds interleaved
    contenders = [(f"gyrojax {label}", lambda label=label: _best_of(
        lambda: jax.block_until_ready(compiled[label](rate)), args.repeats, budget_s=0.2)[0]) for label in labels]
    contenders += [(key, fn) for key, fn in chosen_runs.items()]
    best = _interleaved(contenders, args.rounds)
    for r in rows:
        key = r["method"] if r["method"].startswith("gyrojax") else (r["method"].split()[-1], r["tol"])
        r["time_s"] = best.get(key)

    _print()
    table, verdicts = [], {}
    for label in labels:
        ours = next(r for r in rows if r["method"] == f"gyrojax {label}")
        theirs = [r for r in rows if r["accuracy"] == label and r["method"].startswith("scipy")]
        best_row = min((r for r in theirs if r["time_s"] is not None), key=lambda r: r["time_s"])
        ratio = best_row["time_s"] / ours["time_s"]
        verdicts[label] = {"E_ppm": targets[label], "gyrojax_s": ours["time_s"], "gyrojax_error_ppm": ours["error_ppm"],
                           "best_scipy": best_row["method"], "best_scipy_s": best_row["time_s"],
                           "best_scipy_tol": best_row["tol"], "best_scipy_error_ppm": best_row["error_ppm"],
                           "ratio": ratio, "meets_target": ratio >= TARGET_FULL_VS_SCIPY}
        for r in [ours] + theirs:
            r["time_over_gyrojax"] = None if r["time_s"] is None else r["time_s"] / ours["time_s"]
            table.append([f"{label} (E {targets[label]:.4f})", r["method"],
                          "" if r["tol"] is None else f"{r['tol']:.1e}",
                          "not reached" if r["time_s"] is None else f"{r['time_s']:.4f}",
                          "" if r["nfev"] is None else r["nfev"], "" if r["steps"] is None else r["steps"],
                          "" if r["error_ppm"] is None else f"{r['error_ppm']:+.5f}",
                          "" if r["rate_lsb"] is None else f"{(r['rate_lsb'] / steady_rate - 1) * 1e6:+.4f}",
                          "" if r["time_s"] is None else f"{r['time_over_gyrojax']:.1f}"])
    _print(_table(table, ["accuracy class (E, ppm FS)", "method", "rtol=atol", "time s", "nfev", "steps",
                          "error vs ref ppm", "vs steady ppm", "time / gyrojax"]))
    _print(f"(times: best of {args.rounds} interleaved rounds; gyrojax compile times: "
           + ", ".join(f"{r['accuracy']} {r['compile_s']:.1f} s" for r in rows if r["method"].startswith("gyrojax"))
           + ")")
    for label, v in verdicts.items():
        _print(f"at E = {v['E_ppm']:.5f} ppm ({label}): gyrojax {v['gyrojax_s'] * 1e3:.1f} ms, best scipy "
               f"{v['best_scipy']} at tol {v['best_scipy_tol']:.1e} {v['best_scipy_s']:.3f} s: {v['ratio']:.1f}x "
               f"(target >= {TARGET_FULL_VS_SCIPY:g}x: {'meets' if v['meets_target'] else 'MISSES'})")
    return {"rate_dps": 200.0, "t1_s": problem.t1, "num_states": problem.n, "reference_rate_lsb": ref_rate,
            "steady_rate_lsb": steady_rate, "numpy_rhs_check": {"max_abs_diff_over_max_abs": norm_err,
                                                                "worst_component": comp_err, "passed_1e-12": ok},
            "rhs_eval_us": rhs_us, "rows": rows, "searches": searches, "verdicts": verdicts}


# -------------------------------------------------------------------------------------------- part 3


def part3(gyro, args, p1, p2, accuracy):
    label = p1["default"]
    verdict = p2["verdicts"][label]
    e_target = verdict["E_ppm"]
    dps = np.asarray(p1["rates_dps"])
    npts = dps.size
    ref = np.asarray(p1["tiers"][p1["reference"]]["rate_lsb_ideal"])
    steady = np.asarray(p1["tiers"]["steady"]["rate_lsb_ideal"])
    fs = p1["full_scale_lsb"]["ideal"]
    _print(f"\n== Part 3: the {npts}-point sweep on the ideal device at E = {e_target:.5f} ppm FS (the default "
           "full tier's accuracy): scipy point by point and stacked, gyrojax vmapped and in a loop ==")
    problems = [FlatProblem(gyro, float(r) * DEG, args.settle, args.average_periods) for r in dps]
    fields = [NumpyFullField(p) for p in problems]
    batch = NumpyFullFieldBatch(problems)
    comp = check_batch_field(problems, batch)
    _print(f"vectorised NumPy RHS vs JAX full_field, {npts} points at 4 random states: worst component "
           f"{comp:.2e} of its size [{'OK' if comp <= 1e-12 else 'FAILED'} at 1e-12]")
    if comp > 1e-12:
        raise SystemExit("The vectorised NumPy mirror disagrees with the JAX field; not timing it.")
    t_b, _ = _best_of(lambda: [batch(0.01, batch.y0) for _ in range(200)], 3)
    _print(f"one vectorised RHS evaluation for all {npts} points: {t_b / 200 * 1e6:.1f} us "
           f"({t_b / 200 / npts * 1e6:.2f} us per point)")

    def err_of(rates):
        return float(np.max(np.abs(np.asarray(rates) - ref)) / fs * 1e6)

    def sweep_stats(rates):
        sf, nl = _fit(dps * DEG, np.asarray(rates))
        sf_s, nl_s = _fit(dps * DEG, steady)
        return (sf / sf_s - 1) * 1e6, nl - nl_s

    rows, contenders = [], []
    for method in SCIPY_METHODS[1:]:  # RK45 is 5-10x slower than these at this accuracy (part 2)
        def run_loop(tol, method=method):
            total, rates, nfev = 0.0, [], 0
            for p, f in zip(problems, fields):
                seconds, ys, ye, n = _scipy_run(method, f, p.y0, p.settle_time, p.t1, tol)
                total += seconds
                rates.append(float(p.rate_from(ys, ye)))
                nfev += n
            return total, np.array(rates), nfev

        def run_stacked(tol, method=method):
            seconds, ys, ye, nfev = _scipy_run(method, batch, batch.y0, problems[0].settle_time, problems[0].t1, tol)
            return seconds, batch.rates_from(problems[0], ys, ye), nfev

        start = next((r["tol"] for r in p2["rows"] if r["method"] == f"scipy {method}" and r["accuracy"] == label),
                     None)
        if start is None:
            continue
        for name, run in (("point by point, scalar RHS", run_loop), ("stacked, vectorised RHS", run_stacked)):
            if name.startswith("point") and method != verdict["best_scipy"].split()[-1]:
                continue  # the per-point loop only for part 2's best method: 22 single solves each
            chosen = None
            for tol in [t for t in TOLERANCES if t <= start * 1.0001]:
                seconds, rates, nfev = run(tol)
                err = err_of(rates)
                _print(f"scipy {method} {name}: tol {tol:.1e}: {seconds:.2f} s, E {err:.5f} ppm FS")
                if err <= e_target:
                    chosen = (tol, rates, nfev, err)
                    break
            if chosen is None:
                continue
            tol, rates, nfev, err = chosen
            sf, nl = sweep_stats(rates)
            key = f"scipy {method}, {name}"
            rows.append({"method": key, "tol": tol, "nfev": nfev, "error_ppm_fs": err, "sf_vs_steady_ppm": sf,
                         "nl_minus_steady_ppm": nl})
            contenders.append((key, lambda run=run, tol=tol: run(tol)[0]))

    default_tier = accuracy[label][0]
    one = jax.jit(lambda r: settle(gyro, Stimulus(rate=r), default_tier).rate)
    one_c, _ = _compile(one, 1.0)
    sweep = _sweep_program(default_tier)
    rates_j = [float(r) * DEG for r in dps]
    rates_v = jnp.asarray(dps * DEG)
    out_v = np.asarray(jax.block_until_ready(sweep(gyro, rates_v))[0])
    out_l = np.array([float(one_c(r)) for r in rates_j])
    for name, out, fn in (
        ("gyrojax default full tier, vmapped (jit(vmap))", out_v,
         lambda: _best_of(lambda: jax.block_until_ready(sweep(gyro, rates_v)), 2, budget_s=0.0)[0]),
        ("gyrojax default full tier, loop over one compiled point", out_l,
         lambda: _best_of(lambda: [float(jax.block_until_ready(one_c(r))) for r in rates_j], 2, budget_s=0.0)[0])):
        sf, nl = sweep_stats(out)
        rows.append({"method": name, "tol": float(default_tier.rtol), "nfev": None, "error_ppm_fs": err_of(out),
                     "sf_vs_steady_ppm": sf, "nl_minus_steady_ppm": nl})
        contenders.append((name, fn))
    best = _interleaved(contenders, args.rounds)
    for r in rows:
        r["sweep_s"] = best[r["method"]]
        r["per_point_ms"] = r["sweep_s"] / npts * 1e3
    best_g = min((r for r in rows if r["method"].startswith("gyrojax")), key=lambda r: r["sweep_s"])
    best_s = min((r for r in rows if r["method"].startswith("scipy")), key=lambda r: r["sweep_s"])
    _print()
    _print(_table([[r["method"], f"{r['tol']:.1e}", f"{r['sweep_s']:.3f}", f"{r['per_point_ms']:.2f}",
                    "" if r["nfev"] is None else r["nfev"], f"{r['error_ppm_fs']:.5f}", f"{r['sf_vs_steady_ppm']:+.4f}",
                    f"{r['nl_minus_steady_ppm']:+.4f}", f"{r['sweep_s'] / best_g['sweep_s']:.1f}"] for r in rows],
                  ["method", "rtol=atol", "sweep s", "ms/point", "nfev", "E ppm FS", "SF vs steady ppm",
                   "NL - NL steady ppm", "time / best gyrojax"]))
    ratio = best_s["sweep_s"] / best_g["sweep_s"]
    _print(f"(times: best of {args.rounds} interleaved rounds)")
    _print(f"\nsweep: best gyrojax ({best_g['method']}) {best_g['per_point_ms']:.1f} ms/point, best scipy "
           f"({best_s['method']}) {best_s['per_point_ms']:.1f} ms/point: {ratio:.1f}x "
           f"(target >= {TARGET_FULL_VS_SCIPY:g}x: {'meets' if ratio >= TARGET_FULL_VS_SCIPY else 'MISSES'})")
    return {"E_ppm_fs": e_target, "rows": rows, "ratio": ratio, "vectorised_rhs_us_all_points": t_b / 200 * 1e6}


# -------------------------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[1] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="settle 0.02 s everywhere, fewer settings and repeats")
    parser.add_argument("--json", metavar="PATH", help="also write the results to this JSON file")
    parser.add_argument("--repeats", type=int, default=None, help="repeats of each gyrojax single-point timing")
    parser.add_argument("--skip-part3", action="store_true", help="skip the scipy sweep (part 3)")
    parser.add_argument("--tiers-only", action="store_true",
                        help="part 1 only, with the reference, steady, averaged and the two DOP853 settings")
    args = parser.parse_args(argv)
    args.average_periods = 40
    args.settle = 0.02 if args.quick else 0.12
    args.repeats = args.repeats or (3 if args.quick else 5)
    args.sweep_repeats = 1 if args.quick else 3
    args.rounds = 1 if args.quick else 3
    args.scipy_budget = 20.0 if args.quick else 90.0

    versions, machine = _versions(), _machine()
    _print("gyrojax tier benchmark  " + datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    _print("versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    _print(f"machine: {machine['platform']}, {machine['processor']}, {machine['cpu_count']} CPUs, "
           f"JAX backend {machine['jax_backend']}, load average at start {machine['load_average']}")
    _print(f"mode: {'quick' if args.quick else 'full'}")

    gyro = paper_qmg()
    devices = {"ideal": gyro, "inl": add_effect(gyro, DacInl.typical(1.0))}
    payload = {"mode": "quick" if args.quick else "full", "versions": versions, "machine": machine,
               "device": "paper_qmg()"}
    t_start = time.perf_counter()
    p1 = part1(devices, args)
    payload["tiers_sweep"] = p1
    if args.tiers_only:
        payload["wall_s"] = time.perf_counter() - t_start
        if args.json:
            _write_json(args.json, payload)
        return

    def full(**kw):
        return FullWaveform(settle_time=args.settle, average_periods=args.average_periods, **kw)

    errors = {name: row["numerical_error_ppm_fs"] for name, row in p1["tiers"].items()}
    accuracy = {"reference": (full(solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12), 0.0),
                DEFAULT: (full(), errors[DEFAULT])}
    if FAST in errors:
        accuracy[FAST] = (full(rtol=1e-6, atol=1e-6), errors[FAST])
    p2 = part2(gyro, args, accuracy)
    payload["full_vs_scipy_one_point"] = p2
    if not args.skip_part3:
        payload["full_vs_scipy_sweep"] = part3(gyro, args, p1, p2, accuracy)
    payload["wall_s"] = time.perf_counter() - t_start
    machine["load_average_at_end"] = os.getloadavg()
    _print(f"\ntotal wall time {payload['wall_s']:.1f} s; load average at end {machine['load_average_at_end']}")
    if args.json:
        _write_json(args.json, payload)
        _print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
