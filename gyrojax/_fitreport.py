"""A `Fit` as the JSON report of `gyrojax identify` (DESIGN.md §7)."""

import math

import numpy as np

from ._identify import Fit


def _num(x):
    """A float for JSON: None for NaN (held parameters have no standard error)."""
    x = float(x)
    return None if not math.isfinite(x) else x


def fit_report(fit: Fit) -> dict:
    """The identify report: `devices` (per device `device`, `parameters` {name: {`value`, `stderr`, `held`}},
    `scale_factor_lsb_per_dps`, `scale_factor_stderr`, `chi2_red`, `converged`, `message`), `lot` (shared
    parameters {name: {`value`, `stderr`}}), `unidentifiable` (every parameter name taking part in a direction
    the data cannot fix), `unidentifiable_directions` (each with `parameters`, `held`, `singular_value`),
    `chi2_red` (whole lot), `source`, `compare` (where the model fails: `gyrojax.compare`)."""
    from ._compare import compare

    values, stderr = np.asarray(fit.values), np.asarray(fit.stderr)
    chi2_red = np.asarray(fit.chi2_red)
    devices = []
    for i, d in enumerate(fit.devices):
        params = {nm: {"value": _num(values[i, k]), "stderr": _num(stderr[i, k]), "held": not fit.free[k]}
                  for k, nm in enumerate(fit.names)}
        devices.append({
            "device": d, "parameters": params,
            "scale_factor_lsb_per_dps": _num(fit.scale_factor[i]),
            "scale_factor_stderr": _num(fit.scale_factor_stderr[i]),
            "chi2_red": _num(chi2_red[i]), "converged": bool(fit.converged[i]), "message": fit.result_message[i],
        })
    lot = {nm: {"value": _num(fit.lot_values[k]), "stderr": _num(fit.lot_stderr[k])}
           for k, nm in enumerate(fit.lot_names)}
    names = []
    for u in fit.unidentifiable:
        names.extend(p for p in u.parameters if p not in names)
    return {
        "source": fit.data.source, "chi2_red": _num(fit.chi2_red_total), "devices": devices, "lot": lot,
        "unidentifiable": names,
        "unidentifiable_directions": [{"parameters": list(u.parameters), "held": u.held,
                                       "singular_value": _num(u.singular_value)} for u in fit.unidentifiable],
        "compare": compare(fit).to_json(),
    }
