"""Table-level checks: raw columns -> the normalised, read-only columns of a `Table`, or a `DataError`.

**Missing values.** In the required columns every cell must hold a value. In an optional column a cell may be
empty (CSV) or null (Parquet): "not given". It is held as NaN in memory and written back as empty / null. A
NaN or an infinity *written as a value* (`nan`, `inf` in a CSV cell, a NaN float in Parquet) is an error, so that
a failed measurement is never mistaken for a point that was simply not recorded.
"""

import difflib
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._sweeps.registry import sweep_kind
from .cells import (
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    DataError,
    Where,
    is_missing,
    parse_dac_word,
    parse_float,
    parse_int,
    parse_str,
    parse_sweep,
    show,
)


# Rad/s heuristic (see `looks_like_rad_s`).
_RAD_TOL = 1e-6
_RAD_SIG_DIGITS = 3


def looks_like_rad_s(inputs: np.ndarray) -> bool:
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


def rows_text(where: Where, rows: Sequence[int] | np.ndarray) -> str:
    rows = list(rows)
    if len(rows) <= 4:
        return ", ".join(where.row(r) for r in rows)
    return f"{where.row(rows[0])} ... {where.row(rows[-1])} ({len(rows)} rows)"


def validate_columns(raw: Mapping[str, Any], source: str, lines: Sequence[int] | None,
              nan_is_missing: bool) -> dict[str, np.ndarray]:
    """Parse and check raw columns; return the normalised columns (same order) or raise a DataError."""
    where = Where(source, lines)
    names = list(raw)
    n = _check_shape(raw, source, "header (line 1)" if lines is not None else "columns")
    device = [parse_str(_required_cell(where, "device", i, x), where, i, "device")
              for i, x in enumerate(_cells(raw, "device"))]
    run = [parse_int(_required_cell(where, "run", i, x), where, i, "run") for i, x in enumerate(_cells(raw, "run"))]
    sweep = [parse_sweep(_required_cell(where, "sweep", i, x), where, i, "sweep")
             for i, x in enumerate(_cells(raw, "sweep"))]
    inputs, word_kinds = _inputs(raw, where, sweep, n)
    output = np.array([parse_float(_required_cell(where, "output", i, x), where, i, "output")
                       for i, x in enumerate(_cells(raw, "output"))], dtype=np.float64).reshape(n)
    optional = _optional_columns(raw, where, n, nan_is_missing)
    _check_word_notation(raw, where, word_kinds)
    out: dict[str, np.ndarray] = {}
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
    _check_duplicates(ordered, where, device, run, sweep, inputs)
    _check_rad_s(ordered, where, inputs)
    for arr in ordered.values():
        arr.flags.writeable = False
    return ordered


def _check_shape(raw: Mapping[str, Any], source: str, header: str) -> int:
    """The number of rows, after checking that every required column is there (with a near spelling as a hint),
    that every column has as many values as 'device', and that there are rows."""
    names = list(raw)
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
    return n


def _cells(raw: Mapping[str, Any], c: str) -> list:
    v = raw[c]
    return v.tolist() if isinstance(v, np.ndarray) else list(v)


def _required_cell(where: Where, c: str, i: int, cell):
    if is_missing(cell):
        raise where.error(i, c, "is empty; every row needs a value in the required columns.")
    return cell


def _inputs(raw: Mapping[str, Any], where: Where, sweep: list, n: int):
    """The 'input' column as numbers (a DAC word parsed where the row's kind takes words), and the rows of each
    notation of the words: (inputs, {notation: rows})."""
    inputs = np.empty(n)
    word_kinds: dict[str, list[int]] = {}
    for i, x in enumerate(_cells(raw, "input")):
        x = _required_cell(where, "input", i, x)
        if sweep_kind(sweep[i]).word_input:
            word, kind = parse_dac_word(x, where, i, "input")
            inputs[i] = word
            word_kinds.setdefault(kind, []).append(i)
        else:
            inputs[i] = parse_float(x, where, i, "input")
    return inputs, word_kinds


def _optional_columns(raw: Mapping[str, Any], where: Where, n: int, nan_is_missing: bool) -> dict[str, np.ndarray]:
    """The optional columns given, as numbers (NaN where missing), each value checked for its column's range."""
    optional: dict[str, np.ndarray] = {}
    for c in OPTIONAL_COLUMNS:
        if c not in raw:
            continue
        col = np.full(n, np.nan)
        for i, x in enumerate(_cells(raw, c)):
            if is_missing(x) or (nan_is_missing and isinstance(x, float) and math.isnan(x)):
                continue
            col[i] = parse_float(x, where, i, c)
            if c == "output_sigma" and col[i] < 0:
                raise where.error(i, c, f"{show(x)} is negative; a standard uncertainty is >= 0.")
            if c == "n_samples" and (col[i] < 1 or col[i] != math.floor(col[i])):
                raise where.error(i, c, f"{show(x)} is not a positive whole number of samples.")
            if c == "drive_freq_hz" and col[i] <= 0:
                raise where.error(i, c, f"{show(x)} is not a positive frequency.")
            if c == "time_s" and col[i] < 0:
                raise where.error(i, c, f"{show(x)} is negative; time_s is seconds since the run's power-on.")
        optional[c] = col
    return optional


def _check_word_notation(raw: Mapping[str, Any], where: Where, word_kinds: dict) -> None:
    """Hex words without a prefix next to plain-digit words: '539' could be decimal 539 or hex 0x539 (seed 000
    Table 2 prints both 'A95' and '539'). Refuse rather than guess."""
    if "bare hex" in word_kinds and "digits" in word_kinds:
        i_dec, i_hex = word_kinds["digits"][0], word_kinds["bare hex"][0]
        raise where.error(i_dec, "input", f"DAC word {show(_cells(raw, 'input')[i_dec])} is ambiguous: it reads "
                          f"as a decimal integer, but {where.row(i_hex)} has the bare hex word "
                          f"{show(_cells(raw, 'input')[i_hex])}, so it may be hex too. Write hex words with a 0x "
                          "prefix, or give every word as a signed decimal integer.")


def _check_duplicates(ordered, where: Where, device, run, sweep, inputs) -> None:
    """Duplicate points. A point applied again within a run (at each plateau of a plateau run) is told apart by
    its time_s."""
    source = where.source
    n = len(device)
    seen: dict[tuple, int] = {}
    times = np.asarray(ordered["time_s"], dtype=float) if "time_s" in ordered else np.full(n, np.nan)
    for i in range(n):
        key = (device[i], run[i], sweep[i], float(inputs[i]), None if np.isnan(times[i]) else float(times[i]))
        if key in seen:
            j = seen[key]
            raise DataError(f"{source}: {where.row(i)}, column 'input': duplicate point: {where.row(j)} has the "
                            f"same (device, run, sweep, input) = ({device[i]!r}, {run[i]}, {sweep[i]!r}, "
                            f"{inputs[i]:g}) and time_s. Each settled point appears once; give repeats a different "
                            "run, or a point applied again within a run (a plateau run) its own time_s.",
                            source=source, row=i + 1, column="input")
        seen[key] = i


def _check_rad_s(ordered, where: Where, inputs) -> None:
    """Rate-table inputs that look like rad/s."""
    source = where.source
    for (dev, r, s), rows in group_rows(ordered).items():
        if sweep_kind(s).rate_input and looks_like_rad_s(inputs[rows]):
            raise DataError(
                f"{source}: {rows_text(where, rows)}, column 'input': device {dev!r} run {r} {s} inputs "
                f"look like rad/s, but rate-table inputs are deg/s (docs/data_format.md): max |input| = "
                f"{np.abs(inputs[rows]).max():.6g} < 2 pi and every input x 180/pi is a round deg/s value "
                f"(e.g. {inputs[rows][np.argmax(np.abs(inputs[rows]))]:.6g} -> "
                f"{np.abs(inputs[rows]).max() * 180 / math.pi:.6g} deg/s) to 1e-6. Convert with "
                "input_dps = input_rad_s * 180 / pi (gyrojax.units.rad_s_to_dps).",
                source=source, row=int(rows[0]) + 1, column="input")


def group_rows(columns: Mapping[str, np.ndarray]) -> dict[tuple[str, int, str], np.ndarray]:
    """Row indices of each (device, run, sweep) group, groups and rows in order of first appearance."""
    groups: dict[tuple[str, int, str], list[int]] = {}
    for i, key in enumerate(zip(columns["device"].tolist(), columns["run"].tolist(), columns["sweep"].tolist())):
        groups.setdefault(key, []).append(i)
    return {k: np.asarray(v, dtype=np.int64) for k, v in groups.items()}


def check_outputs_change(table, groups: Mapping[tuple[str, int, str], np.ndarray]) -> None:
    """Refuse a run whose outputs are all equal in a sweep whose output must change with its input (a kind
    whose slope's sign a convention sets, `AbstractSweep.sign_definite`: a rate table, a VCF or DAC sweep):
    a disconnected or saturated output, which has no scale factor to measure or compensate. The one rule of
    `metrics_report` and `compensate`: a `DataError` naming the file, row, device, run and sweep.

    `groups`: the rows of each `(device, run, sweep)` of `table` (`Table.groups`)."""
    for (dev, run, sweep), rows in groups.items():
        kind = sweep_kind(sweep)
        if not (kind.straight_line and kind.sign_definite) or len(rows) < 2:
            continue
        out = table["output"][rows]
        if np.ptp(out) == 0.0:
            each = "rate" if kind.rate_input else kind.input_quantity
            raise DataError(f"{table.locate(int(rows[0]), 'output')}: device {dev!r}, run {run}: the {sweep} outputs "
                            f"are all {float(out[0])!r}, the same at every {each}: there is no scale factor to "
                            "measure or compensate (a disconnected or saturated output?). Remove the run or fix the "
                            "file.", source=table.source, row=int(rows[0]) + 1, column="output")
