"""Lots of devices: one Gyroscope PyTree with a leading device axis, for vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._checks import check_nonnegative
from ._gyroscope import Gyroscope


def as_arrays(tree):
    """Every Python-number leaf as a float64 array, so that it is differentiable and batchable."""
    def convert(x):
        if isinstance(x, (bool,)):
            return x
        if isinstance(x, (int, float)):
            return jnp.asarray(x, dtype=float)
        return x

    return jax.tree.map(convert, tree)


class ProcessSpread(eqx.Module):
    """Relative (1-sigma) device-to-device spread of a lot, Gaussian.

    Defaults are ASSUMPTIONS typical of one MEMS wafer lot: resonances +/-0.3 % (etch variation of spring
    width), Q +/-10 % (vacuum and anchor loss), mass +/-0.5 %, feedback and drive electrode factors +/-1 %
    (gap), angular gain +/-0.2 %, absolute couplings from their own spread. Seed 003 §3 names Q and the
    resonant frequencies as the main differences between devices of one batch.
    """

    omega: float = 3e-3
    q: float = 0.10
    mass: float = 5e-3
    electrode: float = 1e-2
    angular_gain: float = 2e-3
    stiffness_coupling: float = 0.0  # rad^2/s^2, absolute
    damping_coupling: float = 0.0  # 1/s, absolute

    def __check_init__(self):
        for name in ("omega", "q", "mass", "electrode", "angular_gain", "stiffness_coupling",
                     "damping_coupling"):
            check_nonnegative("ProcessSpread", name, getattr(self, name))


def make_lot(gyro: Gyroscope, n: int, key, spread: ProcessSpread = ProcessSpread()) -> Gyroscope:
    """`n` devices drawn around `gyro` with `spread`; returns one Gyroscope whose array leaves have a
    leading axis of size `n` (the loops' firmware gains stay those of the design)."""
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n (number of devices) must be an integer >= 1, got {n!r}.")
    gyro = as_arrays(gyro)
    batched = jax.tree.map(lambda x: jnp.broadcast_to(x, (n,) + jnp.shape(x)), gyro)
    keys = jax.random.split(key, 9)
    r = batched.resonator

    def rel(k, sigma):
        return 1.0 + sigma * jax.random.normal(k, (n,))

    common = rel(keys[0], spread.omega)  # both modes move together with the etch
    split = rel(keys[1], spread.omega * 0.1)
    fb = batched.feedback_electrode
    return eqx.tree_at(
        lambda g: (g.resonator.omega_x, g.resonator.omega_y, g.resonator.q_x, g.resonator.q_y,
                   g.resonator.mass, g.resonator.angular_gain, g.resonator.stiffness_coupling,
                   g.resonator.damping_coupling, g.drive_electrode.force_per_volt)
        + ((g.feedback_electrode.k_vf,) if g.feedback_electrode is not None else ()),
        batched,
        (r.omega_x * common, r.omega_y * common * split, r.q_x * rel(keys[2], spread.q),
         r.q_y * rel(keys[3], spread.q), r.mass * rel(keys[4], spread.mass),
         r.angular_gain * rel(keys[5], spread.angular_gain),
         r.stiffness_coupling + spread.stiffness_coupling * jax.random.normal(keys[6], (n,)),
         r.damping_coupling + spread.damping_coupling * jax.random.normal(keys[7], (n,)),
         batched.drive_electrode.force_per_volt * rel(keys[8], spread.electrode))
        + ((fb.k_vf * rel(jax.random.fold_in(keys[8], 1), spread.electrode),) if fb is not None else ()),
    )
