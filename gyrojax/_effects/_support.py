"""What a device must have for an effect to act on it, and the error when it does not."""

import jax
import jax.core  # Tracer: jax.core is not imported by `import jax` for type checkers
import jax.numpy as jnp
import numpy as np

from .._gyroscope import Gyroscope


def rebalance_is_leaky(gyro: Gyroscope) -> bool:
    """Whether a closed-loop device's rebalance loop has a finite DC gain (`RebalanceLoop.leak` > 0), so that
    the sense mass keeps a residual motion proportional to the rate.

    With an ideal integrator the settled sense motion is exactly zero and nothing that depends on the sense
    displacement reaches the settled output. A traced leak cannot be checked and counts as leaky; a lot is
    leaky when every device is.
    """
    if gyro.rebalance_loop is None:  # open loop
        return False
    leak = gyro.rebalance_loop.leak
    if isinstance(leak, jax.core.Tracer):
        return True
    return bool(np.all(np.asarray(leak, dtype=float) > 0.0))


def sense_moves(gyro: Gyroscope) -> bool:
    """Whether the settled sense mass moves at the carrier: open loop, or a leaky rebalance loop."""
    return (not gyro.closed_loop) or rebalance_is_leaky(gyro)


def require(name: str, gyro: Gyroscope, supported: bool, needs: str) -> None:
    """Raise a `ValueError` naming the effect and the device when the effect cannot act on it."""
    if not supported:
        raise ValueError(f"effect {name!r} cannot act on device {gyro.name!r}: it needs {needs}.")


def as_parameter(value):
    """An effect parameter as a float64 array (Python numbers included), so that it is differentiable and
    adds to a device leaf without changing its dtype."""
    return jnp.asarray(value, dtype=float)
