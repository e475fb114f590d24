"""Whether a fit was made on the data it is used with: the one check of every entry that takes a fit and data.

A fit keeps the data it was fitted to (`Fit.data`, stored in a fit file), so a fit given with data (`diagnose`,
`plan`, the command line's `--fit`) is compared with them point by point: the same sweeps, devices and runs,
and the same values in every column at every point, bit for bit (a table read again from its CSV or Parquet
file gives the identical float64 values). A fit of other data with the same device names and point counts
would otherwise be taken as the fit of these data, and everything read from it would describe other data.
"""

from __future__ import annotations

import numpy as np

from .._data.arrays import ARRAY_FIELDS, COORDINATES


COLUMNS = {"inputs": "input", "outputs": "output", "sigmas": "output_sigma", **COORDINATES}
"""The table's column each array field of a sweep comes from (`mask` says which points exist)."""

_ADVICE = "give the fit of this data (or no fit, to fit the baseline here)"


def _number(x) -> str:
    return f"{float(x)!r}"


def _field_difference(sweep: str, device: str, runs, field: str, theirs, ours, mask, inputs) -> str | None:
    """The first difference of one device's values of `field` (over its points `mask`; `inputs` the given
    data's inputs, to name the point), described."""
    a, b = np.asarray(theirs)[mask], np.asarray(ours)[mask]
    same = (a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind in "fc" else a == b
    if same.all():
        return None
    where = np.argwhere(mask)
    k = int(np.argmin(same))
    r, p = map(int, where[k])
    what = COLUMNS.get(field, field)
    return (f"sweep {sweep!r}, device {device!r}, column {what!r}: {int((~same).sum())} of {same.size} values "
            f"differ; the first at run {runs[r]}, point {p} (input {_number(np.asarray(inputs)[r, p])} in the data "
            f"given): {_number(a[k])} in the fit's data, {_number(b[k])} in the data given")


def data_difference(theirs, ours) -> str | None:
    """What first differs between two `FitData` (the fit's `theirs`, the given `ours`), or None if they hold
    the same points with the same values."""
    if set(theirs.blocks) != set(ours.blocks):
        return f"the fit's data have sweeps {list(theirs.sweeps)}, the data given {list(ours.sweeps)}"
    if tuple(theirs.devices) != tuple(ours.devices):
        return f"the fit's data have devices {list(theirs.devices)}, the data given {list(ours.devices)}"
    if bool(theirs.weighted) != bool(ours.weighted):
        has, lacks = ("the fit's data", "the data given") if theirs.weighted else ("the data given", "the fit's data")
        return f"{has} have output_sigma, {lacks} do not"
    for s in ours.sweeps:
        a, b = theirs.blocks[s], ours.blocks[s]
        counts = (int(np.asarray(a.mask).sum()), int(np.asarray(b.mask).sum()))
        if counts[0] != counts[1]:
            return f"sweep {s!r}: the fit's data have {counts[0]} points, the data given {counts[1]}"
        for i, d in enumerate(ours.devices):
            if tuple(a.runs[i]) != tuple(b.runs[i]):
                return (f"sweep {s!r}, device {d!r}: the fit's data have runs {list(a.runs[i])}, the data given "
                        f"{list(b.runs[i])}")
            mask_a, mask_b = np.asarray(a.mask)[i], np.asarray(b.mask)[i]
            if mask_a.shape != mask_b.shape or (mask_a != mask_b).any():
                return (f"sweep {s!r}, device {d!r}: the fit's data have {int(mask_a.sum())} points, the data given "
                        f"{int(mask_b.sum())}, or the same number at other places")
            for field in ARRAY_FIELDS:
                if field == "mask":
                    continue
                fa, fb = getattr(a, field), getattr(b, field)
                if (fa is None) != (fb is None):
                    has, lacks = ("the fit's data", "the data given") if fb is None else ("the data given",
                                                                                          "the fit's data")
                    return f"sweep {s!r}: {has} have column {COLUMNS.get(field, field)!r}, {lacks} do not"
                if fa is not None:
                    found = _field_difference(s, d, b.runs[i], field, np.asarray(fa)[i], np.asarray(fb)[i], mask_b,
                                              np.asarray(b.inputs)[i])
                    if found:
                        return found
    return None


def check_fit_data(fit, data) -> None:
    """Raise a `ValueError` naming what differs (sweep, device, column, how many values, the first differing
    point) unless `fit` was fitted to `data` (a `FitData`)."""
    if tuple(fit.devices) != tuple(data.devices):
        raise ValueError(f"fit: it was fitted to devices {list(fit.devices)}, the data have {list(data.devices)}; "
                         f"{_ADVICE}.")
    theirs = {s: int(np.asarray(fit.data.blocks[s].mask).sum()) for s in fit.data.sweeps}
    ours = {s: int(np.asarray(data.blocks[s].mask).sum()) for s in data.sweeps}
    if theirs != ours:
        raise ValueError(f"fit: it was fitted to {theirs} points per sweep, the data have {ours}; {_ADVICE}.")
    found = data_difference(fit.data, data)
    if found is not None:
        raise ValueError(f"fit: it was fitted to other data than those given{_source(fit.data, data)}: {found}; "
                         f"{_ADVICE}.")


def _source(theirs, ours) -> str:
    if theirs.source and ours.source and theirs.source != ours.source:
        return f" (the fit's data came from {theirs.source}, the data given from {ours.source})"
    return ""
