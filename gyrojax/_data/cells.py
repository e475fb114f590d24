"""Cells of the tidy table: the column names, `DataError`, and the parsers of one cell each.

A cell is a Python object: str (CSV, or text in memory), int/float (Parquet, memory) or None (an empty CSV cell,
a Parquet null). Each parser returns the parsed value or raises a `DataError` naming the source, the data row
and the column (`Where`).

**Row numbers in messages.** Rows are counted as *data rows*, 1-based, not counting the header: "data row 1"
is the first record after the header. For CSV files the physical line of the file is given too ("line 2"; the
header is line 1), which is what an editor shows.
"""

import decimal
import difflib
import math
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._sweeps.registry import SWEEP_KINDS


REQUIRED_COLUMNS = ("device", "run", "sweep", "input", "output")
"""Columns every table must have."""

OPTIONAL_COLUMNS = ("output_sigma", "n_samples", "phase_deg", "temperature_c", "drive_freq_hz", "rate_dps",
                    "time_s")
"""Known optional columns; float64 in memory, NaN where a value was not given."""

DAC_WORD_BITS = 24
"""Width of a DAC word (seed 000 Table 2: 24-bit two's complement, printed in hex)."""

_WORD_MIN = -(1 << (DAC_WORD_BITS - 1))
_WORD_MAX = (1 << (DAC_WORD_BITS - 1)) - 1
_HEX_DIGITS = DAC_WORD_BITS // 4

_FLOAT_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_INT_RE = re.compile(r"[+-]?\d+\Z")
_INTEGRAL_DEC_RE = re.compile(r"[+-]?\d+\.0*\Z")
_HEX_RE = re.compile(r"[0-9A-Fa-f]+\Z")

# Run ids: int32, so that any id fits every integer column it is copied into.
_INT_MIN, _INT_MAX = -(1 << 31), (1 << 31) - 1


class DataError(ValueError):
    """A measured-data file or table that gyrojax refuses, with the file, row and column named.

    Attributes `source`, `row` (1-based data row, or None) and `column` (or None) repeat what the message says,
    for programs that want to point at the cell.
    """

    def __init__(self, message: str, *, source: str | None = None, row: int | None = None,
                 column: str | None = None):
        super().__init__(message)
        self.source = source
        self.row = row
        self.column = column


# ---------------------------------------------------------------------------------------------------------------
# Locations for messages.


class Where:
    """Formats "<source>: data row N (line L), column 'c'" for error messages."""

    def __init__(self, source: str, lines: Sequence[int] | None):
        self.source = source
        self.lines = lines

    def row(self, i: int) -> str:
        if self.lines is None:
            return f"data row {i + 1}"
        return f"data row {i + 1} (line {self.lines[i]})"

    def cell(self, i: int, column: str) -> str:
        return f"{self.source}: {self.row(i)}, column {column!r}"

    def error(self, i: int, column: str, what: str) -> DataError:
        return DataError(f"{self.cell(i, column)}: {what}", source=self.source, row=i + 1, column=column)


def show(cell: Any) -> str:
    text = repr(cell)
    return text if len(text) <= 40 else text[:37] + "..."


# ---------------------------------------------------------------------------------------------------------------
# Cell parsers. A cell is a Python object: str (CSV, or text in memory), int/float (Parquet, memory) or None
# (an empty CSV cell, a Parquet null). Each returns the parsed value or raises a DataError via `where`.


def is_missing(cell: Any) -> bool:
    return cell is None or (isinstance(cell, str) and cell.strip() == "")


def parse_float(cell: Any, where: Where, i: int, column: str) -> float:
    if isinstance(cell, (bool, np.bool_)):
        raise where.error(i, column, f"got the boolean {cell!r}; expected a finite number.")
    if isinstance(cell, (int, float, np.integer, np.floating)):
        value = float(cell)
    elif isinstance(cell, str):
        text = cell.strip()
        if not _FLOAT_RE.match(text):
            try:
                value = float(text)  # 'nan', 'inf', 'Infinity', ...: parseable, but not finite
            except ValueError:
                raise where.error(i, column, f"{show(cell)} is not a number; expected a finite decimal "
                                  "number such as 12.5 or -3e-4.") from None
            if "_" in text or math.isfinite(value):
                raise where.error(i, column, f"{show(cell)} is not a plain decimal number; expected a finite "
                                  "decimal number such as 12.5 or -3e-4.")
        else:
            value = float(text)
            if not math.isfinite(value):
                raise where.error(i, column, f"{show(cell)} overflows float64; expected a finite number (a hex "
                                  "DAC word belongs in a dac sweep).")
            if value == 0.0 and re.search(r"[1-9]", text.split("e")[0].split("E")[0]):
                raise where.error(i, column, f"{show(cell)} underflows float64 to 0; expected 0 or a number "
                                  "of magnitude at least 5e-324, the smallest float64.")
    else:
        raise where.error(i, column, f"got {type(cell).__name__} {show(cell)}; expected a finite number.")
    if not math.isfinite(value):
        raise where.error(i, column, f"{show(cell)} is not finite; expected a finite number (leave an optional "
                          "cell empty if the value was not measured).")
    return value


def parse_int(cell: Any, where: Where, i: int, column: str) -> int:
    expected = f"expected an integer in [{_INT_MIN}, {_INT_MAX}] such as 0 or 3"
    if isinstance(cell, (bool, np.bool_)):
        raise where.error(i, column, f"got the boolean {cell!r}; {expected}.")
    if isinstance(cell, (int, np.integer)):
        value = decimal.Decimal(int(cell))
    elif isinstance(cell, str) and _FLOAT_RE.match(cell.strip()):
        value = decimal.Decimal(cell.strip())  # exact: '1.0000000000000001' is not 1, '1e23' is 10**23
    else:
        value = decimal.Decimal(parse_float(cell, where, i, column))
    if value != value.to_integral_value():
        raise where.error(i, column, f"{show(cell)} is not an integer; {expected}.")
    if not _INT_MIN <= value <= _INT_MAX:  # compared as decimals: int('1e999999999') would never finish
        raise where.error(i, column, f"{show(cell)} is outside the range of a run id; {expected}.")
    return int(value)


def parse_str(cell: Any, where: Where, i: int, column: str) -> str:
    if isinstance(cell, str):
        text = cell.strip()
    elif isinstance(cell, (int, np.integer)) and not isinstance(cell, (bool, np.bool_)):
        text = str(int(cell))  # an integer device id in a Parquet file
    else:
        raise where.error(i, column, f"got {type(cell).__name__} {show(cell)}; expected text.")
    if not text:
        raise where.error(i, column, "is empty; expected a non-empty name.")
    return text


def parse_sweep(cell: Any, where: Where, i: int, column: str) -> str:
    text = parse_str(cell, where, i, column)
    names = tuple(SWEEP_KINDS)
    if text not in names:
        close = difflib.get_close_matches(text.lower(), names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise where.error(i, column, f"unknown sweep {text!r}{hint}; expected one of {', '.join(names)}.")
    return text


def decode_dac_word(text: str) -> int:
    """Decode a hex DAC word as a 24-bit two's-complement signed integer.

    **Arguments:**

    - `text`: one to six hex digits, with or without a `0x` prefix, e.g. `"29E345"`, `"0xD61C74"`, `"A95"`.
      Fewer than six digits are zero-extended (`"A95"` is `0x000A95` = 2709): a hex number means what it says;
      a dropped leading digit cannot be guessed in general (see `gyrojax/data/README.md` for the one case in
      seed 000 where it can).

    **Returns:**

    The signed integer in [-2**23, 2**23 - 1]: `0x800000` and above are negative.

    Raises `ValueError` for anything else (non-hex characters, more than six digits, a sign).
    """
    body = text.strip()
    if body[:2].lower() == "0x":
        body = body[2:]
    if not body or not _HEX_RE.match(body):
        bad = sorted({ch for ch in body if ch not in "0123456789abcdefABCDEF"})
        detail = f"the characters {''.join(bad)!r} are not hex digits" if bad else "there are no hex digits"
        raise ValueError(f"{text!r} is not a hex DAC word: {detail}.")
    if len(body) > _HEX_DIGITS:
        raise ValueError(f"{text!r} has {len(body)} hex digits; a {DAC_WORD_BITS}-bit word has at most "
                         f"{_HEX_DIGITS}.")
    value = int(body, 16)
    return value - (1 << DAC_WORD_BITS) if value > _WORD_MAX else value


def parse_dac_word(cell: Any, where: Where, i: int, column: str) -> tuple[int, str]:
    """A DAC word: a signed decimal integer, `0x`-prefixed hex, or bare hex. Returns (word, how it was written)."""
    expected = (f"expected a DAC word: a signed decimal integer in [{_WORD_MIN}, {_WORD_MAX}] or a "
                f"{DAC_WORD_BITS}-bit two's-complement hex word of at most {_HEX_DIGITS} digits such as "
                "29E345 or 0x29E345")
    if isinstance(cell, (bool, np.bool_)):
        raise where.error(i, column, f"got the boolean {cell!r}; {expected}.")
    if isinstance(cell, (int, np.integer)):
        word, kind = int(cell), "decimal"
    elif isinstance(cell, (float, np.floating)):
        if not math.isfinite(cell) or cell != math.floor(cell):
            raise where.error(i, column, f"{show(cell)} is not an integer; {expected}.")
        word, kind = int(cell), "decimal"
    elif isinstance(cell, str):
        text = cell.strip()
        if _INT_RE.match(text) or _INTEGRAL_DEC_RE.match(text):
            word = int(text.split(".")[0])
            # Only unsigned digit strings short enough to be a hex word could be misread.
            kind = "digits" if re.fullmatch(r"\d{1,%d}" % _HEX_DIGITS, text) else "decimal"
        elif _FLOAT_RE.match(text) and not _HEX_RE.match(text):
            raise where.error(i, column, f"{show(cell)} is not an integer; {expected}.")
        else:
            try:
                word = decode_dac_word(text)
            except ValueError as e:
                hint = ""
                if "," in text:
                    hint = (" A comma is not a hex digit (seed 000 prints some words with a stray thousands "
                            "separator, e.g. '43,033' for 0x43033): remove it if that is what happened.")
                raise where.error(i, column, f"{e} {expected}.{hint}") from None
            kind = "hex" if text[:2].lower() == "0x" else "bare hex"
    else:
        raise where.error(i, column, f"got {type(cell).__name__} {show(cell)}; {expected}.")
    if not _WORD_MIN <= word <= _WORD_MAX:
        raise where.error(i, column, f"{show(cell)} is outside the {DAC_WORD_BITS}-bit range; {expected}.")
    return word, kind




def check_sweep_name(sweep: str):
    if sweep not in SWEEP_KINDS:
        raise ValueError(f"sweep must be one of {', '.join(SWEEP_KINDS)}, got {sweep!r}.")
