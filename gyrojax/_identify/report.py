"""A `Fit` as the JSON report of `gyrojax identify`."""

import math

import numpy as np

from . import HELD_LABEL, Fit


def _num(x):
    """A float for JSON: None for NaN or infinity (held parameters have no standard error, a scale factor the
    data do not determine has no value)."""
    x = float(x)
    return None if not math.isfinite(x) else x


def fit_report(fit: Fit) -> dict:
    """The identify report.

    **Returns:** a dict with

    - `devices`: per device `device`, `status` (`"ok"`, `"model rejected"`, `"not determined"`,
      `"not converged"`; `"unknown"` for a fit file that predates the checks), `warnings` (sentences: why the status
      is not `"ok"`, the noise estimate, implausible values), `parameters` {name: {`value`, `stderr`, `held`}
      (held ones also `note`: held at the design value, not determined by the data)},
      `parameter_stderr_scaled` {name: stderr times sqrt(chi2_red) where the model is rejected, else the
      stderr}, `scale_factor_lsb_per_dps` and `scale_factor_stderr` (null where the data do not determine
      it), `scale_factor_stderr_scaled`, `chi2_red`, `p_value` (null without degrees of freedom),
      `noise_dof` (effective degrees of freedom of an estimated noise; null where the data gave
      output_sigma), `converged`, `message`;
    - `lot`: shared parameters {name: {`value`, `stderr`, `stderr_scaled`}};
    - `unidentifiable`: every parameter name taking part in a direction the data cannot fix;
      `unidentifiable_directions` (each with `parameters`, `held`, `singular_value`);
    - `chi2_red`, `p_value` (whole lot), `reject_alpha`, `exit_status` (see `Fit.exit_status`), `source`;
    - `compare`: where the model fails (`gyrojax.compare`).
    """
    from .._diagnose.compare import compare

    values, stderr = np.asarray(fit.values), np.asarray(fit.stderr)
    scaled = np.asarray(fit.stderr_scaled)
    chi2_red, p_value = np.asarray(fit.chi2_red), fit.p_value
    devices = []
    for i, d in enumerate(fit.devices):
        params = {}
        for k, nm in enumerate(fit.names):
            params[nm] = {"value": _num(values[i, k]), "stderr": _num(stderr[i, k]), "held": not fit.free[k]}
            if not fit.free[k]:
                params[nm]["note"] = HELD_LABEL
        devices.append({
            "device": d, "status": fit.status[i], "warnings": list(fit.warnings[i]), "parameters": params,
            "parameter_stderr_scaled": {nm: _num(scaled[i, k]) for k, nm in enumerate(fit.names)},
            "scale_factor_lsb_per_dps": _num(fit.scale_factor[i]),
            "scale_factor_stderr": _num(fit.scale_factor_stderr[i]),
            "scale_factor_stderr_scaled": _num(fit.scale_factor_stderr_scaled[i]),
            "chi2_red": _num(chi2_red[i]), "p_value": _num(p_value[i]), "noise_dof": _num(fit.noise_dof[i]),
            "converged": bool(fit.converged[i]), "message": fit.result_message[i],
        })
    lot = {nm: {"value": _num(fit.lot_values[k]), "stderr": _num(fit.lot_stderr[k]),
                "stderr_scaled": _num(fit.lot_stderr_scaled[k])}
           for k, nm in enumerate(fit.lot_names)}
    names = []
    for u in fit.unidentifiable:
        names.extend(p for p in u.parameters if p not in names)
    return {
        "source": fit.data.source, "chi2_red": _num(fit.chi2_red_total), "p_value": _num(fit.p_value_total),
        "reject_alpha": _num(fit.reject_alpha), "exit_status": fit.exit_status, "devices": devices, "lot": lot,
        "unidentifiable": names,
        "unidentifiable_directions": [{"parameters": list(u.parameters), "held": u.held,
                                       "singular_value": _num(u.singular_value)} for u in fit.unidentifiable],
        "compare": compare(fit).to_json(),
    }
