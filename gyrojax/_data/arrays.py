"""`SweepArrays`: one sweep kind of a table as padded (device, run, point) arrays with a mask."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .cells import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, DataError, check_sweep_name
from .table import Table


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
        check_sweep_name(self.sweep)
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


def padded_columns(table: Table, sweep: str) -> dict[str, Any]:
    """The padded NumPy arrays and metadata of one sweep kind of `table` (behind `Table.to_arrays`; the metrics
    report uses them as they are: NumPy, no compilation)."""
    columns = table.columns
    check_sweep_name(sweep)
    groups = table.groups(sweep)
    if not groups:
        present = sorted(set(columns["sweep"].tolist()))
        raise DataError(f"{table.source}: no rows with sweep {sweep!r}; the table has {', '.join(present)}.",
                        source=table.source, column="sweep")
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
    aux_names = [c for c in columns if c in OPTIONAL_COLUMNS and c != "output_sigma"]
    aux = {c: np.zeros(shape) for c in aux_names}
    has_sigma = "output_sigma" in columns
    sigmas = np.ones(shape)
    for (dev, r, _), rows in groups.items():
        d, k, m = devices.index(dev), runs[dev].index(r), len(rows)
        inputs[d, k, :m] = columns["input"][rows]
        outputs[d, k, :m] = columns["output"][rows]
        mask[d, k, :m] = True
        if has_sigma:
            sigmas[d, k, :m] = columns["output_sigma"][rows]
        for c in aux_names:
            aux[c][d, k, :m] = columns[c][rows]
    return {"inputs": inputs, "outputs": outputs, "sigmas": sigmas if has_sigma else None, "mask": mask,
            "aux": aux, "sweep": sweep, "devices": tuple(devices), "runs": tuple(tuple(runs[d]) for d in devices),
            "column_order": tuple(c for c in columns if c in REQUIRED_COLUMNS or c in OPTIONAL_COLUMNS)}


def sweep_arrays(table: Table, sweep: str) -> SweepArrays:
    """`table.to_arrays(sweep)`: the padded arrays of `padded_columns` as a `SweepArrays`."""
    p = padded_columns(table, sweep)
    return SweepArrays(
        inputs=jnp.asarray(p["inputs"]), outputs=jnp.asarray(p["outputs"]),
        sigmas=None if p["sigmas"] is None else jnp.asarray(p["sigmas"]), mask=jnp.asarray(p["mask"]),
        aux={c: jnp.asarray(v) for c, v in p["aux"].items()}, sweep=sweep, devices=p["devices"],
        runs=p["runs"], column_order=p["column_order"])
