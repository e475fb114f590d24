"""The three tiers and the one entry point that settles a measurement point with any of them."""

import abc
import functools as ft
import math

import diffrax
import equinox as eqx
import jax
import jax.core  # Tracer: jax.core is not imported by `import jax` for type checkers
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Float, Int

from .._checks import check_positive
from .._gyroscope import Gyroscope
from .._numerics.linsolve import PivotedLU, lu_factor, lu_solve
from .._physics.stimulus import Stimulus
from .._solution import RESULTS, result_code, result_message
from ._hairer_controller import HairerController
from ._implicit import implicit_root
from ._model import (
    Outputs,
    SlowState,
    WaveState,
    averaged_field,
    full_field,
    operating_point,
    output_scales,
    slow_scales,
    wave_from_slow,
    wave_scales,
)
from ._unrolled_rk import UnrolledRK


def _mul(a, b):
    return jax.tree.map(lambda x, y: x * y, a, b)


def _div(a, b):
    return jax.tree.map(lambda x, y: x / y, a, b)


class Settled(eqx.Module):
    """A settled measurement point.

    **Fields:**

    - `rate`: the rate output (closed loop: the rebalance word; open loop: the demodulated rate channel),
      mean over the averaging window, LSB.
    - `quadrature`: the quadrature word / channel, LSB.
    - `frequency`: the PLL frequency, rad/s.
    - `state`: the final state of the tier (`SlowState` or `WaveState`).
    - `result`: a `gyrojax.RESULTS` code; check `result == RESULTS.successful` or call `.check()`.
    - `num_steps`: solver steps (ODE steps or root-find iterations).
    """

    rate: Float[Array, "*point"]
    quadrature: Float[Array, "*point"]
    frequency: Float[Array, "*point"]
    state: SlowState | WaveState
    result: RESULTS
    num_steps: Int[Array, "*point"]

    @property
    def status(self) -> str:
        """In words: "settled" when every point settled, else the reasons (eager use only)."""
        import numpy as np

        codes = np.atleast_1d(np.asarray(result_code(self.result)))
        bad = codes != result_code(RESULTS.successful)
        if not bad.any():
            return "settled"
        reasons = sorted({result_message(c) for c in codes[bad]})
        return f"{int(bad.sum())} of {codes.size} point(s) did not settle: " + " / ".join(reasons)

    def check(self) -> "Settled":
        """Raise a RuntimeError with the reason if any point did not settle (eager use only; under jit
        inspect `result`)."""
        if self.status != "settled":
            raise RuntimeError(self.status)
        return self


class AbstractTier(eqx.Module):
    """How to compute a settled point. Subclasses: `Steady`, `Averaged`, `FullWaveform`."""

    @abc.abstractmethod
    def settle(self, gyro: Gyroscope, stimulus: Stimulus) -> Settled:
        """Settle `gyro` under a constant `stimulus`."""

    def settle_points(self, gyros: Gyroscope, stimuli: Stimulus, groups: tuple[tuple[int, int], ...] | None = None
                      ) -> Settled:
        """Settle the points of a sweep: `gyros` and `stimuli` carry a leading point axis on every array leaf
        (e.g. the device at each point's die temperature). `groups` (None: one) is a tuple of `(start, stop)`
        slices of the points that belong together (several sweeps settled in one call; `Steady` forms one
        chord Jacobian per group). Default: `settle` vmapped over the points."""
        return jax.vmap(self.settle)(gyros, stimuli)


def _finalise(rate, quad, freq, state, result, steps):
    bad = ~(jnp.isfinite(rate) & jnp.isfinite(quad) & jnp.isfinite(freq))
    result = RESULTS.where(bad & (result == RESULTS.successful), RESULTS.nonfinite_output, result)
    return Settled(rate, quad, freq, state, result, steps)


class Steady(AbstractTier):
    """The averaged equations at equilibrium, by a chord or Newton root find (optimistix), differentiated
    implicitly.

    Only constant stimuli have an equilibrium: a modulated rate or VCF is refused.

    `jacobian="once"` (default) is the chord method: the Jacobian of the averaged equations is formed and
    factorised once, at the operating point every solve starts from, which is already within ~1e-6 of the
    root; each further step costs one evaluation of the equations (a typical DAC INL: 4 chord steps instead of
    3 Newton steps at ~1/3 of the cost). `jacobian="every_step"` is Newton's method, for starts far from the
    root. Both stop at the same tolerance, so they agree to ~1e-10 ppm of full scale.
    """

    # 1e-10 on O(1)-scaled states (1e-10 of the drive amplitude: far below any ppm): 1e-12 sits at
    # round-off for an open-loop sense at 200 deg/s, and 1e-11 still stalls on ~2 % of open-loop lot points,
    # where Newton's steps stop shrinking and the root find would be reported as failed.
    rtol: float = 1e-10
    atol: float = 1e-10
    max_steps: int = eqx.field(static=True, default=40)
    jacobian: str = eqx.field(static=True, default="once")

    def __check_init__(self):
        if self.jacobian not in ("once", "every_step"):
            raise ValueError(f"Steady.jacobian must be 'once' (chord) or 'every_step' (Newton), got "
                             f"{self.jacobian!r}.")

    def settle(self, gyro: Gyroscope, stimulus: Stimulus) -> Settled:
        _check_constant(stimulus)
        orders = _orders(gyro)
        z, (result, steps) = implicit_root((gyro, stimulus), find=ft.partial(_steady_find, self, orders),
                                           residual=ft.partial(_steady_residual, orders))
        return _steady_settled(gyro, stimulus, orders, z, result == RESULTS.successful, steps)

    def settle_points(self, gyros: Gyroscope, stimuli: Stimulus, groups: tuple[tuple[int, int], ...] | None = None
                      ) -> Settled:
        """A sweep's points from one Jacobian (`jacobian="once"`): formed and factorised at the sweep's centre
        (the mean over points of every parameter and input: zero rate for a symmetric rate table), then
        refined per point by Broyden updates (`_sweep_broyden`); each point costs only evaluations of the
        equations. With `groups`, one Jacobian per group, at the group's centre, all groups in one loop (a point
        takes the same steps as in a call of its group alone). Each point's derivative is still exact (the
        implicit function theorem at its own root). Newton (`"every_step"`) settles point by point."""
        if self.jacobian != "once":
            return super().settle_points(gyros, stimuli)
        _check_constant(stimuli)
        one = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, gyros)
        orders = _orders(one)
        frozen = jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, (gyros, stimuli))
        z, ok, steps = _sweep_broyden(self, orders, frozen, groups)

        def point(gyro, stimulus, z_i, ok_i, steps_i):
            z_i, _ = implicit_root((gyro, stimulus, z_i), find=_given_root,
                                   residual=ft.partial(_given_root_residual, orders))
            return _steady_settled(gyro, stimulus, orders, z_i, ok_i, steps_i)

        return jax.vmap(point)(gyros, stimuli, z, ok, steps)


def _check_constant(stimulus):
    for name in ("rate_frequency", "vcf_frequency"):
        value = getattr(stimulus, name)
        if not isinstance(value, jax.core.Tracer) and bool(np.any(np.asarray(value) != 0.0)):
            raise ValueError(f"Steady tier: stimulus.{name} must be 0 (a constant input has an "
                             f"equilibrium; a modulated one does not), got {value!r}. Use the "
                             "averaged or full tier, or gyrojax.physics.frequency_response.")


def _orders(gyro):
    scales = jax.eval_shape(slow_scales, gyro)
    return scales.loops.drive_lpf.shape[0], scales.loops.sense_lpf.shape[0]


def _steady_settled(gyro, stimulus, orders, z, ok, steps):
    state = _all_stages(_mul(z, _last_stages(slow_scales(gyro))), orders)
    _, out = averaged_field(0.0, state, gyro, stimulus)
    # equinox's Enumeration types its items as their message strings; they are RESULTS items at run time.
    result = RESULTS.where(ok, RESULTS.successful, RESULTS.root_find_failed)  # pyright: ignore[reportArgumentType]
    return _finalise(out.rate, out.quadrature, out.frequency, state, result, steps)


def _given_root(inputs):
    return inputs[2], ()


def _given_root_residual(orders, z, inputs):
    return _steady_residual(orders, z, inputs[:2])


def _steady_start(inputs):
    gyro, stimulus = inputs
    return _div(_last_stages(operating_point(gyro, stimulus)), _last_stages(slow_scales(gyro)))


def _sweep_broyden(tier, orders, inputs, groups=None):
    """Every point of a sweep from one Jacobian, formed and factorised once at the sweep's centre, then
    improved per point by Broyden's rank-one secant updates of its inverse (O(n^2) per step, no further
    Jacobian). Measured on paper-qmg + typical INL, 22 points: 2-3 steps per point where the plain chord took
    3-6 (its edges at +/-200 deg/s converge slowly on the centre's Jacobian). Stops per point on
    optimistix's Chord test (max norm: step within atol + rtol |z|, residual within atol). Not differentiated.
    `groups`: `(start, stop)` slices of the points, each with its own centre and Jacobian (None: one group).
    """
    y0 = jax.vmap(lambda i: ravel_pytree(_steady_start(i))[0])(inputs)
    _, unravel = ravel_pytree(_steady_start(jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, inputs)))

    def residual(z, inp):
        return ravel_pytree(_steady_residual(orders, unravel(z), inp))[0]

    def centre_of(a, b):
        return jax.tree.map(lambda x: (jnp.mean(x[a:b], axis=0) if jnp.issubdtype(x.dtype, jnp.inexact) else x[a])
                            if eqx.is_array(x) else x, inputs)

    def inverse_at(centre):
        lu, perm = lu_factor(jax.jacfwd(residual)(ravel_pytree(_steady_start(centre))[0], centre))
        return jax.vmap(lambda e: lu_solve(lu, perm, e), out_axes=1)(jnp.eye(n_unknowns))

    n, n_unknowns = y0.shape
    if groups is None or len(groups) == 1:
        h0 = jnp.broadcast_to(inverse_at(centre_of(0, n)), (n, n_unknowns, n_unknowns))
    else:
        # One traced Jacobian for all groups (vmapped over their centres).
        centres = jax.tree.map(lambda *x: jnp.stack(x) if eqx.is_array(x[0]) else x[0],
                               *[centre_of(a, b) for a, b in groups])
        arrays, static = eqx.partition(centres, eqx.is_array)
        inverses = jax.vmap(lambda c: inverse_at(eqx.combine(c, static)))(arrays)
        h0 = jnp.concatenate([jnp.broadcast_to(inverses[i], (b - a, n_unknowns, n_unknowns))
                              for i, (a, b) in enumerate(groups)])
    batched = jax.vmap(residual)

    def cond(carry):
        *_, done, _, k = carry
        return (k < tier.max_steps) & ~jnp.all(done)

    def body(carry):
        z, f, h, done, steps, k = carry
        dz = -jnp.einsum("pij,pj->pi", h, f)
        z_new = z + dz
        f_new = batched(z_new, inputs)
        df = f_new - f
        h_df = jnp.einsum("pij,pj->pi", h, df)
        dz_h = jnp.einsum("pi,pij->pj", dz, h)
        denom = jnp.sum(dz * h_df, axis=-1)
        safe = jnp.where(denom == 0, 1.0, denom)
        h_new = h + jnp.where((denom == 0)[:, None, None], 0.0,
                              jnp.einsum("pi,pj->pij", dz - h_df, dz_h) / safe[:, None, None])
        small = (jnp.max(jnp.abs(dz) / (tier.atol + tier.rtol * jnp.abs(z_new)), axis=-1) < 1.0) & \
            (jnp.max(jnp.abs(f_new), axis=-1) < tier.atol)
        keep = done[:, None]
        return (jnp.where(keep, z, z_new), jnp.where(keep, f, f_new), jnp.where(keep[..., None], h, h_new),
                done | small, steps + jnp.where(done, 0, 1), k + 1)

    z, _, _, done, steps, _ = jax.lax.while_loop(
        cond, body, (y0, batched(y0, inputs), h0, jnp.zeros(n, bool), jnp.zeros(n, int), 0))
    return jax.vmap(unravel)(z), done, steps


def _steady_residual(orders, z, inputs):
    """The averaged equations at the scaled unknowns `z` (last LPF stages only), each component a relative
    error."""
    gyro, stimulus = inputs
    full_scales = slow_scales(gyro)
    scales = _last_stages(full_scales)
    rates = _last_stages(_residual_rates(gyro, full_scales))
    d, _ = averaged_field(0.0, _all_stages(_mul(z, scales), orders), gyro, stimulus)
    return _div(_div(_first_stages(d), scales), rates)


def _steady_find(tier, orders, inputs):
    y0 = _steady_start(inputs)
    # XLA-only linear solves: see gyrojax/_numerics/linsolve.py. Not differentiated (see implicit_root).
    method = optx.Chord if tier.jacobian == "once" else optx.Newton
    sol = optx.root_find(ft.partial(_steady_residual, orders), method(rtol=tier.rtol, atol=tier.atol,
                         linear_solver=PivotedLU()), y0, inputs, max_steps=tier.max_steps, throw=False,
                         adjoint=optx.RecursiveCheckpointAdjoint())
    return sol.value, (RESULTS.promote(sol.result), sol.stats["num_steps"])


# At equilibrium every demodulator low-pass stage equals its input (unit DC gain), so the root find solves for
# the last stage of each chain only (what the loops read) and the chain's first-stage balance (input - stage)
# stands for the whole chain: 12 unknowns instead of 24 on paper-qmg, the same root, half the Jacobian.
def _with_stages(state, drive_lpf, sense_lpf):
    return eqx.tree_at(lambda s: (s.loops.drive_lpf, s.loops.sense_lpf), state, (drive_lpf, sense_lpf))


def _last_stages(state):
    return _with_stages(state, state.loops.drive_lpf[-1:], state.loops.sense_lpf[-1:])


def _first_stages(state):
    return _with_stages(state, state.loops.drive_lpf[:1], state.loops.sense_lpf[:1])


def _all_stages(state, orders):
    drive, sense = state.loops.drive_lpf, state.loops.sense_lpf
    return _with_stages(state, jnp.broadcast_to(drive, (orders[0], 2)), jnp.broadcast_to(sense, (orders[1], 2)))


def _residual_rates(gyro, scales):
    """Rates (1/s) that make each Newton residual component a relative error: 1 everywhere but the AGC
    integrator, whose derivative ki (setpoint - |e_d|) - leak z is a difference of demodulated amplitudes of
    ~4e6 LSB. Its round-off (~ki ulp(setpoint) = 6e-10 V/s on paper-qmg) sat above the 1e-10 tolerance as
    soon as a leak (`agc_finite_gain`) made the balance inexact: every point failed to settle. Divided by
    ki setpoint it is the relative amplitude error."""
    ones = jax.tree.map(jnp.ones_like, scales)
    dl = gyro.drive_loop
    agc = jnp.maximum(jnp.abs(dl.agc_ki) * jnp.abs(dl.amplitude_setpoint) / scales.loops.agc, 1.0)
    return eqx.tree_at(lambda s: s.loops.agc, ones, agc * ones.loops.agc)


def _ode_settle(tier, field, y0, scales, gyro, stimulus, average_time):
    out_scales = output_scales(gyro)

    def vector_field(t, z, _):
        d, out = field(t, _mul(z[0], scales), gyro, stimulus)
        return _div(d, scales), _div(out, out_scales)

    zero = Outputs(jnp.zeros(()), jnp.zeros(()), jnp.zeros(()))
    t1 = tier.settle_time + average_time
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        tier.solver,
        t0=0.0,
        t1=t1,
        dt0=tier.dt0,
        y0=(_div(y0, scales), zero),
        saveat=diffrax.SaveAt(ts=jnp.stack([jnp.asarray(tier.settle_time, dtype=float), t1])),
        stepsize_controller=diffrax.PIDController(rtol=tier.rtol, atol=tier.atol),
        max_steps=tier.max_steps,
        adjoint=tier.adjoint,
        throw=False,
    )
    if sol.ys is None:  # SaveAt(ts=...) above saves both times
        raise RuntimeError("the settle's ODE solve returned no saved states.")
    state = jax.tree.map(lambda s, x: s[-1] * x, sol.ys[0], scales)
    mean = jax.tree.map(lambda acc, s: (acc[1] - acc[0]) / average_time * s, sol.ys[1], out_scales)
    return _finalise(mean.rate, mean.quadrature, mean.frequency, state, _ode_result(sol.result),
                     sol.stats["num_steps"])


class Averaged(AbstractTier):
    """The slow-flow (envelope) ODE with describing functions, integrated with diffrax from the ideal
    operating point for `settle_time`, then averaged over `average_time`.

    For `jax.jacfwd` / Levenberg-Marquardt pass `adjoint=diffrax.ForwardMode()` (or `DirectAdjoint()`).
    """

    settle_time: float = 0.12
    average_time: float = 0.01
    solver: diffrax.AbstractSolver = diffrax.Tsit5()
    rtol: float = 1e-10
    atol: float = 1e-10
    dt0: float = 1e-5
    max_steps: int = eqx.field(static=True, default=100_000)
    adjoint: diffrax.AbstractAdjoint = diffrax.RecursiveCheckpointAdjoint()

    def __check_init__(self):
        check_positive("Averaged", "settle_time", self.settle_time)
        check_positive("Averaged", "average_time", self.average_time)

    def settle(self, gyro: Gyroscope, stimulus: Stimulus) -> Settled:
        y0 = operating_point(gyro, stimulus)
        return _ode_settle(self, averaged_field, y0, slow_scales(gyro), gyro, stimulus, self.average_time)


def _ode_result(result):
    """A diffrax result in gyrojax's codes: a failure says what to try when settling (every diffrax failure
    but max_steps is `solver_failed`)."""
    result = RESULTS.promote(result)
    failed = RESULTS.where(result == RESULTS.max_steps_reached, RESULTS.settle_max_steps, RESULTS.solver_failed)
    return RESULTS.where(result == RESULTS.successful, result, failed)


def _window_settle(tier, field, y0, scales, gyro, stimulus, average_time):
    """Settle with one `diffeqsolve` run twice by a `lax.scan` (so compiled once): over [0, settle_time],
    then over the averaging window, each time with the running integrals of the outputs restarted from
    zero; the window's integrals give the means.

    The ODE state is the pair (scaled state flattened to one vector, the three output integrals). Each
    choice was measured (`benchmarks/README.md`): the integrals ride along through the settling span
    because the settled output is then ~40x more accurate at the same tolerance (the step size at the
    end of the settling span matches the window's); a separate 3-vector beside the 25-state vector keeps
    XLA's fused step (one 28-vector ran 1.7-1.9x slower per step); only end points are saved
    (`SaveAt(ts=...)` at both window ends ran ~5x slower).
    """
    out_scales = output_scales(gyro)
    solver = tier.solver
    if tier.unroll_stages and isinstance(solver, diffrax.AbstractERK):
        solver = UnrolledRK.from_solver(solver)
    controller = HairerController(rtol=tier.rtol, atol=tier.atol)
    flat0, unravel = ravel_pytree(_div(y0, scales))
    out_scale = jnp.stack([out_scales.rate, out_scales.quadrature, out_scales.frequency])

    def vector_field(t, y, _):
        z, _ = y
        d, out = field(t, _mul(unravel(z), scales), gyro, stimulus)
        return ravel_pytree(_div(d, scales))[0], jnp.stack([out.rate, out.quadrature, out.frequency]) / out_scale

    def segment(z, span):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(vector_field), solver, t0=span[0], t1=span[1], dt0=tier.dt0,
            y0=(z, jnp.zeros(3)), saveat=diffrax.SaveAt(t1=True), stepsize_controller=controller,
            max_steps=tier.max_steps, adjoint=tier.adjoint, throw=False,
        )
        z_end, integral = jax.tree.map(lambda v: v[-1], sol.ys)
        return z_end, (integral, sol.result, sol.stats["num_steps"])

    settle_time = jnp.asarray(tier.settle_time, dtype=float)
    zero = jnp.zeros(())
    spans = jnp.stack([jnp.stack([zero, settle_time]), jnp.stack([settle_time, settle_time + average_time])])
    z_end, (integrals, results, steps) = jax.lax.scan(segment, flat0, spans)
    first, window = (_ode_result(jax.tree.map(lambda v: v[i], results)) for i in (0, 1))
    mean = integrals[1] / average_time * out_scale
    result = RESULTS.where(first == RESULTS.successful, window, first)
    return _finalise(mean[0], mean[1], mean[2], _mul(unravel(z_end), scales), result, jnp.sum(steps))


class FullWaveform(AbstractTier):
    """The carrier-level ODE of resonator and loops, integrated with diffrax: the ground truth.

    Starts from the ideal operating point, settles for `settle_time`, then averages the outputs over
    `average_periods` whole carrier periods (so the demodulators' 2w ripple averages out).

    How it runs (`benchmarks/README.md` has the measurements behind each choice): the default solver is
    DOP853 (Dormand-Prince order 8 with Hairer's error estimate, the method of scipy's
    `solve_ivp(method="DOP853")`) with its stages written out at trace time (`UnrolledRK`), under Hairer's
    step-size rule (`HairerController`), on the state flattened to one vector. An explicit Runge-Kutta
    solver of diffrax (`Tsit5()`, `Dopri5()`, `Dopri8()`, ...) is unrolled the same way (same tableau,
    same numbers) when `unroll_stages=True`: diffrax's own stage loop costs several times this small
    vector field. Other solvers are used as given. Unrolling lengthens compilation (about 8 s for one
    point on a 2-core CPU; several times that for reverse-mode gradients): pass `unroll_stages=False`
    with a diffrax solver where compile time matters more than run time.

    Tolerance: the default rtol = atol = 1e-8 on the O(1)-scaled state keeps the settled output within
    ~1e-4 ppm of full scale of a 1e-12 solve on paper-qmg's sweep, and is also tight enough for the lower-
    order diffrax solvers; with DOP853, rtol = atol = 1e-6 (~40% faster) still stays within ~0.03 ppm, far
    inside the tiers' 0.25 ppm physical difference and their 1 ppm agreement target
    (`benchmarks/README.md` has the measured figures).

    **Fields:**

    - `settle_time`: settling span, s.
    - `average_periods`: whole carrier periods (of the nominal drive frequency) averaged over.
    - `solver`: a diffrax solver (default `UnrolledRK.dop853()`).
    - `rtol`, `atol`: the step-size controller's tolerances on the O(1)-scaled state.
    - `dt0`: first step of the settling span and of the window, s.
    - `max_steps`: step limit of each of the two spans.
    - `adjoint`: the diffrax adjoint (`ForwardMode()` / `DirectAdjoint()` for `jax.jacfwd`).
    - `unroll_stages`: run a diffrax explicit Runge-Kutta `solver`'s stages as straight-line code.
    """

    settle_time: float = 0.12
    average_periods: int = eqx.field(static=True, default=40)
    solver: diffrax.AbstractSolver = UnrolledRK.dop853()
    rtol: float = 1e-8
    atol: float = 1e-8
    dt0: float = 1e-6
    max_steps: int = eqx.field(static=True, default=400_000)
    adjoint: diffrax.AbstractAdjoint = diffrax.RecursiveCheckpointAdjoint()
    unroll_stages: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        check_positive("FullWaveform", "settle_time", self.settle_time)
        if self.average_periods < 1:
            raise ValueError(f"FullWaveform.average_periods must be >= 1, got {self.average_periods!r}.")

    def settle(self, gyro: Gyroscope, stimulus: Stimulus) -> Settled:
        slow = operating_point(gyro, stimulus)
        omega = gyro.drive_loop.center_frequency
        period = 2.0 * math.pi / omega
        return _window_settle(self, full_field, wave_from_slow(slow, omega), wave_scales(gyro), gyro, stimulus,
                              self.average_periods * period)


def settle(gyro: Gyroscope, stimulus: Stimulus, tier: AbstractTier = Steady()) -> Settled:
    """Settle `gyro` under a constant `stimulus` with the given tier (default: `Steady()`).

    **Arguments:**

    - `gyro`: the device.
    - `stimulus`: a `Stimulus` (rate in rad/s, VCF voltages, time since power-on).
    - `tier`: `Steady()`, `Averaged()` or `FullWaveform()`.

    **Returns:** a `Settled` solution; its `result` says whether the point settled.
    """
    if not isinstance(tier, AbstractTier):
        raise ValueError(f"tier must be Steady(), Averaged() or FullWaveform(), got {tier!r}.")
    return tier.settle(gyro, stimulus)
