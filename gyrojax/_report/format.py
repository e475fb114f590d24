"""`AbstractFormat`: one output format of a result (JSON, Markdown, text, or a user's), written atomically."""

import abc
import os
from typing import ClassVar

import equinox as eqx
from equinox import AbstractClassVar

from .._data.io import atomic_write_bytes
from .result import AbstractResult


class AbstractFormat(eqx.Module):
    """An output format: how a result (`AbstractResult`) becomes the bytes of a file.

    Subclass it with a `name` (what `--format` and `write_result(..., format=...)` take), the file `suffixes`
    it is picked by (with the dot, e.g. `(".csv",)`), and `render(result)`; register an instance with
    `register_format`. `write` writes `render`'s bytes atomically (a temporary file moved into place); a format
    that checks what it writes against the path (the JSON format names the file and the key of a NaN) overrides
    it.
    """

    name: AbstractClassVar[str]
    suffixes: ClassVar[tuple[str, ...]] = ()

    @abc.abstractmethod
    def render(self, result: AbstractResult) -> bytes:
        """The file's bytes for `result`."""

    def write(self, result: AbstractResult, path: str | os.PathLike) -> None:
        atomic_write_bytes(path, self.render(result))
