"""`Table`: the validated, immutable tidy table of settled points (docs/data_format.md).

One row is one settled point of one sweep. Required columns are `device` (str), `run` (int), `sweep` (one of
[`gyrojax.sweeps.SWEEP_KINDS`][]), `input` and `output`; the optional columns are
[`gyrojax.io.OPTIONAL_COLUMNS`][]; any other column is kept (and written back) but ignored.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, final

import jax.numpy as jnp
import numpy as np

from .._sweeps.base import AbstractSweep
from .._sweeps.registry import SWEEP_KINDS, sweep_kind
from .arrays import ARRAY_FIELDS, COORDINATES, PADDING, SweepArrays, time_order
from .cells import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, DataError, Where, check_sweep_name
from .validate import group_rows, validate_columns


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
        self._columns = validate_columns(columns, str(source), lines, nan_is_missing)
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
        """Build and validate a table from row dicts (e.g. from [`gyrojax.io.aggregate_samples`][]).

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
        where = Where(self._source, self._lines)
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
        groups = group_rows(self._columns)
        if sweep is not None:
            check_sweep_name(sweep)
            groups = {k: v for k, v in groups.items() if k[2] == sweep}
        return groups

    def kinds(self) -> dict[str, AbstractSweep]:
        """The sweep kinds the rows hold, by their `sweep` name, in the order of
        [`gyrojax.sweeps.SWEEP_KINDS`][]: each with its default settings (a file names a kind, not its
        settings). What code that reads the table asks its questions of (units, a straight-line fit or not)."""
        present = set(self._columns["sweep"].tolist())
        return {name: sweep_kind(name) for name in SWEEP_KINDS if name in present}

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

    @classmethod
    def from_arrays(cls, arrays: SweepArrays, *, source: str | None = None) -> Table:
        """The real (unmasked) points of `arrays` back as a table, grouped by device then run (the inverse of
        `to_arrays`)."""
        if arrays.devices is None or arrays.runs is None:
            raise ValueError("Table.from_arrays: these arrays have no device and run labels (unlabelled).")
        mask = np.asarray(arrays.mask)
        values = {"input": arrays.inputs, "output": arrays.outputs, "output_sigma": arrays.sigmas,
                  **{c: getattr(arrays, f) for f, c in COORDINATES.items()}, **arrays.aux}
        order = list(arrays.column_order)
        order += [c for c in REQUIRED_COLUMNS if c not in order]
        order += [c for c in values if c not in order and c in arrays.aux]
        if arrays.sigmas is not None and "output_sigma" not in order:
            order.append("output_sigma")
        order = [c for c in order if c not in values or values[c] is not None]
        cols: dict[str, list] = {c: [] for c in order}
        for d, dev in enumerate(arrays.devices):
            for k, r in enumerate(arrays.runs[d]):
                sel = mask[d, k]
                m = int(sel.sum())
                cols["device"] += [dev] * m
                cols["run"] += [r] * m
                cols["sweep"] += [arrays.sweep] * m
                for c in order:
                    if c not in ("device", "run", "sweep"):
                        cols[c] += np.asarray(values[c])[d, k][sel].tolist()
        return cls({c: np.asarray(v, dtype=np.float64) if c not in ("device", "run", "sweep")
                      else np.asarray(v) for c, v in cols.items()},
                     source=source or f"<SweepArrays {arrays.sweep}>")

    def to_arrays(self, sweep: str) -> SweepArrays:
        """The rows of one sweep kind as padded (device, run, point) arrays with a mask, for vmapping lots.

        Devices and, within a device, runs are in order of first appearance; points keep file order (the order
        a sweep was taken in matters for drift). Extra (unknown) columns are not carried.

        **Arguments:**

        - `sweep`: one of [`gyrojax.sweeps.SWEEP_KINDS`][].

        **Returns:**

        A [`gyrojax.io.SweepArrays`][]. `Table.from_arrays` gives back exactly these rows (same column
        order, values and, for a table grouped by device and run, row order).
        """
        return sweep_arrays(self, sweep)


def device_runs(groups) -> tuple[list[str], dict[str, list[int]]]:
    """The devices of `groups` (`Table.groups`: (device, run, sweep) -> rows) in order of first appearance, and
    each one's runs in order."""
    devices: list[str] = []
    runs: dict[str, list[int]] = {}
    for dev, run, _ in groups:
        if dev not in runs:
            devices.append(dev)
            runs[dev] = []
        runs[dev].append(run)
    return devices, runs


def padded_columns(table: Table, sweep: str) -> dict[str, Any]:
    """The padded NumPy arrays and labels of one sweep kind of `table`, by `SweepArrays` field (behind
    `Table.to_arrays`; the metrics report uses them as they are: NumPy, no compilation)."""
    columns = table.columns
    check_sweep_name(sweep)
    groups = table.groups(sweep)
    if not groups:
        present = sorted(set(columns["sweep"].tolist()))
        raise DataError(f"{table.source}: no rows with sweep {sweep!r}; the table has {', '.join(present)}.",
                        source=table.source, column="sweep")
    devices, runs = device_runs(groups)
    n_dev, n_run = len(devices), max(len(v) for v in runs.values())
    n_pt = max(len(v) for v in groups.values())
    shape = (n_dev, n_run, n_pt)
    sources = {"inputs": "input", "outputs": "output", "sigmas": "output_sigma", **COORDINATES}
    arrays = {f: np.full(shape, PADDING[f]) for f in sources}
    mask = np.zeros(shape, dtype=bool)
    aux_names = [c for c in columns if c in OPTIONAL_COLUMNS and c not in sources.values()]
    aux = {c: np.zeros(shape) for c in aux_names}
    for (dev, r, _), rows in groups.items():
        d, k, m = devices.index(dev), runs[dev].index(r), len(rows)
        mask[d, k, :m] = True
        for f, c in sources.items():
            arrays[f][d, k, :m] = columns[c][rows] if c in columns else np.nan
        for c in aux_names:
            aux[c][d, k, :m] = columns[c][rows]
    return {**arrays, "sigmas": arrays["sigmas"] if "output_sigma" in columns else None,
            "mask": mask, "order": time_order(arrays["times"], mask), "aux": aux, "sweep": sweep,
            "kind": sweep_kind(sweep),
            "devices": tuple(devices), "runs": tuple(tuple(runs[d]) for d in devices),
            "column_order": tuple(c for c in columns if c in REQUIRED_COLUMNS or c in OPTIONAL_COLUMNS)}


def sweep_arrays(table: Table, sweep: str) -> SweepArrays:
    """`table.to_arrays(sweep)`: the padded arrays of `padded_columns` as a `SweepArrays`."""
    p = padded_columns(table, sweep)
    optional = {f: None if p[f] is None else jnp.asarray(p[f]) for f in ARRAY_FIELDS}  # sigmas may be None
    return SweepArrays(inputs=jnp.asarray(p["inputs"]), outputs=jnp.asarray(p["outputs"]), sigmas=optional["sigmas"],
                       temperatures=optional["temperatures"], mask=jnp.asarray(p["mask"]), times=optional["times"],
                       drive_freqs=optional["drive_freqs"], order=optional["order"],
                       aux={c: jnp.asarray(v) for c, v in p["aux"].items()}, kind=p["kind"], devices=p["devices"],
                       runs=p["runs"], column_order=p["column_order"])
