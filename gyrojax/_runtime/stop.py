"""A stop asked for by a signal (the command line's SIGTERM/SIGINT), acted on at safe points.

The command line's signal handler raises `Interrupted` at once, but an exception raised by a signal handler is
lost when the signal lands in code whose exceptions Python ignores (a `gc.callbacks` hook such as JAX's
`_xla_gc_callback`, a `__del__`, a weak-reference callback). So the handler also records the stop here, and
`check` raises it again from ordinary code: at every progress step (`gyrojax._runtime.progress.Progress`, called even
when silent) and just before an output file or folder is moved into place (`gyrojax._data.io`), so that a stopped
command never writes its outputs. Nothing here is set outside the command line.
"""


class Interrupted(BaseException):
    """SIGTERM or SIGINT, raised in the main thread so that `finally` and `except` cleanups run."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


_requested: list[int] = []  # the signal number of the stop asked for, if any


def request(signum: int) -> None:
    """Record a stop asked for by signal `signum` (the first one is kept)."""
    if not _requested:
        _requested.append(signum)


def requested() -> int | None:
    """The signal number of the stop asked for, or None."""
    return _requested[0] if _requested else None


def clear() -> None:
    """Forget the stop (the command line, when its command has returned)."""
    _requested.clear()


def check() -> None:
    """Raise `Interrupted` if a stop was asked for: a safe point, between steps or before an output is written."""
    if _requested:
        raise Interrupted(_requested[0])
