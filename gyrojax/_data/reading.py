"""Opening inputs for reading, for the whole package: only regular files, and never more than a bound.

A path given to gyrojax (a data file, a fit file, a cache entry) may name something that is not a file: a FIFO
blocks the first `open` until a writer comes, `/dev/zero` or `/dev/urandom` never end, a folder cannot be read.
[`open_regular`][] looks at what the path names (a symbolic link resolved) before opening it, and again at what
it opened (the path may have been swapped in between), and refuses all but a regular file, naming the path and
what was expected. Readers then bound what they read by the size the file has, or by what its header says it
holds.
"""

from __future__ import annotations

import os
import stat


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return f"{name}, not a regular file"
    return "not a regular file"


class NotARegularFile(ValueError):
    """A path given to read names something other than a regular file (a folder, a FIFO, a device)."""


def check_regular(path: str, give: str) -> os.stat_result:
    """The status of the regular file `path` names (a symbolic link followed to its target), without opening
    it; raises `NotARegularFile` naming `path` (and the link's target), what it is and what to give instead
    (`give`, e.g. "give a .csv or .parquet file"), and `FileNotFoundError` as `open` would."""
    real = os.path.realpath(path)
    st = os.stat(real)
    if not stat.S_ISREG(st.st_mode):
        target = f" (a link to {real})" if real != os.path.abspath(path) else ""
        raise NotARegularFile(f"{path}{target} is {_kind(st.st_mode)}; {give}.")
    return st


def open_regular(path: str, give: str):
    """`open(path, "rb")` for a regular file only (see the module, and `check_regular` for `give`); returns the
    binary file object, whose size is `os.fstat(f.fileno()).st_size`."""
    check_regular(path, give)
    # O_NONBLOCK: should a FIFO be put at the path after the check, opening it does not wait for a writer.
    nonblock = getattr(os, "O_NONBLOCK", 0)
    fd = os.open(path, os.O_RDONLY | nonblock | getattr(os, "O_BINARY", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotARegularFile(f"{path} is {_kind(st.st_mode)}; {give}.")
        if nonblock:
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_exactly(f, size: int, path: str) -> bytes:
    """The next `size` bytes of `f`; raises `ValueError` naming `path` if it ends sooner (a file cut while it
    was read)."""
    data = f.read(size)
    if len(data) != size:
        raise ValueError(f"{path}: the file ended after {len(data)} of the {size} bytes expected (it changed while "
                         "it was read?).")
    return data
