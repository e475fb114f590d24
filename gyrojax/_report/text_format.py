"""The `text` format: a result's `summary()`, the terminal text, as a file."""

from typing import ClassVar

from .format import AbstractFormat, for_people
from .result import AbstractResult


class TextFormat(AbstractFormat):
    """`result.summary()` with a final newline, UTF-8, the data's device names escaped (`for_people`)."""

    name: ClassVar[str] = "text"
    suffixes: ClassVar[tuple[str, ...]] = (".txt",)

    def render(self, result: AbstractResult) -> bytes:
        return (for_people(result, result.summary()) + "\n").encode()
