"""`DistributedSolve`: how a lot is run in chunks of devices on Dask distributed, and the client it opens."""

import contextlib
from collections.abc import Iterator
from typing import Any

import equinox as eqx


INSTALL = "pip install 'gyrojax[distributed]'"


class DistributedSolve(eqx.Module):
    """A lot's independent per-device fits, in fixed-size chunks of devices, each chunk one `identify` (with
    `VmapSolve(pad_to=chunk)`: one compiled program per worker, reused through the persistent compilation
    cache) in a worker process of a Dask distributed cluster. Needs the `distributed` extra.

    **Arguments:**

    - `workers`: start a local cluster of this many worker processes (one thread each) on this machine.
    - `scheduler`: the address of an existing Dask scheduler (`tcp://host:8786`), e.g. one started by
      dask-jobqueue on Slurm or by the Dask Kubernetes operator; its workers must have gyrojax installed.
    - `chunk`: devices per chunk (the last one is padded to it); 16 by default. On a CPU a multiple of 16 solves
      16 devices at a time, as one process does, and gives its fit bit for bit; another size solves another
      number at once and agrees to round-off.
    - `retries`: how many more times a chunk whose worker died is run elsewhere before it counts as failed (a
      local cluster's; an existing cluster keeps its scheduler's `distributed.scheduler.allowed-failures`).
    """

    workers: int | None = eqx.field(static=True, default=None)
    scheduler: str | None = eqx.field(static=True, default=None)
    chunk: int = eqx.field(static=True, default=16)
    retries: int = eqx.field(static=True, default=2)

    def __check_init__(self):
        if (self.workers is None) == (self.scheduler is None):
            raise ValueError("DistributedSolve: give workers (a local cluster of that many processes) or scheduler "
                             f"(an existing cluster's address), exactly one; got workers={self.workers!r}, "
                             f"scheduler={self.scheduler!r}.")
        for name in ("workers", "chunk"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v < 1):
                raise ValueError(f"DistributedSolve: {name} must be an integer >= 1, got {v!r}.")
        if not isinstance(self.retries, int) or isinstance(self.retries, bool) or self.retries < 0:
            raise ValueError(f"DistributedSolve: retries must be an integer >= 0, got {self.retries!r}.")
        if self.scheduler is not None and not (isinstance(self.scheduler, str) and self.scheduler.strip()):
            raise ValueError(f"DistributedSolve: scheduler must be an address like tcp://host:8786, got "
                             f"{self.scheduler!r}.")

    @staticmethod
    def require() -> None:
        """Raise an ImportError that says how to install Dask distributed where it is missing."""
        try:
            import dask  # noqa: F401
            import distributed  # noqa: F401
        except ImportError:
            raise ImportError(f"a distributed lot needs Dask distributed: {INSTALL}") from None

    @contextlib.contextmanager
    def client(self) -> Iterator[Any]:  # a distributed.Client (an optional dependency, imported here)
        """A Dask client of this cluster; a local cluster is started here and closed at the end."""
        self.require()
        import dask.config
        import distributed

        # A worker that dies mid-chunk: the scheduler runs the chunk elsewhere up to `retries` more times.
        with dask.config.set({"distributed.scheduler.allowed-failures": self.retries,
                              "distributed.worker.multiprocessing-method": "spawn"}):
            if self.scheduler is not None:
                with distributed.Client(self.scheduler) as c:
                    yield c
                return
            # Processes, not threads: JAX is not fork-safe and holds the GIL in tracing; spawned workers, one
            # thread each, each with its own compiled program.
            with distributed.LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                          dashboard_address=":0", silence_logs=40) as cluster:
                with distributed.Client(cluster) as c:
                    yield c
