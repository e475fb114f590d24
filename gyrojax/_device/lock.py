"""Whether a device's loops can lock: the closed-loop poles of each PI loop with its demodulator filter.

The plants are those gyrojax's loop design places the poles with (`design_drive_loop`, `design_rebalance_loop`):

- the PLL: the drive phasor's phase integrates the frequency error, plant 1/s;
- the AGC: the drive envelope, plant b / (s + g) with b = K_dx |G_d| / (2 w m) and g = w_x / (2 Q_x);
- the rebalance loop (the rate and the quadrature channel, equal gains): the sense envelope at the drive
  frequency, plant b / (s + g) with b the rebalance force per word LSB times |G_s| / (2 w m) and g = w_y / (2 Q_y)
  (mode-matched: the residual split is left out);

each behind its demodulator's `demod_order` first-order low-pass stages at `demod_cutoff`, with its PI (and its
leak, a finite integrator gain). A closed-loop pole with a real part >= 0 is a loop that oscillates or runs away
instead of settling: it cannot lock, whatever the steady state the model would solve for.
"""

import math

import numpy as np
from numpy.polynomial import polynomial as P


def _poles(b, kp, ki, leak, g, cutoff, order):
    """The closed-loop poles (rad/s) of PI (kp + ki / (s + leak)) x plant b / (s + g) x (1 + s / cutoff)^-order,
    from the characteristic polynomial in p = s / cutoff (scaled so that its coefficients stay O(1))."""
    lpf = P.polypow([1.0, 1.0], order)
    open_part = P.polymul(P.polymul([leak / cutoff, 1.0], [g / cutoff, 1.0]), lpf)
    feedback = P.polyadd(P.polymul([b * kp / cutoff], [leak / cutoff, 1.0]), [b * ki / cutoff**2])
    return P.polyroots(P.polyadd(open_part, feedback)) * cutoff


def _f(x) -> float:
    return float(np.asarray(x, dtype=float))


def loop_designs(gyro) -> list:
    """`(loop name, b, kp, ki, leak, g, cutoff, order)` for each loop of one device."""
    r = gyro.resonator
    w, wy = _f(r.omega_x), _f(r.omega_y)
    d = gyro.drive_loop
    g_d = abs(complex(np.asarray(gyro.drive_frontend.phasor_gain(w))))
    b_agc = _f(gyro.drive_electrode.force_per_volt) / (2.0 * w * _f(r.mass)) * g_d
    out = [("drive PLL", 1.0, _f(d.pll_kp), _f(d.pll_ki), 0.0, 0.0, _f(d.demod_cutoff), d.demod_order),
           ("drive AGC", b_agc, _f(d.agc_kp), _f(d.agc_ki), _f(d.agc_leak), w / (2.0 * _f(r.q_x)),
            _f(d.demod_cutoff), d.demod_order)]
    if gyro.closed_loop:
        rb = gyro.rebalance_loop
        g_s = abs(complex(np.asarray(gyro.sense_frontend.phasor_gain(w))))
        b_fb = _f(gyro.rebalance_gain(w)) / (2.0 * w * _f(r.mass)) * g_s
        out.append(("rebalance loop (rate and quadrature channels)", b_fb, _f(rb.kp), _f(rb.ki), _f(rb.leak),
                    wy / (2.0 * _f(r.q_y)), _f(rb.demod_cutoff), rb.demod_order))
    return out


def lock_problems(gyro) -> list[str]:
    """Why each loop of one device that cannot lock cannot, in words (empty: every loop settles)."""
    problems = []
    for name, b, kp, ki, leak, g, cutoff, order in loop_designs(gyro):
        if not all(math.isfinite(x) for x in (b, kp, ki, leak, g, cutoff)):
            problems.append(f"the {name} cannot lock: its gains or its plant are not finite")
            continue
        poles = _poles(b, kp, ki, leak, g, cutoff, order)
        worst = poles[np.argmax(poles.real)]
        if worst.real >= 0.0:
            natural_hz = math.sqrt(max(b * ki, 0.0)) / (2.0 * math.pi)
            problems.append(
                f"the {name} cannot lock: with kp = {kp:.4g} and ki = {ki:.4g} behind its demodulator's {order} "
                f"first-order low-pass stage(s) at {cutoff / (2.0 * math.pi):.4g} Hz, its closed loop has a pole at "
                f"{abs(worst.imag) / (2.0 * math.pi):.4g} Hz that grows (real part {worst.real:+.3g} 1/s): the "
                f"loop's natural frequency, {natural_hz:.4g} Hz, is too close to the demodulator's cutoff (lower kp "
                "and ki, or raise demod_cutoff)")
    return problems
