"""A tidy table as the arrays a fit needs: every sweep padded to one common device axis."""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._data.arrays import COORDINATES, SweepArrays
from .._data.cells import REQUIRED_COLUMNS, DataError
from .._data.table import Table
from .._sweeps.base import AbstractSweep
from .._sweeps.registry import SWEEP_KINDS


FIT_COLUMNS = REQUIRED_COLUMNS + ("output_sigma",) + tuple(COORDINATES.values())
"""The columns a sweep of `FitData` holds (its `column_order`, whatever the table's was: one static
structure for every fit's data, as a fit file rebuilds it)."""


class FitData(eqx.Module):
    """All sweeps of a lot, each a `SweepArrays` aligned on the same devices.

    `blocks` maps each sweep kind's name to its arrays (without `aux`: the fit reads the model's coordinates
    only); a device a sweep lacks has only padding there. Each block carries its kind (`SweepArrays.kind`):
    code that reads the data asks `kind(sweep)` (or `kinds`), not the registry, so that the kind the data were
    built with is the one that predicts them; the names are the keys users index (`blocks["rate_table"]`,
    `Fit.residuals["rate_table"]`) and files store. `weighted` is False when the table had no `output_sigma`:
    then unit weights are used (`sigmas` 1) and the fit's covariance is scaled by its reduced chi2. `source`
    names the table, for messages.

    The labels (`devices`, `run_ids`, `source`) and `weighted` are read outside the compiled functions only:
    `unlabelled()` is the same arrays without them (None), the form the compiled fit sees, so that every lot of
    the same shapes, weighted or not, shares its traced and compiled programs.
    """

    blocks: dict[str, SweepArrays]
    weighted: bool | None = eqx.field(static=True)
    source: str | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        for s, b in self.blocks.items():
            if s != b.sweep:
                raise ValueError(f"FitData.blocks[{s!r}] holds the arrays of sweep {b.sweep!r}; each sweep's "
                                 "arrays are keyed by their kind's name.")

    @property
    def sweeps(self) -> tuple[str, ...]:
        """The sweeps' names, in the order of `gyrojax.sweeps.SWEEP_KINDS` (the residuals' order)."""
        return tuple(s for s in SWEEP_KINDS if s in self.blocks)

    @property
    def kinds(self) -> dict[str, AbstractSweep]:
        """The sweep kind of each sweep, by name, in the order of `sweeps`."""
        return {s: self.blocks[s].kind for s in self.sweeps}

    def kind(self, sweep: str) -> AbstractSweep:
        """The sweep kind of the arrays of `sweep` (a name, a key of `blocks`)."""
        return self.blocks[sweep].kind

    @property
    def devices(self) -> tuple[str, ...] | None:
        """The devices' names (None when unlabelled)."""
        return next(iter(self.blocks.values())).devices

    @property
    def runs(self) -> tuple:
        """`(sweep, run ids per device)` pairs (padding runs are masked); see `run_ids`."""
        return tuple((s, b.runs) for s, b in self.blocks.items())

    def device_names(self) -> tuple[str, ...]:
        """The devices' names; a ValueError for unlabelled data (`unlabelled()`), which carry none."""
        return next(iter(self.blocks.values())).labels()[0]

    def run_ids(self, sweep: str) -> tuple[tuple[int, ...], ...]:
        """Run ids per device of `sweep`; a ValueError for unlabelled data."""
        return self.blocks[sweep].labels()[1]

    def unlabelled(self) -> "FitData":
        """The same arrays without device names, run ids, source and `weighted` (None): what compiled
        functions are given."""
        return FitData({s: dataclasses.replace(b, devices=None, runs=None, column_order=())
                        for s, b in self.blocks.items()}, None)

    def device_slice(self, i: int) -> "FitData":
        import jax
        return jax.tree.map(lambda x: x[i:i + 1], self)

    def num_points(self) -> int:
        return int(sum(np.asarray(b.mask).sum() for b in self.blocks.values()))


def fit_data(table: Table, sweeps: Sequence[str] | None = None) -> FitData:
    """Convert a validated `Table` to `FitData` (only the sweeps named, default all present)."""
    present = [s for s in SWEEP_KINDS if s in set(table["sweep"].tolist())]
    if sweeps is None:
        sweeps = present
    missing = [s for s in sweeps if s not in present]
    if missing:
        raise DataError(f"{table.source}: no rows with sweep {missing[0]!r}; the table has {', '.join(present)}.",
                        source=table.source, column="sweep")
    if not sweeps:
        raise DataError(f"{table.source}: no sweeps to fit.", source=table.source)
    devices = []
    for d in table["device"].tolist():
        if d not in devices:
            devices.append(d)
    weighted = "output_sigma" in table
    blocks = {}
    for s in sweeps:
        arr = table.to_arrays(s)
        if weighted:
            bad = np.asarray(arr.mask) & ~(np.asarray(arr.sigmas) > 0)
            if bad.any():
                d, r, p = map(int, np.argwhere(bad)[0])
                names, runs = arr.labels()
                raise DataError(f"{table.source}: sweep {s!r}, device {names[d]!r}, run {runs[d][r]}, "
                                f"point {p}: output_sigma must be > 0 to weight a fit, got "
                                f"{np.asarray(arr.sigmas)[d, r, p]!r}.", source=table.source, column="output_sigma")
        else:
            arr = dataclasses.replace(arr, sigmas=jnp.ones_like(arr.outputs))
        blocks[s] = dataclasses.replace(arr, aux={}, column_order=FIT_COLUMNS).aligned(devices)
    return FitData(blocks, weighted, table.source)
