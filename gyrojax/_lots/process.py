"""A process-level lot: device parameters generated together by the structural thickness, the etch and local
mismatch, so that they co-vary the way the physics makes them (unlike `ProcessSpread`, which draws every leaf
independently).

Why it matters for batch calibration (seed 003): the ratio of the rate-table scale factor to the virtual one is
2 Ag m a w_d / (K_svf V_fc), and m, a and K_svf all move with the thickness h and the critical-dimension (CD)
loss of the etch. With independent draws their spreads simply add; with the process they partly cancel, and
which combinations cancel decides what a virtual-Coriolis (VCF) test can predict.

The model (first order in the process variables, every geometric number an ASSUMPTION in `WaferProcess`):

- thickness h (relative t = h / h0): every electrostatic factor (comb and plate) and the mass scale with h;
  the resonances do not (spring and mass both scale with h).
- CD loss delta (m, about its mean, which the design absorbs): every etched edge recedes by delta, so beams
  narrow (w0 - 2 delta), gaps widen (g0 + 2 delta), and the perforated proof mass loses area
  (A0 - P delta). The spring k ~ E h w^3 and m ~ h A give w ~ (w0 - 2 delta)^(3/2) / sqrt(A).
- electrodes: the drive comb and both pick-off combs (area-varying) go as h / g; the VCF electrode (a
  parallel plate on the sense axis) as h / g^2.
- the AGC holds the drive pick-off signal K_xi a, so the drive amplitude a goes as 1 / K_xi ~ g / h.
- local mismatch: each of Ag, the drive and sense pick-offs, the drive comb and the VCF electrode gets its own
  independent relative error `mismatch` (neighbouring structures of one die are not identical).
- plus, as in `ProcessSpread`: a frequency residual not tied to the CD (Young's modulus, anchors), the mode
  split, and each Q.

Consequences (derived, checked numerically in `experiments/lot_batch_calibration.py`): the open-loop rate-table
scale factor goes as G K_yi Ag a w_d / |sense dynamics| ~ G Ag (1 + mm_yi) / (1 + mm_xi) w_d / |...|: h and
delta cancel between the sense pick-off and the AGC-held amplitude, leaving Ag and the two pick-off mismatches
(`rate_path_sigma`). The ratio SF_rate / SF_virtual ~ Ag A w_d g_p g_e^2 / h keeps h and delta.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from .._checks import check_nonnegative, check_positive
from .._gyroscope import Gyroscope
from .stack import as_arrays


class WaferProcess(eqx.Module):
    """Process variables of one lot (Gaussian, 1-sigma) and the design geometry that maps them onto a device.

    **Fields** (the defaults are ASSUMPTIONS for a lot of seed 003's devices, "machined almost simultaneously",
    seed 003 §3; the reasons are in the comments of the source):

    - `thickness`: relative spread of the structural thickness.
    - `cd_loss`: spread of the CD loss per edge, m.
    - `beam_width`, `comb_gap`, `vcf_gap`: design spring-beam width, comb gap (drive comb and both pick-offs)
      and VCF parallel-plate gap, m.
    - `perimeter_per_area`: etched edge length per area of the perforated proof mass, 1/m.
    - `mismatch`: relative local mismatch of each of Ag, the drive and sense pick-offs, the drive comb and the
      VCF electrode.
    - `omega`: relative frequency residual of both modes not tied to the CD.
    - `split`: the sense resonance relative to the drive's (as `ProcessSpread.split`).
    - `q`: relative spread of each Q.
    """

    thickness: float = 1e-3  # ASSUMPTION: 0.1 % (50 nm on a 50 um SOI device layer) across one batch
    cd_loss: float = 1e-9  # m, ASSUMPTION: 1 nm of CD loss per edge across one batch. Fixed with `thickness`
    #                        and `mismatch` so that the seed-003 ratio spreads by ~0.24 % (1-sigma; 0.240 %
    #                        measured on a 64-device draw), an expected ~0.8 % range over 13 devices: seed 003
    #                        measured 0.79 %, the only
    #                        measured anchor of the part of the lot a VCF test cannot see
    beam_width: float = 5e-6  # m, ASSUMPTION: a typical suspension beam of a 1.8 kHz z-axis gyro
    comb_gap: float = 2.5e-6  # m, ASSUMPTION: comb gap of the drive comb and of both pick-offs
    vcf_gap: float = 2.5e-6  # m, ASSUMPTION: gap of the VCF parallel-plate electrode (seed 003 Fig. 1)
    perimeter_per_area: float = 2e5  # 1/m, ASSUMPTION: a proof mass perforated with ~4 um holes on a 10 um pitch
    mismatch: float = 5e-4  # ASSUMPTION: 0.05 % local mismatch per element; seed-003 spread's Ag figure
    #                         (`SEED003_SPREAD.angular_gain`), neighbouring structures of one die etched together
    omega: float = 1e-3  # ASSUMPTION: 0.1 % (1.8 Hz) from Young's modulus / anchors, as SEED003_SPREAD.omega
    split: float = 1.5e-3  # ASSUMPTION: as SEED003_SPREAD.split (seed 003 §3 names frequency errors first)
    q: float = 0.15  # ASSUMPTION: as SEED003_SPREAD.q (seed 003 §3 names Q first)

    def __check_init__(self):
        for name in ("thickness", "cd_loss", "mismatch", "omega", "split", "q"):
            check_nonnegative("WaferProcess", name, getattr(self, name))
        for name in ("beam_width", "comb_gap", "vcf_gap"):
            check_positive("WaferProcess", name, getattr(self, name))
        check_nonnegative("WaferProcess", "perimeter_per_area", self.perimeter_per_area)

    @property
    def rate_path_sigma(self) -> float:
        """Relative 1-sigma spread of the open-loop rate path G K_yi Ag a that no electrical test sees:
        Ag and the two pick-off mismatches (h and the CD cancel, see the module docstring)."""
        return math.sqrt(3.0) * self.mismatch

    def draw(self, gyro: Gyroscope, n: int, key: PRNGKeyArray) -> Gyroscope:
        """`n` devices drawn around `gyro`: one Gyroscope whose array leaves have a leading axis of size `n`
        (the loops' firmware gains stay those of the design)."""
        if not isinstance(n, int) or n < 1:
            raise ValueError(f"n (number of devices) must be an integer >= 1, got {n!r}.")
        gyro = as_arrays(gyro)
        b = jax.tree.map(lambda x: jnp.broadcast_to(x, (n,) + jnp.shape(x)), gyro)
        k = jax.random.split(key, 12)

        def normal(i):
            return jax.random.normal(k[i], (n,))

        t = 1.0 + self.thickness * normal(0)
        delta = self.cd_loss * normal(1)
        area = 1.0 - self.perimeter_per_area * delta
        comb = t * self.comb_gap / (self.comb_gap + 2.0 * delta)
        plate = t * (self.vcf_gap / (self.vcf_gap + 2.0 * delta)) ** 2
        freq = ((self.beam_width - 2.0 * delta) / self.beam_width) ** 1.5 / jnp.sqrt(area)
        freq = freq * (1.0 + self.omega * normal(2))

        def local(i):
            return 1.0 + self.mismatch * normal(i)

        def leaves(g):
            return (g.resonator.mass, g.resonator.omega_x, g.resonator.omega_y, g.resonator.q_x, g.resonator.q_y,
                    g.resonator.angular_gain, g.drive_electrode.force_per_volt, g.drive_frontend.current_per_velocity,
                    g.sense_frontend.current_per_velocity, g.vcf_electrode.force_per_volt2)

        r = b.resonator
        values = (r.mass * t * area,
                  r.omega_x * freq,
                  r.omega_y * freq * (1.0 + self.split * normal(3)),
                  r.q_x * (1.0 + self.q * normal(4)),
                  r.q_y * (1.0 + self.q * normal(5)),
                  r.angular_gain * local(6),
                  b.drive_electrode.force_per_volt * comb * local(7),
                  b.drive_frontend.current_per_velocity * comb * local(8),
                  b.sense_frontend.current_per_velocity * comb * local(9),
                  b.vcf_electrode.force_per_volt2 * plate * local(10))
        return eqx.tree_at(leaves, b, values)
