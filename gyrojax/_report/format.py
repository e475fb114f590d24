"""`AbstractFormat`: one output format of a result (JSON, Markdown, text, or a user's), written atomically."""

import abc
import os
from typing import ClassVar

import equinox as eqx
from equinox import AbstractClassVar

from .._data.io import atomic_write_bytes
from .._text import safe_text
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


def for_people(result: AbstractResult, text: str) -> str:
    """`text` about `result` made safe for a terminal or a Markdown page: the device names its JSON form holds
    are escaped wherever the text quotes them (a name with a newline does not start a line of its own), and any
    other control character too (`gyrojax._text.safe_text`)."""
    return safe_text(text, _device_names(result.to_json()))


def _device_names(form) -> set[str]:
    """The strings under the keys `device` and `devices` anywhere in a JSON form."""
    out: set[str] = set()
    if isinstance(form, dict):
        for key, value in form.items():
            if key in ("device", "devices"):
                out |= {value} if isinstance(value, str) else {v for v in value if isinstance(v, str)} \
                    if isinstance(value, list) else set()
            out |= _device_names(value)
    elif isinstance(form, list):
        for value in form:
            out |= _device_names(value)
    return out
