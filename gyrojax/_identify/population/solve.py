"""`PopulationSolve`: the lot strategy of a population fit, its settings and their checks."""

from typing import ClassVar

import equinox as eqx
from jaxtyping import Array, ArrayLike, Float

from ..._model.parameters import PARAMETERS
from ..evaluation import Evaluation
from ..problem import Problem
from ..strategies import AbstractLotSolve, LotSpread, Solver, VmapSolve


class PopulationSolve(AbstractLotSolve):
    """A population fit of the lot: `random` per-device parameters are drawn from a lot distribution whose mean
    and spread are estimated with them; each device's estimate is shrunk toward the lot by the fit. `identify`
    then returns a `PopulationFit` (see `gyrojax/_identify/population/` for the method).

    **Arguments:**

    - `random`: names of `gyrojax.PARAMETERS` fitted per device as random effects; `None`: every per-device
      physical parameter a first independent fit leaves free.
    - `max_refits`: most refits of the lot with the population prior (each one vmapped fit).
    - `tol`: convergence: mu and log s move by less than this many of their standard errors.
    - `start_spread`: the weak prior of the first fit, as a spread in the fit's coordinates (relative for
      `"log"` parameters, in `Parameter.scale` for `"linear"` ones).
    - `propagate`: add the uncertainty of the lot mean and spread to each device's scale factor (2 refits per
      random parameter).
    - `em_steps`: most EM iterations per estimate of mu and s.
    - `vmap`: the `VmapSolve` that solves every fit.
    """

    random: tuple[str, ...] | None = eqx.field(static=True, default=None)
    max_refits: int = eqx.field(static=True, default=8)
    tol: float = eqx.field(static=True, default=0.01)
    start_spread: float = eqx.field(static=True, default=0.3)
    propagate: bool = eqx.field(static=True, default=True)
    em_steps: int = eqx.field(static=True, default=200_000)
    vmap: VmapSolve = VmapSolve()
    joint: ClassVar[bool] = False

    def __check_init__(self):
        if self.random is not None and (isinstance(self.random, str) or not self.random
                                        or not all(isinstance(r, str) for r in self.random)):
            raise ValueError(f"PopulationSolve: random must be a non-empty tuple of parameter names or None, got "
                             f"{self.random!r}.")
        for name in self.random or ():
            if name not in PARAMETERS:
                raise ValueError(f"PopulationSolve: unknown parameter {name!r} in random; expected per-device "
                                 f"physical parameters of gyrojax.PARAMETERS ({', '.join(PARAMETERS)}).")
        if not (isinstance(self.max_refits, int) and self.max_refits >= 1):
            raise ValueError(f"PopulationSolve: max_refits must be an integer >= 1, got {self.max_refits!r}.")
        if not (isinstance(self.tol, (int, float)) and self.tol > 0):
            raise ValueError(f"PopulationSolve: tol must be > 0, got {self.tol!r}.")
        if not (isinstance(self.start_spread, (int, float)) and self.start_spread > 0):
            raise ValueError(f"PopulationSolve: start_spread must be > 0, got {self.start_spread!r}.")

    def spread(self, n: int) -> LotSpread:
        return self.vmap.spread(n)

    def solve(self, problem: Problem, spread: LotSpread, u0: Float[ArrayLike, "device dev"],
              u_lot0: Float[ArrayLike, " lot"], solver: Solver, max_steps: int | Array
              ) -> tuple[Array, Array, Array, Array, Array, Evaluation]:
        return self.vmap.solve(problem, spread, u0, u_lot0, solver, max_steps)
