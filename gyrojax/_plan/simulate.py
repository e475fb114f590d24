"""A plan's added runs, simulated for the lot a simulation study drew: what a lab would measure next, with the
same devices and a fresh noise draw, appended to the data given."""

import equinox as eqx
import jax
import numpy as np

from .._data.table import Table
from .._gyroscope import Gyroscope
from .._lots.campaign import campaign_lot, simulate_table
from .._physics.thermal import ConstantTemperature


def simulate_runs(runs: dict, gyro: Gyroscope, table: Table | None = None, *, devices: int = 1,
                  runs_given: int = 1, seed: int = 0, noise_seed: int = 1000) -> Table:
    """`runs` (as `Plan.runs` gives them) for the lot `simulate_table(gyro, devices=devices, seed=seed)` draws
    (see `Plan.simulate`)."""
    if not runs:
        raise ValueError("the plan recommends no runs (every candidate is testable or out of reach): nothing to "
                         "simulate.")
    if not isinstance(gyro, Gyroscope):
        raise TypeError(f"gyro must be a gyrojax.Gyroscope (the device the data were simulated from), got "
                        f"{type(gyro).__name__}.")
    lot = campaign_lot(gyro, devices=devices, seed=seed)
    most = max(k for _, k, _ in runs.values())
    parts = []
    for name, (e, k, _) in runs.items():
        hot = name.endswith("_hot")
        for i in range(devices):
            one = jax.tree.map(lambda x, i=i: x[i] if eqx.is_array(x) else x, lot)
            if hot:  # the die's ambient at the chamber's plateau, numbered after the room-temperature runs
                if not isinstance(one.temperature, ConstantTemperature):
                    raise ValueError(f"{name}: a run at another chamber temperature is simulated for a device "
                                     "whose ambient is a ConstantTemperature; this one's is "
                                     f"{type(one.temperature).__name__}.")
                one = eqx.tree_at(lambda g: g.temperature, one,
                                  ConstantTemperature(float(dict(e.settings)["chamber_c"])))
            t = simulate_table(one, devices=1, runs=k, sweeps=(e.kind,), protocol=e.protocol,
                               seed=seed + noise_seed + i, progress=False)
            cols = dict(t.columns)
            cols["device"] = np.full(len(t), f"{gyro.name}-{i:03d}")
            cols["run"] = np.asarray(cols["run"]) + runs_given + (1 + most if hot else 0)
            parts.append(cols)
    return append(table, parts)


def append(table: Table | None, parts) -> Table:
    """`table` (None: nothing) with the columns of `parts` (dicts of arrays) appended; a column missing from
    one of them is NaN there."""
    pieces = ([] if table is None else [table.columns]) + list(parts)
    names = list(dict.fromkeys(c for q in pieces for c in q))
    return Table.from_columns({c: np.concatenate([np.asarray(q[c]) if c in q else
                                                  np.full(len(next(iter(q.values()))), np.nan) for q in pieces])
                               for c in names})
