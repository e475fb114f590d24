r"""What a baseline fit leaves of an effect's fingerprint: the linearised noncentrality of a reading.

For a reading y(p) with standard uncertainties sigma, the effect's fingerprint is d = (y_effect - y_0) / sigma.
A baseline fit moves its free parameters (internal coordinates u, `gyrojax.PARAMETERS`' transforms) and its
nuisance offsets (a per-run bias, a meter gain: given as columns) to absorb what it can; to first order it
removes the projection of d onto the columns of the weighted Jacobian J = [dy/du, offsets] / sigma:

    r = (I - J J^+) d,   lambda = |r|^2,

lambda the noncentrality of the chi^2 the baseline leaves (the score test's power follows from it). |d| is
the fingerprint before any absorption. Both are in units of sigma.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._compile.jit import jit
from .._gyroscope import Gyroscope
from .._model.parameters import PARAMETERS


NEGLIGIBLE = 1e-6
"""sigma per natural-size change of a parameter (u = 1) below which its column is dropped as round-off."""


class Absorption(eqx.Module):
    """The fingerprint of an effect on one reading, before and after a baseline fit absorbs what it can.

    **Fields:**

    - `signature_sigmas`: |d|, the change of the reading in noise sigmas (root sum of squares).
    - `residual_sigmas`: |r|, what the baseline's free parameters and offsets leave (sqrt of the noncentrality).
    - `residual`: r per reading, in sigmas.
    - `free`: the parameter names the baseline moved.
    """

    signature_sigmas: float
    residual_sigmas: float
    residual: np.ndarray
    free: tuple = eqx.field(static=True)


def _perturbed(gyro: Gyroscope, names, u):
    leaves = []
    for i, name in enumerate(names):
        p = PARAMETERS[name]
        value = p.where(gyro)
        leaves.append(value * jnp.exp(u[i]) if p.transform == "log" else value + p.scale * u[i])
    return eqx.tree_at(lambda g: tuple(PARAMETERS[n].where(g) for n in names), gyro, tuple(leaves))


def baseline_jacobian(reading, gyro: Gyroscope, free) -> jnp.ndarray:
    """d reading / d u for the named `free` parameters (`gyrojax.PARAMETERS`, internal coordinates), forward
    mode through the steady tier's implicit derivative; shape (readings, len(free))."""
    names = tuple(n for n in free if PARAMETERS[n].exists_on(gyro))
    if not names:
        return jnp.zeros((jnp.size(reading(gyro)), 0))

    @jit
    def jac(gyro):
        return jax.jacfwd(lambda u: jnp.ravel(reading(_perturbed(gyro, names, u))))(jnp.zeros(len(names)))

    return jac(gyro)


def absorption(reading, gyro: Gyroscope, with_effect: Gyroscope, sigma, *, free=(), offsets=None) -> Absorption:
    """The fingerprint of `with_effect` against `gyro` on `reading` and what a baseline fit leaves of it.

    **Arguments:**

    - `reading`: a function from a device to a 1-d array of readings (noise-free).
    - `gyro`: the baseline device; `with_effect`: the same device with the effect added.
    - `sigma`: standard uncertainty of each reading (same shape, or a scalar).
    - `free`: names of `gyrojax.PARAMETERS` the baseline fits (those the device lacks are skipped).
    - `offsets`: nuisance columns the baseline fits too, shape (readings, k): a per-run bias is a column of
      ones on that run's readings, a meter gain the reading itself.

    **Returns:** an `Absorption`.
    """
    compiled = jit(reading)
    y0 = np.ravel(np.asarray(compiled(gyro), dtype=float))
    sigma = np.broadcast_to(np.asarray(sigma, dtype=float), y0.shape)
    d = (np.ravel(np.asarray(compiled(with_effect), dtype=float)) - y0) / sigma
    names = tuple(n for n in free if PARAMETERS[n].exists_on(gyro))
    columns = [np.asarray(baseline_jacobian(reading, gyro, names), dtype=float)]
    if offsets is not None:
        columns.append(np.asarray(offsets, dtype=float).reshape(y0.size, -1))
    j = np.concatenate(columns, axis=1) / sigma[:, None]
    # A column that moves the reading by less than NEGLIGIBLE sigma for a natural-size change (u = 1) is
    # round-off of a reading the parameter does not reach (e.g. the rate channel's answer to a quadrature
    # injection at phi = 0: ~1e-14 LSB); scaled to unit norm it would be a random direction that absorbs.
    scale = np.linalg.norm(j, axis=0)
    j = j[:, scale > NEGLIGIBLE]
    if j.shape[1]:
        # Column-scaled least squares; a rank-deficient J (two parameters moving the reading alike) is fine.
        unit = j / np.linalg.norm(j, axis=0)
        coef, *_ = np.linalg.lstsq(unit, d, rcond=1e-10)
        r = d - unit @ coef
    else:
        r = d
    return Absorption(float(np.linalg.norm(d)), float(np.linalg.norm(r)), r, names)


def run_offsets(groups) -> np.ndarray:
    """Columns of ones, one per distinct value of `groups` (a per-run bias for each run label)."""
    groups = np.asarray(groups)
    return np.stack([(groups == g).astype(float) for g in np.unique(groups)], axis=1)
