"""The named physical parameters of a device that a fit can free (`gyrojax.PARAMETERS`): where each lives in the
device, its transform and natural scale, its unit and its plausible range."""

from collections.abc import Callable

import equinox as eqx

from .._gyroscope import Gyroscope


class Parameter(eqx.Module):
    """One named physical parameter of a device.

    **Fields:**

    - `name`: the name used in specs and reports.
    - `where`: a function from the `Gyroscope` to the leaf (as for `eqx.tree_at`).
    - `transform`: `"log"` or `"linear"` (see the module docstring).
    - `scale`: natural size of a change for `"linear"` parameters (in `unit`); unused for `"log"`.
    - `unit`, `description`: for reports.
    - `closed_loop_only`, `open_loop_only`: which devices have it.
    - `plausible`: how far a fitted value may lie from its design (start) value and still be a device of this
      design: a factor for `"log"` parameters (within [design / plausible, design x plausible]), an absolute
      deviation in `unit` for `"linear"` ones; `None`: no bound. `identify` flags a fitted value outside it.
    - `plausible_why`: where that range comes from, in one line.
    """

    name: str = eqx.field(static=True)
    where: Callable = eqx.field(static=True)
    transform: str = eqx.field(static=True)
    scale: float = eqx.field(static=True, default=1.0)
    unit: str = eqx.field(static=True, default="")
    description: str = eqx.field(static=True, default="")
    closed_loop_only: bool = eqx.field(static=True, default=False)
    open_loop_only: bool = eqx.field(static=True, default=False)
    plausible: float | None = eqx.field(static=True, default=None)
    plausible_why: str = eqx.field(static=True, default="")

    def __check_init__(self):
        if self.transform not in ("log", "linear"):
            raise ValueError(f"Parameter {self.name!r}: transform must be 'log' or 'linear', got {self.transform!r}.")
        if self.plausible is not None and not (self.plausible > (1.0 if self.transform == "log" else 0.0)):
            raise ValueError(f"Parameter {self.name!r}: plausible must be a factor > 1 for a 'log' parameter or a "
                             f"deviation > 0 for a 'linear' one, got {self.plausible!r}.")

    def exists_on(self, gyro: Gyroscope) -> bool:
        return not ((self.closed_loop_only and not gyro.closed_loop)
                    or (self.open_loop_only and gyro.closed_loop))


def _p(name, where, transform, *, scale=1.0, unit="", description="", closed=False, opened=False, plausible=None,
       why=""):
    return Parameter(name, where, transform, scale, unit, description, closed, opened, plausible, why)


PARAMETERS: dict[str, Parameter] = {p.name: p for p in (
    # The order is the order of preference when a combination is unidentifiable: earlier names stay free,
    # later ones are held (e.g. a rate table alone sees only Ag m a w / K_vf: K_vf is fitted, Ag held).
    _p("k_vf", lambda g: g.feedback_electrode.k_vf, "log", unit="N/V", closed=True,
       description="force per volt of the FTR feedback combs (seed 000 Eq. 2)", plausible=2.0,
       why="comb gaps and thickness vary by percents over a wafer, not by a factor of 2"),
    _p("sense_gain", lambda g: g.sense_frontend.gain, "log", unit="V/C or V/A", opened=True,
       description="gain of the sense front end (open-loop scale factor)", plausible=2.0,
       why="front-end gains are set by resistors and capacitors good to 1-20 %, not to a factor of 2"),
    _p("vcf_gain", lambda g: g.vcf_electrode.force_per_volt2, "log", unit="N/V^2",
       description="virtual-Coriolis electrode factor K_svf (seed 003 Eq. 7)", plausible=2.0,
       why="an electrode factor scales with gap and thickness, which vary by percents (seed 003 measured 1.76x "
           "its Eq. 7 design value: inside 2)"),
    _p("dac_gain_error", lambda g: g.excitation.dac.gain_error, "linear", scale=1e-3, closed=True,
       description="relative gain error of the FTR DAC", plausible=0.05,
       why="a DAC's gain error, reference included, is below 1 % for any data-sheet grade; 5 % is generous"),
    _p("omega_y", lambda g: g.resonator.omega_y, "log", unit="rad/s", description="sense resonance", plausible=1.25,
       why="resonances land within ~10 % of design over process corners (stiffness and mass move together)"),
    _p("q_y", lambda g: g.resonator.q_y, "log", description="sense quality factor", plausible=10.0,
       why="Q follows the package vacuum and the anchors, which vary by several times between parts"),
    _p("omega_x", lambda g: g.resonator.omega_x, "log", unit="rad/s", description="drive resonance", plausible=1.25,
       why="resonances land within ~10 % of design over process corners (stiffness and mass move together)"),
    _p("q_x", lambda g: g.resonator.q_x, "log", description="drive quality factor", plausible=10.0,
       why="Q follows the package vacuum and the anchors, which vary by several times between parts"),
    _p("angular_gain", lambda g: g.resonator.angular_gain, "log", description="angular gain Ag", plausible=2.0,
       why="Ag is a mode-shape ratio between 0.5 and 1 for vibratory gyroscopes"),
    _p("mass", lambda g: g.resonator.mass, "log", unit="kg", description="modal mass", plausible=1.5,
       why="mass follows the structural thickness and the etch, good to ~10 % over a wafer"),
    _p("drive_force_per_volt", lambda g: g.drive_electrode.force_per_volt, "log", unit="N/V",
       description="drive comb force per volt", plausible=2.0,
       why="comb gaps and thickness vary by percents over a wafer, not by a factor of 2"),
    _p("stiffness_coupling", lambda g: g.resonator.stiffness_coupling, "linear", scale=1e3, unit="rad^2/s^2",
       description="stiffness (quadrature) coupling kap", plausible=1e6,
       why="about 1000 deg/s of quadrature-equivalent rate at 5-10 kHz: the upper end of untrimmed MEMS "
           "quadrature"),
)}
"""The named physical parameters a fit can free, in order of preference."""


DEFAULT_FREE = ("k_vf", "sense_gain", "vcf_gain", "dac_gain_error", "omega_y", "q_y")
"""What the baseline frees per device before the identifiability check holds what the data cannot see."""
