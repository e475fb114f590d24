"""Hairer's step-size rule and the unrolled DOP853 against scipy's solve_ivp(method="DOP853")."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gyrojax._simulate._hairer_controller import HairerController
from gyrojax._simulate._unrolled_rk import UnrolledRK


W, G = 7.0, 0.05


def _field(t, y, args):
    return jnp.stack([y[1], -(W**2) * y[0] - 2 * G * y[1] + jnp.cos(3.0 * t)])


@jax.jit
def _solve(y0):
    """Unrolled DOP853 at rtol = atol = 1e-7 under Hairer's rule and under diffrax's PIDController."""
    out = []
    for controller in (HairerController(rtol=1e-7, atol=1e-7), diffrax.PIDController(rtol=1e-7, atol=1e-7)):
        sol = diffrax.diffeqsolve(diffrax.ODETerm(_field), UnrolledRK.dop853(), 0.0, 3.0, 1e-3, y0,
                                  stepsize_controller=controller, saveat=diffrax.SaveAt(t1=True))
        out.append((sol.ys[-1], sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]))
    return out


def test_dop853_with_hairer_rule_follows_scipy():
    y0 = jnp.array([1.0, 0.0])
    (ours, accepted, rejected), (_, pid_accepted, pid_rejected) = _solve(y0)
    ref = solve_ivp(lambda t, y: np.array([y[1], -(W**2) * y[0] - 2 * G * y[1] + np.cos(3.0 * t)]), (0.0, 3.0),
                    np.array([1.0, 0.0]), method="DOP853", rtol=1e-7, atol=1e-7, first_step=1e-3)
    # the same method and rule: the same accepted steps (scipy's error norm weights the two embedded
    # errors by the tolerances, ours does not: allow one step either way) and the same accuracy
    assert abs(int(accepted) - (ref.t.size - 1)) <= 1
    tight = solve_ivp(lambda t, y: np.array([y[1], -(W**2) * y[0] - 2 * G * y[1] + np.cos(3.0 * t)]), (0.0, 3.0),
                      np.array([1.0, 0.0]), method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    ours_error = np.max(np.abs(np.asarray(ours) - tight))
    scipy_error = np.max(np.abs(ref.y[:, -1] - tight))
    assert 1e-8 < scipy_error < 1e-6  # a real, tolerance-sized error to compare with
    assert ours_error < 1.5 * scipy_error
    # diffrax's rule never shrinks after an accepted step: it rejects more often on the same problem
    assert int(pid_rejected) > int(rejected)
    assert int(pid_accepted) > 0


def test_refuses_bad_settings():
    with pytest.raises(ValueError, match="HairerController.rtol must be > 0"):
        HairerController(rtol=0.0, atol=1e-6)
    with pytest.raises(ValueError, match="HairerController.factormax must be > 0"):
        HairerController(rtol=1e-6, atol=1e-6, factormax=-1.0)
    with pytest.raises(ValueError, match="needs a first step"):
        diffrax.diffeqsolve(diffrax.ODETerm(_field), UnrolledRK.dop853(), 0.0, 1.0, None, jnp.array([1.0, 0.0]),
                            stepsize_controller=HairerController(rtol=1e-6, atol=1e-6))
