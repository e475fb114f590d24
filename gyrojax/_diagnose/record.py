r"""A guard from what the data record beside the output: an effect must not move a recorded quantity that the
record shows standing still (or move it the wrong way).

The fit explains the `output` column; the data often record more. The drive loop's PLL frequency
(`drive_freq_hz`) is one the model predicts too: the settled points of a steady sweep carry it. A candidate
effect fitted to the output changes that prediction by

    x_i = ln f_after,i - ln f_before,i,

and the record, beyond the model before it, shows y_i = ln f_recorded,i - ln f_before,i. With an offset per
device (a device's resonance is not a fitted parameter), y_i = a_d + beta x_i + e_i: beta ~ 1 where the record
moves as the effect says, beta ~ 0 where it stands still. The noise of the record is estimated from the
regression's own residuals (its reading noise is not in the data format), so a record with structure the
model does not have widens the interval instead of sharpening the verdict.

An effect is refused when the record shows less than half or more than 1.5 times the change it predicts
(|beta - 1| > `MAX_MISMATCH`) and that is `Z_RECORD` standard errors from 1; a record that cannot resolve beta
to `MAX_STDERR`, or a predicted change under `MIN_CHANGE` (1 ppm), says nothing. Any effect that changes the
modelled drive frequency (a library term or a user's own) is checked; one that leaves it alone is not.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._identify import Fit
from .._simulate.tiers import Steady
from .._sweeps.steady import AbstractSteadySweep, steady_points


MAX_MISMATCH = 0.5  # the record must show between half and 1.5 times the predicted change
Z_RECORD = 5.0  # standard errors of beta from 1 before the record contradicts (readings drift, not white)
MAX_STDERR = 0.25  # a record that fixes beta less well than this cannot tell
# ASSUMPTION: the modelled PLL frequency is trusted for changes of 1 ppm and more; below, the settle's tolerance
# and the loop's second-order terms (a frequency word's resolution, ~0.02 ppm over a 2-min dwell at 4.6 kHz)
# are of the same order, so a smaller predicted change is not held against the record
MIN_CHANGE = 1e-6


def _frequency_blocks(data):
    """The steady sweeps of `data` whose every real point records the drive frequency."""
    out = []
    for s, b in data.blocks.items():
        if not isinstance(b.kind, AbstractSteadySweep) or b.drive_freqs is None:
            continue
        m = np.asarray(b.mask)
        if m.any() and np.all(np.isfinite(np.asarray(b.drive_freqs)[m])):
            out.append(s)
    return tuple(out)


@eqx.filter_jit
def _settled_frequency(model, inputs, temperatures, times, kinds, tier):
    def one(m, x, t, tm):
        requests = [(k, xi.ravel(), ti.ravel(), None if tmi is None else tmi.ravel())
                    for k, xi, ti, tmi in zip(kinds, x, t, tm)]
        settled = steady_points(m.gyroscope(), requests, tier)
        return tuple(p.frequency.reshape(xi.shape) / (2.0 * jnp.pi) for p, xi in zip(settled, x))

    return eqx.filter_vmap(one)(model, inputs, temperatures, times)


def predicted_drive_frequency(fit: Fit, tier=Steady()) -> dict:
    """The model's settled PLL frequency (Hz) at every point of the steady sweeps of `fit.data` that record
    `drive_freq_hz`: sweep -> (device, run, point)."""
    sweeps = _frequency_blocks(fit.data)
    if not sweeps:
        return {}
    blocks = [fit.data.blocks[s] for s in sweeps]
    out = _settled_frequency(fit.model, tuple(b.inputs for b in blocks), tuple(b.temperatures for b in blocks),
                             tuple(b.times for b in blocks), tuple(b.kind for b in blocks), tier)
    return {s: np.asarray(f, float) for s, f in zip(sweeps, out)}


def record_slope(before: Fit, after: Fit, tier=Steady()):
    """(beta, its standard error, the largest predicted change of ln f) of the recorded drive frequency on the
    change the refit `after` predicts beyond `before` (module docstring); None where no point records it or
    the refit does not change the prediction."""
    f0, f1 = predicted_drive_frequency(before, tier), predicted_drive_frequency(after, tier)
    xs, ys, devs = [], [], []
    for s in f0:
        b = before.data.blocks[s]
        m = np.asarray(b.mask) & (f0[s] > 0) & (f1[s] > 0) & np.isfinite(f0[s]) & np.isfinite(f1[s])
        rec = np.asarray(b.drive_freqs, float)
        m &= np.isfinite(rec) & (rec > 0)
        idx = np.nonzero(m)
        xs.append(np.log(f1[s][idx]) - np.log(f0[s][idx]))
        ys.append(np.log(rec[idx]) - np.log(f0[s][idx]))
        devs.append(idx[0])
    if not xs:
        return None
    x, y, dev = np.concatenate(xs), np.concatenate(ys), np.concatenate(devs)
    fitted = slope_with_offsets(x, y, dev)
    return None if fitted is None or not np.max(np.abs(x)) > 0 else (*fitted, float(np.max(np.abs(x))))


def slope_with_offsets(x, y, group):
    """The least-squares slope of y on x with an offset per `group`, and its standard error from the residual
    scatter: (beta, stderr), or None with fewer than 2 degrees of freedom or no spread of x within a group."""
    x, y, group = np.asarray(x, float), np.asarray(y, float), np.asarray(group)
    xc, yc = x.copy(), y.copy()
    for g in np.unique(group):
        k = group == g
        xc[k] -= x[k].mean()
        yc[k] -= y[k].mean()
    sxx = float(xc @ xc)
    dof = x.size - len(np.unique(group)) - 1
    if dof < 2 or not sxx > 0:
        return None
    beta = float(xc @ yc) / sxx
    rss = float(np.sum((yc - beta * xc) ** 2))
    return beta, float(np.sqrt(rss / dof / sxx))


def record_guard(before: Fit, after: Fit, effect: str, tier=Steady()) -> str | None:
    """A reason not to confirm `effect` (refitted from `before` to `after`) from the recorded drive frequency,
    or None (see the module docstring)."""
    slope = record_slope(before, after, tier)
    if slope is None:
        return None
    beta, se, largest = slope
    if largest < MIN_CHANGE or not np.isfinite(se) or se > MAX_STDERR:
        return None
    if abs(beta - 1.0) > MAX_MISMATCH and abs(beta - 1.0) > Z_RECORD * se:
        return (f"the recorded drive frequency (drive_freq_hz) contradicts it: its refit moves the modelled PLL "
                f"frequency by up to {1e6 * largest:.3g} ppm along the points, and the record shows "
                f"{beta:.3g} +/- {se:.2g} times that change (an offset per device; 1 if the effect were there)")
    return None
