"""The `markdown` format: a result's own Markdown report where it has one (`Diagnosis`), else its summary and
its JSON form as tables."""

import json
from typing import Any, ClassVar

from .._text import safe_name
from .format import AbstractFormat, for_people
from .result import AbstractResult


class MarkdownFormat(AbstractFormat):
    """Markdown: `result.markdown()` where the result defines it, else a generic page (the kind as title, the
    summary in a code block, then the JSON form: its scalars in one table, each list of records or mapping of
    records as a table of their scalar fields, anything else as a JSON block). `figures`, (title, image file)
    pairs, are appended as sections with the image (the diagnosis report's plots). The data's device names are
    escaped (`for_people`)."""

    figures: tuple[tuple[str, str], ...] = ()

    name: ClassVar[str] = "markdown"
    suffixes: ClassVar[tuple[str, ...]] = (".md",)

    def render(self, result: AbstractResult) -> bytes:
        own = getattr(result, "markdown", None)
        text = for_people(result, str(own()) if callable(own) else generic_markdown(result))
        for title, image in self.figures:
            text += "\n" + "\n".join([f"## {title}", "", f"![{title}]({image})", ""])
        return text.encode()


def _scalar(value: Any) -> bool:
    return value is None or isinstance(value, (str, int, float, bool))


def _cell(value: Any) -> str:
    text = safe_name(value) if isinstance(value, str) else json.dumps(value, default=float)
    return text.replace("|", "\\|")


def _table(rows: list[dict[str, Any]], first: str | None = None) -> list[str]:
    """A Markdown table of the scalar fields of `rows` (columns in first-seen order)."""
    columns = list(dict.fromkeys(k for row in rows for k, v in row.items() if _scalar(v)))
    if first is not None:
        columns = [first] + [c for c in columns if c != first]
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_cell(row.get(c)) for c in columns) + " |" for row in rows]
    return lines


def _records(value: Any) -> list[dict[str, Any]] | None:
    """`value` as a list of records (dicts with at least one scalar field), or None."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        rows = value
    elif isinstance(value, dict) and value and all(isinstance(v, dict) for v in value.values()):
        rows = [{"name": k, **v} for k, v in value.items()]
    else:
        return None
    return rows if any(_scalar(v) for row in rows for v in row.values()) else None


def generic_markdown(result: AbstractResult) -> str:
    """The generic Markdown page of `result` (see `MarkdownFormat`)."""
    lines = [f"# gyrojax {result.kind}", "", "```", result.summary(), "```", ""]
    form = result.to_json()
    if not isinstance(form, dict):
        form = {result.kind: form}
    scalars = [{"key": k, "value": v} for k, v in form.items() if _scalar(v)]
    if scalars:
        lines += _table(scalars) + [""]
    for key, value in form.items():
        if _scalar(value):
            continue
        lines += [f"## {key}", ""]
        rows = _records(value)
        if rows is not None:
            lines += _table(rows, "name" if isinstance(value, dict) else None)
        else:
            lines += ["```json", json.dumps(value, indent=2, default=float), "```"]
        lines.append("")
    return "\n".join(lines)
