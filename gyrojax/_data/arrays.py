"""`SweepArrays`: one sweep kind of a table as padded (device, run, point) arrays with a mask."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._sweeps.base import AbstractSweep
from .._sweeps.registry import sweep_kind
from .cells import REQUIRED_COLUMNS


COORDINATES = {"temperatures": "temperature_c", "times": "time_s", "drive_freqs": "drive_freq_hz"}
"""The fields of `SweepArrays` that hold a recorded coordinate of each point, and the column each comes from."""

PADDING = {"inputs": 0.0, "outputs": 0.0, "sigmas": 1.0, "temperatures": 25.0, "mask": False, "times": np.nan,
           "drive_freqs": np.nan, "order": 0.0}
"""What each array field holds on padding points (`aux` holds 0)."""

ARRAY_FIELDS = tuple(PADDING)
"""The array fields of `SweepArrays`, in the order its leaves flatten (`aux` follows them)."""


class SweepArrays(eqx.Module):
    """One sweep kind of a lot as padded arrays, shape (n_device, n_run, n_point), with a mask.

    Ragged lots (devices with different numbers of runs, runs with different numbers of points) are padded;
    `mask` is True on real points. Padding holds values that keep masked sums and their gradients finite (see
    below). Build with `Table.to_arrays(sweep)`; `Table.from_arrays` inverts it. It is also the form the fit takes:
    every sweep of a fit's data (`Fit.data.blocks`, a `FitData`) is one, aligned on the lot's devices.

    **Fields** (float64 unless said; see the data format, docs/data_format.md, for units per sweep kind):

    - `inputs`, `outputs`: padding 0.
    - `sigmas`: `output_sigma` (NaN where not given), padding 1; None if the table had no such column (in
      `FitData`, 1 on every point then: unit weights).
    - `temperatures` (deg C, from `temperature_c`), `times` (s since the run's power-on, from `time_s`),
      `drive_freqs` (Hz, from `drive_freq_hz`): NaN where not recorded; padding 25, NaN, NaN.
    - `mask`: bool, True on real points.
    - `order`: each point's position in its run in time order (by `times` where every point of the run has
      one, else file order), padding 0.
    - `aux`: the other optional columns the table had (`n_samples`, `rate_dps`, ...), NaN where a value was
      not given, padding 0 (`FitData` keeps none).
    - `kind`: the sweep kind, an `AbstractSweep` (given by its `sweep` name, the kind with its default settings),
      static: what the code that reads the arrays asks about them (its measurement model, whether runs carry a
      bias, its units). `sweep` is its name, the key of `FitData.blocks`.
    - `devices`, `runs` (run ids per device), `column_order`: labels for reports and `Table.from_arrays`, static.
      `FitData.unlabelled()` sets `devices` and `runs` to None, so that compiled fits see only arrays, shapes and
      the kinds (equal kinds, equal programs).

    `temperatures`, `times`, `drive_freqs` and `order` are None only in a fit read from a file of an early
    format (which did not store them).
    """

    inputs: Float[Array, "device run point"]
    outputs: Float[Array, "device run point"]
    sigmas: Float[Array, "device run point"] | None
    temperatures: Float[Array, "device run point"] | None
    mask: Bool[Array, "device run point"]
    times: Float[Array, "device run point"] | None = None
    drive_freqs: Float[Array, "device run point"] | None = None
    order: Float[Array, "device run point"] | None = None
    aux: dict[str, Float[Array, "device run point"]] = eqx.field(default_factory=dict)
    kind: AbstractSweep = eqx.field(static=True, kw_only=True, converter=sweep_kind)
    devices: tuple[str, ...] | None = eqx.field(static=True, kw_only=True, default=None)
    runs: tuple[tuple[int, ...], ...] | None = eqx.field(static=True, kw_only=True, default=None)
    column_order: tuple[str, ...] = eqx.field(static=True, kw_only=True, default=REQUIRED_COLUMNS)

    def __check_init__(self):
        try:
            hash(self.kind)
        except TypeError as e:  # a static field: compiled programs are looked up by it
            raise ValueError(f"SweepArrays.kind must be hashable (its settings tuples and numbers, not arrays), got "
                             f"{self.kind!r}: {e}") from None
        shape = self.mask.shape
        if len(shape) != 3:
            raise ValueError(f"SweepArrays.mask must have shape (device, run, point), got {shape}.")
        arrays = {**{f: getattr(self, f) for f in ARRAY_FIELDS if f != "mask"},
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
        if (self.devices is None) != (self.runs is None):
            raise ValueError("SweepArrays: devices and runs are given together or not at all.")
        if self.devices is not None and self.runs is not None and (len(self.devices) != shape[0]
                                                                   or len(self.runs) != shape[0]):
            raise ValueError(f"SweepArrays: {len(self.devices)} device ids and {len(self.runs)} run lists for "
                             f"{shape[0]} devices.")
        if self.runs is not None and any(len(r) > shape[1] for r in self.runs):
            raise ValueError(f"SweepArrays: a device has more run ids than the run axis ({shape[1]}).")

    @property
    def sweep(self) -> str:
        """The kind's name: the `sweep` value of the table's rows."""
        return self.kind.name

    @property
    def run_mask(self) -> Bool[Array, "device run"]:
        """True where (device, run) holds at least one point."""
        return jnp.any(self.mask, axis=-1)

    def fit_sigmas(self) -> Float[Array, "device run point"]:
        """`sigmas`; a ValueError where the table had none (a fit's data, `FitData`, has 1 there)."""
        if self.sigmas is None:
            raise ValueError(f"sweep {self.sweep!r}: these arrays have no sigmas (the table had no output_sigma); "
                             "a fit's data (gyrojax FitData) sets them to 1.")
        return self.sigmas

    def labels(self) -> tuple[tuple[str, ...], tuple[tuple[int, ...], ...]]:
        """`(devices, runs)`; a ValueError for unlabelled arrays (`FitData.unlabelled()`), which carry neither."""
        if self.devices is None or self.runs is None:
            raise ValueError(f"SweepArrays of sweep {self.sweep!r} are unlabelled (FitData.unlabelled() drops the "
                             "device names and run ids); this needs the labelled arrays.")
        return self.devices, self.runs

    def aligned(self, devices: Sequence[str]) -> SweepArrays:
        """These arrays with one row per device of `devices`, in that order: a device this sweep lacks gets
        padding only (no runs)."""
        names, runs = self.labels()
        index = [names.index(d) if d in names else -1 for d in devices]

        def align(x, fill):
            if x is None:
                return None
            x = np.asarray(x)
            out = np.full((len(index),) + x.shape[1:], fill, dtype=x.dtype)
            for k, i in enumerate(index):
                if i >= 0:
                    out[k] = x[i]
            return jnp.asarray(out)

        return dataclasses.replace(self, **{f: align(getattr(self, f), PADDING[f]) for f in ARRAY_FIELDS},
                                   aux={c: align(v, 0.0) for c, v in self.aux.items()}, devices=tuple(devices),
                                   runs=tuple(runs[i] if i >= 0 else () for i in index))


def time_order(times, mask):
    """Each real point's position in its run in time order: by `times` where every point of the run has one,
    else the file order (a stable sort keeps file order among equal times)."""
    order = np.zeros(mask.shape)
    for d, k in np.ndindex(mask.shape[:2]):
        m = mask[d, k]
        t = times[d, k][m]
        rank = np.argsort(np.argsort(t, kind="stable"), kind="stable") if np.all(np.isfinite(t)) else np.arange(t.size)
        order[d, k][m] = rank
    return order
