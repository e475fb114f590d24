"""The two-mode Coriolis resonator of seed 000 Eq. (1), per unit mass.

    x'' + (wx/Qx) x' + wx^2 x + c y' + kap y - 2 Ag Om y' = Fx/m - bx x^3
    y'' + (wy/Qy) y' + wy^2 y + c x' + kap x + 2 Ag Om x' = Fy/m - by y^3

`wy` is the sense resonance as operated: with the bias and open-loop tuning voltages applied (seed 000 §5
tunes the 77 Hz as-built split out electrostatically), so the electrostatic spring of the feedback combs at
rest is already inside it.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._checks import check_finite, check_positive


class Resonator(eqx.Module):
    """Drive (x) and sense (y) modes of a Coriolis vibratory gyroscope.

    **Arguments:**

    - `mass`: equivalent (modal) mass, kg.
    - `omega_x`, `omega_y`: drive and sense resonances at `t_ref`, rad/s.
    - `q_x`, `q_y`: quality factors at `t_ref`.
    - `angular_gain`: Ag, the share of the modal mass that carries the Coriolis force.
    - `damping_coupling`: c, 1/s (per unit mass); in phase with the Coriolis force, so it reads as rate.
    - `stiffness_coupling`: kap, rad^2/s^2 (per unit mass); gives quadrature.
    - `duffing_x`, `duffing_y`: cubic stiffness per unit mass, 1/(m^2 s^2); zero for a linear resonator.
    - `tcf`: relative frequency change per kelvin of both modes (silicon: about -30e-6/K).
    - `tcq`: relative Q change per kelvin.
    - `tcf_split`: extra relative change per kelvin of the sense resonance only (the sense mode's TCF is
      `tcf + tcf_split`): the mode split drifts with temperature, which an open-loop gyro amplifies by w/dw.
    - `t_ref`: temperature of the nominal values, deg C.
    """

    mass: float
    omega_x: float
    omega_y: float
    q_x: float
    q_y: float
    angular_gain: float = 1.0
    damping_coupling: float = 0.0
    stiffness_coupling: float = 0.0
    duffing_x: float = 0.0
    duffing_y: float = 0.0
    tcf: float = 0.0
    tcq: float = 0.0
    tcf_split: float = 0.0
    t_ref: float = 25.0

    def __check_init__(self):
        for name in ("mass", "omega_x", "omega_y", "q_x", "q_y", "angular_gain"):
            check_positive("Resonator", name, getattr(self, name))
        for name in ("damping_coupling", "stiffness_coupling", "duffing_x", "duffing_y", "tcf", "tcq",
                     "tcf_split", "t_ref"):
            check_finite("Resonator", name, getattr(self, name))

    def at_temperature(self, temperature: Float[ArrayLike, "*s"]
                       ) -> tuple[Float[Array, "*s"], Float[Array, "*s"], Float[Array, "*s"], Float[Array, "*s"]]:
        """Resonances and Q's at `temperature` (deg C): `(omega_x, omega_y, q_x, q_y)`."""
        dt = jnp.asarray(temperature, dtype=float) - self.t_ref
        f = 1.0 + self.tcf * dt
        f_y = 1.0 + (self.tcf + self.tcf_split) * dt
        q = 1.0 + self.tcq * dt
        return self.omega_x * f, self.omega_y * f_y, self.q_x * q, self.q_y * q
