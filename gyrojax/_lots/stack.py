"""Lots of devices: one Gyroscope PyTree with a leading device axis, for vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from .._checks import check_nonnegative
from .._gyroscope import Gyroscope


# Lots of up to this many devices are padded to the next power of two (1, 2, 4, 8, 16) by the compiled programs
# that take a lot (a fit's vmapped solve, a campaign's settle): a lot of a nearby size then reuses the program (a
# refit without one device, the next lot of a notebook) instead of tracing and compiling it again (~10-15 s on
# 2 CPU cores for the demo's sweeps). Above it the CPU chunk of 16 rounds a fit's device axis to a multiple of 16.
BUCKET_MAX = 16


def bucket_size(n: int) -> int:
    """The number of devices a lot of `n` is padded to: the next power of two up to `BUCKET_MAX`, else `n`."""
    return 1 << (n - 1).bit_length() if 0 < n <= BUCKET_MAX else n


def pad_devices(tree, size: int):
    """Every array leaf of `tree` with its leading (device) axis padded to `size` with copies of its last device."""
    def pad(x):
        x = jnp.asarray(x)
        extra = size - x.shape[0]
        return jnp.concatenate([x, jnp.repeat(x[-1:], extra, axis=0)]) if extra else x

    return jax.tree.map(lambda x: pad(x) if eqx.is_array(x) else x, tree)


def unpad_devices(tree, n: int):
    """Every array leaf of `tree` cut to its first `n` devices (what `pad_devices` added dropped)."""
    return jax.tree.map(lambda x: x[:n] if eqx.is_array(x) else x, tree)


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

    - `omega`: both resonances together (etch variation of the spring width).
    - `split`: the sense resonance relative to the drive's (the mode split moves by `split` x omega_y).
    - `q`: each quality factor.
    - `mass`, `angular_gain`: the modal mass and Ag.
    - `electrode`: the drive and feedback electrode factors (gap).
    - `vcf_electrode`: the virtual-Coriolis electrode factor K_svf.
    - `stiffness_coupling` (rad^2/s^2), `damping_coupling` (1/s): absolute spreads.

    Defaults are ASSUMPTIONS typical of one MEMS wafer lot: resonances +/-0.3 %, split +/-0.03 % of omega_y,
    Q +/-10 % (vacuum and anchor loss), mass +/-0.5 %, electrode factors +/-1 % (the VCF electrode is etched
    with the same gap), angular gain +/-0.2 %, no coupling spread. Seed 003 §3 names Q and the resonant
    frequencies as the main differences between devices of one batch, with K_svf and m_d "very close".
    """

    omega: float = 3e-3
    q: float = 0.10
    mass: float = 5e-3
    electrode: float = 1e-2
    angular_gain: float = 2e-3
    stiffness_coupling: float = 0.0  # rad^2/s^2, absolute
    damping_coupling: float = 0.0  # 1/s, absolute
    split: float = 3e-4
    vcf_electrode: float = 1e-2

    def __check_init__(self):
        for name in ("omega", "q", "mass", "electrode", "angular_gain", "stiffness_coupling",
                     "damping_coupling", "split", "vcf_electrode"):
            check_nonnegative("ProcessSpread", name, getattr(self, name))


def make_lot(gyro: Gyroscope, n: int, key: PRNGKeyArray, spread: ProcessSpread = ProcessSpread()) -> Gyroscope:
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
    split = rel(keys[1], spread.split)
    fb = batched.feedback_electrode
    return eqx.tree_at(
        lambda g: (g.resonator.omega_x, g.resonator.omega_y, g.resonator.q_x, g.resonator.q_y,
                   g.resonator.mass, g.resonator.angular_gain, g.resonator.stiffness_coupling,
                   g.resonator.damping_coupling, g.drive_electrode.force_per_volt,
                   g.vcf_electrode.force_per_volt2)
        + ((g.feedback_electrode.k_vf,) if g.feedback_electrode is not None else ()),
        batched,
        (r.omega_x * common, r.omega_y * common * split, r.q_x * rel(keys[2], spread.q),
         r.q_y * rel(keys[3], spread.q), r.mass * rel(keys[4], spread.mass),
         r.angular_gain * rel(keys[5], spread.angular_gain),
         r.stiffness_coupling + spread.stiffness_coupling * jax.random.normal(keys[6], (n,)),
         r.damping_coupling + spread.damping_coupling * jax.random.normal(keys[7], (n,)),
         batched.drive_electrode.force_per_volt * rel(keys[8], spread.electrode),
         batched.vcf_electrode.force_per_volt2 * rel(jax.random.fold_in(keys[8], 2), spread.vcf_electrode))
        + ((fb.k_vf * rel(jax.random.fold_in(keys[8], 1), spread.electrode),) if fb is not None else ()),
    )
