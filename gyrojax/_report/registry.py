"""The output formats by name (`FORMATS`), `register_format` for a new one, and the format of a path."""

import os

from .format import AbstractFormat
from .json_format import JsonFormat
from .markdown_format import MarkdownFormat
from .text_format import TextFormat


FORMATS: dict[str, AbstractFormat] = {f.name: f for f in (JsonFormat(), MarkdownFormat(), TextFormat())}
"""The output formats by name: `json`, `markdown`, `text`, and those added with `register_format`."""


def known_formats() -> str:
    """The registered formats with their suffixes, for error messages: "json (.json), markdown (.md), ..."."""
    return ", ".join(f"{name} ({', '.join(f.suffixes) or 'no suffix'})" for name, f in FORMATS.items())


def register_format(fmt: AbstractFormat) -> AbstractFormat:
    """Add the output format `fmt` (an instance of a concrete `AbstractFormat`) to `FORMATS` under its `name`,
    for `write_result` and the command line's `--format`; returns it. Registering an equal format again does
    nothing; a name or a suffix that another format holds is refused with a `ValueError`."""
    if not isinstance(fmt, AbstractFormat):
        raise TypeError(f"register_format expects an instance of a gyrojax.io.AbstractFormat subclass, got "
                        f"{type(fmt).__name__}.")
    name = fmt.name
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"{type(fmt).__name__}.name must be a name such as 'csv', got {name!r}.")
    bad = [s for s in fmt.suffixes if not (isinstance(s, str) and s.startswith(".") and len(s) > 1)]
    if bad:
        raise ValueError(f"{type(fmt).__name__}.suffixes must be file suffixes with the dot, e.g. ('.csv',), got "
                         f"{bad[0]!r}.")
    existing = FORMATS.get(name)
    if existing is not None:
        if existing == fmt:
            return existing
        raise ValueError(f"an output format named {name!r} is registered already ({type(existing).__name__}); "
                         "give the new one another name.")
    for other in FORMATS.values():
        taken = set(other.suffixes) & {s.lower() for s in fmt.suffixes}
        if taken:
            raise ValueError(f"the suffix {sorted(taken)[0]!r} of format {name!r} belongs to the format "
                             f"{other.name!r} already; give another suffix (or none: it is then picked by name).")
    FORMATS[name] = fmt
    return fmt


def format_for(path: str | os.PathLike, format: str | AbstractFormat | None = None) -> AbstractFormat:
    """The format to write `path` in: `format` (a registered name or a format), or the one whose suffix `path`
    has. A `ValueError` names the path and the known formats when there is none."""
    if isinstance(format, AbstractFormat):
        return format
    where = os.fspath(path)
    if format is not None:
        if isinstance(format, str) and format in FORMATS:
            return FORMATS[format]
        raise ValueError(f"{where}: unknown output format {format!r}; the known formats are {known_formats()}.")
    suffix = os.path.splitext(where)[1].lower()
    for fmt in FORMATS.values():
        if suffix in fmt.suffixes:
            return fmt
    raise ValueError(f"{where}: no output format for the suffix {suffix or '(none)'!r}; the known formats are "
                     f"{known_formats()} (name one as the format).")
