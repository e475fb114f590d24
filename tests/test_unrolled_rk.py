"""The unrolled explicit Runge-Kutta step (the full-waveform tier's default) against diffrax's own solvers."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gyrojax._simulate._unrolled_rk import UnrolledRK


def _oscillator(t, y, args):
    # a damped oscillator with a time-dependent drive, as a pytree (so leaf-wise stages are exercised)
    w, g = args
    x, v = y
    return {"x": v["v"]}, {"v": -(w**2) * x["x"] - 2 * g * v["v"] + jnp.cos(3.0 * t)}


def _pair(y):
    return {"x": y[0]}, {"v": y[1]}


def _flat(t, y, args):
    x, v = _oscillator(t, _pair(y), args)
    return jnp.stack([x["x"], v["v"]])


CASES = (
    (diffrax.Tsit5(), lambda: diffrax.PIDController(rtol=1e-9, atol=1e-9)),
    (diffrax.Dopri8(), lambda: diffrax.PIDController(rtol=1e-9, atol=1e-9)),
    (diffrax.Heun(), diffrax.ConstantStepSize),  # not FSAL
)


@jax.jit
def _solve_all(y0, args):
    """For each case: (diffrax's own solver, the unrolled one), each (y(2), steps, rejected steps); and a
    Dopri8 solve at rtol 1e-13."""
    out = []
    for solver, controller in CASES:
        pair = []
        for s in (solver, UnrolledRK.from_solver(solver)):
            sol = diffrax.diffeqsolve(diffrax.ODETerm(_flat), s, 0.0, 2.0, 1e-3, y0, args=args,
                                      stepsize_controller=controller(), saveat=diffrax.SaveAt(t1=True))
            pair.append((sol.ys[-1], sol.stats["num_steps"], sol.stats["num_rejected_steps"]))
        out.append(pair)
    tight = diffrax.diffeqsolve(diffrax.ODETerm(_flat), diffrax.Dopri8(), 0.0, 2.0, 1e-4, y0, args=args,
                                stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-13),
                                saveat=diffrax.SaveAt(t1=True))
    return out, tight.ys[-1]


@pytest.mark.slow
def test_unrolled_matches_diffrax_step_for_step():
    y0 = jnp.array([1.0, 0.0])
    args = (jnp.asarray(7.0), jnp.asarray(0.05))
    pairs, tight = _solve_all(y0, args)
    for (ref, ref_steps, ref_rejected), (got, steps, rejected) in pairs:
        # same tableau and controller: the same accepted and rejected steps, the same answer up to the
        # rounding of differently ordered sums (Dopri8's coefficients reach ~1e2: ~1e-12 after 31 steps)
        assert int(steps) == int(ref_steps) and int(rejected) == int(ref_rejected)
        assert np.allclose(np.asarray(got), np.asarray(ref), rtol=1e-10, atol=1e-12)
    # and the answer is right: the unrolled Dopri8 at rtol 1e-9 against Dopri8 at 1e-13
    assert np.allclose(np.asarray(pairs[1][1][0]), np.asarray(tight), rtol=0, atol=1e-8)
    assert not np.allclose(np.asarray(pairs[2][1][0]), np.asarray(tight), rtol=0, atol=1e-8)  # Heun is 2nd order


def test_pytree_state_and_dense_output():
    # a pytree state, and SaveAt(ts) through the Hermite interpolant (third order: a loose check)
    solver = UnrolledRK.from_solver(diffrax.Tsit5())
    y0 = ({"x": jnp.asarray(1.0)}, {"v": jnp.asarray(0.0)})
    args = (jnp.asarray(2.0), jnp.asarray(0.0))
    ts = jnp.linspace(0.1, 1.0, 4)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, a: _oscillator(t, y, a)), solver, 0.0, 1.0, 1e-3, y0,
                              args=args, saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-10))
    # x'' + 4 x = cos 3t, x(0) = 1, x'(0) = 0:  x = (6/5) cos 2t - (1/5) cos 3t
    exact = 1.2 * np.cos(2 * np.asarray(ts)) - 0.2 * np.cos(3 * np.asarray(ts))
    assert np.allclose(np.asarray(sol.ys[0]["x"]), exact, rtol=0, atol=1e-6)


def test_from_solver_refuses_what_it_cannot_unroll():
    with pytest.raises(ValueError, match="explicit Runge-Kutta solver of diffrax"):
        UnrolledRK.from_solver(diffrax.Kvaerno5())
    with pytest.raises(ValueError, match="explicit Runge-Kutta solver of diffrax"):
        UnrolledRK.from_solver(diffrax.Euler())
    with pytest.raises(ValueError, match="b_sol and b_error need 2 weights"):
        UnrolledRK(c=(1.0,), a=((1.0,),), b_sol=(1.0,), b_error=(0.5, -0.5), fsal=False, method_order=1)
    with pytest.raises(ValueError, match="lower-triangular"):
        UnrolledRK(c=(0.5, 1.0), a=((0.5,), (1.0,)), b_sol=(0.0, 0.0, 1.0), b_error=(0.0, 0.0, 0.0),
                   fsal=False, method_order=2)
