"""Lots beyond one process: a lot's independent per-device fits run in fixed-size chunks of devices on a Dask
distributed cluster (a local one of worker processes, or an existing one by its scheduler's address), each
chunk's result written to a results folder as it finishes, so that a killed run restarted with the same command
continues where it stopped. One concept per file:

- `engine.py`: `DistributedSolve` (workers, scheduler, chunk size, retries) and the Dask client it opens.
- `plan.py`: the chunks of a lot and the results folder's manifest (what a restart must match).
- `task.py`: one chunk's fit, run in a worker process.
- `run.py`: `identify_lot`: plan, submit, progress line, merge, the every-device-once check.
"""

from .engine import DistributedSolve as DistributedSolve
from .run import identify_lot as identify_lot
