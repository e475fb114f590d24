"""Measured data: the tidy table of docs/data_format.md, its validation, its file formats and its padded array form.

One row is one settled point of one sweep. Required columns are `device` (str), `run` (int), `sweep` (one of
[`SWEEPS`][]), `input` and `output`; the optional columns are [`OPTIONAL_COLUMNS`][]; any other column is kept
(and written back) but ignored.

**Row numbers in messages.** Every error names the source, the row and the column. Rows are counted as
*data rows*, 1-based, not counting the header: "data row 1" is the first record after the header. For CSV files
the physical line of the file is given too ("line 2"; the header is line 1), which is what an editor shows.

**Missing values.** In the required columns every cell must hold a value. In an optional column a cell may be
empty (CSV) or null (Parquet): "not given". It is held as NaN in memory and written back as empty / null. A
NaN or an infinity *written as a value* (`nan`, `inf` in a CSV cell, a NaN float in Parquet) is an error, so that
a failed measurement is never mistaken for a point that was simply not recorded.
"""

from __future__ import annotations

import codecs
import csv
import decimal
import difflib
import io
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, final

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._io import atomic_open, atomic_path


SWEEPS = ("rate_table", "vcf_static", "vcf_dynamic", "dac")
"""The sweep kinds of the data format (docs/data_format.md)."""

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

# Rad/s heuristic (see `_looks_like_rad_s`).
_RAD_TOL = 1e-6
_RAD_SIG_DIGITS = 3

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


class _Where:
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


def _show(cell: Any) -> str:
    text = repr(cell)
    return text if len(text) <= 40 else text[:37] + "..."


# ---------------------------------------------------------------------------------------------------------------
# Cell parsers. A cell is a Python object: str (CSV, or text in memory), int/float (Parquet, memory) or None
# (an empty CSV cell, a Parquet null). Each returns the parsed value or raises a DataError via `where`.


def _is_missing(cell: Any) -> bool:
    return cell is None or (isinstance(cell, str) and cell.strip() == "")


def _parse_float(cell: Any, where: _Where, i: int, column: str) -> float:
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
                raise where.error(i, column, f"{_show(cell)} is not a number; expected a finite decimal "
                                  "number such as 12.5 or -3e-4.") from None
            if "_" in text or math.isfinite(value):
                raise where.error(i, column, f"{_show(cell)} is not a plain decimal number; expected a finite "
                                  "decimal number such as 12.5 or -3e-4.")
        else:
            value = float(text)
            if not math.isfinite(value):
                raise where.error(i, column, f"{_show(cell)} overflows float64; expected a finite number (a hex "
                                  "DAC word belongs in a dac sweep).")
            if value == 0.0 and re.search(r"[1-9]", text.split("e")[0].split("E")[0]):
                raise where.error(i, column, f"{_show(cell)} underflows float64 to 0; expected 0 or a number "
                                  "of magnitude at least 5e-324, the smallest float64.")
    else:
        raise where.error(i, column, f"got {type(cell).__name__} {_show(cell)}; expected a finite number.")
    if not math.isfinite(value):
        raise where.error(i, column, f"{_show(cell)} is not finite; expected a finite number (leave an optional "
                          "cell empty if the value was not measured).")
    return value


def _parse_int(cell: Any, where: _Where, i: int, column: str) -> int:
    expected = f"expected an integer in [{_INT_MIN}, {_INT_MAX}] such as 0 or 3"
    if isinstance(cell, (bool, np.bool_)):
        raise where.error(i, column, f"got the boolean {cell!r}; {expected}.")
    if isinstance(cell, (int, np.integer)):
        value = decimal.Decimal(int(cell))
    elif isinstance(cell, str) and _FLOAT_RE.match(cell.strip()):
        value = decimal.Decimal(cell.strip())  # exact: '1.0000000000000001' is not 1, '1e23' is 10**23
    else:
        value = decimal.Decimal(_parse_float(cell, where, i, column))
    if value != value.to_integral_value():
        raise where.error(i, column, f"{_show(cell)} is not an integer; {expected}.")
    if not _INT_MIN <= value <= _INT_MAX:  # compared as decimals: int('1e999999999') would never finish
        raise where.error(i, column, f"{_show(cell)} is outside the range of a run id; {expected}.")
    return int(value)


def _parse_str(cell: Any, where: _Where, i: int, column: str) -> str:
    if isinstance(cell, str):
        text = cell.strip()
    elif isinstance(cell, (int, np.integer)) and not isinstance(cell, (bool, np.bool_)):
        text = str(int(cell))  # an integer device id in a Parquet file
    else:
        raise where.error(i, column, f"got {type(cell).__name__} {_show(cell)}; expected text.")
    if not text:
        raise where.error(i, column, "is empty; expected a non-empty name.")
    return text


def _parse_sweep(cell: Any, where: _Where, i: int, column: str) -> str:
    text = _parse_str(cell, where, i, column)
    if text not in SWEEPS:
        close = difflib.get_close_matches(text.lower(), SWEEPS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise where.error(i, column, f"unknown sweep {text!r}{hint}; expected one of {', '.join(SWEEPS)}.")
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


def _parse_dac_word(cell: Any, where: _Where, i: int, column: str) -> tuple[int, str]:
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
            raise where.error(i, column, f"{_show(cell)} is not an integer; {expected}.")
        word, kind = int(cell), "decimal"
    elif isinstance(cell, str):
        text = cell.strip()
        if _INT_RE.match(text) or _INTEGRAL_DEC_RE.match(text):
            word = int(text.split(".")[0])
            # Only unsigned digit strings short enough to be a hex word could be misread.
            kind = "digits" if re.fullmatch(r"\d{1,%d}" % _HEX_DIGITS, text) else "decimal"
        elif _FLOAT_RE.match(text) and not _HEX_RE.match(text):
            raise where.error(i, column, f"{_show(cell)} is not an integer; {expected}.")
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
        raise where.error(i, column, f"got {type(cell).__name__} {_show(cell)}; {expected}.")
    if not _WORD_MIN <= word <= _WORD_MAX:
        raise where.error(i, column, f"{_show(cell)} is outside the {DAC_WORD_BITS}-bit range; {expected}.")
    return word, kind


# ---------------------------------------------------------------------------------------------------------------
# Table-level checks.


def _looks_like_rad_s(inputs: np.ndarray) -> bool:
    """Whether a rate-table run's inputs look like a round deg/s grid converted to rad/s.

    The heuristic, made so that it essentially never fires on real deg/s data:

    1. the run has at least two distinct non-zero |input| values;
    2. max |input| < 2 pi (a rad/s file of any usual table range, up to 360 deg/s);
    3. every non-zero |input| x 180/pi lies within 1e-6 (relative) of a number with at most three significant
       digits (0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 45, 100, 200, 360, ...).

    A genuine deg/s grid fails 3 (1 deg/s x 180/pi = 57.2957..., 7e-5 away from 57.3). A random value passes 3
    with probability at most ~2e-3 (the tolerance band over the spacing of 3-digit numbers), two independent
    ones with at most ~4e-6. Conversions made with a truncated pi (3.1416) are not caught: this is a guard
    against the usual mistake, not a proof.
    """
    mags = np.unique(np.abs(inputs[inputs != 0]))
    if mags.size < 2 or mags.max() >= 2 * math.pi:
        return False
    deg = mags * (180.0 / math.pi)
    step = 10.0 ** (np.floor(np.log10(deg)) - (_RAD_SIG_DIGITS - 1))
    nearest = np.round(deg / step) * step
    return bool(np.all(np.abs(deg - nearest) <= _RAD_TOL * deg))


def _rows_text(where: _Where, rows: Sequence[int]) -> str:
    rows = list(rows)
    if len(rows) <= 4:
        return ", ".join(where.row(r) for r in rows)
    return f"{where.row(rows[0])} ... {where.row(rows[-1])} ({len(rows)} rows)"


def _validate(raw: Mapping[str, Any], source: str, lines: Sequence[int] | None,
              nan_is_missing: bool) -> dict[str, np.ndarray]:
    """Parse and check raw columns; return the normalised columns (same order) or raise a DataError."""
    where = _Where(source, lines)
    names = list(raw)
    header = "header (line 1)" if lines is not None else "columns"
    missing = [c for c in REQUIRED_COLUMNS if c not in raw]
    if missing:
        # Suggest a near spelling: 'Output', 'out put', 'sweep_kind' ...
        hints = []
        for c in missing:
            close = difflib.get_close_matches(c, [n.lower() for n in names], n=1)
            if close:
                hints.append(f"{c!r} (found {names[[n.lower() for n in names].index(close[0])]!r})")
            else:
                hints.append(repr(c))
        raise DataError(f"{source}: {header}: missing required column{'s' if len(missing) > 1 else ''} "
                        f"{', '.join(hints)}; required are {', '.join(REQUIRED_COLUMNS)}; found "
                        f"{', '.join(map(repr, names)) or 'no columns'}.", source=source,
                        column=missing[0])
    lengths = {c: len(v) for c, v in raw.items()}
    n = lengths["device"]
    for c, length in lengths.items():
        if length != n:
            raise DataError(f"{source}: column {c!r} has {length} values but column 'device' has {n}.",
                            source=source, column=c)
    if n == 0:
        raise DataError(f"{source}: empty: the {header} is there but there are no data rows.", source=source)

    def cells(c):
        v = raw[c]
        return v.tolist() if isinstance(v, np.ndarray) else list(v)

    def required_cell(c, i, cell):
        if _is_missing(cell):
            raise where.error(i, c, "is empty; every row needs a value in the required columns.")
        return cell

    out: dict[str, np.ndarray] = {}
    device = [_parse_str(required_cell("device", i, x), where, i, "device") for i, x in enumerate(cells("device"))]
    run = [_parse_int(required_cell("run", i, x), where, i, "run") for i, x in enumerate(cells("run"))]
    sweep = [_parse_sweep(required_cell("sweep", i, x), where, i, "sweep") for i, x in enumerate(cells("sweep"))]
    inputs = np.empty(n)
    word_kinds: dict[str, list[int]] = {}
    for i, x in enumerate(cells("input")):
        x = required_cell("input", i, x)
        if sweep[i] == "dac":
            word, kind = _parse_dac_word(x, where, i, "input")
            inputs[i] = word
            word_kinds.setdefault(kind, []).append(i)
        else:
            inputs[i] = _parse_float(x, where, i, "input")
    output = np.array([_parse_float(required_cell("output", i, x), where, i, "output")
                       for i, x in enumerate(cells("output"))], dtype=np.float64).reshape(n)

    optional: dict[str, np.ndarray] = {}
    for c in OPTIONAL_COLUMNS:
        if c not in raw:
            continue
        col = np.full(n, np.nan)
        for i, x in enumerate(cells(c)):
            if _is_missing(x) or (nan_is_missing and isinstance(x, float) and math.isnan(x)):
                continue
            col[i] = _parse_float(x, where, i, c)
            if c == "output_sigma" and col[i] < 0:
                raise where.error(i, c, f"{_show(x)} is negative; a standard uncertainty is >= 0.")
            if c == "n_samples" and (col[i] < 1 or col[i] != math.floor(col[i])):
                raise where.error(i, c, f"{_show(x)} is not a positive whole number of samples.")
            if c == "drive_freq_hz" and col[i] <= 0:
                raise where.error(i, c, f"{_show(x)} is not a positive frequency.")
            if c == "time_s" and col[i] < 0:
                raise where.error(i, c, f"{_show(x)} is negative; time_s is seconds since the run's power-on.")
        optional[c] = col

    # Hex words without a prefix next to plain-digit words: '539' could be decimal 539 or hex 0x539 (seed 000
    # Table 2 prints both 'A95' and '539'). Refuse rather than guess.
    if "bare hex" in word_kinds and "digits" in word_kinds:
        i_dec, i_hex = word_kinds["digits"][0], word_kinds["bare hex"][0]
        raise where.error(i_dec, "input", f"DAC word {_show(cells('input')[i_dec])} is ambiguous: it reads as a "
                          f"decimal integer, but {where.row(i_hex)} has the bare hex word "
                          f"{_show(cells('input')[i_hex])}, so it may be hex too. Write hex words with a 0x "
                          "prefix, or give every word as a signed decimal integer.")

    for c in names:
        if c in REQUIRED_COLUMNS:
            continue
        if c in optional:
            out[c] = optional[c]
        else:
            v = raw[c]
            arr = np.array(v) if not isinstance(v, np.ndarray) else v.copy()
            if arr.ndim != 1:
                raise DataError(f"{source}: extra column {c!r} must be one-dimensional, got shape {arr.shape}.",
                                source=source, column=c)
            out[c] = arr
    required = {"device": np.array(device, dtype=str), "run": np.array(run, dtype=np.int64),
                "sweep": np.array(sweep, dtype=str), "input": inputs, "output": output}
    ordered = {c: (required[c] if c in required else out[c]) for c in names}

    # Duplicate points.
    seen: dict[tuple, int] = {}
    for i in range(n):
        key = (device[i], run[i], sweep[i], float(inputs[i]))
        if key in seen:
            j = seen[key]
            raise DataError(f"{source}: {where.row(i)}, column 'input': duplicate point: {where.row(j)} has the "
                            f"same (device, run, sweep, input) = ({device[i]!r}, {run[i]}, {sweep[i]!r}, "
                            f"{inputs[i]:g}). Each settled point appears once; give repeats a different run.",
                            source=source, row=i + 1, column="input")
        seen[key] = i

    # Rate-table inputs that look like rad/s.
    for (dev, r, s), rows in _group_rows(ordered).items():
        if s == "rate_table" and _looks_like_rad_s(inputs[rows]):
            raise DataError(
                f"{source}: {_rows_text(where, rows)}, column 'input': device {dev!r} run {r} rate_table inputs "
                f"look like rad/s, but rate-table inputs are deg/s (docs/data_format.md): max |input| = "
                f"{np.abs(inputs[rows]).max():.6g} < 2 pi and every input x 180/pi is a round deg/s value "
                f"(e.g. {inputs[rows][np.argmax(np.abs(inputs[rows]))]:.6g} -> "
                f"{np.abs(inputs[rows]).max() * 180 / math.pi:.6g} deg/s) to 1e-6. Convert with "
                "input_dps = input_rad_s * 180 / pi (gyrojax.units.rad_s_to_dps).",
                source=source, row=int(rows[0]) + 1, column="input")
    for arr in ordered.values():
        arr.flags.writeable = False
    return ordered


def _group_rows(columns: Mapping[str, np.ndarray]) -> dict[tuple[str, int, str], np.ndarray]:
    """Row indices of each (device, run, sweep) group, groups and rows in order of first appearance."""
    groups: dict[tuple[str, int, str], list[int]] = {}
    for i, key in enumerate(zip(columns["device"].tolist(), columns["run"].tolist(), columns["sweep"].tolist())):
        groups.setdefault(key, []).append(i)
    return {k: np.asarray(v, dtype=np.int64) for k, v in groups.items()}


# ---------------------------------------------------------------------------------------------------------------
# The table.


@final
class Table:
    """A validated tidy table of settled points (docs/data_format.md): plain NumPy columns, immutable.

    Build one with [`gyrojax.read_table`][], `Table.from_columns` or `Table.from_records`; every constructor
    validates (see [`gyrojax.DataError`][]). Columns are read-only NumPy arrays: `device` and `sweep` str,
    `run` int64, `input` and `output` float64 (DAC words as integer-valued floats, exact below 2**53), the
    optional columns float64 with NaN for "not given", and extra columns as read (text from CSV).
    """

    __slots__ = ("_columns", "_source", "_lines")

    def __init__(self, columns: Mapping[str, Any], *, source: str = "<memory>"):
        """**Arguments:**

        - `columns`: column name -> 1-D sequence or array, all the same length. In memory, NaN in an optional
          column means "not given"; `input` of `dac` rows may be integers or hex strings.
        - `source`: a name for messages (a path, or "<memory>").
        """
        self._init(columns, source, None, nan_is_missing=True)

    def _init(self, columns, source, lines, nan_is_missing):
        self._columns = _validate(columns, str(source), lines, nan_is_missing)
        self._source = str(source)
        self._lines = None if lines is None else tuple(lines)

    def __init_subclass__(cls, **kwargs):
        raise TypeError("gyrojax.Table is final; compose it instead of subclassing.")

    @classmethod
    def from_columns(cls, columns: Mapping[str, Any], *, source: str = "<memory>") -> "Table":
        """Build and validate a table from a dict of columns (same as `Table(columns, source=...)`)."""
        return cls(columns, source=source)

    @classmethod
    def from_records(cls, records: Iterable[Mapping[str, Any]], *, source: str = "<memory>") -> "Table":
        """Build and validate a table from row dicts (e.g. from [`gyrojax.aggregate_samples`][]).

        A key missing from some records is "not given" (NaN) there; it is an error for required columns.
        """
        records = list(records)
        names: list[str] = []
        for rec in records:
            names.extend(k for k in rec if k not in names)
        return cls({k: [rec.get(k) for rec in records] for k in names}, source=source)

    @classmethod
    def _from_file(cls, columns, source, lines) -> "Table":
        self = object.__new__(cls)
        self._init(columns, source, lines, nan_is_missing=False)
        return self

    # -- access --------------------------------------------------------------------------------------------------

    @property
    def source(self) -> str:
        """Where the table came from (a path, or "<memory>"), for messages."""
        return self._source

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """A new dict of the (read-only) column arrays, in file order."""
        return dict(self._columns)

    @property
    def column_names(self) -> tuple[str, ...]:
        return tuple(self._columns)

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._columns[name]
        except KeyError:
            raise KeyError(f"{self._source}: no column {name!r}; columns are {', '.join(self._columns)}.") from None

    def __contains__(self, name: object) -> bool:
        return name in self._columns

    def __len__(self) -> int:
        return len(self._columns["device"])

    def __repr__(self) -> str:
        return f"Table({len(self)} rows, columns={list(self._columns)}, source={self._source!r})"

    def locate(self, row: int, column: str | None = None, *, with_source: bool = True) -> str:
        """Describe 0-based row index `row` as a user sees it: "<source>: data row N (line L)[, column 'c']"."""
        where = _Where(self._source, self._lines)
        text = where.row(row) + ("" if column is None else f", column {column!r}")
        return f"{self._source}: {text}" if with_source else text

    def equals(self, other: "Table") -> bool:
        """Exact equality of column names, order, dtypes kinds and values (NaN equal to NaN)."""
        if not isinstance(other, Table) or self.column_names != other.column_names:
            return False
        for c in self._columns:
            a, b = self._columns[c], other._columns[c]
            if a.shape != b.shape:
                return False
            if a.dtype.kind == "f" and b.dtype.kind == "f":
                if not np.array_equal(a, b, equal_nan=True):
                    return False
            elif a.dtype.kind != b.dtype.kind or not np.array_equal(a, b):
                return False
        return True

    def groups(self, sweep: str | None = None) -> dict[tuple[str, int, str], np.ndarray]:
        """Row indices (0-based, file order) of each (device, run, sweep) group, in order of first appearance.

        **Arguments:**

        - `sweep`: keep only groups of this sweep kind.
        """
        groups = _group_rows(self._columns)
        if sweep is not None:
            _check_sweep_name(sweep)
            groups = {k: v for k, v in groups.items() if k[2] == sweep}
        return groups

    def select(self, rows: Sequence[int] | np.ndarray) -> "Table":
        """A new table of the given 0-based rows (in the given order), same columns, same source."""
        rows = np.asarray(rows, dtype=np.int64)
        new = object.__new__(Table)
        new._columns = {}
        for c, arr in self._columns.items():
            sub = arr[rows]
            sub.flags.writeable = False
            new._columns[c] = sub
        new._source = self._source
        new._lines = None if self._lines is None else tuple(self._lines[r] for r in rows)
        return new

    # -- array form ----------------------------------------------------------------------------------------------

    def to_arrays(self, sweep: str) -> "SweepArrays":
        """The rows of one sweep kind as padded (device, run, point) arrays with a mask, for vmapping lots.

        Devices and, within a device, runs are in order of first appearance; points keep file order (the order
        a sweep was taken in matters for drift). Extra (unknown) columns are not carried.

        **Arguments:**

        - `sweep`: one of [`SWEEPS`][].

        **Returns:**

        A [`gyrojax.SweepArrays`][]. `SweepArrays.to_table()` gives back exactly these rows (same column
        order, values and, for a table grouped by device and run, row order).
        """
        p = self._padded(sweep)
        return SweepArrays(
            inputs=jnp.asarray(p["inputs"]), outputs=jnp.asarray(p["outputs"]),
            sigmas=None if p["sigmas"] is None else jnp.asarray(p["sigmas"]), mask=jnp.asarray(p["mask"]),
            aux={c: jnp.asarray(v) for c, v in p["aux"].items()}, sweep=sweep, devices=p["devices"],
            runs=p["runs"], column_order=p["column_order"])

    def _padded(self, sweep: str) -> dict[str, Any]:
        """The padded NumPy arrays and metadata behind `to_arrays` (also used by the metrics report)."""
        _check_sweep_name(sweep)
        groups = self.groups(sweep)
        if not groups:
            present = sorted(set(self._columns["sweep"].tolist()))
            raise DataError(f"{self._source}: no rows with sweep {sweep!r}; the table has {', '.join(present)}.",
                            source=self._source, column="sweep")
        devices: list[str] = []
        runs: dict[str, list[int]] = {}
        for dev, r, _ in groups:
            if dev not in runs:
                devices.append(dev)
                runs[dev] = []
            runs[dev].append(r)
        n_dev, n_run = len(devices), max(len(v) for v in runs.values())
        n_pt = max(len(v) for v in groups.values())
        shape = (n_dev, n_run, n_pt)
        inputs, outputs = np.zeros(shape), np.zeros(shape)
        mask = np.zeros(shape, dtype=bool)
        aux_names = [c for c in self._columns if c in OPTIONAL_COLUMNS and c != "output_sigma"]
        aux = {c: np.zeros(shape) for c in aux_names}
        has_sigma = "output_sigma" in self._columns
        sigmas = np.ones(shape)
        for (dev, r, _), rows in groups.items():
            d, k, m = devices.index(dev), runs[dev].index(r), len(rows)
            inputs[d, k, :m] = self._columns["input"][rows]
            outputs[d, k, :m] = self._columns["output"][rows]
            mask[d, k, :m] = True
            if has_sigma:
                sigmas[d, k, :m] = self._columns["output_sigma"][rows]
            for c in aux_names:
                aux[c][d, k, :m] = self._columns[c][rows]
        return {"inputs": inputs, "outputs": outputs, "sigmas": sigmas if has_sigma else None, "mask": mask,
                "aux": aux, "sweep": sweep, "devices": tuple(devices), "runs": tuple(tuple(runs[d]) for d in devices),
                "column_order": tuple(c for c in self._columns if c in REQUIRED_COLUMNS or c in OPTIONAL_COLUMNS)}


def _check_sweep_name(sweep: str):
    if sweep not in SWEEPS:
        raise ValueError(f"sweep must be one of {', '.join(SWEEPS)}, got {sweep!r}.")


class SweepArrays(eqx.Module):
    """One sweep kind of a lot as padded arrays, shape (n_device, n_run, n_point), with a mask.

    Ragged lots (devices with different numbers of runs, runs with different numbers of points) are padded;
    `mask` is True on real points. Padding holds 0 in `inputs`, `outputs` and `aux`, and 1 in `sigmas`, so that
    masked sums and their gradients stay finite. Build with `Table.to_arrays(sweep)`; `to_table()` inverts it.

    **Fields:**

    - `inputs`, `outputs`: float64 (see the data format, docs/data_format.md, for units per sweep kind).
    - `sigmas`: float64 `output_sigma` (NaN where not given), or None if the table had no such column.
    - `mask`: bool, True on real points.
    - `aux`: the other optional columns the table had (`n_samples`, `rate_dps`, ...), float64, NaN where a
      value was not given.
    - `sweep`, `devices`, `runs` (run ids per device), `column_order`: static metadata.
    """

    inputs: Float[Array, "device run point"]
    outputs: Float[Array, "device run point"]
    sigmas: Float[Array, "device run point"] | None
    mask: Bool[Array, "device run point"]
    aux: dict[str, Float[Array, "device run point"]]
    sweep: str = eqx.field(static=True)
    devices: tuple[str, ...] = eqx.field(static=True)
    runs: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    column_order: tuple[str, ...] = eqx.field(static=True, default=REQUIRED_COLUMNS)

    def __check_init__(self):
        _check_sweep_name(self.sweep)
        shape = self.mask.shape
        if len(shape) != 3:
            raise ValueError(f"SweepArrays.mask must have shape (device, run, point), got {shape}.")
        arrays = {"inputs": self.inputs, "outputs": self.outputs, "sigmas": self.sigmas,
                  **{f"aux[{k!r}]": v for k, v in self.aux.items()}}
        for name, arr in arrays.items():
            if arr is None:
                continue
            if arr.shape != shape:
                raise ValueError(f"SweepArrays.{name} has shape {arr.shape}, expected {shape} like mask.")
            if arr.dtype != jnp.float64:
                raise ValueError(f"SweepArrays.{name} has dtype {arr.dtype}, expected float64 (enable "
                                 "jax_enable_x64; importing gyrojax does).")
        if self.mask.dtype != jnp.bool_:
            raise ValueError(f"SweepArrays.mask has dtype {self.mask.dtype}, expected bool.")
        if len(self.devices) != shape[0] or len(self.runs) != shape[0]:
            raise ValueError(f"SweepArrays: {len(self.devices)} device ids and {len(self.runs)} run lists for "
                             f"{shape[0]} devices.")
        if any(len(r) > shape[1] for r in self.runs):
            raise ValueError(f"SweepArrays: a device has more run ids than the run axis ({shape[1]}).")

    @property
    def run_mask(self) -> Bool[Array, "device run"]:
        """True where (device, run) holds at least one point."""
        return jnp.any(self.mask, axis=-1)

    def to_table(self, *, source: str | None = None) -> Table:
        """The real (unmasked) points back as a [`gyrojax.Table`][], grouped by device then run."""
        mask = np.asarray(self.mask)
        inputs, outputs = np.asarray(self.inputs), np.asarray(self.outputs)
        order = list(self.column_order)
        order += [c for c in REQUIRED_COLUMNS if c not in order]
        if self.sigmas is not None and "output_sigma" not in order:
            order.append("output_sigma")
        order += [c for c in self.aux if c not in order]
        if self.sigmas is None and "output_sigma" in order:
            order.remove("output_sigma")
        cols: dict[str, list] = {c: [] for c in order}
        for d, dev in enumerate(self.devices):
            for k, r in enumerate(self.runs[d]):
                sel = mask[d, k]
                m = int(sel.sum())
                cols["device"] += [dev] * m
                cols["run"] += [r] * m
                cols["sweep"] += [self.sweep] * m
                cols["input"] += inputs[d, k][sel].tolist()
                cols["output"] += outputs[d, k][sel].tolist()
                if "output_sigma" in cols:
                    cols["output_sigma"] += np.asarray(self.sigmas)[d, k][sel].tolist()
                for c, v in self.aux.items():
                    cols[c] += np.asarray(v)[d, k][sel].tolist()
        return Table({c: np.asarray(v, dtype=np.float64) if c not in ("device", "run", "sweep")
                      else np.asarray(v) for c, v in cols.items()},
                     source=source or f"<SweepArrays {self.sweep}>")


# ---------------------------------------------------------------------------------------------------------------
# Files.


def table_format(path: str | os.PathLike, what: str) -> str:
    """The table format of `path` from its suffix (".csv" or ".parquet"); `what` names the caller in the error."""
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in (".csv", ".parquet"):
        raise ValueError(f"{what}: cannot tell the format of {os.fspath(path)!r} from its suffix "
                         f"{suffix or '(none)'!r}; use .csv or .parquet.")
    return suffix


def read_table(path: str | os.PathLike) -> Table:
    """Read and validate a tidy table of settled points (docs/data_format.md) from CSV or Parquet.

    **Arguments:**

    - `path`: a `.csv` (UTF-8, comma-separated, one header line) or `.parquet` file.

    **Returns:**

    A validated [`gyrojax.Table`][].

    Raises [`gyrojax.DataError`][] (a `ValueError`) naming the file, the data row (1-based, header not counted;
    for CSV also the file line) and the column for: an empty file, a missing required column, an unknown sweep
    name, an empty required cell, NaN or infinity, a non-numeric cell, a malformed DAC word, duplicate
    (device, run, sweep, input) points, and rate-table inputs that look like rad/s. Raises `ValueError` for an
    unknown suffix. Nothing is dropped silently (blank CSV lines hold nothing and are skipped).
    """
    suffix = table_format(path, "read_table")
    source = os.fspath(path)
    if os.path.isdir(source):
        raise DataError(f"{source} is a directory; give a .csv or .parquet file.", source=source)
    if suffix == ".csv":
        columns, lines = _read_csv(source)
        return Table._from_file(columns, source, lines)
    columns = _read_parquet(source)
    return Table._from_file(columns, source, None)


def _read_csv(source: str) -> tuple[dict[str, list], list[int]]:
    with open(source, "rb") as f:
        data = f.read()
    bom = data.startswith(codecs.BOM_UTF8)
    try:
        text = data[3 if bom else 0:].decode("utf-8")
    except UnicodeDecodeError as e:
        at = e.start + (3 if bom else 0)
        line = data[:at].count(b"\n") + 1
        raise DataError(f"{source}: line {line}: not UTF-8 text (byte {at}: {e.reason}); save the CSV as UTF-8.",
                        source=source) from None
    reader = csv.reader(io.StringIO(text, newline=""))
    records: list[tuple[int, list[str]]] = []  # (first line, fields)
    previous = 0
    try:
        for row in reader:
            records.append((previous + 1, row))
            previous = reader.line_num
    except csv.Error as e:
        raise DataError(f"{source}: line {reader.line_num}: not a readable CSV line: {e}.", source=source) from None

    def blank(row):
        return not any(cell.strip() for cell in row)

    first = next((k for k, (_, row) in enumerate(records) if not blank(row)), None)
    if first is None:
        raise DataError(f"{source}: empty file: no header line (expected a header naming at least "
                        f"{', '.join(REQUIRED_COLUMNS)}).", source=source)
    if records[first][0] != 1:
        raise DataError(f"{source}: the header must be line 1, found blank lines before it.", source=source)
    header = records[first][1]
    names = [h.strip() for h in header]
    if len(names) == 1:
        for sep, what in ((";", "semicolon"), ("\t", "tab"), ("|", "bar")):
            if sep in names[0]:
                raise DataError(f"{source}: the header (line 1) has one column {_show(names[0])}: the file looks "
                                f"{what}-separated; gyrojax reads comma-separated CSV (save it with ',' between "
                                "fields and '.' as the decimal mark).", source=source)
    for j, name in enumerate(names):
        if not name:
            raise DataError(f"{source}: header (line 1): column {j + 1} has no name.", source=source)
        if name in names[:j]:
            raise DataError(f"{source}: header (line 1): column {name!r} appears twice.", source=source,
                            column=name)
    data_records = [(line, row) for line, row in records[first + 1:] if not (blank(row) and len(row) <= 1)]
    # A file cut short inside its last record would read as complete, with a wrong last number: refuse a last
    # line that holds text but no newline (a blank last line holds no data).
    tail = text[max(text.rfind("\n"), text.rfind("\r")) + 1:]
    if tail.strip():
        where = (f"data row {len(data_records)} (line {data_records[-1][0]})" if data_records
                 else "the header (line 1)")
        raise DataError(f"{source}: {where} does not end with a newline, so the file may have been cut short "
                        "inside it (a partial copy or an interrupted write). If the file is complete, add a final "
                        "newline.", source=source, row=len(data_records) or None)
    columns: dict[str, list] = {name: [] for name in names}
    lines: list[int] = []
    for k, (start, row) in enumerate(data_records):
        if len(row) != len(names):
            raise DataError(f"{source}: data row {k + 1} (line {start}) has {len(row)} fields but the header has "
                            f"{len(names)}.", source=source, row=k + 1)
        for name, cell in zip(names, row):
            columns[name].append(cell)
        lines.append(start)
    return columns, lines


def _read_parquet(source: str) -> dict[str, Any]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(source)
    except (pa.ArrowInvalid, OSError) as e:
        if os.path.exists(source) and os.path.getsize(source) == 0:
            raise DataError(f"{source}: empty file.", source=source) from None
        if isinstance(e, FileNotFoundError):
            raise
        raise DataError(f"{source}: not a readable Parquet file: {e}", source=source) from None
    columns: dict[str, Any] = {}
    for name in table.column_names:
        col = table.column(name)
        if name in REQUIRED_COLUMNS or name in OPTIONAL_COLUMNS:
            columns[name] = col.to_pylist()  # None for nulls, so empty cells are told from NaN values
        elif (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)) and col.null_count == 0:
            columns[name] = np.array(col.to_pylist(), dtype=str)  # as text read from a CSV
        else:
            columns[name] = col.to_numpy(zero_copy_only=False)
    if not columns:
        raise DataError(f"{source}: empty file: no columns.", source=source)
    return columns


def write_table(table: Table, path: str | os.PathLike) -> None:
    """Write a table atomically as CSV or Parquet (chosen by the suffix of `path`).

    The file is written to a temporary file in the same directory and moved into place with `os.replace`, so a
    reader never sees a half-written file and a failed write leaves any old file untouched (a symbolic link is
    written through, a new file gets `0o666 & ~umask`, a replaced one keeps its mode).

    **Arguments:**

    - `table`: a [`gyrojax.Table`][].
    - `path`: ending in `.csv` or `.parquet`; anything else is a `ValueError`.

    CSV floats are written with `repr` (the shortest text that reads back to the identical float64: exact
    round trip); DAC words, runs and sample counts as integers; "not given" optional values as empty cells.
    Every line, the last included, ends with a newline ([`gyrojax.read_table`][] refuses a file that does
    not: it may have been cut short). Parquet keeps dtypes, with nulls for "not given".
    """
    if not isinstance(table, Table):
        raise TypeError(f"write_table expects a gyrojax.Table, got {type(table).__name__}.")
    suffix = table_format(path, "write_table")
    if suffix == ".csv":
        with atomic_open(path, "w", newline="", encoding="utf-8") as f:
            _write_csv(table, f)
    else:
        with atomic_path(path) as tmp:
            _write_parquet(table, tmp)


def _csv_cells(name: str, arr: np.ndarray, table: Table) -> list[str]:
    if name in ("device", "sweep"):
        return arr.tolist()
    if name == "run":
        return [str(int(v)) for v in arr.tolist()]
    if name == "input":
        dac = table["sweep"] == "dac"
        return [str(int(v)) if is_dac else repr(float(v)) for v, is_dac in zip(arr.tolist(), dac.tolist())]
    if name == "n_samples":
        return ["" if math.isnan(v) else str(int(v)) for v in arr.tolist()]
    if name in REQUIRED_COLUMNS or name in OPTIONAL_COLUMNS:
        return ["" if math.isnan(v) else repr(float(v)) for v in arr.tolist()]
    # An extra column: text as is; numbers exactly; nulls empty.
    out = []
    for v in arr.tolist():
        if v is None or (isinstance(v, float) and math.isnan(v)):
            out.append("")
        elif isinstance(v, float):
            out.append(repr(v))
        else:
            out.append(str(v))
    return out


def _write_csv(table: Table, f) -> None:
    writer = csv.writer(f, lineterminator="\n")
    names = table.column_names
    writer.writerow(names)
    cols = [_csv_cells(c, table[c], table) for c in names]
    writer.writerows(zip(*cols))


def _write_parquet(table: Table, path: str) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays, names = [], []
    for c in table.column_names:
        arr = table[c]
        if c in ("device", "sweep"):
            col = pa.array(arr.tolist(), type=pa.string())
        elif c == "run":
            col = pa.array(arr, type=pa.int64())
        elif c in ("input", "output"):
            col = pa.array(arr, type=pa.float64())
        elif c in OPTIONAL_COLUMNS:
            col = pa.array(arr, type=pa.float64(), mask=np.isnan(arr))
        else:
            col = pa.array(arr.tolist() if arr.dtype.kind in "OU" else arr)
        arrays.append(col)
        names.append(c)
    pq.write_table(pa.Table.from_arrays(arrays, names=names), path)


# ---------------------------------------------------------------------------------------------------------------
# Raw sample streams -> settled points.


def aggregate_samples(device: str, run: int, sweep: str, input: Any, samples: Float[ArrayLike, " sample"], *,
                      sample_rate_hz: float, discard_s: float = 0.0, n_batches: int = 20) -> dict[str, Any]:
    """Reduce one raw output stream of one settled point to a row of the tidy table.

    The mean is over every sample left after the settling time is discarded. Its standard error is estimated by
    **batch means**: the kept samples are cut into `n_batches` consecutive batches of equal length
    m = N // n_batches (a remainder of fewer than `n_batches` samples, at the end, counts in the mean but not in
    the error estimate), and

        output_sigma = std(batch means, ddof=1) / sqrt(n_batches).

    Why not std(samples)/sqrt(N): gyro output noise is correlated (loop filters, 1/f, quantization
    shaping), and the naive formula then understates the error, by sqrt((1+phi)/(1-phi)) for AR(1) noise with
    coefficient phi (6x for phi = 0.95). Batch means are unbiased for any noise whose correlation time is short
    compared with a batch (T / n_batches); for white noise they agree with the naive formula on average, with a
    relative scatter of about 1/sqrt(2 (n_batches - 1)) (16% for 20 batches). The batch-means variance is the
    ordinary variance of adjacent block averages; for white noise it equals the Allan variance at
    tau = T / n_batches. For flicker noise no standard error of a mean exists; the estimate then describes the
    noise at the batch time scale, and a longer record will not shrink it as 1/sqrt(T).

    **Arguments:**

    - `device`, `run`, `sweep`, `input`: the point's identity, as in the table (`input` of a `dac` sweep may be
      an integer or a hex word).
    - `samples`: 1-D array of output samples, in time order, all finite.
    - `sample_rate_hz`: sampling rate.
    - `discard_s`: settling time at the start to drop; ceil(discard_s * sample_rate_hz) samples are dropped.
    - `n_batches`: number of batches for the error estimate; at least 2 samples per batch are required.

    **Returns:**

    A dict with `device`, `run`, `sweep`, `input`, `output` (mean), `output_sigma` (batch-means standard error)
    and `n_samples` (samples in the mean), ready for `Table.from_records`.
    """
    label = f"aggregate_samples(device={device!r}, run={run!r}, sweep={sweep!r}, input={input!r})"
    where = _Where(label, None)
    device = _parse_str(device, where, 0, "device")
    run = _parse_int(run, where, 0, "run")
    sweep = _parse_sweep(sweep, where, 0, "sweep")
    value = _parse_dac_word(input, where, 0, "input")[0] if sweep == "dac" else _parse_float(input, where, 0,
                                                                                               "input")
    if not (isinstance(sample_rate_hz, (int, float, np.number)) and sample_rate_hz > 0
            and math.isfinite(sample_rate_hz)):
        raise ValueError(f"{label}: sample_rate_hz must be a positive finite number, got {sample_rate_hz!r}.")
    if not (discard_s >= 0 and math.isfinite(discard_s)):
        raise ValueError(f"{label}: discard_s must be >= 0, got {discard_s!r}.")
    if not (isinstance(n_batches, (int, np.integer)) and n_batches >= 2):
        raise ValueError(f"{label}: n_batches must be an integer >= 2, got {n_batches!r}.")
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1:
        raise DataError(f"{label}: samples must be one-dimensional, got shape {x.shape}.", source=label)
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise DataError(f"{label}: sample {bad[0]} (0-based) is {float(x[bad[0]])!r}; every sample must be finite "
                        f"({bad.size} are not).", source=label)
    drop = math.ceil(discard_s * sample_rate_hz - 1e-9)
    kept = x[drop:]
    if kept.size < 2 * n_batches:
        raise DataError(f"{label}: {kept.size} samples left after discarding {drop} ({discard_s} s at "
                        f"{sample_rate_hz} Hz); need at least {2 * n_batches} for {n_batches} batches.",
                        source=label)
    m = kept.size // n_batches
    batch_means = kept[: m * n_batches].reshape(n_batches, m).mean(axis=1)
    sigma = float(np.std(batch_means, ddof=1) / math.sqrt(n_batches))
    return {"device": device, "run": run, "sweep": sweep, "input": value, "output": float(np.mean(kept)),
            "output_sigma": sigma, "n_samples": int(kept.size)}
