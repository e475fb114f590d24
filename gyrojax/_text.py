"""Names from data files made safe for terminal and Markdown text.

A device name is whatever a data file says: one holding a newline would start a line of its own in a summary
(a fake verdict), one holding an escape sequence would drive the terminal. Where such names are written into
text for people, their control characters (and the invisible format characters, such as the bidirectional
overrides) are escaped as Python's `repr` would write them: a newline in a name shows as a backslash and an `n`,
never as a line break. Names in JSON are kept as they are (JSON escapes them itself).
"""

import unicodedata


def _unsafe(ch: str) -> bool:
    # Cc: C0/C1 controls (newline, ESC, DEL); Cf: format characters (bidi overrides); Zl/Zp: line separators.
    return unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp")


def _escaped(ch: str) -> str:
    return repr(ch)[1:-1] if ch not in "'\"" else ch


def safe_name(name) -> str:
    """`name` as text with its control and format characters escaped (`repr`-style: `\\n`, `\\x1b`, `\\u202e`)."""
    text = str(name)
    return "".join(_escaped(c) if _unsafe(c) else c for c in text)


def safe_text(text: str, names=()) -> str:
    """A multi-line `text` for the terminal or Markdown: each of `names` (the data's device names) that holds
    unsafe characters is replaced by its `safe_name` wherever the text quotes it (longest first), then every
    other unsafe character but the newline is escaped (an escape sequence from anywhere else)."""
    for name in sorted({str(n) for n in names if any(_unsafe(c) for c in str(n))}, key=len, reverse=True):
        if name.strip("\n"):  # a name of newlines only would match the text's own line breaks
            text = text.replace(name, safe_name(name))
    return "".join(c if c == "\n" or not _unsafe(c) else _escaped(c) for c in text)
