"""The reporting wing: what a result offers an output format, the formats, and one way to write a result.

One concept per file:

- `result.py`: `AbstractResult`, the contract every result satisfies (`kind`, `to_json()`, `summary()`).
- `format.py`: `AbstractFormat`, an output format (`name`, `suffixes`, `render(result)`, an atomic `write`).
- `json_format.py`, `markdown_format.py`, `text_format.py`: the built-in formats, one file each.
- `registry.py`: `FORMATS` by name, `register_format`, and the format of a path (`format_for`).
- `write.py`: `write_result(result, path, format=None)`, which the command line, `write_report` and scripts use.

Public through `gyrojax.io`.
"""

from .format import AbstractFormat as AbstractFormat
from .json_format import JsonFormat as JsonFormat
from .markdown_format import MarkdownFormat as MarkdownFormat, generic_markdown as generic_markdown
from .registry import FORMATS as FORMATS, format_for as format_for, register_format as register_format
from .result import AbstractResult as AbstractResult
from .text_format import TextFormat as TextFormat
from .write import write_result as write_result
