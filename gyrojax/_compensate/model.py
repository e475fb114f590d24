r"""`model`: model-based compensation: invert an identified physical model of the closed-loop output.

**The model** (docs/physics.md, seed 000 Eq. 2 and §3.3). In force-to-rebalance operation the rate loop
settles the word $W$ (the gyro output, LSB) where the carrier fundamental of the FTR DAC's output balances the
Coriolis force. With the DAC's integral nonlinearity acting on the instantaneous carrier samples
$W \sin\theta$, that balance reads

$$ D(W) \equiv W + L \sum_{n} \rho_n\, c_n \left(\frac{W}{H}\right)^n = K(f)\,\Omega,
   \qquad K(f) = K_{ref} \left(\frac{f}{f_{ref}}\right)^{\beta}, \qquad y = W + b_r + 10^6 d\,(f/f_{ref}-1), $$

- $c_n$: the DAC INL in DAC LSB as the coefficient of $u^n$, $u = $ code / $2^{bits-1}$ (the convention of
  `gyrojax.effects.DacInl`), $L = 2^{word\_bits - bits}$ word LSB per DAC LSB, $H = 2^{word\_bits-1}$;
- $\rho_n$: the describing-function weight of $u^n$ for a sine, $\binom{n}{(n-1)/2} 2^{1-n}$ for odd $n$
  ($\rho_3 = 3/4$, $\rho_5 = 5/8$) and 0 for even $n$: even INL terms do not reach the carrier
  fundamental, so a rate table cannot see them (they are reported as unidentifiable, never guessed);
- $K(f)$: the scale factor tracking the thermal state through the measured drive frequency $f$;
  $K_{ref}$ at $f_{ref}$, the mean training drive frequency. Eq. 2 gives $SF \propto \omega_d$ when the AGC
  holds the displacement amplitude ($\beta = 1$, the default, as seed 000's initial calibration assumes);
  with `frequency_exponent=None` $\beta$ is identified instead, which needs training runs that span the
  drive frequencies the compensation will meet (its standard error says whether they did);
- $b_r + 10^6 d\,(f/f_{ref} - 1)$: a bias per training run (turn-on bias; applying the model uses their mean)
  plus its thermal drift, again through the drive frequency (quadrature times a demodulation phase that moves
  with temperature is the classic source); $d$ in LSB per ppm of drive frequency, identifiable only when the
  drive frequency moves within a training run (otherwise it is one more per-run constant).

When the points carry `temperature_c`, the drive frequency's temperature coefficient is identified jointly:
$f = f_{ref} (1 + \phi + \mathrm{TCF}\,(T - T_{ref}))$, so the scale factor's temperature coefficient is
$\beta\,\mathrm{TCF}$ (silicon: about -30 ppm/K). That block shares no parameter with the rate block; it
explains the repeatability in physical units.

**Identification.** All coefficients are fitted at once by Levenberg-Marquardt (optimistix) to the outputs of
the training runs (output error, weighted by `output_sigma` when every training point has a positive one).
The predicted output needs $W$ from the balance at a given rate: a few Newton steps from $W_0 = K\Omega$
(quadratic convergence, $D'(W) \approx 1$). The fit is one traceable function of the data, so the
coefficients are differentiable in the measurements (implicit differentiation through the optimum).

The solver works in coordinates whitened at the start (the start's Jacobian has orthonormal columns in them:
the INL powers are nearly collinear on a rate table) on residuals formed from terms of the size of the change
(not outputs of millions of LSB minus the data, whose rounding would be a noise on chi2 at the size of the
stopping tolerance). Whether the fit converged is judged where it stopped: a full Gauss-Newton step from
there must not lower chi2 by more than `DECREMENT_TOL`. A fit that did not converge is returned as the best
point reached, with `converged` False and a message; it is not raised, so one device of a lot cannot stop the
others (see [`gyrojax.compensate`][]).

**Compensation** inverts the model: the same balance solved by Newton steps for the rate $\Omega$ at the
measured $W = y - \bar b$ and $f$. The balance is linear in $\Omega$ here (every nonlinearity of this model
sits on the word side), so the first step is already exact and no polynomial is refitted anywhere.
"""

import math
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float

from .._compile.jit import jit
from .balance import balance_offset, balance_word, describing_weight, fundamental, inl_term, newton
from .base import AbstractCompensation, AbstractCompensator, check_side, require_side
from .points import RatePoints


FREQ_SIGMA_REL = 1e-7
"""ASSUMPTION: relative standard uncertainty of a drive-frequency reading (0.46 mHz at 4634 Hz) because a PLL
frequency averaged over a 2-minute dwell resolves far below 1 mHz. It only weights the TCF block against the
rate block; the two share no parameter, so it changes neither fit, only the reported chi2."""


WHITEN_FLOOR = 1e-8
"""Singular values of the unit-column start Jacobian below this are not whitened up to one (a direction the
data do not fix is not amplified by more than 1e8)."""

DECREMENT_TOL = 1e-6
"""A fit counts as converged when a full Gauss-Newton step would lower chi2 by less than this: the point is then
within 1e-3 standard errors of the minimum along every direction."""


class ModelCompensation(AbstractCompensation):
    r"""The identified physical model (see the module docstring), ready to invert.

    **Fields:** `sf_ref` (LSB per deg/s at `f_ref_hz`), `f_ref_hz`, `frequency_exponent` ($\beta$),
    `inl_lsb` (DAC LSB, one per order of `inl_orders`), `bias_lsb` (mean training bias), `run_bias_lsb` (one
    per `train_runs`), `bias_drift_lsb_per_ppm` ($d$), `tcf_per_k` and `t_ref_c` (NaN when the training points
    have no temperatures), `stderr` (standard errors of the fitted parameters, same keys as
    `summary()["parameters"]`),
    `chi2_red`, `converged` (the fit reached its minimum: Gauss-Newton decrement below `DECREMENT_TOL` and the
    balance closed), `num_steps` (Levenberg-Marquardt steps), `decrement` (the chi2 a full Gauss-Newton step
    from the fitted point would still remove), `condition_number` (of the Jacobian with unit columns at the fitted
    point), `balance_residual` (relative, of the last Newton solve of D(W) = K Omega), and static
    `inl_orders`, `word_bits`, `dac_bits`, `newton_steps`, `train_runs`, `unidentifiable` (names of parameters
    the data cannot determine, held at their prior values: even INL orders, $\beta$ without a
    drive-frequency spread), `weighted`, `message` (empty when converged; else what did not converge and what
    to try).

    An unconverged fit is returned as the best point the solver reached (lowest chi2), never silently:
    `status()` is `(False, message)` and [`gyrojax.compensate`][] reports no compensated figures for it.
    """

    sf_ref: Float[Array, ""]
    f_ref_hz: Float[Array, ""]
    frequency_exponent: Float[Array, ""]
    inl_lsb: Float[Array, " orders"]
    bias_lsb: Float[Array, ""]
    run_bias_lsb: Float[Array, " runs"]
    bias_drift_lsb_per_ppm: Float[Array, ""]
    tcf_per_k: Float[Array, ""]
    t_ref_c: Float[Array, ""]
    stderr: dict[str, Float[Array, ""]]
    chi2_red: Float[Array, ""]
    converged: Bool[Array, ""]
    num_steps: Array
    decrement: Float[Array, ""]
    condition_number: Float[Array, ""]
    balance_residual: Float[Array, ""]
    inl_orders: tuple[int, ...] = eqx.field(static=True)
    word_bits: int = eqx.field(static=True)
    dac_bits: int = eqx.field(static=True)
    quadrature_lsb: float = eqx.field(static=True)
    newton_steps: int = eqx.field(static=True)
    train_runs: tuple[int, ...] = eqx.field(static=True)
    unidentifiable: tuple[str, ...] = eqx.field(static=True)
    weighted: bool = eqx.field(static=True)
    message: str = eqx.field(static=True, default="")

    def status(self) -> tuple[bool, str]:
        """`(converged, message)`: see the class docstring."""
        return bool(self.converged), self.message

    def scale_factor(self, drive_freq_hz: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """$K(f)$, LSB per deg/s at drive frequency `drive_freq_hz` (Hz)."""
        f = jnp.asarray(drive_freq_hz, dtype=jnp.float64)
        return self.sf_ref * (f / self.f_ref_hz) ** self.frequency_exponent

    def bias(self, drive_freq_hz: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """The bias (LSB) at drive frequency `drive_freq_hz`: mean training bias plus its thermal drift."""
        f = jnp.asarray(drive_freq_hz, dtype=jnp.float64)
        return self.bias_lsb + self.bias_drift_lsb_per_ppm * 1e6 * (f / self.f_ref_hz - 1.0)

    def fundamental(self, word: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """$D(W)$ in word LSB: what the DAC puts on the carrier fundamental for a carrier of amplitude `word`."""
        return fundamental(jnp.asarray(word, dtype=jnp.float64), self.inl_lsb, self)

    def output(self, rate_dps: Float[ArrayLike, " n"], *, drive_freq_hz: Float[ArrayLike, " n"],
               bias_lsb: Float[ArrayLike, " n"] | None = None) -> Float[Array, " n"]:
        """The model's output (LSB) at table rate `rate_dps` and drive frequency `drive_freq_hz`: the word
        solving the balance by Newton steps, plus the bias (default: `bias(drive_freq_hz)`)."""
        v = self.scale_factor(drive_freq_hz) * jnp.asarray(rate_dps, dtype=jnp.float64)
        w = balance_word(v, self.inl_lsb, self, self.newton_steps)
        return w + (self.bias(drive_freq_hz) if bias_lsb is None else bias_lsb)

    def rate(self, output: Float[ArrayLike, " n"], *, drive_freq_hz: Float[ArrayLike, " n"] | None = None,
             temperature_c: Float[ArrayLike, " n"] | None = None) -> Float[Array, " n"]:
        """The rate estimate (deg/s): the balance solved for the rate by Newton steps; needs `drive_freq_hz`."""
        f = check_side("model", "drive_freq_hz", drive_freq_hz)
        d = self.fundamental(jnp.asarray(output, dtype=jnp.float64) - self.bias(f))
        k = jnp.broadcast_to(self.scale_factor(f), d.shape)
        return newton(lambda x: d - k * x, jnp.zeros_like(d), self.newton_steps)

    def summary(self) -> dict[str, Any]:
        def num(v):
            v = float(v)
            return None if math.isnan(v) else v

        params = {"sf_ref_lsb_per_dps": self.sf_ref, "frequency_exponent": self.frequency_exponent,
                  **{f"inl_u{n}_lsb": self.inl_lsb[i] for i, n in enumerate(self.inl_orders)},
                  "bias_drift_lsb_per_ppm": self.bias_drift_lsb_per_ppm,
                  "tcf_ppm_per_k": 1e6 * self.tcf_per_k}
        return {
            "parameters": {k: {"value": num(v), "stderr": num(self.stderr[k]) if k in self.stderr else None}
                           for k, v in params.items()},
            "f_ref_hz": float(self.f_ref_hz), "t_ref_c": num(self.t_ref_c),
            "sf_tempco_ppm_per_k": num(1e6 * self.frequency_exponent * self.tcf_per_k),
            "bias_lsb": float(self.bias_lsb),
            "run_bias_lsb": {str(r): float(b) for r, b in zip(self.train_runs, np.asarray(self.run_bias_lsb))},
            "unidentifiable": list(self.unidentifiable), "chi2_red": num(self.chi2_red),
            "weighted": self.weighted, "converged": bool(self.converged), "num_steps": int(self.num_steps),
            "gauss_newton_decrement": num(self.decrement), "condition_number": num(self.condition_number),
            "balance_residual": num(self.balance_residual), "message": self.message,
            "inl_orders": list(self.inl_orders), "dac_bits": self.dac_bits, "word_bits": self.word_bits,
            "quadrature_lsb": self.quadrature_lsb,
        }


class ModelCompensator(AbstractCompensator):
    r"""Model-based compensation: identify the physical output model of the module docstring on the
    training runs (Levenberg-Marquardt), then invert it by Newton steps.

    **Arguments:**

    - `inl_orders`: the powers $n$ of the INL polynomial (default (3, 5): the odd terms a rate table can
      see, to fifth order; even orders may be listed and are reported unidentifiable).
    - `dac_bits`, `word_bits`: DAC resolution and controller word width (seed 000 §5 and Table 2: a 16-bit
      DAC fed from a 24-bit word).
    - `frequency_exponent`: $\beta$ held at this value (default 1.0, Eq. 2), or None to identify it.
    - `quadrature_lsb`: the quadrature word $Q$ the DAC carries beside the rate word (LSB; default 0). The DAC
      sees the amplitude $\sqrt{W^2+Q^2}$, so the in-phase fundamental of $u^n$ is
      $\rho_n (W^2+Q^2)^{(n-1)/2} W / H^n$. Left at 0 with a steady $Q$ the fit absorbs it (the $u^5$ term
      shifts the $u^3$ coefficient by $2 (\rho_5/\rho_3) c_5 (Q/H)^2$, 1.5 LSB for paper-qmg's 10 deg/s)
      and the compensation is unchanged; give it to read the INL in the DAC's own terms.
    - `newton_steps`: Newton steps per balance solve (default 4: from $W_0 = K\Omega$ the error falls as
      $(D'-1)^{2^k}$, below 1e-15 relative after 3 for INLs of thousands of LSB).
    - `rtol`, `atol`, `max_steps`: Levenberg-Marquardt settings (optimistix) in the solver's internal units
      (coordinates whitened at the start, residuals in output sigmas); `atol` is raised to the data's own
      float64 resolution (eps max|y| / min sigma) where it asks for less. Whether the fit
      converged is judged at its end, by the Gauss-Newton decrement (`DECREMENT_TOL`), not by the solver's
      stopping rule; an unconverged fit is returned with `converged` False and a message (see
      [`gyrojax.compensation.ModelCompensation`][]).
    """

    inl_orders: tuple[int, ...] = eqx.field(static=True, default=(3, 5))
    dac_bits: int = eqx.field(static=True, default=16)
    word_bits: int = eqx.field(static=True, default=24)
    frequency_exponent: float | None = eqx.field(static=True, default=1.0)
    quadrature_lsb: float = eqx.field(static=True, default=0.0)
    newton_steps: int = eqx.field(static=True, default=4)
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-10)
    max_steps: int = eqx.field(static=True, default=256)

    name: ClassVar[str] = "model"
    requires: ClassVar[tuple[str, ...]] = ("drive_freq_hz",)

    def __check_init__(self):
        orders = self.inl_orders
        if (not isinstance(orders, tuple) or not orders
                or any(not isinstance(n, int) or isinstance(n, bool) or n < 2 for n in orders)
                or len(set(orders)) != len(orders)):
            raise ValueError("ModelCompensator.inl_orders must be a non-empty tuple of distinct integers >= 2 "
                             f"(orders 0 and 1 are the bias and the scale factor), got {orders!r}.")
        for name, low in (("dac_bits", 1), ("newton_steps", 1), ("max_steps", 1)):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < low:
                raise ValueError(f"ModelCompensator.{name} must be an integer >= {low}, got {v!r}.")
        if not isinstance(self.word_bits, int) or self.word_bits < self.dac_bits:
            raise ValueError(f"ModelCompensator.word_bits must be an integer >= dac_bits ({self.dac_bits}), got "
                             f"{self.word_bits!r}.")
        if isinstance(self.quadrature_lsb, bool) or not isinstance(self.quadrature_lsb, (int, float)) \
                or not math.isfinite(self.quadrature_lsb):
            raise ValueError(f"ModelCompensator.quadrature_lsb must be a finite number (LSB), got "
                             f"{self.quadrature_lsb!r}.")
        if self.frequency_exponent is not None and (isinstance(self.frequency_exponent, bool) or not isinstance(
                self.frequency_exponent, (int, float)) or not math.isfinite(self.frequency_exponent)):
            raise ValueError(f"ModelCompensator.frequency_exponent must be a finite number or None, got "
                             f"{self.frequency_exponent!r}.")

    def fit(self, points: RatePoints) -> ModelCompensation:
        require_side(points, "drive_freq_hz", "model")
        runs = points.runs
        run_index = np.asarray([runs.index(int(r)) for r in points.run], dtype=np.int64)
        n_par = 2 + len(self.inl_orders) + len(runs) + 1
        sig = points.output_sigma
        weighted = bool(np.all(np.isfinite(sig) & (sig > 0)))
        temps = points.temperature_c
        with_tcf = bool(np.all(np.isfinite(temps)) and np.ptp(temps) > 0)
        f = points.drive_freq_hz
        free = np.ones(n_par + 2 * with_tcf, dtype=bool)
        names = ["sf_ref_lsb_per_dps", "frequency_exponent"] + [f"inl_u{n}_lsb" for n in self.inl_orders]
        unidentifiable = []
        no_spread = np.ptp(f) <= 1e-9 * np.mean(f)
        if self.frequency_exponent is not None:
            free[1] = False
        elif no_spread:
            free[1] = False
            unidentifiable.append("frequency_exponent")
        within = max(float(np.ptp(f[points.run == r])) for r in runs)
        if within <= 1e-9 * np.mean(f):
            free[n_par - 1] = False
            unidentifiable.append("bias_drift_lsb_per_ppm")
        for i, n in enumerate(self.inl_orders):
            if describing_weight(n) == 0.0:
                free[2 + i] = False
                unidentifiable.append(names[2 + i])
        n_rates, n_shape = np.unique(points.rate_dps).size, int(free[2:2 + len(self.inl_orders)].sum())
        if n_rates < 3 + n_shape:
            raise ValueError(f"model compensation with {n_shape} identifiable INL term(s) needs at least "
                             f"{3 + n_shape} distinct training rates (a line, one per term, one to spare), got "
                             f"{n_rates}; use more rates or fewer inl_orders.")
        data = {"x": jnp.asarray(points.rate_dps), "y": jnp.asarray(points.output), "f": jnp.asarray(f),
                "temp": jnp.asarray(np.where(np.isfinite(temps), temps, 0.0)),
                "sigma": jnp.asarray(sig if weighted else np.ones_like(sig)), "run_index": jnp.asarray(run_index),
                "beta0": jnp.asarray(1.0 if self.frequency_exponent is None else float(self.frequency_exponent))}
        out = _fit_arrays(self, len(runs), with_tcf, tuple(bool(b) for b in free), data)
        converged, message = self._status(out)
        theta, stderr = np.asarray(out["theta"]), np.asarray(out["stderr"])
        k = len(self.inl_orders)
        all_names = (names + [f"bias_run{r}_lsb" for r in runs] + ["bias_drift_lsb_per_ppm"]
                     + (["freq_offset", "tcf_ppm_per_k"] if with_tcf else []))
        err = {nm: jnp.asarray(stderr[i]) for i, nm in enumerate(all_names) if free[i]}
        if with_tcf:
            err["tcf_ppm_per_k"] = jnp.asarray(1e6 * stderr[-1])
        biases = theta[2 + k:2 + k + len(runs)]
        nan = jnp.asarray(np.nan)
        return ModelCompensation(
            sf_ref=jnp.asarray(theta[0]), f_ref_hz=out["f_ref"], frequency_exponent=jnp.asarray(theta[1]),
            inl_lsb=jnp.asarray(theta[2:2 + k]), bias_lsb=jnp.asarray(float(np.mean(biases))),
            run_bias_lsb=jnp.asarray(biases), bias_drift_lsb_per_ppm=jnp.asarray(theta[n_par - 1]),
            tcf_per_k=jnp.asarray(theta[-1]) if with_tcf else nan,
            t_ref_c=out["t_ref"] if with_tcf else nan, stderr=err, chi2_red=out["chi2_red"],
            converged=jnp.asarray(converged), num_steps=out["num_steps"], decrement=out["decrement"],
            condition_number=out["condition_number"], balance_residual=out["balance_residual"],
            inl_orders=self.inl_orders,
            word_bits=self.word_bits, dac_bits=self.dac_bits, quadrature_lsb=self.quadrature_lsb,
            newton_steps=self.newton_steps,
            train_runs=tuple(runs), unidentifiable=tuple(unidentifiable), weighted=weighted, message=message)

    def _status(self, out) -> tuple[bool, str]:
        """Whether the identification reached its minimum, and if not, a message: what, and what to try."""
        dec, bal = float(out["decrement"]), float(out["balance_residual"])
        steps, cond, chi2 = int(out["num_steps"]), float(out["condition_number"]), float(out["chi2_red"])
        problems, tries = [], []
        if not dec < DECREMENT_TOL:  # also NaN
            how = (f"reached max_steps={self.max_steps}" if steps >= self.max_steps
                   else f"stopped after {steps} steps" + ("" if bool(out["solver_successful"]) else " (failed)"))
            problems.append(f"Levenberg-Marquardt {how} at chi2_red {chi2:.6g}, where a Gauss-Newton step would "
                            f"still lower chi2 by {dec:.3g} (converged: below {DECREMENT_TOL:g}); the Jacobian "
                            f"with unit columns has condition number {cond:.3g} there")
            if steps >= self.max_steps:
                tries.append("more steps (ModelCompensator(max_steps=...))")
            if not cond < 1e6:
                tries.append("fewer free terms (fewer inl_orders, frequency_exponent held), as some are not fixed "
                             "by these training runs")
            tries.append("a look at the training runs for outliers or a response the model does not describe "
                         "(gyrojax metrics; the polynomial and composite methods need no iterative fit)")
        if not bal < 1e-9:
            problems.append(f"the balance D(W) = K Omega did not close in {self.newton_steps} Newton steps "
                            f"(relative residual {bal:.3g})")
            tries.append("more newton_steps, unless the fitted INL is so large that D(W) is not monotone")
        if not problems:
            return True, ""
        return False, ("model compensation did not converge: " + "; ".join(problems)
                       + ". The fit returned is the best point reached. Try " + "; ".join(tries) + ".")


def _lsq(a, b):
    """Least squares by QR (full column rank; cheaper to compile than an SVD)."""
    q, r = jnp.linalg.qr(a)
    return jax.scipy.linalg.solve_triangular(r, q.T @ b)


def _start(k: int, n_runs: int, with_tcf: bool, data: dict[str, Array]):
    """The start of the fit (no gradient through it: only the solver's path depends on it), with the reference
    frequency and temperature: the straight line at the starting beta and no INL (linear least squares, exact for
    a linear device), and the drive frequency's line in temperature."""
    x, y, f, temp = data["x"], data["y"], data["f"], data["temp"]
    run_index = data["run_index"]
    f_ref = jnp.mean(f)
    t_ref = jnp.mean(temp)
    onehot = (run_index[:, None] == jnp.arange(n_runs)[None, :]).astype(jnp.float64)
    lin = _lsq(jnp.concatenate([(x * (f / f_ref) ** data["beta0"])[:, None], onehot], axis=1), y)
    parts = [lin[:1], data["beta0"][None], jnp.zeros(k), lin[1:], jnp.zeros(1)]
    if with_tcf:
        ft = _lsq(jnp.stack([jnp.ones_like(temp), temp - t_ref], axis=1), f / f_ref - 1.0)
        parts.append(ft)
    return jax.lax.stop_gradient(jnp.concatenate(parts)), f_ref, t_ref


def _whitened_basis(residuals, n_all: int, idx):
    """Internal coordinates z, delta = basis @ z, whitened at the start: the Jacobian in z has orthonormal columns
    there (directions weaker than WHITEN_FLOOR keep that floor). The default INL basis (u^3, u^5) on a rate
    table is nearly collinear (singular value 0.025 with unit columns), and Levenberg-Marquardt's first
    damping (1 in these units) needed 12 steps to walk down to it; whitened, the near-linear problem is
    solved in a few. Only the solver's path depends on the basis, not the optimum: no gradient through it.
    Returns the columns' scales, the start's singular values and the basis."""
    j0 = jax.lax.stop_gradient(jax.jacfwd(residuals)(jnp.zeros(n_all))[:, idx])
    norms = jnp.linalg.norm(j0, axis=0)
    col = 1.0 / jnp.where(norms > 0, norms, 1.0)
    _, s0, vt0 = jnp.linalg.svd(j0 * col, full_matrices=False)
    return col, s0, col[:, None] * (vt0.T / jnp.maximum(s0, WHITEN_FLOOR))


def _balance_residual(theta, k: int, ratio, x, cfg: ModelCompensator):
    """How well the last Newton solve closed the balance at `theta`, relative to the largest word."""
    sf, beta, inl = theta[0], theta[1], theta[2:2 + k]
    v = sf * ratio**beta * x
    d = newton(lambda d: d + inl_term(v + d, inl, cfg), jnp.zeros_like(v), cfg.newton_steps)
    return jnp.max(jnp.abs(d + inl_term(v + d, inl, cfg))) / jnp.max(jnp.abs(v))


@jit
def _fit_arrays(cfg: ModelCompensator, n_runs: int, with_tcf: bool, free: tuple[bool, ...],
                data: dict[str, Array]) -> dict[str, Array]:
    """The whole identification as one traceable function of the data (jitted; differentiable in `data`).

    `free` (static) says which entries of the parameter vector are fitted; the others stay at their start."""
    x, y, f, temp, sigma = data["x"], data["y"], data["f"], data["temp"], data["sigma"]
    run_index = data["run_index"]
    idx = jnp.asarray([i for i, b in enumerate(free) if b])
    k = len(cfg.inl_orders)
    theta0, f_ref, t_ref = _start(k, n_runs, with_tcf, data)

    # The residuals as functions of the deviation `delta` from the start, each formed from terms of the size of
    # the change: the start's misfit (outputs of millions of LSB minus the data) once, then the small
    # corrections. Formed as model(theta) - y at every step they would round anew to ~eps max|y| / sigma
    # (1e-10 sigma for 2.7e6 LSB and 4.4 LSB): a noise on chi2 (~1e-10) that the solver's accept test and its
    # stopping rule (1e-10 by default) both see, so that at the optimum it kept shrinking rejected steps.
    sg = jax.lax.stop_gradient
    ratio = f / f_ref
    log_ratio = jnp.log(ratio)
    sf0, beta0, inl0 = theta0[0], theta0[1], theta0[2:2 + k]
    g0 = ratio**beta0
    v0 = sf0 * g0 * x
    b0, drift0 = theta0[2 + k:2 + k + n_runs], theta0[2 + k + n_runs]
    misfit0 = v0 + b0[run_index] + drift0 * 1e6 * (ratio - 1.0) - y
    if with_tcf:
        fmisfit0 = ratio - 1.0 - theta0[-2] - theta0[-1] * (temp - t_ref)

    def residuals(delta):
        dsf, dbeta, inl = delta[0], delta[1], inl0 + delta[2:2 + k]
        dg = g0 * jnp.expm1(dbeta * log_ratio)  # (f/f_ref)^beta - (f/f_ref)^beta0
        dv = (dsf * (g0 + dg) + sf0 * dg) * x
        d = balance_offset(v0 + dv, inl, cfg, cfg.newton_steps)
        db, ddrift = delta[2 + k:2 + k + n_runs], delta[2 + k + n_runs]
        r = (misfit0 + dv + d + db[run_index] + ddrift * 1e6 * (ratio - 1.0)) / sigma
        if not with_tcf:
            return r
        rf = (fmisfit0 - delta[-2] - delta[-1] * (temp - t_ref)) / FREQ_SIGMA_REL
        return jnp.concatenate([r, rf])

    n_all = theta0.shape[0]
    col, s0, basis = _whitened_basis(residuals, n_all, idx)

    def delta_of(z, b):
        return jnp.zeros(n_all).at[idx].set(b @ z)

    def fn(z, b):
        return residuals(delta_of(z, b))

    # The stopping rule (no residual moves by more than atol + rtol |r|, sigma units) is never asked for less
    # than the resolution of the data themselves: float64 stores y to eps |y|.
    floor = jnp.finfo(jnp.float64).eps * jnp.max(jnp.abs(y)) / jnp.min(sigma)
    atol = jnp.maximum(cfg.atol, floor)
    # optimistix annotates atol as a float; a traced array is what it gets here, and works.
    solver = optx.LevenbergMarquardt(rtol=cfg.rtol, atol=atol)  # pyright: ignore[reportArgumentType]
    sol = optx.least_squares(fn, solver, jnp.zeros(len(idx)),
                             args=basis, max_steps=cfg.max_steps, throw=False)
    delta = delta_of(sol.value, basis)
    theta = theta0 + delta
    r = residuals(delta)
    jz = jax.jacfwd(residuals)(delta)[:, idx] * col
    chi2_red = jnp.sum(r**2) / max(r.shape[0] - len(idx), 1)
    cov_z = jnp.linalg.pinv(jz.T @ jz, hermitian=True)
    stderr = jnp.zeros_like(theta).at[idx].set(jnp.sqrt(jnp.abs(jnp.diag(cov_z)) * chi2_red) * col)
    # Convergence judged at the end, not by the solver's step sizes: the chi2 a full Gauss-Newton step from
    # here would still remove (r^T J (J^T J)^+ J^T r), and the conditioning of the unit-column Jacobian.
    g = sg(jz.T @ r)
    decrement = g @ sg(cov_z) @ g
    sv = jnp.linalg.svd(sg(jz), compute_uv=False)
    cond = sv[0] / sv[-1]
    bal = _balance_residual(theta, k, ratio, x, cfg)
    return {"theta": theta, "stderr": stderr, "chi2_red": chi2_red, "f_ref": f_ref, "t_ref": t_ref,
            "solver_successful": sol.result == optx.RESULTS.successful, "num_steps": sol.stats["num_steps"],
            "balance_residual": bal, "decrement": decrement, "condition_number": cond,
            "condition_number_start": s0[0] / s0[-1], "atol": atol}
