"""What `identify` tries when a solve ends badly, as small policies: `MultiStart` makes the first solution (the
lowest chi2 of several starts), then each `AbstractRecovery` in turn may improve it: `DecrementCertificate`
accepts a solve stopped at `max_steps` that a Gauss-Newton step would barely improve, `RetryWithSolver`
re-solves a device that did not converge with another solver, `RestartRunoffs` re-solves a device that ran off
along a direction the data no longer fix. A new policy is one more `AbstractRecovery` here, composed in
`identify`."""

import abc
import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._solution import RESULTS, result_code
from .covariance import gauss_newton_decrement
from .evaluation import Evaluation
from .identifiability import weak_directions
from .problem import Problem
from .shortcuts import solver_from
from .strategies import Lot, Solver


class Solving(eqx.Module):
    """What the policies solve with: the problem (held parameters masked), the lot strategy and the solver."""

    problem: Problem
    lot: Lot
    solver: Solver
    solver_name: object  # as given to identify: a name of SOLVERS, or the solver
    max_steps: int = eqx.field(static=True)
    n_lot: int = eqx.field(static=True)  # shared entries (a joint fit)
    free_index: tuple[int, ...] = eqx.field(static=True)
    names_dev: tuple[str, ...] = eqx.field(static=True)
    threshold: float

    def full(self, u_free) -> np.ndarray:
        """The full internal vector of the solver's `u_free`: held entries at 0 (their start)."""
        return np.asarray(u_free) * np.asarray(self.problem.free_mask)

    def solve(self, u0: np.ndarray, u_lot0: np.ndarray, stage: str, *, problem: Problem | None = None,
              solver: Solver | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, Evaluation]:
        """The lot strategy's solve from `u0`, `u_lot0`: numpy `(u, u_lot, code, steps, chi2)` per device and
        the `Evaluation` at the solution."""
        return self.lot.solve(self.problem if problem is None else problem, u0, u_lot0,
                              self.solver if solver is None else solver, self.max_steps, stage)


class Solution(eqx.Module):
    """Where a fit stands: the solver's coordinates `u_free` (device, n_dev) and `u_lot`, each device's result
    `code`, `steps` and `chi2`, the `notes` its message gets, and the evaluation `final` at `u_full`."""

    u_free: np.ndarray
    u_lot: np.ndarray
    code: np.ndarray
    steps: np.ndarray
    chi2: np.ndarray | None
    u_full: np.ndarray
    final: Evaluation
    notes: tuple[str, ...] = eqx.field(static=True)


def _pick(better, new, old):
    """Per device (leading axis of every leaf), `new` where `better`, else `old`."""
    better = np.asarray(better)

    def where(a, b):
        cond = better.reshape(better.shape + (1,) * (np.ndim(b) - 1))
        return np.where(cond, a, b) if isinstance(b, np.ndarray) else jnp.where(cond, a, b)

    return jax.tree.map(where, new, old)


def _better(new, old):
    """Per device, whether the chi2 `new` is below `old` (NaN counts as infinite)."""
    return np.nan_to_num(new, nan=np.inf) < np.nan_to_num(old, nan=np.inf)


class MultiStart(eqx.Module):
    """The first solve of `identify(start=...)`: `starts` solves per device, the first from the model, the
    others perturbed by `spread` in internal units (drawn with `seed`); the lowest chi2 wins, per device (for a
    joint fit: the lot's sum). `seed` also seeds the Monte Carlo of the noise estimate of data without
    `output_sigma`, per device with its position in the lot; `first_device` is the position of the first
    device where the lot is a chunk of a larger one (`identify_lot`), so that a chunk draws what one fit of the
    whole lot draws for the same devices."""

    starts: int = eqx.field(static=True, default=1)
    spread: float = 0.05
    seed: int = eqx.field(static=True, default=0)
    first_device: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        if not isinstance(self.starts, int) or isinstance(self.starts, bool) or self.starts < 1:
            raise ValueError(f"starts must be an integer >= 1, got {self.starts!r}.")
        if not isinstance(self.first_device, int) or isinstance(self.first_device, bool) or self.first_device < 0:
            raise ValueError(f"first_device must be an integer >= 0, got {self.first_device!r}.")

    def __call__(self, solving: Solving) -> Solution:
        n, n_dev = solving.problem.free_mask.shape
        n_lot = solving.n_lot
        free_index = list(solving.free_index)
        rng = np.random.default_rng(self.seed)
        joint = solving.lot.joint
        best = None
        for k in range(self.starts):
            # The solve runs over every per-device entry (held ones masked out of the model), so that a model's
            # compiled solve is shared by every choice of free parameters (diagnose adds effects by unmasking).
            u0 = np.zeros((n, n_dev))
            if k > 0:
                u0[:, free_index] = rng.normal(scale=self.spread, size=(n, len(free_index)))
            u0_lot = np.zeros(0)
            if joint:
                u0_lot = np.zeros(n_lot) if k == 0 else rng.normal(scale=self.spread, size=n_lot)
            res = solving.solve(u0, u0_lot, f"during the {'joint ' if joint else ''}solve (start {k})")
            if best is None:
                best = res
            elif joint:
                if np.nansum(res[4]) < np.nansum(best[4]):
                    best = res
            else:
                # Per device: the lower chi2 wins (u_lot, index 1, is empty here: no device axis to pick on).
                (u, _, *rest), (u_b, u_lot, *rest_b) = res, best
                u, *rest = _pick(_better(res[4], best[4]), (u, *rest), (u_b, *rest_b))
                best = (u, u_lot, *rest)
        if best is None:
            raise ValueError(f"MultiStart: starts must be >= 1, got {self.starts!r}.")
        u_free, u_lot, code, steps, chi2, final = best
        return Solution(u_free, u_lot, code, steps, chi2, solving.full(u_free), final, ("",) * n)


class AbstractRecovery(eqx.Module):
    """A policy that may improve a solution after the first solve: `identify(recovery=...)` applies each of a
    tuple of them in turn."""

    @abc.abstractmethod
    def __call__(self, solving: Solving, solution: Solution) -> Solution:
        """The solution improved where the policy applies, with a note on each device it changed."""


class DecrementCertificate(AbstractRecovery):
    """A solve that stopped at `max_steps` counts as converged when a full Gauss-Newton step from where it
    stopped would lower chi2 by less than `tol` (the point is then within sqrt(tol) standard errors of the
    minimum); the solver's own test can keep failing on the round-off of the steady-state solves (the
    Gauss-Newton decrement r^T J (J^T J)^+ J^T r)."""

    tol: float = 1e-6

    def __call__(self, solving: Solving, solution: Solution) -> Solution:
        final, code = solution.final, solution.code
        stopped = (code == result_code(RESULTS.nonlinear_max_steps_reached)) & (np.asarray(final.failed) == 0)
        if not stopped.any():
            return solution
        decrement = gauss_newton_decrement(np.asarray(final.jac)[:, :, list(solving.free_index)],
                                           np.asarray(final.jac_lot), np.asarray(final.residuals),
                                           joint=bool(solving.lot.joint))
        certified = stopped & (decrement < self.tol)
        notes = tuple(f"stopped at max_steps={solving.max_steps}, where a full Gauss-Newton step would lower chi2 "
                      f"by only {dec:.3g} < tol={self.tol:g}" if c else note
                      for note, c, dec in zip(solution.notes, certified, decrement))
        code = np.where(certified, result_code(RESULTS.successful), code)
        return dataclasses.replace(solution, code=code, notes=notes)


class RetryWithSolver(AbstractRecovery):
    """A device whose solve did not converge (e.g. Levenberg-Marquardt crawling to `max_steps` in a curved
    valley) is solved again from its start with the solver named `solver` (`"gauss-newton"`,
    `"levenberg-marquardt"` or `"bfgs"`, with `rtol`, `atol`; None: `identify`'s); the retry is kept where it
    converged at no higher chi2, and the device's message says so (a joint fit is retried as a whole: all
    devices or none). `identify` applies it only after a named solver other than this one."""

    solver: str = eqx.field(static=True, default="gauss-newton")
    rtol: float | None = None
    atol: float | None = None

    def __call__(self, solving: Solving, solution: Solution) -> Solution:
        # Levenberg-Marquardt can crawl where a full Gauss-Newton step would not (measured: a leaky-rebalance
        # paper-qmg lot with comb_gap free, LM 200 steps at chi2_red 6.3, Gauss-Newton 10 steps to 1.02).
        ok = result_code(RESULTS.successful)
        failed = solution.code != ok
        if not failed.any():
            return solution
        n, n_dev = solution.u_free.shape
        u_lot0 = np.zeros(solving.n_lot if solving.lot.joint else 0)
        v, v_lot, code2, steps2, chi2_2, final2 = solving.solve(
            np.zeros((n, n_dev)), u_lot0, f"during the {self.solver} retry",
            solver=solver_from(self.solver, self.rtol, self.atol))
        u_lot, chi2 = solution.u_lot, solution.chi2
        if chi2 is None:  # an evaluation without a solve has every code successful, so it returned above
            raise ValueError("RetryWithSolver: the solution to retry has no chi2 (an evaluation, not a solve).")
        if solving.lot.joint:
            total, total_2 = (np.sum(np.nan_to_num(c, nan=np.inf)) for c in (chi2, chi2_2))
            better = np.full(n, bool(np.all(code2 == ok)) and total_2 <= total * (1 + 1e-6))
            if better[0]:
                u_lot = v_lot
        else:
            better = failed & (code2 == ok) & (np.nan_to_num(chi2_2, nan=np.inf) <=
                                               np.nan_to_num(chi2, nan=np.inf) * (1 + 1e-6))
        u_free = np.where(better[:, None], v, solution.u_free)
        notes = tuple(f"re-solved from the start with {self.solver} after {solving.solver_name} did not converge"
                      if b else note for note, b in zip(solution.notes, better))
        final = _pick(better, final2, solution.final)
        return Solution(u_free, u_lot, np.where(better, code2, solution.code),
                        np.where(better, solution.steps + steps2, solution.steps), np.where(better, chi2_2, chi2),
                        solving.full(u_free), final, notes)


class RestartRunoffs(AbstractRecovery):
    """A device whose solution leaves a direction the data no longer fix (a parameter run off towards 0 or
    infinity, e.g. an open-loop Q_y whose steep sense resonance the first steps overshot) is solved again from
    its start with that direction held, then released from there; the lower chi2 wins, and its message says
    so. Independent fits only (costs two more solves when it fires)."""

    def __call__(self, solving: Solving, solution: Solution) -> Solution:
        if solving.lot.joint:
            return solution
        free_index = list(solving.free_index)
        weak = weak_directions(np.asarray(solution.final.jac)[:, :, free_index], solving.threshold)
        runoff = [sorted({free_index[k] for members, _ in w for k in members}) for w in weak]
        if not any(runoff):
            return solution
        stage = "during the restart of a run-off fit"
        held_mask = np.array(solving.problem.free_mask)
        u_hold = np.array(solution.u_free)
        for d, idx in enumerate(runoff):
            held_mask[d, idx] = 0.0
            if idx:
                u_hold[d] = 0.0  # from the start again
        held = eqx.tree_at(lambda p: p.free_mask, solving.problem, jnp.asarray(held_mask))
        v1, _, steps1, _, _, _ = solving.solve(u_hold, np.zeros(0), stage, problem=held)
        v2, _, code2, steps2, chi2_2, final2 = solving.solve(v1, np.zeros(0), stage)
        better = np.array([bool(idx) for idx in runoff]) & _better(chi2_2, solution.chi2)
        if not better.any():
            return solution
        u_free = np.where(better[:, None], v2, solution.u_free)
        final = _pick(better, final2, solution.final)
        names = [", ".join(solving.names_dev[i] for i in idx) for idx in runoff]
        notes = tuple("; ".join(filter(None, (note, f"restarted with {nm} held, then released, after the first "
                                                    "solve ran off along it" if b else "")))
                      for note, nm, b in zip(solution.notes, names, better))
        # chi2 stays the first solve's, as before this policy: the Fit recomputes it from `final`.
        return Solution(u_free, solution.u_lot, np.where(better, code2, solution.code),
                        np.where(better, solution.steps + steps1 + steps2, solution.steps), solution.chi2,
                        solving.full(u_free), final, notes)


RECOVERY = (DecrementCertificate(), RetryWithSolver(), RestartRunoffs())
"""`identify`'s default recovery policies, applied in this order."""
