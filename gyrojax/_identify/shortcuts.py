"""The strings `identify` accepts for its strategy objects, mapped in this one place: solver names
(`solver="levenberg-marquardt"`) and the lot options (`lot_solve`, `shard`, `lot_chunk`)."""

import lineax as lx
import optimistix as optx

from .._linsolve import PivotedLU
from .._lm import LevenbergMarquardt
from .lot import AbstractLotSolve, JointSolve, LoopSolve, VmapSolve


SOLVERS = ("levenberg-marquardt", "gauss-newton", "bfgs")
"""The solver names `identify(solver=...)` accepts besides an optimistix solver."""

LOT_SOLVES = ("vmap", "loop")
"""The names `identify(lot_solve=...)` accepts."""


def solver_from(solver, rtol, atol):
    """The optimistix solver a name of `SOLVERS` stands for (with `rtol`, `atol`); a solver object as it is."""
    if not isinstance(solver, str):
        return solver
    # Normal equations through an XLA-only LU, not lineax's LAPACK QR: see gyrojax/_linsolve.py.
    linear_solver = lx.Normal(PivotedLU(zero_pivot_gives_zero=True))
    if solver == "levenberg-marquardt":
        return LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=linear_solver)
    if solver == "gauss-newton":
        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=linear_solver)
    if solver == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    raise ValueError(f"solver must be one of {SOLVERS} or an optimistix solver, got {solver!r}.")


def check_lot_options(lot_solve, shard, lot_chunk) -> None:
    """Raise a `ValueError` naming the argument for a `lot_solve`, `shard` or `lot_chunk` `identify` cannot take."""
    if isinstance(lot_solve, AbstractLotSolve):
        if shard is not None or lot_chunk != "auto":
            raise ValueError(f"shard and lot_chunk go into the lot strategy when lot_solve is one "
                             f"({type(lot_solve).__name__}(...)); got shard={shard!r}, lot_chunk={lot_chunk!r}.")
        return
    if lot_solve not in LOT_SOLVES:
        raise ValueError(f"lot_solve must be a lot strategy (VmapSolve, LoopSolve, JointSolve) or one of "
                         f"{LOT_SOLVES}, got {lot_solve!r}.")
    if shard and lot_solve == "loop":
        raise ValueError("shard=True needs lot_solve='vmap' (the loop solves one device at a time).")
    if lot_chunk != "auto" and lot_chunk is not None and (not isinstance(lot_chunk, int) or lot_chunk < 1):
        raise ValueError(f"lot_chunk must be 'auto', None or an integer >= 1, got {lot_chunk!r}.")


def lot_solve_from(lot_solve, shard, lot_chunk, *, joint: bool) -> AbstractLotSolve:
    """The lot strategy of `identify`'s `lot_solve`, `shard` and `lot_chunk` (checked by `check_lot_options`),
    for a fit with shared parameters (`joint`) or without; a strategy object as it is, if it fits."""
    if isinstance(lot_solve, AbstractLotSolve):
        if lot_solve.joint != joint:
            raise ValueError(f"lot_solve={type(lot_solve).__name__}(...) "
                             + ("solves devices independently, but shared parameters need JointSolve()."
                                if joint else "is a joint solve, which needs shared parameters (shared=...)."))
        return lot_solve
    if lot_chunk not in ("auto", None) and (joint or lot_solve == "loop"):
        raise ValueError("lot_chunk applies to the vmapped solve of independent devices on one JAX device; "
                         "drop it, or drop shard / shared / lot_solve='loop'.")
    if joint:
        return JointSolve(shard=shard if lot_solve == "vmap" else False)
    if lot_solve == "loop":
        return LoopSolve()
    return VmapSolve(chunk=lot_chunk, shard=shard)
