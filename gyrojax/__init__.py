"""gyrojax: differentiable system identification of MEMS Coriolis vibratory gyroscopes."""

import jax as _jax


# ppm-level work needs float64; gyrojax switches it on at import.
_jax.config.update("jax_enable_x64", True)

from . import _units as units  # noqa: E402
