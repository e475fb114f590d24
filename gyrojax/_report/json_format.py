"""The `json` format: a result's `to_json()`, indented, as every `--json` file of the command line holds it."""

import json
import os
from typing import ClassVar

from .._data.io import atomic_write_json
from .format import AbstractFormat
from .result import AbstractResult


class JsonFormat(AbstractFormat):
    """`result.to_json()` as indented JSON with a final newline (`gyrojax.io.atomic_write_json`); a NaN or
    infinity is refused with the file and the key (JSON has no such numbers: a value the data do not give is
    null)."""

    name: ClassVar[str] = "json"
    suffixes: ClassVar[tuple[str, ...]] = (".json",)

    def render(self, result: AbstractResult) -> bytes:
        return (json.dumps(result.to_json(), indent=2, allow_nan=False, default=float) + "\n").encode()

    def write(self, result: AbstractResult, path: str | os.PathLike) -> None:
        atomic_write_json(result.to_json(), path)
