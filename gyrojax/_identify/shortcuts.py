"""The strings `identify` accepts for its strategy objects, mapped in this one place: solver names
(`solver="levenberg-marquardt"`) and the lot strategies (`lot_solve="vmap"`)."""

import optimistix as optx

from .._numerics.lm import LevenbergMarquardt
from .strategies import AbstractLotSolve, JointSolve, LoopSolve, VmapSolve


SOLVERS = ("levenberg-marquardt", "gauss-newton", "bfgs")
"""The solver names `identify(solver=...)` accepts besides an optimistix solver."""

LOT_SOLVES = ("vmap", "loop")
"""The names `identify(lot_solve=...)` accepts."""


def solver_from(solver, rtol, atol):
    """The optimistix solver a name of `SOLVERS` stands for (with `rtol`, `atol`); a solver object as it is."""
    if not isinstance(solver, str):
        return solver
    if solver == "levenberg-marquardt":
        return LevenbergMarquardt(rtol=rtol, atol=atol)
    if solver == "gauss-newton":
        # optimistix's GaussNewton step, as a flag of the Levenberg-Marquardt solver: one compiled solve for both.
        return LevenbergMarquardt(rtol=rtol, atol=atol, undamped=True)
    if solver == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    raise ValueError(f"solver must be one of {SOLVERS} or an optimistix solver, got {solver!r}.")


def lot_solve_from(lot_solve, *, joint: bool) -> AbstractLotSolve:
    """The lot strategy of `identify(lot_solve=...)` for a fit with shared parameters (`joint`) or without: a
    strategy object as it is, if it fits; `"vmap"`: `VmapSolve()` (`JointSolve()` if joint), `"loop"`:
    `LoopSolve()` (`JointSolve(shard=False)` if joint)."""
    if isinstance(lot_solve, AbstractLotSolve):
        if lot_solve.joint != joint:
            raise ValueError(f"lot_solve={type(lot_solve).__name__}(...) "
                             + ("solves devices independently, but shared parameters need JointSolve()."
                                if joint else "is a joint solve, which needs shared parameters (shared=...)."))
        return lot_solve
    if lot_solve not in LOT_SOLVES:
        raise ValueError(f"lot_solve must be a lot strategy (VmapSolve, LoopSolve, JointSolve) or one of "
                         f"{LOT_SOLVES}, got {lot_solve!r}.")
    if joint:
        return JointSolve() if lot_solve == "vmap" else JointSolve(shard=False)
    return LoopSolve() if lot_solve == "loop" else VmapSolve()
