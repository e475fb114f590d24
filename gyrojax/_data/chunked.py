"""A table file read a chunk of devices at a time, for lots larger than memory: the device list in one streamed
pass, a CSV split by device into one file per chunk in one more streamed pass, and a chunk's rows read back
(Parquet through its row-group statistics, `read_parquet_devices`). Every reader check applies per chunk: a
chunk is read with `read_table`, whose messages are mapped back to the input's data rows and lines."""

from __future__ import annotations

import csv
import os
import re

from .._sweeps.base import AbstractSweep
from .._sweeps.registry import sweep_kind
from .cells import DataError
from .files import csv_records, read_parquet_devices, read_table, table_format
from .reading import open_regular
from .table import Table


_EXPECTED = "give a .csv or .parquet file"
# Rows and characters held in memory before they are appended to their chunk files: bound the split's memory.
_FLUSH_ROWS = 200_000
_FLUSH_CHARS = 64 * 2**20


def _column_index(source: str, header: list[str], column: str) -> int:
    names = [h.strip() for h in header]
    if column not in names:
        raise DataError(f"{source}: the header (line 1) has no {column!r} column (columns: {', '.join(names)}).",
                        source=source, column=column)
    return names.index(column)


def device_order(path: str | os.PathLike) -> list[str]:
    """The devices of a table file in order of first appearance, read in one streamed pass (CSV) or from the
    `device` column alone (Parquet): memory in the number of devices, not of rows."""
    return column_values(path, "device")


def file_sweep_kinds(path: str | os.PathLike) -> list[AbstractSweep]:
    """The sweep kinds a table file's rows name (`column_values` of `sweep`), in order of first appearance."""
    return [sweep_kind(name) for name in column_values(path, "sweep")]


def column_values(path: str | os.PathLike, column: str) -> list[str]:
    """The distinct values of one column of a table file (stripped text) in order of first appearance, read in
    one streamed pass (CSV) or from that column alone (Parquet): memory in the number of values, not of rows."""
    source = os.fspath(path)
    if table_format(source, "column_values") == ".parquet":
        import pyarrow.parquet as pq

        with open_regular(source, _EXPECTED) as f:
            pf = pq.ParquetFile(f)
            if column not in pf.schema_arrow.names:
                raise DataError(f"{source}: no {column!r} column (columns: {', '.join(pf.schema_arrow.names)}).",
                                source=source, column=column)
            seen: dict[str, None] = {}
            for batch in pf.iter_batches(columns=[column]):
                seen.update(dict.fromkeys(str(d) for d in batch.column(0).to_pylist()))
            return list(seen)
    rows = csv_records(source)
    header = next((row for _, row in rows if any(c.strip() for c in row)), None)
    if header is None:
        raise DataError(f"{source}: empty file: no header line.", source=source)
    k = _column_index(source, header, column)
    seen = {}
    for _, row in rows:
        if len(row) > k and row[k].strip():
            seen[row[k].strip()] = None
    return list(seen)


def split_csv(path: str | os.PathLike, groups: list[list[str]], targets: list[str]) -> None:
    """Write the rows of each group of devices of the CSV file `path` to its file in `targets` (same header, rows
    in file order), in one streamed pass; beside each, `TARGET.lines` gives every row's data row and line
    in `path` (`read_chunk` maps messages back with it). Each file is complete when it appears (written beside
    under a temporary name, then renamed)."""
    source = os.fspath(path)
    chunk_of = {d: k for k, group in enumerate(groups) for d in group}
    temps = [f"{t}.partial" for t in targets]
    buffers: list[list] = [[] for _ in targets]
    where: list[list] = [[] for _ in targets]
    held = chars = 0

    def flush():
        for k, rows in enumerate(buffers):
            if rows:
                with open(temps[k], "a", newline="", encoding="utf-8") as f:
                    csv.writer(f, lineterminator="\n").writerows(rows)
                with open(f"{temps[k]}.lines", "a", encoding="utf-8") as f:
                    f.writelines(f"{r} {n}\n" for r, n in where[k])
                rows.clear()
                where[k].clear()

    rows = csv_records(source)
    header = next((row for _, row in rows if any(c.strip() for c in row)), None)
    if header is None:
        raise DataError(f"{source}: empty file: no header line.", source=source)
    col = _column_index(source, header, "device")
    for t in temps:
        with open(t, "w", newline="", encoding="utf-8") as f:
            csv.writer(f, lineterminator="\n").writerow(header)
        open(f"{t}.lines", "w").close()
    data_row = 0
    for line, row in rows:
        if not any(c.strip() for c in row) and len(row) <= 1:
            continue  # a blank line holds nothing (read_table skips it too)
        data_row += 1
        device = row[col].strip() if len(row) > col else ""
        if device not in chunk_of:
            raise DataError(f"{source}: data row {data_row} (line {line}): device {device!r} is not in the device "
                            "list this run was planned with: the file changed since (start again with a new "
                            "results folder).", source=source, row=data_row, column="device")
        k = chunk_of[device]
        buffers[k].append(row)
        where[k].append((data_row, line))
        held += 1
        chars += sum(len(c) for c in row)
        if held >= _FLUSH_ROWS or chars >= _FLUSH_CHARS:
            flush()
            held = chars = 0
    flush()
    for k, target in enumerate(targets):
        os.replace(f"{temps[k]}.lines", f"{target}.lines")
        os.replace(temps[k], target)


_ROW_LINE = re.compile(r"data row (\d+) \(line (\d+)\)")


def read_chunk(path: str | os.PathLike, devices: list[str], split_file: str | None = None) -> Table:
    """The rows of `devices` of the table file `path`: from its chunk file `split_file` (a CSV written by
    `split_csv`; messages name `path` and its data rows and lines) or, for Parquet, from `path` itself."""
    if split_file is None:
        return read_parquet_devices(path, devices)
    try:
        return read_table(split_file)
    except DataError as e:
        with open(f"{split_file}.lines", encoding="utf-8") as f:
            rows = [tuple(int(v) for v in line.split()) for line in f]

        def original(m):
            r = int(m.group(1))
            if 1 <= r <= len(rows):
                return f"data row {rows[r - 1][0]} (line {rows[r - 1][1]})"
            return m.group(0)

        message = _ROW_LINE.sub(original, str(e)).replace(split_file, os.fspath(path))
        row = rows[e.row - 1][0] if e.row is not None and 1 <= e.row <= len(rows) else None
        raise DataError(message, source=os.fspath(path), row=row, column=e.column) from None
