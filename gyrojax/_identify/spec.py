"""`FitSpec`: how a fit is made (what is free, shared and held, the priors, the starts, the solver, the recovery
policies, how the lot is solved), as one object that `identify`, `diagnose` and `plan` accept whole, so that a
choice made once reaches every fit a verb makes."""

import dataclasses
from collections.abc import Iterable

import equinox as eqx
import numpy as np

from .._gyroscope import Gyroscope
from .._model.fitdata import FitData
from .._model.parameters import DEFAULT_FREE
from .._simulate.tiers import Steady
from .._sweeps.base import AbstractSweep
from .recovery import RECOVERY, AbstractRecovery, MultiStart


class FitSpec(eqx.Module):
    """How a fit is made; each field as the `identify` keyword of the same name (its default too).

    - `free`, `shared`, `hold`, `priors`: what is fitted per device, fitted once for the lot, held at its
      start, and the Gaussian priors. `free=None`: `gyrojax.identification.default_free(device, data)`, the
      default free parameters and those the data's sweep kinds read on the device.
    - `tier`: the settling tier of rate-table and static-VCF points.
    - `solver`, `rtol`, `atol`, `max_steps`: the solver (a name or an optimistix solver) and its stopping.
    - `start`: the first solve (`gyrojax.MultiStart`).
    - `lot_solve`: how the lot's devices are solved (a strategy or `"vmap"`, `"loop"`).
    - `recovery`: the `gyrojax.AbstractRecovery` policies tried after the first solve, in turn.
    - `identifiability_threshold`, `reject_alpha`: what the data cannot fix, and the chi2 test's level.

    `diagnose` and `plan` hold their candidate effects on top of `hold`, and `plan` frees on top of `free` the
    parameters its experiments read.
    """

    free: tuple | None = None
    shared: tuple = ()
    hold: tuple = ()
    priors: dict | None = None
    tier: object = Steady()
    solver: object = "levenberg-marquardt"
    rtol: float = 1e-8
    atol: float = 1e-8
    max_steps: int = 200
    start: MultiStart = MultiStart()
    lot_solve: object = "vmap"
    recovery: tuple = RECOVERY
    identifiability_threshold: float = 1.0
    reject_alpha: float = 0.01

    def __check_init__(self):
        if not (isinstance(self.reject_alpha, (int, float)) and 0.0 < self.reject_alpha < 1.0):
            raise ValueError(f"reject_alpha must be a significance level in (0, 1), got {self.reject_alpha!r}.")
        if (not isinstance(self.max_steps, (int, np.integer)) or isinstance(self.max_steps, bool)
                or self.max_steps < 1):
            raise ValueError(f"max_steps must be an integer >= 1, got {self.max_steps!r}.")
        if not isinstance(self.start, MultiStart):
            raise TypeError(f"start must be a gyrojax.MultiStart, got {type(self.start).__name__}.")
        if isinstance(self.recovery, AbstractRecovery) or not all(isinstance(r, AbstractRecovery)
                                                                   for r in self.recovery):
            raise TypeError(f"recovery must be a tuple of gyrojax.AbstractRecovery policies, got {self.recovery!r}.")

    def holding(self, names: Iterable[str]) -> "FitSpec":
        """This spec with `names` held too (after its own `hold`)."""
        return dataclasses.replace(self, hold=tuple(self.hold) + tuple(names))

    def options(self) -> dict:
        """The fields as `identify` keywords."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


def default_free(gyro: Gyroscope, data: FitData) -> tuple[str, ...]:
    """The baseline's free parameters for `data` on the device `gyro`: `DEFAULT_FREE`, then each parameter a
    sweep kind of the data reads there (`AbstractSweep.reads_on`: the drive frequency's omega_x, a closed-loop
    dynamic VCF's angular gain) that the standard sweeps leave to the design. The identifiability check holds
    any the data still cannot fix."""
    return free_reading((data.kind(s) for s in data.sweeps), gyro)


def free_reading(kinds: Iterable[AbstractSweep], gyro: Gyroscope) -> tuple[str, ...]:
    """`DEFAULT_FREE` and what the sweep kinds `kinds` read on `gyro` (`default_free` of data with them)."""
    read = (p for kind in kinds for p in kind.reads_on(gyro))
    return tuple(dict.fromkeys((*DEFAULT_FREE, *read)))


_DEFAULTS = {f.name: f.default for f in dataclasses.fields(FitSpec)}


def _is_default(value, default) -> bool:
    if value is default:
        return True
    try:
        return type(value) is type(default) and bool(value == default)
    except (TypeError, ValueError):  # an array's comparison has no single truth value: not the default
        return False


def fit_spec(spec: FitSpec | None, who: str, **given) -> FitSpec:
    """`spec`, or, where it is None, the `FitSpec` of a verb's own fit keywords `given`. A keyword given with a
    value other than its default beside `spec` is refused: one of the two would be ignored."""
    if spec is None:
        return FitSpec(**given)
    if not isinstance(spec, FitSpec):
        raise TypeError(f"{who}: spec must be a gyrojax.FitSpec, got {type(spec).__name__}.")
    both = [k for k, v in given.items() if not _is_default(v, _DEFAULTS[k])]
    if both:
        raise ValueError(f"{who}: {', '.join(both)} given as keyword(s) beside spec; give each in spec only "
                         f"(spec=gyrojax.FitSpec({both[0]}=...)).")
    return spec
