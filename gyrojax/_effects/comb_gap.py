"""`comb_gap`: the gap-dependent finger-tip term of the force-feedback combs (seed 000 Eq. 5-7)."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_range
from .._gyroscope import Gyroscope, closed_loop_parts
from ._support import as_parameter, rebalance_is_leaky, require
from .base import AbstractEffect


# ASSUMPTION: seed 000 prints no comb geometry. By `FeedbackElectrode.from_geometry` (Eq. 5-7) the tip share
# of the force gradient is about (b/d0) / (1 + b/d0) for many fingers; a finger-tip width b of half the gap
# gives rho = 1/3, rounded to 0.3. On paper-qmg with a proportional-only rebalance loop (leak 1e4/s, the
# largest residual sense motion its gains allow: 19 nm at 200 deg/s) this is a few ppm of odd cubic
# nonlinearity, a 15 ppm gain change and, through the residual quadrature motion, a few ppm of even term;
# with the preset's ideal integrator it is exactly nothing.
_TYPICAL_GAP_FRACTION = 0.3


class CombGap(AbstractEffect):
    r"""Share rho of the feedback combs' force gradient that comes from the gap-dependent finger-tip term,
    added to `FeedbackElectrode.gap_fraction`:

        C+'(y) = a [(1 - rho) + rho d0^2 / (d0 - y)^2],   C-'(y) = a [(1 - rho) + rho d0^2 / (d0 + y)^2].

    The pair's gain is even in the sense displacement: with a residual sense motion y = Y cos(theta) and the
    rate carrier v = V sin(theta) the feedback gain changes by (3/4) rho (Y/d0)^2, and Y grows with the rate:
    an odd cubic in the scale factor, first order in rho (with a residual quadrature motion too, its cross
    term with the rate motion adds an even term). The residual motion needs a finite DC gain of the
    rebalance loop (`RebalanceLoop.leak` > 0): with an ideal integrator the settled sense mass is exactly at
    rest (seed 000 §3.2: "the sensing force-feedback comb electrodes do not introduce nonlinearity"), so
    `supports` says no for such devices, the presets included. Closed loop only.
    """

    gap_fraction: jnp.ndarray = eqx.field(converter=as_parameter)

    name = "comb_gap"
    description = "gap-dependent finger-tip force of the feedback combs, seen through residual sense motion"
    plugs_into = "feedback_electrode.gap_fraction"
    revealed_by = ("a rate table with the rebalance loop's gain changed between runs (the residual sense motion,"
                   " and the odd cubic with it, scales with the loop's DC gain)")

    def __check_init__(self):
        check_range("CombGap", "gap_fraction", self.gap_fraction, 0.0, 1.0)

    @classmethod
    def supports(cls, gyro: Gyroscope) -> bool:
        return rebalance_is_leaky(gyro)

    def apply(self, gyro: Gyroscope) -> Gyroscope:
        require(self.name, gyro, self.supports(gyro),
                "a closed-loop device whose rebalance loop has a finite DC gain (RebalanceLoop.leak > 0), or "
                "the sense mass never moves and the gap term cannot act")
        fb = closed_loop_parts(gyro, self.name).feedback_electrode
        return eqx.tree_at(lambda g: g.feedback_electrode.gap_fraction, gyro, fb.gap_fraction + self.gap_fraction)

    @classmethod
    def typical(cls, scale: float = 1.0) -> "CombGap":
        return cls(scale * jnp.asarray(_TYPICAL_GAP_FRACTION))
