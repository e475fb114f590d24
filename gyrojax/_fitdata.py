"""A tidy table as the arrays a fit needs: every sweep padded to one common device axis."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._data.cells import DataError
from ._data.table import Table
from ._sweeps.registry import sweep_names


"""The built-in sweeps whose output carries the run's turn-on bias (a free bias per run, eliminated by
projection); `gyrojax.sweep_kind(name).biased` answers for any registered kind."""


class SweepBlock(eqx.Module):
    """One sweep kind of a lot, shape (device, run, point), aligned on `FitData.devices`.

    Besides the input, every coordinate the data record for a point, to test the residuals against:
    `temperatures` (deg C), `times` (s since the run's power-on), `drive_freqs` (Hz), NaN where not recorded,
    and `order`, the point's position in its run in time order (by `time_s` where recorded, else file order).
    """

    inputs: Float[Array, "device run point"]
    outputs: Float[Array, "device run point"]
    sigmas: Float[Array, "device run point"]
    temperatures: Float[Array, "device run point"]  # deg C, NaN where not recorded
    mask: Bool[Array, "device run point"]
    times: Float[Array, "device run point"] | None = None  # s since power-on, NaN where not recorded
    drive_freqs: Float[Array, "device run point"] | None = None  # Hz, NaN where not recorded
    order: Float[Array, "device run point"] | None = None  # 0, 1, ... in time order within the run


class FitData(eqx.Module):
    """All sweeps of a lot, with static metadata for reports.

    `runs` is a tuple of `(sweep, run ids per device)` pairs (padding runs are masked); see `run_ids`.
    `weighted` is False when the table had no `output_sigma`: then unit weights are used and the fit's
    covariance is scaled by its reduced chi2.
    """

    blocks: dict[str, SweepBlock]
    devices: tuple[str, ...] = eqx.field(static=True)
    runs: tuple = eqx.field(static=True)
    weighted: bool = eqx.field(static=True)
    source: str = eqx.field(static=True)

    @property
    def sweeps(self) -> tuple[str, ...]:
        return tuple(s for s in sweep_names() if s in self.blocks)

    def run_ids(self, sweep: str) -> tuple[tuple[int, ...], ...]:
        return dict(self.runs)[sweep]

    def device_slice(self, i: int) -> "FitData":
        import jax
        return jax.tree.map(lambda x: x[i:i + 1], self)

    def num_points(self):
        return int(sum(np.asarray(b.mask).sum() for b in self.blocks.values()))


def _time_order(times, mask):
    """Each real point's position in its run in time order: by `times` where every point of the run has one,
    else the file order (a stable sort keeps file order among equal times)."""
    order = np.zeros(mask.shape)
    for d, k in np.ndindex(mask.shape[:2]):
        m = mask[d, k]
        t = times[d, k][m]
        rank = np.argsort(np.argsort(t, kind="stable"), kind="stable") if np.all(np.isfinite(t)) else np.arange(t.size)
        order[d, k][m] = rank
    return order


def fit_data(table: Table, sweeps=None) -> FitData:
    """Convert a validated `Table` to `FitData` (only the sweeps named, default all present)."""
    present = [s for s in sweep_names() if s in set(table["sweep"].tolist())]
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
    blocks, runs = {}, {}
    for s in sweeps:
        arr = table.to_arrays(s)
        index = [arr.devices.index(d) if d in arr.devices else -1 for d in devices]
        n_run, n_pt = arr.mask.shape[1:]

        def align(x, fill):
            x = np.asarray(x)
            out = np.full((len(devices), n_run, n_pt), fill, dtype=x.dtype)
            for k, i in enumerate(index):
                if i >= 0:
                    out[k] = x[i]
            return out

        sig = np.ones_like(np.asarray(arr.outputs)) if arr.sigmas is None else np.asarray(arr.sigmas)
        if weighted:
            bad = np.asarray(arr.mask) & ~(sig > 0)
            if bad.any():
                d, r, p = map(int, np.argwhere(bad)[0])
                raise DataError(f"{table.source}: sweep {s!r}, device {arr.devices[d]!r}, run {arr.runs[d][r]}, "
                                f"point {p}: output_sigma must be > 0 to weight a fit, got {sig[d, r, p]!r}.",
                                source=table.source, column="output_sigma")
        def column(name):
            return np.asarray(arr.aux[name]) if name in arr.aux else np.full(sig.shape, np.nan)

        temps, times, freqs = column("temperature_c"), column("time_s"), column("drive_freq_hz")
        real = np.asarray(arr.mask)
        blocks[s] = SweepBlock(
            inputs=jnp.asarray(align(arr.inputs, 0.0)), outputs=jnp.asarray(align(arr.outputs, 0.0)),
            sigmas=jnp.asarray(align(np.where(real, sig, 1.0), 1.0)),
            temperatures=jnp.asarray(align(np.where(real, temps, 25.0), 25.0)),
            mask=jnp.asarray(align(arr.mask, False)),
            times=jnp.asarray(align(np.where(real, times, np.nan), np.nan)),
            drive_freqs=jnp.asarray(align(np.where(real, freqs, np.nan), np.nan)),
            order=jnp.asarray(align(_time_order(times, real), 0.0)))
        runs[s] = tuple(arr.runs[i] if i >= 0 else () for i in index)
    return FitData(blocks, tuple(devices), tuple(runs.items()), weighted, table.source)
