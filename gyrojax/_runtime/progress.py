"""Progress of long steps: what gyrojax is doing, which step of how many, how long it has taken.

Every long entry point (`simulate_table`, `identify`, `diagnose`, `compensate`, the demo) takes `progress=`:
`True` (the default) writes one line per step to standard error, `False` or `None` is silent, and a callable
receives each message instead (a notebook widget, a logger). The first call with new shapes compiles its
programs: the message says so, and that later calls with the same shapes (in this process, and in later ones
through the persistent compilation cache) are fast. While XLA compiles a large program it may print its own
"Very slow compile?" notice: that is expected on a small CPU, not an error.
"""

import sys
import time
from collections.abc import Callable

from .stop import check as _check_stop


_SEEN: set = set()  # what was compiled in this process (by key): later calls with it are fast


class Progress:
    """A reporter for one entry point's steps.

    **Arguments:**

    - `progress`: `True` (lines on standard error), `False`/`None` (silent), or a callable taking a message.
    - `name`: the entry point's name, the prefix of every line.
    """

    def __init__(self, progress, name: str):
        if progress is True:
            self._out = lambda m: print(m, file=sys.stderr, flush=True)
        elif progress is None or progress is False:
            self._out = None
        elif callable(progress):
            self._out = progress
        else:
            raise ValueError(f"progress must be True, False, None or a callable taking a message, got {progress!r}.")
        self.name = name
        self.start = time.perf_counter()

    @property
    def enabled(self) -> bool:
        return self._out is not None

    def __call__(self, message: str) -> None:
        _check_stop()  # a safe point for a stop asked for by a signal (gyrojax._runtime.stop), silent or not
        if self._out is not None:
            self._out(f"{self.name}: {message} (t = {time.perf_counter() - self.start:.0f} s)")

    def compiling(self, key, what: str) -> None:
        """Say that `what` compiles now if `key` was not compiled before in this process."""
        _check_stop()
        if key in _SEEN:
            return
        first = not _SEEN
        _SEEN.add(key)
        self(f"compiling {what} (first call with these shapes; later calls reuse it)" + (
            ". Compiling takes up to a few minutes on a 2-core CPU, less once the persistent cache holds it; XLA "
            "may print a 'Very slow compile?' notice meanwhile, which is expected" if first else ""))


ProgressArg = bool | Callable[[str], object] | Progress | None
"""What an entry point's `progress=` takes: True (lines on standard error), False or None (silent), a callable
taking each message, or a `Progress` passed on."""


def as_progress(progress: ProgressArg, name: str) -> Progress:
    """`progress` as a `Progress` (a `Progress` is passed through, keeping its clock and prefix)."""
    return progress if isinstance(progress, Progress) else Progress(progress, name)
