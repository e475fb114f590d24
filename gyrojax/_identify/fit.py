"""`Fit`, the solution of `identify`: per device the fitted values and their uncertainties, the status that
says whether they are a measurement (`STATUSES`), and the exit code a command reports for it (`EXIT_CODES`)."""

import math
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._model.fitdata import FitData
from .._model.parameters import Entry, Model


STATUSES = ("ok", "model rejected", "not determined", "not converged")
"""A device's `Fit.status`: `"ok"`; `"model rejected"` (fitted, but its chi2 is too large for the noise at
`reject_alpha`, or a fitted parameter is implausible); `"not determined"` (the data do not fix the scale factor,
or its uncertainty: it is NaN); `"not converged"` (the solve failed). A fit read from a file written before
these checks has `"unknown"`."""


EXIT_CODES = {"ok": 0, "not converged": 1, "model rejected": 3, "not determined": 4, "unknown": 5}
"""Exit code of a command for a fit whose devices all have this status (see `Fit.exit_status`): 0 every device
`"ok"`; 1 a computation failed (the solve did not converge, as for any failed computation); 3 fitted, but the
model does not describe the data; 4 the data do not determine the scale factor; 5 the fit predates these
checks. (2 stays a usage or data error.)"""


EXIT_PRECEDENCE = ("not converged", "not determined", "unknown", "model rejected", "ok")
"""When devices differ, the first of these statuses present gives the exit code: a failed solve over a number
that is missing, over one that is unchecked, over one that is there but with a model the data reject."""


HELD_LABEL = "held at the design value, not determined by the data"
"""How summaries and reports label a parameter the fit did not move (held as unidentifiable, or by `hold`)."""


class Unidentifiable(eqx.Module):
    """A direction of parameter space the data cannot fix: `parameters` (names) take part in it,
    `held` was held at its start value, `singular_value` is its size in internal units (< threshold)."""

    parameters: tuple[str, ...]
    held: str
    singular_value: float


class Fit(eqx.Module):
    """The solution of `identify`.

    **Fields** (device axis first where per device):

    - `model`: the fitted `Model` (device batched, effects included).
    - `names`: per-device parameter names (flattened, effect arrays element-wise); `lot_names` shared ones.
    - `values`, `stderr`: (device, n) physical values and standard errors; NaN stderr for held parameters.
    - `lot_values`, `lot_stderr`: (n_lot,).
    - `free`: (n,) bool, False for parameters held because the data cannot determine them.
    - `covariance`: (device, n, n) covariance of the internal coordinates (zero rows for held ones);
      `correlation` likewise.
    - `u`, `u_lot`: the internal coordinates (0 = start).
    - `residuals`: dict sweep -> (device, run, point) standardised residuals; `predictions`, `biases`
      (dict sweep -> (device, run)).
    - `chi2`, `dof`, `chi2_red`: per device; `chi2_total`, `dof_total`, `chi2_red_total` for the lot.
    - `converged`: (device,) bool; `result_message`: (device,) text (a converged device whose data no longer
      fix some direction at the solution, as when a parameter ran off to a flat region, says so there and in
      `summary()`); `num_steps`: solver steps;
      `unsettled`: points whose steady state failed at the solution.
    - `unidentifiable`: tuple of `Unidentifiable`.
    - `scale_factor`, `scale_factor_stderr`: (device,) LSB per deg/s of the fitted model at zero rate; NaN
      for a device whose status is `"not determined"`.
    - `devices`: names; `data`: the `FitData` (for data without `output_sigma`, with the estimated noise
      as its sigmas: the residuals are in units of it).
    - `status`: per device, one of `STATUSES`; `warnings`: per device, a tuple of sentences (why the status is
      not `"ok"`, the noise estimate, implausible values); `reject_alpha`: the significance level of the chi2
      test.
    - `stderr_scaled`, `lot_stderr_scaled`, `scale_factor_stderr_scaled`: the standard errors times
      sqrt(chi2_red) where the chi2 test rejects the model (the lot's for shared parameters); equal to the
      fitted ones elsewhere.
    - `noise_dof`: (device,) effective degrees of freedom of the estimated noise (inf where the data gave
      `output_sigma`); `p_value` (device,), `p_value_total`: of the chi2 per device and for the lot (the chi2
      test; where the noise was estimated, against the chi2's null distribution with that estimate);
      NaN without degrees of freedom.
    """

    # Flat, not grouped into sub-objects: a fit file (`save_fit`) stores the leaves in this order, and users
    # read the fields by these names. Arrays are NumPy or JAX: `identify` assembles some on the host.
    model: Model
    names: tuple[str, ...] = eqx.field(static=True)
    lot_names: tuple[str, ...] = eqx.field(static=True)
    values: Float[Array | np.ndarray, "device param"]
    stderr: Float[Array | np.ndarray, "device param"]
    lot_values: Float[Array | np.ndarray, " lot"]
    lot_stderr: Float[Array | np.ndarray, " lot"]
    free: tuple[bool, ...] = eqx.field(static=True)
    covariance: Float[Array | np.ndarray, "device param param"]
    u: Float[Array | np.ndarray, "device param"]
    u_lot: Float[Array | np.ndarray, " lot"]
    residuals: dict[str, Float[Array | np.ndarray, "device run point"]]  # keyed by sweep name (the user's key)
    predictions: dict[str, Float[Array | np.ndarray, "device run point"]]
    biases: dict[str, Float[Array | np.ndarray, "device run"]]
    chi2: Float[Array | np.ndarray, " device"]
    dof: Int[Array | np.ndarray, " device"]
    converged: Bool[Array | np.ndarray, " device"]
    result_message: tuple[str, ...] = eqx.field(static=True)
    num_steps: Int[Array | np.ndarray, " device"]
    unsettled: Int[Array | np.ndarray, " device"]
    unidentifiable: tuple[Unidentifiable, ...] = eqx.field(static=True)
    scale_factor: Float[Array | np.ndarray, " device"]
    scale_factor_stderr: Float[Array | np.ndarray, " device"]
    devices: tuple[str, ...] = eqx.field(static=True)
    data: FitData
    entries: tuple[Entry, ...] = eqx.field(static=True)
    weighted: bool = eqx.field(static=True)
    # d(residual)/du for every per-device entry, held ones too
    jacobian: Float[Array | np.ndarray, "device residual param"]
    residual_vector: Float[Array | np.ndarray, "device residual"]  # all standardised residuals (data then priors)
    status: tuple[str, ...] = eqx.field(static=True)
    warnings: tuple[tuple[str, ...], ...] = eqx.field(static=True)
    reject_alpha: float = eqx.field(static=True)
    stderr_scaled: Float[Array | np.ndarray, "device param"]
    lot_stderr_scaled: Float[Array | np.ndarray, " lot"]
    scale_factor_stderr_scaled: Float[Array | np.ndarray, " device"]
    noise_dof: Float[Array | np.ndarray, " device"]
    p_value: Float[Array | np.ndarray, " device"]
    p_value_total: Float[Array | np.ndarray, ""]

    @property
    def chi2_red(self) -> Float[Array | np.ndarray, " device"]:
        return self.chi2 / jnp.maximum(self.dof, 1).astype(self.chi2.dtype)

    @property
    def chi2_total(self) -> float:
        return float(jnp.sum(self.chi2))

    @property
    def dof_total(self) -> int:
        return int(jnp.sum(self.dof)) - len(self.lot_names)

    @property
    def chi2_red_total(self) -> float:
        return self.chi2_total / max(self.dof_total, 1)

    @property
    def correlation(self) -> Float[Array | np.ndarray, "device param param"]:
        sd = jnp.sqrt(jnp.diagonal(self.covariance, axis1=-2, axis2=-1))
        sd = jnp.where(sd > 0, sd, jnp.inf)
        return self.covariance / (sd[..., :, None] * sd[..., None, :])

    @property
    def all_converged(self) -> bool:
        return bool(np.all(np.asarray(self.converged)))

    @property
    def exit_status(self) -> int:
        """The exit code for a command that made this fit (`EXIT_CODES`): 0 only when every device is `"ok"`;
        when devices differ, the first status of `EXIT_PRECEDENCE` present decides."""
        for status in EXIT_PRECEDENCE:
            if status in self.status:
                return EXIT_CODES[status]
        raise ValueError(f"unknown device status in {self.status!r}; expected those of {EXIT_PRECEDENCE}.")

    def value(self, name: str, device: int | None = None) -> Float[Array | np.ndarray, "*device"]:
        """Fitted physical value of a parameter (all devices, or one)."""
        if name in self.lot_names:
            return self.lot_values[self.lot_names.index(name)]
        if name not in self.names:
            raise KeyError(f"no fitted parameter {name!r}; the fit has {', '.join(self.names + self.lot_names)}.")
        v = self.values[:, self.names.index(name)]
        return v if device is None else v[device]

    def check(self) -> "Fit":
        """Raise a RuntimeError naming the devices whose fit did not converge, or whose scale factor the data
        do not determine, and why."""
        if not self.all_converged:
            parts = []
            unsolved = [f"{d}: {m}" for d, m, s in zip(self.devices, self.result_message, self.status)
                        if s != "not determined"]
            if unsolved:
                parts.append("the fit did not converge for " + "; ".join(unsolved))
            undetermined = [f"{d}: {w[0] if w else 'no reason recorded'}"
                            for d, w, s in zip(self.devices, self.warnings, self.status) if s == "not determined"]
            if undetermined:
                parts.append("the data do not determine the scale factor of " + "; ".join(undetermined))
            raise RuntimeError(". ".join(parts))
        return self

    kind: ClassVar[str] = "fit"

    def to_json(self) -> dict[str, Any]:
        """The fit as JSON: the `gyrojax identify --json` report less its `compare` section (which
        `gyrojax.fit_report` adds).

        **Returns:** a dict with

        - `devices`: per device `device`, `status` (`"ok"`, `"model rejected"`, `"not determined"`,
          `"not converged"`; `"unknown"` for a fit file that predates the checks), `warnings` (sentences: why the
          status is not `"ok"`, the noise estimate, implausible values), `parameters` {name: {`value`, `stderr`,
          `held`} (held ones also `note`: held at the design value, not determined by the data)},
          `parameter_stderr_scaled` {name: stderr times sqrt(chi2_red) where the model is rejected, else the
          stderr}, `scale_factor_lsb_per_dps` and `scale_factor_stderr` (null where the data do not determine
          it), `scale_factor_stderr_scaled`, `chi2_red`, `p_value` (null without degrees of freedom),
          `noise_dof` (effective degrees of freedom of an estimated noise; null where the data gave
          output_sigma), `converged`, `message`;
        - `lot`: shared parameters {name: {`value`, `stderr`, `stderr_scaled`}};
        - `unidentifiable`: every parameter name taking part in a direction the data cannot fix;
          `unidentifiable_directions` (each with `parameters`, `held`, `singular_value`);
        - `chi2_red`, `p_value` (whole lot), `reject_alpha`, `exit_status` (see `Fit.exit_status`), `source`.
        """
        values, stderr = np.asarray(self.values), np.asarray(self.stderr)
        scaled = np.asarray(self.stderr_scaled)
        chi2_red, p_value = np.asarray(self.chi2_red), self.p_value
        devices = []
        for i, d in enumerate(self.devices):
            params = {}
            for k, nm in enumerate(self.names):
                params[nm] = {"value": _num(values[i, k]), "stderr": _num(stderr[i, k]), "held": not self.free[k]}
                if not self.free[k]:
                    params[nm]["note"] = HELD_LABEL
            devices.append({
                "device": d, "status": self.status[i], "warnings": list(self.warnings[i]), "parameters": params,
                "parameter_stderr_scaled": {nm: _num(scaled[i, k]) for k, nm in enumerate(self.names)},
                "scale_factor_lsb_per_dps": _num(self.scale_factor[i]),
                "scale_factor_stderr": _num(self.scale_factor_stderr[i]),
                "scale_factor_stderr_scaled": _num(self.scale_factor_stderr_scaled[i]),
                "chi2_red": _num(chi2_red[i]), "p_value": _num(p_value[i]), "noise_dof": _num(self.noise_dof[i]),
                "converged": bool(self.converged[i]), "message": self.result_message[i],
            })
        lot = {nm: {"value": _num(self.lot_values[k]), "stderr": _num(self.lot_stderr[k]),
                    "stderr_scaled": _num(self.lot_stderr_scaled[k])}
               for k, nm in enumerate(self.lot_names)}
        names = []
        for u in self.unidentifiable:
            names.extend(p for p in u.parameters if p not in names)
        return {
            "source": self.data.source, "chi2_red": _num(self.chi2_red_total), "p_value": _num(self.p_value_total),
            "reject_alpha": _num(self.reject_alpha), "exit_status": self.exit_status, "devices": devices,
            "lot": lot, "unidentifiable": names,
            "unidentifiable_directions": [{"parameters": list(u.parameters), "held": u.held,
                                           "singular_value": _num(u.singular_value)} for u in self.unidentifiable],
        }

    def summary(self) -> str:
        """A few lines for a terminal: per device its status, and the scale factor only where the data
        determine it."""
        p_lot = float(self.p_value_total)
        lines = [f"fit of {len(self.devices)} device(s) from {self.data.source}: chi2_red "
                 f"{self.chi2_red_total:.3f} (chi2 {self.chi2_total:.1f} / dof {self.dof_total}, {p_text(p_lot)})"]
        p = np.asarray(self.p_value)
        for i, d in enumerate(self.devices):
            status, message = self.status[i], self.result_message[i]
            chi = f"chi2_red {float(self.chi2_red[i]):.3f} ({p_text(p[i])})"
            sf, se = float(self.scale_factor[i]), float(self.scale_factor_stderr[i])
            se_scaled = float(self.scale_factor_stderr_scaled[i])
            if status == "not converged":
                lines.append(f"  {d}: NOT CONVERGED ({message}); {chi}; no scale factor reported")
            elif status == "not determined":
                lines.append(f"  {d}: SF NOT DETERMINED (no scale factor reported, see the warning); {chi}")
            elif status == "unknown":
                lines.append(f"  {d}: STATUS UNKNOWN: {chi}, SF {sf:.6f} +/- {se:.2g} LSB/(deg/s) (unchecked); "
                             f"{message}")
            else:
                error = f"+/- {se:.2g} LSB/(deg/s)"
                if se_scaled != se:
                    error = (f"+/- {se_scaled:.2g} LSB/(deg/s) (the fit's {se:.2g} x sqrt(chi2_red): the model "
                             "does not describe the data)")
                head = "ok" if status == "ok" else "MODEL REJECTED"
                if status == "model rejected" and not p[i] < self.reject_alpha:
                    head += " (implausible values, see the warning)"
                lines.append(f"  {d}: {head}: {chi}, SF {sf:.6f} {error}; {message}")
            lines += [f"      warning: {w}" for w in self.warnings[i]]
        held = [e.label for e in self.entries if not e.shared
                and any(not self.free[self.names.index(nm)] for nm in e.names())]
        if held:
            lines.append(f"  {HELD_LABEL}: {', '.join(held)}")
        for u in self.unidentifiable:
            lines.append(f"  unidentifiable: {' x '.join(u.parameters)} (held {u.held}, s = {u.singular_value:.2g})")
        return "\n".join(lines)


def p_text(p) -> str:
    p = float(p)
    if not math.isfinite(p):
        return "no degrees of freedom to test the model"
    return "p < 1e-300" if p == 0.0 else f"p = {p:.2g}"


def _num(x) -> float | None:
    """A float for JSON: None for NaN or infinity (held parameters have no standard error, a scale factor the
    data do not determine has no value)."""
    x = float(x)
    return None if not math.isfinite(x) else x
