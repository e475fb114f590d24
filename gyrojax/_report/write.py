"""`write_result`: a result written to a file in an output format picked by name or by the file's suffix."""

import os

from .format import AbstractFormat
from .registry import format_for
from .result import AbstractResult


def write_result(result: AbstractResult, path: str | os.PathLike,
                 format: str | AbstractFormat | None = None) -> AbstractFormat:
    """Write `result` to `path` atomically (a reader sees the old file or the new one) in `format`: a name of
    `gyrojax.io.FORMATS` (`"json"`, `"markdown"`, `"text"`, or one added with `register_format`), a format
    object, or None to pick it by the suffix of `path` (`.json`, `.md`, `.txt`, ...). Returns the format used.

    Raises a `ValueError` naming the path and the known formats for an unknown format or suffix, and a
    `TypeError` when `result` is not a result (`AbstractResult`: `kind`, `to_json()` and `summary()`).
    """
    fmt = format_for(path, format)
    if not isinstance(result, AbstractResult):
        raise TypeError(f"{os.fspath(path)}: write_result expects a gyrojax result (with kind, to_json() and "
                        f"summary(): a Fit, Diagnosis, Plan, ...), got {type(result).__name__}.")
    fmt.write(result, path)
    return fmt
