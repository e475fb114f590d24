"""The tidy table's file formats: CSV and Parquet, read with validation and written atomically."""

from __future__ import annotations

import codecs
import csv
import io
import math
import os
from typing import Any

import numpy as np

from .._sweeps.registry import sweep_kind
from .cells import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, DataError, show
from .io import atomic_open, atomic_path
from .reading import NotARegularFile, check_regular, open_regular
from .table import Table


MAX_LINE_CHARS = 64 * 2**20
"""The longest line a CSV table may have (a header or data row of tidy columns is well under a kilobyte)."""

_EXPECTED = "give a .csv or .parquet file"


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
    for CSV also the file line) and the column for: a path that is not a regular file (a folder, a FIFO, a
    device such as `/dev/zero`, also behind a symbolic link: refused before it is opened), a CSV line longer
    than `MAX_LINE_CHARS`, an empty file, a missing required column, an unknown sweep
    name, an empty required cell, NaN or infinity, a non-numeric cell, a malformed DAC word, duplicate
    (device, run, sweep, input) points, and rate-table inputs that look like rad/s. Raises `ValueError` for an
    unknown suffix. Nothing is dropped silently (blank CSV lines hold nothing and are skipped).
    """
    suffix = table_format(path, "read_table")
    source = os.fspath(path)
    try:  # before any open: a FIFO would block it, /dev/zero never end
        check_regular(source, _EXPECTED)
    except NotARegularFile as e:
        raise DataError(str(e), source=source) from None
    if suffix == ".csv":
        columns, lines = _read_csv(source)
        return Table._from_file(columns, source, lines)
    columns = _read_parquet(source)
    return Table._from_file(columns, source, None)


def _utf8_error(source: str) -> DataError:
    """The error for the first byte of `source` that is not UTF-8 (its line and offset), found by a second
    streamed pass once decoding failed."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    newlines = 0
    with open_regular(source, _EXPECTED) as f:
        head = f.read(len(codecs.BOM_UTF8))
        fed = len(head) if head == codecs.BOM_UTF8 else 0  # bytes given to the decoder so far, plus the BOM
        chunk, final = (b"" if fed else head), False
        while True:
            pending = len(decoder.getstate()[0])  # bytes of an unfinished character held from the last chunk
            try:
                decoder.decode(chunk, final=final)
            except UnicodeDecodeError as e:
                at = fed - pending + e.start
                newlines += e.object[:e.start].count(b"\n")
                return DataError(f"{source}: line {newlines + 1}: not UTF-8 text (byte {at}: {e.reason}); save the "
                                 "CSV as UTF-8.", source=source)
            if final:
                return DataError(f"{source}: not UTF-8 text; save the CSV as UTF-8.", source=source)
            newlines += chunk.count(b"\n")
            fed += len(chunk)
            chunk = f.read(1 << 16)
            final = not chunk


def csv_records(source: str, tail: list | None = None):
    """(first line, fields) of each CSV record of `source`, read line by line (UTF-8, a byte order mark dropped;
    a line over `MAX_LINE_CHARS` refused): the file is never held whole as one string. `tail`, when given,
    holds the last physical line read (to tell a file cut short)."""
    with open_regular(source, _EXPECTED) as raw:
        # newline="": the csv module sees line ends as they are, and splits lines at \n, \r\n or \r.
        text = io.TextIOWrapper(raw, encoding="utf-8-sig", newline="")

        def physical_lines():
            while True:
                line = text.readline(MAX_LINE_CHARS + 1)
                if not line:
                    return
                if len(line) > MAX_LINE_CHARS:
                    raise DataError(f"{source}: a line (after line {reader.line_num}) is longer than "
                                    f"{MAX_LINE_CHARS} characters; a tidy table's lines are short: is this a CSV "
                                    "table?", source=source)
                if tail is not None:
                    tail[:] = [line]
                yield line

        reader = csv.reader(physical_lines())
        previous = 0
        try:
            for row in reader:
                yield previous + 1, row
                previous = reader.line_num
        except csv.Error as e:
            raise DataError(f"{source}: line {reader.line_num}: not a readable CSV line: {e}.",
                            source=source) from None


def _read_csv(source: str) -> tuple[dict[str, list], list[int]]:
    """The columns (text cells) and each data row's first line, read line by line (`csv_records`)."""
    tail = [""]
    try:
        records: list[tuple[int, list[str]]] = list(csv_records(source, tail))  # (first line, fields)
    except UnicodeDecodeError:
        raise _utf8_error(source) from None
    last = tail[0]

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
                raise DataError(f"{source}: the header (line 1) has one column {show(names[0])}: the file looks "
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
    if last.strip() and not last.endswith(("\n", "\r")):
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


def read_parquet_devices(path: str | os.PathLike, devices) -> Table:
    """The rows of `devices` of a Parquet table file, validated as `read_table` does: only the row groups whose
    statistics may hold them are read (a file written sorted by device, or in row groups by device, is read a
    chunk of devices at a time). Its source, for messages, is the path followed by the devices' range; data rows
    count within those devices' rows."""
    source = os.fspath(path)
    table_format(source, "read_parquet_devices")
    devices = [str(d) for d in devices]
    if not devices:
        raise ValueError(f"read_parquet_devices: no devices given to read from {source!r}.")
    columns = _read_parquet(source, filters=[("device", "in", devices)])
    where = devices[0] if len(devices) == 1 else f"{devices[0]} .. {devices[-1]}, {len(devices)} devices"
    return Table._from_file(columns, f"{source} [{where}]", None)


def _read_parquet(source: str, filters=None) -> dict[str, Any]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        with open_regular(source, _EXPECTED) as f:
            table = pq.read_table(f, filters=filters)
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
        words = [sweep_kind(s).word_input for s in table["sweep"].tolist()]
        return [str(int(v)) if word else repr(float(v)) for v, word in zip(arr.tolist(), words)]
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
