"""How a lot's devices are solved: the compiled passes over the device axis (one evaluation of residuals,
Jacobians and the scale factor; the solves), the padding that chunks or shards that axis (`LotSpread`), and
the strategies that choose among them (`VmapSolve`, `LoopSolve`, `JointSolve`)."""

import abc
import dataclasses
from typing import ClassVar, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from .._compile.export import cached_program
from .._compile.jit import jit
from .._lots.stack import bucket_size, pad_devices, unpad_devices
from .._numerics.lm import RunoffBound, with_max_steps
from .._solution import RESULTS, result_code
from .evaluation import Evaluation, evaluated, evaluation_step, final_evaluation, one_trace
from .problem import Problem, nonfinite_explained


Solver = optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser
"""What `optimistix.least_squares` takes (gyrojax's Levenberg-Marquardt, Gauss-Newton, BFGS ...)."""


def map_devices(f, chunk, *trees):
    """`f` vmapped over the leading (device) axis of the array leaves of `trees`; with `chunk`, `chunk`
    devices at a time (`jax.lax.map`), which bounds memory, and each chunk's solve stops at its own slowest
    device. The axis must be a multiple of `chunk` (see `LotSpread`)."""
    dynamic, static = eqx.partition(trees, eqx.is_array)

    def g(d):
        return f(*eqx.combine(d, static))

    if chunk is None:
        return jax.vmap(g)(dynamic)
    # By hand rather than lax.map(batch_size=...), whose reshape fails on empty leaves (no priors: (n, 0)).
    n = jax.tree.leaves(dynamic)[0].shape[0]
    split = jax.tree.map(lambda x: x.reshape((n // chunk, chunk) + x.shape[1:]), dynamic)
    out = jax.lax.map(jax.vmap(g), split)
    return jax.tree.map(lambda x: x.reshape((n,) + x.shape[2:]), out)


# A positive parameter e^20 (5e8) times its start has run off: no measurement moves a design value that far, and
# the open-loop Q_y that runs off while omega_y is still wrong (vcf-2018) passes e^20 in its first few steps,
# then creeps on for the rest of max_steps. `RestartRunoffs` takes such a device up from its start.
RUNOFF_LOG = 20.0


def runoff_bound(entries) -> RunoffBound:
    """Where each per-device internal coordinate has run off: `RUNOFF_LOG` for log-transformed parameters,
    never for linear ones (an effect's typical size is a guide, not a limit)."""
    return RunoffBound(jnp.asarray(np.concatenate(
        [np.full(e.size, RUNOFF_LOG if e.transform == "log" else np.inf) for e in entries if not e.shared]
        or [np.zeros(0)])))


def _solve_device(problem, y0, u_lot, solver, max_steps):
    """One device's fit: (solution, result code, steps, chi2, the evaluation there as a tuple of its fields:
    what jax.export can store, see cached_program)."""
    def fn(y, _):
        return evaluated(problem, y, u_lot)

    with one_trace():
        sol = optx.least_squares(fn, solver, y0, runoff_bound(problem.entries), has_aux=True,
                                 max_steps=max_steps, throw=False)
        ev = final_evaluation(sol, fn)
    return (sol.value, result_code(RESULTS.promote(sol.result)), sol.stats["num_steps"], jnp.sum(ev.residuals**2),
            _fields(ev))


def _fields(ev: Evaluation) -> tuple:
    return tuple(getattr(ev, f.name) for f in dataclasses.fields(ev))


def _solve_each(problem_batch, u0, u_lot, solver, max_steps, chunk):
    return map_devices(lambda p, y0: _solve_device(p, y0, u_lot, solver, max_steps), chunk, problem_batch, u0)


_solve_independent = cached_program("solve_independent", _solve_each)


_solve_one = jit(_solve_device)


def _solve_loop(problem_batch, u0, u_lot, solver, max_steps, chunk=None):
    """Device by device (one compiled single-device solve): see `LoopSolve`."""
    outs = []
    for d in range(u0.shape[0]):
        problem = jax.tree.map(lambda x: x[d] if eqx.is_array(x) else x, problem_batch)
        outs.append(_solve_one(problem, u0[d], u_lot, solver, max_steps))
    return jax.tree.map(lambda *x: jnp.stack(x), *outs)


@jit
def _solve_joint(problem_batch, u0, u_lot0, solver, max_steps):
    def fn(y, _):
        u_free, u_lot = y
        return eqx.filter_vmap(lambda p, x: evaluated(p, x, u_lot))(problem_batch, u_free)

    with one_trace():
        sol = optx.least_squares(fn, solver, (u0, u_lot0), has_aux=True, max_steps=max_steps, throw=False)
        ev = final_evaluation(sol, fn)
    n = u0.shape[0]
    return (sol.value[0], sol.value[1], jnp.broadcast_to(result_code(RESULTS.promote(sol.result)), (n,)),
            jnp.broadcast_to(sol.stats["num_steps"], (n,)), jnp.sum(ev.residuals**2, axis=-1), ev)


class LotSpread(eqx.Module):
    """Pads the device axis to a multiple of `shards` (placing it across a 1-D mesh of JAX devices) or of
    `chunk` (for `map_devices`), and with `bucket` to `gyrojax._lots.stack.bucket_size` (a lot of at most 16 devices to
    the next power of two); unpads results. Padding devices are copies of the last one: solved, then dropped.
    With one shard, no chunk and no bucket it does nothing."""

    n: int = eqx.field(static=True)
    size: int = eqx.field(static=True)
    shards: int = eqx.field(static=True)
    chunk: int | None = eqx.field(static=True)
    multiple: int = eqx.field(static=True)
    sharding: jax.sharding.NamedSharding | None = eqx.field(static=True)

    def __init__(self, n: int, shards: int, chunk: int | None = None, bucket: bool = False, pad_to: int | None = None):
        self.n, self.shards = n, shards
        base = max(bucket_size(n) if bucket else n, pad_to or 0)
        self.chunk = chunk if chunk is not None and chunk < base else None
        self.multiple = shards * (self.chunk or 1)
        self.size = -(-base // self.multiple) * self.multiple
        self.sharding = None
        if shards > 1:
            mesh = jax.sharding.Mesh(np.asarray(jax.devices()[:shards]), ("lot",))
            self.sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("lot"))

    def pad(self, *trees):
        if self.size == self.n and self.shards == 1:
            return trees
        trees = tuple(pad_devices(t, self.size) for t in trees)
        if self.shards == 1:
            return trees
        return tuple(jax.tree.map(lambda x: jax.device_put(x, self.sharding) if eqx.is_array(x) else x, t)
                     for t in trees)

    def unpad(self, tree):
        if self.size == self.n:
            return tree
        return unpad_devices(tree, self.n)


def _shards(shard) -> int:
    return len(jax.devices()) if shard is None or shard else 1


class AbstractLotSolve(eqx.Module):
    """How the devices of a lot are solved: `VmapSolve` (independent fits, vmapped), `LoopSolve` (independent
    fits, one device after another) or `JointSolve` (one fit of the whole lot, for shared parameters)."""

    joint: eqx.AbstractClassVar[bool]

    @abc.abstractmethod
    def spread(self, n: int) -> LotSpread:
        """How a lot of `n` devices is padded and placed for the solves."""

    @abc.abstractmethod
    def solve(self, problem: Problem, spread: LotSpread, u0: Float[ArrayLike, "device dev"],
              u_lot0: Float[ArrayLike, " lot"], solver: Solver, max_steps: int | Array
              ) -> tuple[Array, Array, Array, Array, Array, Evaluation]:
        """Solve every device of the padded `problem` from `u0` (device, n_dev) and `u_lot0` (n_lot,) with the
        optimistix `solver`: `(u, u_lot, result code, steps, chi2, Evaluation at the solution)`, unpadded, per
        device."""


class VmapSolve(AbstractLotSolve):
    """Every device's independent fit in one vmapped, compiled solve.

    **Arguments:**

    - `chunk`: solve and differentiate at most this many devices at a time (`jax.lax.map` over chunks of the
      vmapped solve; the lot is padded to a multiple of it); `None`: the whole lot at once; `"auto"`: 16 on
      a CPU backend, 1024 on an accelerator, `None` when sharded.
    - `shard`: spread the device axis over every JAX device (a 1-D mesh named `"lot"`); `None`: when more
      than one JAX device exists.
    - `bucket`: pad a lot of at most 16 devices to the next power of two (copies of its last device, solved
      and dropped), so that lots of nearby sizes share one compiled fit: a refit without one device, or the next
      lot of a notebook, reuses it instead of tracing and compiling again. The fitted values do not depend on
      it beyond round-off (each device is solved on its own).
    - `pad_to`: pad a smaller lot to this many devices (as `bucket` does), so that every chunk of a lot run
      in chunks (`gyrojax.DistributedSolve`) shares one compiled fit, the last one included.
    """

    chunk: int | None | Literal["auto"] = eqx.field(static=True, default="auto")
    shard: bool | None = eqx.field(static=True, default=None)
    bucket: bool = eqx.field(static=True, default=True)
    pad_to: int | None = eqx.field(static=True, default=None)
    joint: ClassVar[bool] = False

    def __check_init__(self):
        if self.chunk not in ("auto", None) and (not isinstance(self.chunk, int) or isinstance(self.chunk, bool)
                                                 or self.chunk < 1):
            raise ValueError(f"VmapSolve: chunk must be 'auto', None or an integer >= 1, got {self.chunk!r}.")
        if self.pad_to is not None and (not isinstance(self.pad_to, int) or isinstance(self.pad_to, bool)
                                        or self.pad_to < 1):
            raise ValueError(f"VmapSolve: pad_to must be None or an integer >= 1, got {self.pad_to!r}.")

    def spread(self, n: int) -> LotSpread:
        shards, chunk = _shards(self.shard), self.chunk
        if chunk == "auto":
            # Measured: 256 CPU devices ran 3-4x faster per device in chunks of 16 than of 128; 4096 devices on
            # an H100 ran 2.2 ms/device in chunks of 1024 against 3.0 ms/device at once (the tail's steps).
            chunk = (16 if jax.default_backend() == "cpu" else 1024) if shards == 1 else None
        if chunk is not None and shards > 1:
            raise ValueError("VmapSolve: a chunk applies on one JAX device; drop chunk or shard.")
        return LotSpread(n, shards, chunk, bucket=self.bucket, pad_to=self.pad_to)

    def solve(self, problem: Problem, spread: LotSpread, u0: Float[ArrayLike, "device dev"],
              u_lot0: Float[ArrayLike, " lot"], solver: Solver, max_steps: int | Array
              ) -> tuple[Array, Array, Array, Array, Array, Evaluation]:
        u0_s, = spread.pad(jnp.asarray(u0))
        u, code, steps, chi2, ev = spread.unpad(_solve_independent(problem, u0_s, jnp.zeros(0), solver, max_steps,
                                                                   spread.chunk))
        return u, jnp.zeros(0), code, steps, chi2, Evaluation(*ev)


class LoopSolve(AbstractLotSolve):
    """Every device's independent fit, one device after another through one compiled single-device solve
    (less memory than `VmapSolve`; not sharded)."""

    joint: ClassVar[bool] = False

    def spread(self, n: int) -> LotSpread:
        return LotSpread(n, 1)

    def solve(self, problem: Problem, spread: LotSpread, u0: Float[ArrayLike, "device dev"],
              u_lot0: Float[ArrayLike, " lot"], solver: Solver, max_steps: int | Array
              ) -> tuple[Array, Array, Array, Array, Array, Evaluation]:
        u, code, steps, chi2, ev = _solve_loop(problem, jnp.asarray(u0), jnp.zeros(0), solver, max_steps)
        return u, jnp.zeros(0), code, steps, chi2, Evaluation(*ev)


class JointSolve(AbstractLotSolve):
    """One fit of the whole lot: the per-device parameters and the shared ones (`identify(shared=...)`)
    together. `shard` as for `VmapSolve`; sharded only when the lot divides evenly (padding would add fake
    devices to the sum)."""

    shard: bool | None = eqx.field(static=True, default=None)
    joint: ClassVar[bool] = True

    def spread(self, n: int) -> LotSpread:
        shards = _shards(self.shard)
        return LotSpread(n, shards if n % shards == 0 else 1)

    def solve(self, problem: Problem, spread: LotSpread, u0: Float[ArrayLike, "device dev"],
              u_lot0: Float[ArrayLike, " lot"], solver: Solver, max_steps: int | Array
              ) -> tuple[Array, Array, Array, Array, Array, Evaluation]:
        (u0_s,) = spread.pad(jnp.asarray(u0))
        return spread.unpad(_solve_joint(problem, u0_s, jnp.asarray(u_lot0), solver, max_steps))


class Lot(eqx.Module):
    """A lot strategy applied to a lot of a given size: its compiled passes with the padding done."""

    strategy: AbstractLotSolve
    spread: LotSpread

    def __init__(self, strategy: AbstractLotSolve, n: int):
        self.strategy = strategy
        self.spread = strategy.spread(n)

    @property
    def joint(self) -> bool:
        return self.strategy.joint

    def solve(self, problem: Problem, u0: Float[ArrayLike, "device dev"], u_lot0: Float[ArrayLike, " lot"],
              solver: Solver, max_steps: int, stage: str
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, Evaluation]:
        """The strategy's solve of `problem` from `u0`, `u_lot0`: numpy `(u, u_lot, code, steps, chi2)` and the
        `Evaluation` at the solution."""
        (problem_s,) = self.spread.pad(problem)
        # The step budget as a traced value of gyrojax's LM: a fit retried with more steps reuses the program.
        solver, max_steps = with_max_steps(solver, max_steps)
        with nonfinite_explained(stage):
            u, u_lot, code, steps, chi2, ev = self.strategy.solve(problem_s, self.spread, u0, u_lot0, solver, max_steps)
        return np.asarray(u), np.asarray(u_lot), np.asarray(code), np.asarray(steps), np.asarray(chi2), ev

    def evaluate(self, problem, u, u_lot, solver, max_steps, stage: str) -> Evaluation:
        """Residuals, Jacobians and the scale factor of every device of `problem` at `u`, `u_lot`: the solve's
        own compiled program, stopped after the first step (`evaluation_step`)."""
        return self.solve(problem, u, u_lot, evaluation_step(solver), max_steps, stage)[-1]
