"""A guard that does not depend on the list of shapes: a library effect's coefficient is a constant of the device,
so it does not follow a recorded coordinate along which its physics does not change (a varying-coefficient test).

A misfit the library does not hold can carry a constant part of a library effect's shape: a cubic compression
growing with the die temperature, -c (T - 25 C) s^3, holds a compression of c times the mean temperature
excess. The score test, the refit and every
guard that compares shapes then see the library effect's own shape, significant, and confirm it. What the data
also say is that its size changes along the coordinate. For each device the candidate's columns J are joined by
the same columns times the coordinate, centred on the candidate's information-weighted mean in that device,

    Q = chi2([base, other, J]) - chi2([base, other, J, J * (x - x_mean)]) ~ chi2(df),  df = the added rank,

linear at the fit before the step, summed over the devices. `other` holds the flexible descriptions of the
misfit located at the fit that neither J nor its drift takes (as the probe guard holds them), so that a second,
unrelated misfit along the coordinate is not read as a drift of this one; a location the drift takes is the drift
itself, and is not held. Each other candidate significant at the step is held in turn, and the smallest Q is
read: a DAC INL beside a reference drift, on a protocol whose temperature follows the time, has a drift along the
temperature that the reference drift describes. Along a coordinate a constant-coefficient effect does not
follow, Q is chi2(df) noise; the candidate is refused when, on one of the coordinates, Q is significant at `alpha`
over the coordinates tested and describes at least `MIN_DRIFT_SHARE` of what its constant part does (its score
S), read alone, with the other misfit held and beyond each rival: a drift that material is the missing effect's,
not a second-order difference of shape.

The coordinates are the two along which a property of the device could change within a run: its temperature
(a tempco of the coefficient) and the time (a warm-up, an ageing). Not the input (its curve is the effect's
shape, which the encompassing test reads); not the run, nor the temperature's rate of change, whose sign is a
property of the run where each run warms or cools (`gyrojax._diagnose.repeat` reads the run, by cross-validation);
not the drive frequency, which within a device follows the temperature."""

import numpy as np

from .._identify import Fit
from .._numerics.stats import chi2_sf
from .columns import base_columns, effect_columns, row_blocks
from .descriptions import coordinates
from .guards import other_misfit
from .probes import span_basis


DRIFT_COORDINATES = ("temperature_c", "time_s")
# ASSUMPTION: a drift that describes less than half of what the candidate's constant part does is not read as
# the missing effect's. A term whose size grows along the coordinate from near zero has a drift comparable with
# its mean (a ramp from zero: the drift's variance a third of the mean's square, and the fit's free columns take
# more of the constant than of the drift; Q / S = 0.6-6 on the discovery benchmark's partial look-alikes), while a
# real effect beside a second misfit along the coordinate leaks a small part of it into its drift (Q / S = 0.10
# and 0.22, a DAC INL beside a reference drift and beside a gain per run), and at a high SNR a 1 % difference of
# shape is significant too.
MIN_DRIFT_SHARE = 0.5


def row_coordinate(fit: Fit, name: str) -> np.ndarray:
    """The recorded coordinate `name` at each residual row (device, row); NaN on rows where it is not recorded
    (a sweep that does not record it, the priors)."""
    n_dev, n_rows = np.asarray(fit.residual_vector).shape
    out = np.full((n_dev, n_rows), np.nan)
    for sweep, i, j in row_blocks(fit.data):
        values = coordinates(fit.data.blocks[sweep]).get(name)
        if values is not None:
            out[:, i:j] = np.asarray(values, float).reshape(n_dev, -1)
    return out


def drift_columns(fit: Fit, jac: np.ndarray, name: str) -> np.ndarray:
    """The columns `jac` (device, rows, k) times the coordinate `name`, centred on their information-weighted
    mean and scaled to at most 1 in each device: zero in a device where the coordinate is not recorded on the rows
    the columns touch, or does not move there; (device, rows, 0) where it moves in none."""
    x = row_coordinate(fit, name)
    out = np.zeros(jac.shape)
    for d in range(jac.shape[0]):
        weight = np.sum(jac[d] ** 2, axis=1)
        seen = np.isfinite(x[d]) & (weight > 0)
        if seen.sum() < 3 or np.ptp(x[d][seen]) == 0:
            continue
        centred = np.where(seen, x[d] - np.average(x[d][seen], weights=weight[seen]), 0.0)
        out[d] = jac[d] * (centred / np.max(np.abs(centred)))[:, None]
    return out if np.any(out) else out[:, :, :0]


def coefficient_drift(fit: Fit, effect: str, name: str, other: np.ndarray | None = None) -> tuple[float, int]:
    """(Q, df): the chi2 that `effect`'s columns times the coordinate `name` (centred and scaled in each device)
    remove beyond the fit's free columns, `other` (device, rows, k) and the columns themselves, summed over the
    devices; (0, 0) where the coordinate is not recorded or does not move on the rows the candidate touches."""
    jac = np.asarray(fit.jacobian, float)[:, :, effect_columns(fit, effect)]
    return _drift_chi2(np.asarray(fit.residual_vector, float), _held(base_columns(fit), other), jac,
                       drift_columns(fit, jac, name))


def _held(base: np.ndarray, other: np.ndarray | None) -> np.ndarray:
    return base if other is None or not other.shape[-1] else np.concatenate([base, other], axis=-1)


def _drift_chi2(res, base, jac, drifting) -> tuple[float, int]:
    """`coefficient_drift` on arrays: residuals (device, rows), the held columns, the candidate's and its drift's."""
    q, df = 0.0, 0
    if not drifting.shape[-1]:
        return q, df
    for d in range(res.shape[0]):
        if not np.any(drifting[d]):
            continue
        constant = span_basis(np.concatenate([base[d], jac[d]], axis=1))
        both = span_basis(np.concatenate([base[d], jac[d], drifting[d]], axis=1))
        q += float(np.sum((both.T @ res[d]) ** 2) - np.sum((constant.T @ res[d]) ** 2))
        df += both.shape[1] - constant.shape[1]
    return max(q, 0.0), df


def constancy_guard(fit: Fit, effect: str, score: float, alpha: float, localisation=None,
                    rivals=()) -> str | None:
    """A reason not to confirm `effect` (score test statistic `score` at `fit`), or None: its coefficient
    follows a recorded coordinate (see the module docstring), with and without the misfit located elsewhere
    (`localisation`) held, and beyond each of `rivals` (the other candidates significant at this step): a drift
    that another library effect describes is that effect's misfit beside this one."""
    res, full, base = np.asarray(fit.residual_vector, float), np.asarray(fit.jacobian, float), base_columns(fit)
    jac = full[:, :, effect_columns(fit, effect)]
    drifts = {name: drift_columns(fit, jac, name) for name in DRIFT_COORDINATES}
    alone = {name: _drift_chi2(res, base, jac, drifting) for name, drifting in drifts.items()}
    alone = {name: qd for name, qd in alone.items() if qd[1]}
    if not alone:
        return None
    cut = alpha / len(alone)
    found = []
    for name, (q, df) in alone.items():
        if chi2_sf(q, df) >= cut or q < MIN_DRIFT_SHARE * score:
            continue
        # a location the drift itself takes is the drift; one it does not take is another misfit, held
        drifting = drifts[name]
        other = other_misfit(fit, jac, localisation, alpha, taken_by=np.concatenate([jac, drifting], axis=-1))
        q, df = _drift_chi2(res, _held(base, other), jac, drifting) if other.shape[-1] else (q, df)
        for rival in rivals:
            held = np.concatenate([other, full[:, :, effect_columns(fit, rival)]], axis=-1)
            q_r, df_r = _drift_chi2(res, _held(base, held), jac, drifting)
            if df_r and q_r < q:
                q, df = q_r, df_r
        p = chi2_sf(q, df) if df else 1.0
        if p < cut and q >= MIN_DRIFT_SHARE * score:
            found.append((p, -q, name, q, df))
    if not found:
        return None
    p, _, name, q, df = min(found)
    return (f"its size follows {name}: its columns times {name} remove chi2 Q = {q:.4g} (df {df}, p = {p:.2g}) "
            f"beyond a constant coefficient, {q / max(score, 1e-300):.2g}x what the constant explains (S = "
            f"{score:.4g}); a property of the device does not change along {name}: the missing effect holds a part "
            f"of {effect}'s shape whose size changes with {name}")
