#!/usr/bin/env python
"""Benchmark of gyrojax's simulation tiers (a script, not a test).

    python benchmarks/bench_tiers.py [--quick] [--json PATH] [--repeats N]

Part 1 - the full-waveform tier (diffrax Tsit5 + PIDController) against scipy.integrate.solve_ivp (RK45,
DOP853) on the *same* closed-loop carrier-level ODE of `paper_qmg()`: the same scaled state (WaveState /
wave_scales plus the three output integrals / output_scales, flattened), the same rtol/atol, first step,
span and averaging window. scipy gets the right-hand side two ways: a NumPy mirror of
`gyrojax._simulate._model.full_field` for the ideal device (linear DAC, no INL/DNL, no quantiser),
checked against the JAX field at random states before anything is timed, and the jitted JAX field itself
(`jax.jit` of the flattened field, called once per evaluation from Python).

Part 2 - the steady (optimistix Newton) and averaged (slow-flow diffrax) tiers against the full tier on a
22-point rate sweep (+/-0.1 ... +/-200 deg/s), each tier `jax.jit(jax.vmap(...))`ed; per-point time is the
batch time / 22 after compilation. Also FullWaveform at looser rtol/atol (1e-8, 1e-9).

Timings are best-of-N wall clock after compilation (compile time reported on its own), with
`jax.block_until_ready`. Accuracy is in ppm of the rate output (LSB): relative to the full-scale output
(the full tier at +200 deg/s) and, separately, relative to each point's own output.
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
from scipy.integrate import solve_ivp  # noqa: E402

from gyrojax._io import atomic_write_json  # noqa: E402
from gyrojax._physics.thermal import ConstantTemperature  # noqa: E402
from gyrojax._presets import paper_qmg  # noqa: E402
from gyrojax._simulate._model import (  # noqa: E402
    Outputs,
    full_field,
    operating_point,
    output_scales,
    wave_from_slow,
    wave_scales,
)
from gyrojax._simulate.tiers import Averaged, FullWaveform, Steady, settle  # noqa: E402
from gyrojax._solution import RESULTS  # noqa: E402
from gyrojax._stimulus import Stimulus  # noqa: E402
from gyrojax._units import DEG  # noqa: E402


SWEEP_DPS = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0)
TARGET_FULL_VS_SCIPY = 20.0
TARGET_STEADY_VS_FULL = 1000.0
TARGET_STEADY_PPM = 1.0


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
        if np.asarray(dac.inl).size != 0 or float(dac.dnl_amplitude) != 0.0 or dac.quantize:
            raise ValueError("NumpyFullField mirrors the ideal (linear) DAC only.")
        if not isinstance(g.temperature, ConstantTemperature):
            raise ValueError("NumpyFullField mirrors a constant temperature only.")
        f = float
        r = g.resonator
        wx, wy, qx, qy = (f(v) for v in r.at_temperature(g.temperature(0.0)))
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
        self.spring = 2.0 * self.fb_a * self.vdc**2 * self.rho / self.d0
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
        f_fb = 0.5 * self.fb_a * (plus * (self.vdc + vp) ** 2 - minus * (self.vdc - vm) ** 2) - self.spring * y
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
    """Max relative difference of the NumPy mirror from the JAX field at random scaled states."""
    rng = np.random.default_rng(seed)
    worst_norm = 0.0
    worst_comp = 0.0
    for k in range(samples):
        z = problem.y0 + (0.0 if k == 0 else 0.3) * rng.standard_normal(problem.n)
        z[np.asarray(problem.index[0].phase, dtype=int)] = rng.uniform(0, 2 * math.pi) if k else 0.0
        t = 0.0 if k == 0 else rng.uniform(0.0, problem.t1)
        ref = np.asarray(problem.jax_rhs(t, z))
        got = np_field(t, z)
        diff = np.abs(got - ref)
        worst_norm = max(worst_norm, float(np.max(diff) / np.max(np.abs(ref))))
        # Componentwise, against each component's own size (floored at 1e-9 of the largest).
        floor = 1e-9 * np.max(np.abs(ref))
        worst_comp = max(worst_comp, float(np.max(diff / np.maximum(np.abs(ref), floor))))
    return worst_norm, worst_comp


# -------------------------------------------------------------------------------------------- part 1


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


def part1(gyro, args):
    rate = 200.0 * DEG
    rtol = atol = 1e-10
    settle_time = args.p1_settle
    problem = FlatProblem(gyro, rate, settle_time, args.average_periods)
    dt0 = FullWaveform().dt0
    _print(f"\n== Part 1: full tier vs scipy.solve_ivp, paper_qmg at 200 deg/s, rtol = atol = {rtol:g}, "
           f"span 0 .. {settle_time:g} s settle + {args.average_periods} carrier periods = {problem.t1:.6f} s, "
           f"{problem.n} scaled states, first step {dt0:g} s, best of {args.repeats} (diffrax) / "
           f"{args.scipy_repeats} (scipy) ==")
    if settle_time != 0.12:
        _print(f"(quick mode: the span is shortened to {settle_time:g} s + {args.average_periods} periods for "
               "diffrax and scipy alike)")

    # The NumPy mirror, checked before anything is timed.
    np_field = NumpyFullField(problem)
    c_jax_rhs, _ = _compile(problem.jax_rhs, 0.0, problem.y0)
    norm_err, comp_err = check_numpy_field(problem, np_field)
    ok = norm_err <= 1e-12 and comp_err <= 1e-12
    _print(f"NumPy RHS vs JAX full_field at 8 random states: max |diff| / max |f| = {norm_err:.2e}, "
           f"componentwise max rel = {comp_err:.2e}  [{'OK' if ok else 'FAILED'} at 1e-12]")
    if not ok:
        raise SystemExit("The NumPy mirror of full_field disagrees with the JAX field; not timing it.")

    # Per-evaluation cost of each RHS.
    t_np_eval, _ = _best_of(lambda: [np_field(0.01, problem.y0) for _ in range(1000)], 3)
    t_np_eval /= 1000
    jax_rhs_call = lambda t, y: np.asarray(c_jax_rhs(t, y))  # noqa: E731
    t_jax_eval, _ = _best_of(lambda: [jax_rhs_call(0.01, problem.y0) for _ in range(1000)], 3)
    t_jax_eval /= 1000
    t_xla_eval = _field_cost_in_xla(problem)
    _print(f"one RHS evaluation: NumPy from Python {t_np_eval * 1e6:.1f} us, jitted JAX from Python "
           f"{t_jax_eval * 1e6:.1f} us, JAX field inside XLA (no dispatch) {t_xla_eval * 1e6:.2f} us")

    # diffrax: the library's full tier exactly as `settle` runs it, with its default Tsit5 and two others.
    rows = []
    rate_ref = None
    for label, solver in (("Tsit5 (default)", diffrax.Tsit5()), ("Dopri5", diffrax.Dopri5()),
                          ("Dopri8", diffrax.Dopri8())):
        tier = FullWaveform(settle_time=settle_time, average_periods=args.average_periods, rtol=rtol, atol=atol,
                            solver=solver)
        fn = jax.jit(lambda r, tier=tier: settle(gyro, Stimulus(rate=r), tier))
        compiled, t_compile = _compile(fn, rate)
        t_run, sol = _best_of(lambda: jax.block_until_ready(compiled(rate)), args.repeats)
        if sol.result != RESULTS.successful:
            raise SystemExit(f"full tier ({label}) failed: {sol.result}")
        r_out = float(sol.rate)
        rate_ref = r_out if rate_ref is None else rate_ref
        steps = int(sol.num_steps)
        rows.append({"method": f"diffrax {label}", "rhs": "JAX (in XLA)", "time_s": t_run, "compile_s": t_compile,
                     "steps": steps, "nfev": None, "us_per_step": t_run / steps * 1e6, "rate_lsb": r_out})
        _print(f"full tier, diffrax {label:15s}: compile {t_compile:5.2f} s, run {t_run:8.3f} s, {steps} steps "
               f"({t_run / steps * 1e6:.1f} us/step), rate {r_out:.6f} LSB")
    t_full = rows[0]["time_s"]

    for method in ("RK45", "DOP853"):
        for label, rhs in (("NumPy", np_field), ("jitted JAX", jax_rhs_call)):
            def run(rhs=rhs, method=method):
                return solve_ivp(rhs, (0.0, problem.t1), problem.y0, method=method,
                                 t_eval=[problem.settle_time, problem.t1], rtol=rtol, atol=atol, first_step=dt0)
            t_run, res = _best_of(run, args.scipy_repeats, budget_s=0.0)
            if res.status != 0:
                raise SystemExit(f"solve_ivp {method} failed: {res.message}")
            r_out = float(problem.rate_from(res.y[:, 0], res.y[:, 1]))
            stages = 6 if method == "RK45" else 12
            steps = (res.nfev - 1) // stages  # scipy does not report steps; nfev = 1 + stages x steps (+ a few)
            rows.append({"method": f"scipy {method}", "rhs": label, "time_s": t_run, "compile_s": None,
                         "steps": steps, "nfev": int(res.nfev), "us_per_step": t_run / steps * 1e6, "rate_lsb": r_out})
            _print(f"scipy {method:6s} + {label:10s}: {t_run:8.3f} s, nfev {res.nfev} (~{steps} steps), "
                   f"rate {r_out:.6f} LSB")
    for r in rows:
        r["ppm_vs_full"] = (r["rate_lsb"] - rate_ref) / abs(rate_ref) * 1e6
        r["time_over_full"] = r["time_s"] / t_full

    scipy_rows = [r for r in rows if r["method"].startswith("scipy")]
    best_scipy = min(scipy_rows, key=lambda r: r["time_s"])
    best_diffrax = min((r for r in rows if r["method"].startswith("diffrax")), key=lambda r: r["time_s"])
    ratio = best_scipy["time_s"] / t_full
    ratio_best = best_scipy["time_s"] / best_diffrax["time_s"]
    rk45 = min((r for r in scipy_rows if r["method"] == "scipy RK45"), key=lambda r: r["time_s"])
    dopri5 = next(r for r in rows if r["method"] == "diffrax Dopri5")
    _print()
    _print(_table(
        [[r["method"], r["rhs"], f"{r['time_s']:.3f}", "" if r["compile_s"] is None else f"{r['compile_s']:.2f}",
          ("" if r["nfev"] is None else "~") + str(r["steps"]), "" if r["nfev"] is None else r["nfev"],
          f"{r['us_per_step']:.1f}", f"{r['rate_lsb']:.4f}", f"{r['ppm_vs_full']:+.4f}",
          f"{r['time_over_full']:.2f}"] for r in rows],
        ["method", "RHS", "time s", "compile s", "steps", "nfev", "us/step", "rate LSB", "ppm vs full",
         "time / full"]))
    verdict = "meets" if ratio >= TARGET_FULL_VS_SCIPY else "MISSES"
    _print(f"\nfull tier (default Tsit5) is {ratio:.2f}x faster than the best scipy method "
           f"({best_scipy['method']} + {best_scipy['rhs']}) (target >= {TARGET_FULL_VS_SCIPY:g}x: {verdict})")
    _print(f"best diffrax solver ({best_diffrax['method']}) is {ratio_best:.2f}x faster than the best scipy method")
    _print(f"same Dormand-Prince 5(4) tableau: diffrax Dopri5 is {rk45['time_s'] / dopri5['time_s']:.1f}x faster "
           f"than scipy RK45 + {rk45['rhs']}")
    return {
        "rate_dps": 200.0,
        "rtol": rtol,
        "atol": atol,
        "dt0_s": dt0,
        "settle_time_s": settle_time,
        "average_periods": args.average_periods,
        "t1_s": problem.t1,
        "num_states": problem.n,
        "numpy_rhs_check": {"max_abs_diff_over_max_abs": norm_err, "componentwise_max_rel": comp_err,
                            "passed_1e-12": ok},
        "rhs_eval_us": {"numpy_from_python": t_np_eval * 1e6, "jitted_jax_from_python": t_jax_eval * 1e6,
                        "jax_inside_xla": t_xla_eval * 1e6},
        "rows": rows,
        "speedup_full_vs_best_scipy": ratio,
        "speedup_best_diffrax_vs_best_scipy": ratio_best,
        "speedup_dopri5_vs_rk45": rk45["time_s"] / dopri5["time_s"],
        "target_speedup": TARGET_FULL_VS_SCIPY,
        "meets_target": ratio >= TARGET_FULL_VS_SCIPY,
    }


# -------------------------------------------------------------------------------------------- part 2


def _sweep_fn(gyro, tier):
    def one(r):
        s = settle(gyro, Stimulus(rate=r), tier)
        return s.rate, s.result == RESULTS.successful, s.num_steps

    return jax.jit(jax.vmap(one))


def part2(gyro, args):
    dps = np.array(sorted([-v for v in SWEEP_DPS] + list(SWEEP_DPS)))
    rates = jnp.asarray(dps * DEG)
    npts = dps.size
    settle_time = args.p2_settle
    periods = args.average_periods

    def full(**kw):
        return FullWaveform(settle_time=settle_time, average_periods=periods, **kw)

    # (name, tier, time an unbatched single point too)
    tiers = [
        ("full Tsit5 rtol 1e-10", full(), True),
        ("steady", Steady(), True),
        ("averaged", Averaged(settle_time=settle_time), True),
        ("full Tsit5 rtol 1e-9", full(rtol=1e-9, atol=1e-9), args.single_all),
        ("full Tsit5 rtol 1e-8", full(rtol=1e-8, atol=1e-8), args.single_all),
        ("full Dopri8 rtol 1e-10", full(solver=diffrax.Dopri8()), args.single_all),
    ]
    _print(f"\n== Part 2: tiers on a {npts}-point rate sweep (+/-{', '.join(f'{v:g}' for v in SWEEP_DPS)} deg/s) "
           f"on paper_qmg, jit(vmap(settle)), settle {settle_time:g} s (full: + {periods} carrier periods), "
           f"best of {args.sweep_repeats} (more for fast tiers) ==")
    results = {}
    for name, tier, single in tiers:
        fn = _sweep_fn(gyro, tier)
        compiled, t_compile = _compile(fn, rates)
        t_batch, (out, ok, steps) = _best_of(lambda: jax.block_until_ready(compiled(rates)), args.sweep_repeats)
        out = np.asarray(out)
        if not bool(np.all(np.asarray(ok))):
            raise SystemExit(f"{name}: some sweep points did not settle: {np.asarray(ok)}")
        res = {"out": out, "t_batch": t_batch, "t_compile": t_compile, "steps_max": int(np.max(np.asarray(steps))),
               "t_single": None}
        msg = (f"{name:22s}: compile {t_compile:5.2f} s, batch {t_batch:9.4f} s, "
               f"per point {t_batch / npts * 1e3:9.3f} ms, max steps {res['steps_max']}")
        if single:
            fn1 = jax.jit(lambda r, tier=tier: settle(gyro, Stimulus(rate=r), tier).rate)
            c1, _ = _compile(fn1, 200.0 * DEG)
            res["t_single"], _ = _best_of(lambda: jax.block_until_ready(c1(200.0 * DEG)), args.repeats)
            msg += f"; unbatched single point {res['t_single'] * 1e3:.3f} ms"
        results[name] = res
        _print(msg)

    ref = results["full Tsit5 rtol 1e-10"]
    fs = abs(float(ref["out"][dps == 200.0][0]))
    rows = []
    out_json = {"rates_dps": dps.tolist(), "settle_time_s": settle_time, "average_periods": periods,
                "reference": "full Tsit5 rtol 1e-10", "full_scale_lsb": fs, "tiers": {}}
    for name, _, _ in tiers:
        r = results[name]
        diff = r["out"] - ref["out"]
        ppm_fs = float(np.max(np.abs(diff)) / fs * 1e6)
        ppm_pt = float(np.max(np.abs(diff / ref["out"])) * 1e6)
        per_pt = r["t_batch"] / npts
        speedup = ref["t_batch"] / r["t_batch"]
        speedup1 = None if r["t_single"] is None else ref["t_single"] / r["t_single"]
        rows.append([name, f"{r['t_compile']:.2f}", f"{per_pt * 1e3:.4f}", f"{speedup:.1f}x",
                     "" if r["t_single"] is None else f"{r['t_single'] * 1e3:.4f}",
                     "" if speedup1 is None else f"{speedup1:.1f}x",
                     f"{ppm_fs:.4f}", f"{ppm_pt:.4f}", f"{np.max(np.abs(diff)):.4f}", r["steps_max"]])
        out_json["tiers"][name] = {
            "compile_s": r["t_compile"], "batch_s": r["t_batch"], "per_point_s": per_pt,
            "speedup_vs_full_per_point": speedup, "single_point_s": r["t_single"],
            "speedup_vs_full_single_point": speedup1, "max_abs_diff_lsb": float(np.max(np.abs(diff))),
            "max_ppm_of_full_scale": ppm_fs, "max_ppm_of_point": ppm_pt, "max_steps": r["steps_max"],
            "rate_lsb": r["out"].tolist(),
        }
    _print()
    _print(_table(rows, ["tier", "compile s", "ms/point (vmap)", "x full", "ms single", "x full",
                         "max ppm FS", "max ppm point", "max |diff| LSB", "max steps"]))
    _print(f"(ms/point (vmap): batch time of jit(vmap) over the {npts} points / {npts}; ms single: one unbatched "
           "jitted point at +200 deg/s; x full: full Tsit5 rtol 1e-10 time / this tier's time, same way of "
           "timing; ppm FS: max over the sweep of |out - out_full| / |out_full(+200 deg/s)|; ppm point: max of "
           "|out - out_full| / |out_full| per point; reference: full Tsit5 at rtol = atol = 1e-10)")
    st = out_json["tiers"]["steady"]
    ok_speed = st["speedup_vs_full_per_point"] >= TARGET_STEADY_VS_FULL
    ok_ppm = st["max_ppm_of_full_scale"] <= TARGET_STEADY_PPM
    _print(f"\nsteady tier: {st['speedup_vs_full_per_point']:.0f}x faster than the full tier per settled point "
           f"in the vmapped sweep (target >= {TARGET_STEADY_VS_FULL:g}x: {'meets' if ok_speed else 'MISSES'}), "
           f"{st['speedup_vs_full_single_point']:.0f}x unbatched; {st['max_ppm_of_full_scale']:.3f} ppm of full "
           f"scale (target <= {TARGET_STEADY_PPM:g} ppm: {'meets' if ok_ppm else 'MISSES'})")
    out_json["steady_meets_speed_target"] = ok_speed
    out_json["steady_meets_ppm_target"] = ok_ppm
    return out_json


# -------------------------------------------------------------------------------------------- main


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[1] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="short spans and single repeats (< 2 min)")
    parser.add_argument("--json", metavar="PATH", help="also write the results to this JSON file")
    parser.add_argument("--repeats", type=int, default=None, help="repeats of each diffrax timing")
    parser.add_argument("--skip-part1", action="store_true")
    parser.add_argument("--skip-part2", action="store_true")
    args = parser.parse_args(argv)
    args.average_periods = 40
    if args.quick:
        args.p1_settle = 0.02  # part 1: shorter span, for diffrax and scipy alike
        args.p2_settle = 0.12
        args.repeats = args.repeats or 3
        args.scipy_repeats = 1
        args.sweep_repeats = 1
        args.single_all = False
    else:
        args.p1_settle = 0.12
        args.p2_settle = 0.12
        args.repeats = args.repeats or 5
        args.scipy_repeats = 2
        args.sweep_repeats = 3
        args.single_all = True

    versions, machine = _versions(), _machine()
    _print("gyrojax tier benchmark  " + datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    _print("versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    _print(f"machine: {machine['platform']}, {machine['processor']}, {machine['cpu_count']} CPUs, "
           f"JAX backend {machine['jax_backend']}")
    _print(f"mode: {'quick' if args.quick else 'full'}")

    gyro = paper_qmg()
    payload = {"mode": "quick" if args.quick else "full", "versions": versions, "machine": machine,
               "device": "paper_qmg()"}
    t_start = time.perf_counter()
    if not args.skip_part1:
        payload["full_vs_scipy"] = part1(gyro, args)
    if not args.skip_part2:
        payload["tiers_sweep"] = part2(gyro, args)
    payload["wall_s"] = time.perf_counter() - t_start
    _print(f"\ntotal wall time {payload['wall_s']:.1f} s")
    if args.json:
        _write_json(args.json, payload)
        _print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
