r"""The closed-loop gyroscope as ODEs: carrier-level (full waveform) and slow-flow (averaged) vector fields.

Phasor convention: a carrier-frequency signal is x(t) = Re{X e^{j theta(t)}}, theta' = w the PLL's
frequency. Substituting into seed 000 Eq. (1) and dropping X'' (first-order averaging) gives

    X' = -(g_x - j d_x) X + (Ag Om - c/2 + j kap/(2w)) Y + F_x / (2 j w m)
    Y' = -(g_y - j d_y) Y - (Ag Om + c/2 - j kap/(2w)) X + F_y / (2 j w m)

with g_i = w_i / (2 Q_i), d_i = (w_i^2 - w^2) / (2 w). With X, Y constant the substitution is exact, so
the steady states of the two tiers coincide except for what averaging drops: the harmonics of nonlinear
forces and the carrier ripple of the demodulators. `tests/test_tiers.py` proves the signs and the
agreement against the full waveform.

Nonlinear forces enter the slow flow through their fundamental, taken by quadrature over
`gyro.phase_points` carrier phases (the describing function), with the sense mass's DC deflection solved
by a short fixed-point iteration (the DC force of push-pull mismatch shifts it).

States are stored scaled to O(1) (see `state_scales`) so that scalar ODE tolerances mean the same for
every state.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._gyroscope import Gyroscope, closed_loop_parts, open_loop_readout
from .._physics.stimulus import Stimulus
from .._terms import AbstractRateTerm


def _c(v):
    return jax.lax.complex(v[..., 0], v[..., 1])


def _cx(x):
    """A real array as complex (gyrojax runs with strict dtype promotion)."""
    return jnp.asarray(x).astype(jnp.complex128)


def _cj(re, im):
    return jax.lax.complex(jnp.asarray(re, dtype=float), jnp.asarray(im, dtype=float))


def expj(phase):
    return jax.lax.complex(jnp.cos(phase), jnp.sin(phase))


def _r(z):
    return jnp.stack([jnp.real(z), jnp.imag(z)], axis=-1)


class Loops(eqx.Module):
    """Controller states common to both tiers."""

    pll: jax.Array  # PLL integrator, rad/s
    agc: jax.Array  # AGC integrator, V
    drive_lpf: jax.Array  # (order, re/im), drive demodulator LPF stages, LSB
    sense_lpf: jax.Array  # (order, re/im), sense demodulator LPF stages, LSB
    rebalance: jax.Array  # (re/im), rebalance integrator, word LSB


class SlowState(eqx.Module):
    """Averaged tier: drive and sense envelopes plus the loop states."""

    drive: jax.Array  # X (re/im), m
    sense: jax.Array  # Y (re/im), m
    loops: Loops


class WaveState(eqx.Module):
    """Full-waveform tier: displacements and velocities, carrier phase, loop states."""

    drive: jax.Array  # (x, x'), m and m/s
    sense: jax.Array  # (y, y')
    phase: jax.Array  # PLL carrier phase, rad
    loops: Loops


class Outputs(eqx.Module):
    """Instantaneous readings, and (as an ODE state) their running integrals."""

    rate: jax.Array  # rate output, LSB
    quadrature: jax.Array  # quadrature word (closed loop) or quadrature channel (open loop), LSB
    frequency: jax.Array  # PLL frequency, rad/s


class Controls(eqx.Module):
    omega: jax.Array
    drive_voltage: jax.Array
    word: jax.Array  # complex rebalance word, LSB (0 in open loop)
    outputs: Outputs
    d_pll: jax.Array
    d_agc: jax.Array
    d_rebalance: jax.Array


def controls(gyro: Gyroscope, loops: Loops) -> Controls:
    dl = gyro.drive_loop
    e_d = _c(loops.drive_lpf[-1]) * expj(-dl.reference_phase)
    omega, v_d, d_pll, d_agc = dl.control(e_d, loops.pll, loops.agc)
    if gyro.closed_loop:
        rl = closed_loop_parts(gyro, "controls").rebalance_loop
        e_s = _c(loops.sense_lpf[-1]) * expj(-rl.reference_phase)
        word, dz = rl.control(e_s, _c(loops.rebalance))
        rate, quad = jnp.real(word), jnp.imag(word)
        d_reb = _r(dz)
    else:
        ro = open_loop_readout(gyro, "controls")
        e_s = _c(loops.sense_lpf[-1]) * expj(-(ro.reference_phase + ro.phase_error))
        word = jnp.zeros((), dtype=complex)
        rate, quad = jnp.real(e_s), jnp.imag(e_s)
        d_reb = -loops.rebalance  # unused state: relax it to zero so the steady Jacobian stays regular
    return Controls(omega, v_d, word, Outputs(rate, quad, omega), d_pll, d_agc, d_reb)


def _lpf(cutoff, stages, signal):
    """Cascaded first-order low-pass stages on a complex signal; `stages` is (order, re/im)."""
    z = _c(stages)
    inputs = jnp.concatenate([jnp.reshape(signal, (1,)), z[:-1]])
    return _r(_cx(cutoff) * (inputs - z))


def _sense_demod(gyro):
    """The loop or readout that owns the sense demodulator."""
    if gyro.closed_loop:
        return closed_loop_parts(gyro, "the sense demodulator").rebalance_loop
    return open_loop_readout(gyro, "the sense demodulator")


def _loop_derivatives(gyro, loops, ctl, drive_demod, sense_demod):
    return Loops(
        pll=ctl.d_pll,
        agc=ctl.d_agc,
        drive_lpf=_lpf(gyro.drive_loop.demod_cutoff, loops.drive_lpf, drive_demod),
        sense_lpf=_lpf(_sense_demod(gyro).demod_cutoff, loops.sense_lpf, sense_demod),
        rebalance=ctl.d_rebalance,
    )


def dac_voltage(gyro, word, carrier_phase, omega):
    """Instantaneous DAC output (after the hold's fundamental gain) for the carrier phase(s) given."""
    dac = gyro.excitation.dac
    hold_gain, hold_delay = dac.hold(omega)
    sample = jnp.real(1j * word * expj(carrier_phase + gyro.rebalance_loop.carrier_phase - hold_delay))
    return dac(sample) * hold_gain


def _sense_force(gyro, y, word, carrier_phase, omega, temperature):
    """Sense-axis force (N) other than the linear mechanics: feedback combs (biased at the die
    `temperature`, deg C) and cubic stiffness."""
    r = gyro.resonator
    force = -r.mass * r.duffing_y * y**3
    if gyro.closed_loop:
        v_plus, v_minus = gyro.feedback_voltages(dac_voltage(gyro, word, carrier_phase, omega))
        force = force + gyro.feedback_electrode.force(y, v_plus, v_minus, temperature - r.t_ref)
    return force


def _rate_equivalent(gyro, temperature, time, rate):
    """Om_eq (rad/s) of the device's rate terms: the sense feels the Coriolis force of rate + Om_eq."""
    total = jnp.zeros(())
    for term in gyro.terms_of(AbstractRateTerm):
        total = total + jnp.asarray(term.rate(gyro, temperature, time, rate), dtype=float)
    return total


def phase_grid(n):
    return 2.0 * jnp.pi * jnp.arange(n, dtype=float) / n


def sense_force_fundamental(gyro, sense_phasor, word, omega, omega_y, temperature=None):
    """Fundamental phasor (N) and DC deflection (m) of the sense force, by quadrature over the phase, at
    the die `temperature` (deg C; default the reference temperature)."""
    temperature = gyro.resonator.t_ref if temperature is None else temperature
    theta = phase_grid(gyro.phase_points)
    wave = jnp.real(sense_phasor * expj(theta))
    stiffness = gyro.resonator.mass * omega_y**2

    def deflect(y0, _):
        return jnp.mean(_sense_force(gyro, y0 + wave, word, theta, omega, temperature)) / stiffness, None

    y0, _ = jax.lax.scan(deflect, jnp.zeros(()), None, length=3)
    force = _sense_force(gyro, y0 + wave, word, theta, omega, temperature)
    return 2.0 * jnp.mean(_cx(force) * expj(-theta)), y0


# A jit of its own: the steady tier's root finds, their implicit derivatives and the linearisations call it
# many times within one outer trace; JAX traces a jitted body once per signature and transforms its jaxpr after
# that (measured: the planner's Jacobians of the ten default experiments traced in 24.6 s instead of 31.1 s).
@eqx.filter_jit
def averaged_field(t, state: SlowState, gyro: Gyroscope, stim: Stimulus):
    """Slow-flow vector field; returns `(dstate, outputs)`."""
    temp = gyro.temperature(stim.time + t)
    gyro = gyro.at_die_temperature(temp)
    r = gyro.resonator
    wx, wy, qx, qy = r.at_temperature(temp)
    ctl = controls(gyro, state.loops)
    w = ctl.omega
    m = r.mass
    X, Y = _c(state.drive), _c(state.sense)
    om = stim.rate_at(t)
    om_sense = om + _rate_equivalent(gyro, temp, stim.time + t, om)
    gx, gy = wx / (2 * qx), wy / (2 * qy)
    dx, dy = (wx**2 - w**2) / (2 * w), (wy**2 - w**2) / (2 * w)
    c, kap, ag = r.damping_coupling, r.stiffness_coupling, r.angular_gain

    f_x = (_cj(0.0, gyro.drive_electrode.force(ctl.drive_voltage))
           - _cx(0.75 * m * r.duffing_x * jnp.abs(X) ** 2) * X)
    f_y, _ = sense_force_fundamental(gyro, Y, ctl.word, w, wy, temp)
    # The virtual force's phasor -j K V_ac V_fc e^{j vcf_phase}: -j (in phase with velocity) at phase 0.
    vcf = gyro.vcf_electrode.force_per_volt2 * stim.vcf_at(t)
    f_y = f_y - _cj(-vcf * jnp.sin(stim.vcf_phase), vcf * jnp.cos(stim.vcf_phase))

    force_gain = _cj(0.0, 2 * w * m)
    dX = -_cj(gx, -dx) * X + _cj(ag * om - c / 2, kap / (2 * w)) * Y + f_x / force_gain
    dY = -_cj(gy, -dy) * Y - _cj(ag * om_sense + c / 2, -kap / (2 * w)) * X + f_y / force_gain

    drive_demod = gyro.drive_frontend.phasor_gain(w) * X
    sense_demod = gyro.sense_frontend.phasor_gain(w) * Y
    dloops = _loop_derivatives(gyro, state.loops, ctl, drive_demod, sense_demod)
    return SlowState(_r(dX), _r(dY), dloops), ctl.outputs


def full_field(t, state: WaveState, gyro: Gyroscope, stim: Stimulus):
    """Carrier-level vector field; returns `(dstate, outputs)`."""
    temp = gyro.temperature(stim.time + t)
    gyro = gyro.at_die_temperature(temp)
    r = gyro.resonator
    wx, wy, qx, qy = r.at_temperature(temp)
    ctl = controls(gyro, state.loops)
    m = r.mass
    x, vx = state.drive[0], state.drive[1]
    y, vy = state.sense[0], state.sense[1]
    theta = state.phase
    om = stim.rate_at(t)
    om_sense = om + _rate_equivalent(gyro, temp, stim.time + t, om)
    c, kap, ag = r.damping_coupling, r.stiffness_coupling, r.angular_gain

    f_x = gyro.drive_electrode.force(ctl.drive_voltage) * (-jnp.sin(theta)) - m * r.duffing_x * x**3
    f_y = (_sense_force(gyro, y, ctl.word, theta, ctl.omega, temp)
           + gyro.vcf_electrode.force_per_volt2 * stim.vcf_at(t) * jnp.sin(theta + stim.vcf_phase))
    ax = f_x / m - (wx / qx) * vx - wx**2 * x - c * vy - kap * y + 2 * ag * om * vy
    ay = f_y / m - (wy / qy) * vy - wy**2 * y - c * vx - kap * x - 2 * ag * om_sense * vx

    # Demodulation: 2 v cos(theta) and -2 v sin(theta) are the phasor's re/im parts plus 2w ripple.
    carrier = 2.0 * expj(-theta)
    drive_demod = _cx(gyro.drive_frontend.sample(x, vx)) * carrier
    sense_demod = _cx(gyro.sense_frontend.sample(y, vy)) * carrier
    dloops = _loop_derivatives(gyro, state.loops, ctl, drive_demod, sense_demod)
    return (WaveState(jnp.stack([vx, ax]), jnp.stack([vy, ay]), ctl.omega, dloops), ctl.outputs)


def operating_point(gyro: Gyroscope, stim: Stimulus):
    """The operating point from physics alone (no tier solution): drive locked at its resonance with the
    set-point amplitude, sense held at rest, words at their linear values.

    Closed forms for what would otherwise ring for seconds in a high-Q open-loop sense are included: the
    amplitude sag of a leaky AGC integrator, the drive resonance moved by its cubic stiffness, the sense
    split moved by the sense's cubic stiffness, and the feedback bias at the die temperature. All of them
    are exactly the linear point when those parameters are zero.

    Returns a `SlowState`. It is the starting point of every tier; the nonlinear and loop effects are
    then settled by each tier on its own.
    """
    temp = gyro.temperature(stim.time)
    gyro = gyro.at_die_temperature(temp)
    r = gyro.resonator
    dl = gyro.drive_loop
    wx, wy, qx, qy = r.at_temperature(temp)
    w = wx
    m = r.mass
    a = gyro.drive_amplitude(w)
    gx, gy = wx / (2 * qx), wy / (2 * qy)
    v_d = 2 * w * m * gx * a / gyro.drive_electrode.force_per_volt
    # A leaky AGC integrator settles with err = V_d / (kp + ki / leak), V_d proportional to the amplitude.
    err = v_d * dl.agc_leak / (dl.agc_leak * (dl.agc_kp + v_d / dl.amplitude_setpoint) + dl.agc_ki)
    sag = 1.0 - err / dl.amplitude_setpoint
    a, v_d = a * sag, v_d * sag
    # The drive's cubic stiffness moves the resonance the PLL locks to: w^2 = w_x^2 + 3/4 duffing_x a^2.
    w = wx * jnp.sqrt(1.0 + 0.75 * r.duffing_x * a**2 / wx**2)
    X = _cx(a)
    om = stim.rate_at(0.0)
    om_sense = om + _rate_equivalent(gyro, temp, stim.time, om)
    vcf = gyro.vcf_electrode.force_per_volt2 * stim.vcf_at(0.0)
    dy = (wy**2 - w**2) / (2 * w)
    coupling = _cj((r.angular_gain * om_sense + r.damping_coupling / 2) * a, -r.stiffness_coupling * a / (2 * w))
    drive_meas = gyro.drive_frontend.phasor_gain(w) * X
    if gyro.closed_loop:
        fb, excitation, rebalance_loop = closed_loop_parts(gyro, "operating_point")
        Y = jnp.zeros((), dtype=complex)
        _, hold_delay = excitation.dac.hold(w)
        bias_ratio = fb.bias(temp - r.t_ref) / fb.v_dc
        needed = coupling + _cx(vcf / (2 * w * m)) * expj(stim.vcf_phase)
        word = (needed * _cx(2 * w * m / gyro.rebalance_gain(w)) / _cx(bias_ratio)
                * expj(-(rebalance_loop.carrier_phase - hold_delay)))
        rebalance = _r(-word)
    else:
        # Open loop: the sense answers quasi-statically, and its Coriolis back-action pulls the drive
        # resonance by (Ag Om)^2 / d_y (level repulsion); start there, since a high-Q sense rings for
        # seconds after any frequency step.
        w = w - (r.angular_gain * om) ** 2 / dy
        dy = (wy**2 - w**2) / (2 * w)
        coupling = _cj((r.angular_gain * om_sense + r.damping_coupling / 2) * a,
                       -r.stiffness_coupling * a / (2 * w))
        force = -coupling - _cx(vcf / (2 * w * m)) * expj(stim.vcf_phase)
        Y = force / _cj(gy, -dy)
        for _ in range(3):  # the sense's cubic stiffness: d_y + 3/8 duffing_y |Y|^2 / w, by fixed point
            Y = force / _cj(gy, -(dy + 0.375 * r.duffing_y * jnp.abs(Y) ** 2 / w))
        rebalance = jnp.zeros(2)
        drive_meas = gyro.drive_frontend.phasor_gain(w) * X
    sense_meas = gyro.sense_frontend.phasor_gain(w) * Y
    phase_meas = jnp.angle(drive_meas * expj(-dl.reference_phase))
    loops = Loops(
        pll=w - dl.center_frequency - dl.pll_kp * phase_meas,
        agc=jnp.asarray(v_d - dl.agc_kp * err, dtype=float),
        drive_lpf=jnp.stack([_r(drive_meas)] * dl.demod_order),
        sense_lpf=jnp.stack([_r(sense_meas)] * _sense_demod(gyro).demod_order),
        rebalance=rebalance,
    )
    return SlowState(_r(X), _r(Y), loops)


def wave_from_slow(state: SlowState, omega):
    """Carrier-level state at phase 0 with the envelopes of `state`."""
    X, Y = _c(state.drive), _c(state.sense)
    return WaveState(
        drive=jnp.stack([jnp.real(X), -omega * jnp.imag(X)]),
        sense=jnp.stack([jnp.real(Y), -omega * jnp.imag(Y)]),
        phase=jnp.zeros(()),
        loops=state.loops,
    )


def _loop_scales(gyro: Gyroscope, a, omega):
    g_d = jnp.abs(gyro.drive_frontend.phasor_gain(omega))
    g_s = jnp.abs(gyro.sense_frontend.phasor_gain(omega))
    word = (2.0 ** (closed_loop_parts(gyro, "_loop_scales").excitation.dac.word_bits - 1)) if gyro.closed_loop else 1.0
    return Loops(
        pll=jnp.ones(()),
        agc=jnp.ones(()),
        drive_lpf=jnp.full((gyro.drive_loop.demod_order, 2), g_d * a),
        sense_lpf=jnp.full((_sense_demod(gyro).demod_order, 2), g_s * a * 1e-3),
        rebalance=jnp.full((2,), word),
    )


def slow_scales(gyro: Gyroscope) -> SlowState:
    """Characteristic size of each averaged-tier state: drive amplitude, 1e-3 of it for the sense, the
    full-scale word, the demodulated LSB those mean."""
    omega = gyro.resonator.omega_x
    a = gyro.drive_amplitude(omega)
    return SlowState(jnp.full((2,), a), jnp.full((2,), a * 1e-3), _loop_scales(gyro, a, omega))


def wave_scales(gyro: Gyroscope) -> WaveState:
    omega = gyro.resonator.omega_x
    a = gyro.drive_amplitude(omega)
    return WaveState(jnp.stack([a, a * omega]), jnp.stack([a, a * omega]) * 1e-3, jnp.ones(()),
                     _loop_scales(gyro, a, omega))


def output_scales(gyro: Gyroscope) -> Outputs:
    omega = gyro.resonator.omega_x
    if gyro.closed_loop:
        word = 2.0 ** (closed_loop_parts(gyro, "output_scales").excitation.dac.word_bits - 1)
    else:
        word = jnp.abs(gyro.sense_frontend.phasor_gain(omega)) * gyro.drive_amplitude(omega) * 1e-3
    return Outputs(jnp.asarray(word, dtype=float), jnp.asarray(word, dtype=float), jnp.asarray(omega))
