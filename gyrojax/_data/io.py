"""Writing outputs, for the whole package: atomic files, atomic folders, and the checks of output paths that the
command line makes before any work.

**Files.** [`atomic_path`][] (and [`atomic_open`][], [`atomic_write_bytes`][], [`atomic_write_json`][] on top
of it) writes into a temporary file beside the target and moves it into place with `os.replace`: a reader sees
the old file or the new one, never a half-written one, and a write that fails (an exception, or SIGTERM turned
into one by the command line) removes its temporary file and leaves the old file untouched.

- A symbolic link is written *through*: the file it points to is replaced atomically and the link is kept.
- A target that exists and is neither a regular file nor a folder (a character device such as `/dev/stdout`,
  a FIFO) cannot be replaced atomically, and replacing it would destroy it: it is opened and written directly.
- A new file gets mode `0o666 & ~umask`, as `open()` would give it; a replaced file keeps its mode.

**Folders.** [`atomic_directory`][] builds a folder in a temporary sibling and renames it into place at the
end, so it appears whole or not at all. The rule for a folder that already exists: it is replaced *only as a
whole* (the old one and everything in it are removed once the new one is in place), and only if it is empty
or gyrojax wrote it (it holds the marker file [`FOLDER_MARKER`][]); any other existing folder is refused, so
that a mistyped `--report ~` never removes a user's files.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator

from .._runtime.stop import check as _check_stop


FOLDER_MARKER = ".gyrojax-output"
"""The file [`atomic_directory`][] puts in every folder it writes: such a folder may be replaced by a later run."""


def _read_umask() -> int:
    # /proc/self/status reads the umask without setting it; os.umask can only swap it, and a swap races with
    # any thread that creates files meanwhile, so it is the fallback, done once at import.
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def _through_link(path: str) -> str:
    """The path to write for `path`: the final target if `path` is a symbolic link (kept as a link)."""
    return os.path.realpath(path) if os.path.islink(path) else path


def _stat(path: str) -> os.stat_result | None:
    try:
        return os.stat(path)
    except (FileNotFoundError, NotADirectoryError):  # the path, or a folder on the way to it, is missing
        return None


def _fsync_dir(directory: str) -> None:
    # Makes the rename durable; some file systems cannot open a folder for this, which costs only durability.
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """A path to write the whole content of `path` to; it is moved into place when the block ends normally.

    **Arguments:**

    - `path`: the file to write (through a symbolic link; see the module notes for devices and FIFOs).

    **Returns:**

    A context manager yielding the path to write: a new temporary file beside the target (empty, already
    created), or the target itself when it is a device or a FIFO. On normal exit the temporary file is synced
    to disk, given its mode and moved onto the target; on any exception (`BaseException`: also
    `KeyboardInterrupt` and the command line's signal exception) it is removed and the target is untouched.

    Raises `IsADirectoryError` when the target is an existing folder.
    """
    target = _through_link(os.fspath(path))
    st = _stat(target)
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, "is an existing folder; expected a file path", target)
    if st is not None and not stat.S_ISREG(st.st_mode):
        yield target  # a device or a FIFO: written directly (there is no file to replace)
        return
    mode = stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~_UMASK
    directory = os.path.dirname(os.path.abspath(target))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{os.path.basename(target)}.", suffix=".tmp")
    try:
        os.close(fd)
        os.chmod(tmp, mode)  # mkstemp makes 0600
        yield tmp
        _check_stop()  # a stop asked for by a signal whose exception was lost: keep the old file
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    _fsync_dir(directory)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb", **open_kwargs):
    """`open(path, mode, **open_kwargs)` for writing, atomically (see [`atomic_path`][]).

    **Arguments:**

    - `path`: the file to write.
    - `mode`: a write mode, `"w"` or `"wb"`.
    - `open_kwargs`: passed to `open` (`encoding`, `newline`, ...).

    **Returns:**

    A context manager yielding the open file; what was written replaces `path` when the block ends normally.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode must be 'w' or 'wb', got {mode!r}.")
    with atomic_path(path) as p, open(p, mode, **open_kwargs) as f:
        yield f


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically: into a temporary file beside it, then moved into place, so that a
    reader sees the old file or the new one, never a half-written one; a symbolic link is written through."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def _first_non_finite(obj, where: str = "") -> str | None:
    """Where in a JSON-ready object the first NaN or infinity sits (e.g. `runs[1].residuals[0]`), or None."""
    if isinstance(obj, float):
        return None if math.isfinite(obj) else (where or "the value")
    if isinstance(obj, dict):
        items = ((f"{where}.{k}" if where else str(k), v) for k, v in obj.items())
    elif isinstance(obj, (list, tuple)):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(obj))
    else:
        return None
    for w, v in items:
        found = _first_non_finite(v, w)
        if found is not None:
            return found
    return None


def atomic_write_json(obj: object, path: str | os.PathLike) -> None:
    """Write `obj` as indented JSON atomically (as [`gyrojax.io.atomic_write_bytes`][]).

    Raises `ValueError` naming the file and the key of the first NaN or infinity: JSON has no such numbers,
    and a not-applicable value belongs in the object as None.
    """
    try:
        text = json.dumps(obj, indent=2, allow_nan=False, default=float) + "\n"
    except ValueError:
        where = _first_non_finite(json.loads(json.dumps(obj, default=float)))
        raise ValueError(f"{os.fspath(path)}: not written: {where} is not a finite number, which JSON cannot "
                         "hold (a not-applicable value should be null).") from None
    atomic_write_bytes(path, text.encode())


# ---------------------------------------------------------------------------------------------------------------
# Folders.


def _folder_refusal(target: str) -> str | None:
    """Why an existing `target` may not be replaced by a folder written by gyrojax, or None if it may."""
    st = _stat(target)
    if st is None:
        return None
    if not stat.S_ISDIR(st.st_mode):
        return "is an existing file, not a folder; give a folder path"
    entries = os.listdir(target)
    if entries and FOLDER_MARKER not in entries:
        return (f"is an existing folder that gyrojax did not write (it holds no {FOLDER_MARKER}); give a new or "
                "empty folder, or remove this one (a gyrojax output folder is replaced as a whole)")
    return None


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike) -> Iterator[str]:
    """Build a folder that appears at `path` whole or not at all.

    **Arguments:**

    - `path`: the folder to write. It may not exist yet (its parent must), may be an empty folder, or a folder
      gyrojax wrote before (it holds the marker file `.gyrojax-output`): that one is replaced as a whole, with
      everything in it. A symbolic link is followed, and kept.

    **Returns:**

    A context manager yielding a new temporary folder beside `path` (holding only the marker file): write
    every file of the folder there. When the block ends normally the temporary folder is renamed to `path`
    (an old folder is first renamed aside, then removed; between the two renames `path` is briefly absent,
    never partial). On any exception (`BaseException`) the temporary folder is removed and an old folder is
    left as it was.

    Raises `FileExistsError` when `path` is an existing file or an existing folder gyrojax did not write.
    """
    target = _through_link(os.fspath(path))
    why = _folder_refusal(target)
    if why is not None:
        raise FileExistsError(errno.EEXIST, why, target)
    parent = os.path.dirname(os.path.abspath(target))
    base = os.path.basename(os.path.abspath(target))
    tmp = tempfile.mkdtemp(dir=parent, prefix=f".{base}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o777 & ~_UMASK)  # mkdtemp makes 0700
        with atomic_open(os.path.join(tmp, FOLDER_MARKER), "w", encoding="utf-8") as f:
            f.write("Written by gyrojax: a later gyrojax run may replace this folder as a whole.\n")
        yield tmp
        _check_stop()  # a stop asked for by a signal whose exception was lost: keep the old folder
        why = _folder_refusal(target)  # checked again: something may have appeared meanwhile
        if why is not None:
            raise FileExistsError(errno.EEXIST, why, target)
        if os.path.lexists(target):
            old = tempfile.mkdtemp(dir=parent, prefix=f".{base}.", suffix=".old")
            os.rename(target, old)  # onto the empty folder just made: POSIX rename replaces an empty folder
            try:
                os.rename(tmp, target)
            except BaseException:
                os.rename(old, target)
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _fsync_dir(parent)


# ---------------------------------------------------------------------------------------------------------------
# Checks of output paths, made before any work.


class OutputPathError(ValueError):
    """An output path that cannot be written, found before any work; the message names the argument."""


def check_output_path(path: str | os.PathLike, argument: str, *, folder: bool = False) -> None:
    """Check that `path` can be written as a file (or, with `folder=True`, as a folder by [`atomic_directory`][]).

    **Arguments:**

    - `path`: the output path as given.
    - `argument`: the option that gave it, for the message (e.g. `"--json"`).
    - `folder`: whether `path` is a folder to write.

    Raises [`OutputPathError`][] (a `ValueError`) naming the argument and the path when: the path is empty;
    its folder does not exist, is not a folder or is not writable; a file path is an existing folder; a folder
    path is an existing file or a folder gyrojax did not write; an existing device or FIFO is not writable.
    """
    given = os.fspath(path)
    if not given:
        raise OutputPathError(f"{argument}: the path is empty.")
    target = _through_link(given)
    shown = given if target == given else f"{given} (a link to {target})"
    st = _stat(target)
    if folder:
        why = _folder_refusal(target)
        if why is not None:
            raise OutputPathError(f"{argument} {shown}: {why}.")
    elif st is not None and stat.S_ISDIR(st.st_mode):
        raise OutputPathError(f"{argument} {shown}: is an existing folder; give a file path.")
    elif st is not None and not stat.S_ISREG(st.st_mode):
        if not os.access(target, os.W_OK):
            raise OutputPathError(f"{argument} {shown}: is not writable.")
        return  # a device or a FIFO: written directly
    parent = os.path.dirname(os.path.abspath(target))
    pst = _stat(parent)
    if pst is None:
        raise OutputPathError(f"{argument} {shown}: the folder {parent} does not exist; create it first.")
    if not stat.S_ISDIR(pst.st_mode):
        raise OutputPathError(f"{argument} {shown}: {parent} is not a folder.")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{argument} {shown}: the folder {parent} is not writable.")


def check_output_paths(outputs: list[tuple[str, str | os.PathLike | None, bool]]) -> None:
    """Check several outputs of one command: each with [`check_output_path`][], and no two the same file.

    **Arguments:**

    - `outputs`: `(argument, path or None, folder)` triples; None (an option not given) is skipped.
    """
    seen: dict[str, str] = {}
    for argument, path, folder in outputs:
        if path is None:
            continue
        check_output_path(path, argument, folder=folder)
        key = os.path.realpath(os.fspath(path))
        if key in seen:
            raise OutputPathError(f"{argument} {os.fspath(path)}: {seen[key]} writes the same path; give each "
                                  "output its own path.")
        seen[key] = argument
