"""Settled sweeps: points read from settled states of the tier (the steady kinds from the rate output, the AGC
set-point kinds from the drive loop's registers too), all settled by one call of the tier.

Each point is evaluated at its own die temperature (the `temperature_c` column): the device's temperature
history is replaced by a constant at that temperature, since a settled point sees the temperature of its
dwell. A NaN temperature means "not recorded" and falls back to the device's own history at power-on. The
point's time since power-on (the `time_s` column; 0 when not recorded) reaches the device's terms that
depend on it (`gyrojax.AbstractRateTerm`, `AbstractOutputTerm`); the device's readout terms
(`AbstractOutputTerm`) act on the settled rate output.
"""

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._compile.jit import jit, top_level
from .._gyroscope import Gyroscope
from .._lots.stack import bucket_size, pad_devices, unpad_devices
from .._physics.stimulus import Stimulus
from .._simulate.tiers import AbstractTier, Settled, Steady
from .._solution import RESULTS, result_code
from .._terms import AbstractOutputTerm, PointConditions
from .base import AbstractSweep, at_temperature
from .lot_campaign import LotCampaign


class AbstractSettledSweep(AbstractSweep):
    """A sweep whose points are settled states of the steady (or another) tier, one device configuration and
    constant `Stimulus` per point. Every such sweep of a device settles in one call of the tier (one compiled
    settle, `steady_points`): a kind says what a point is (`point`), what it reads from the settled points
    (`finish`, `read`) and which points share a chord Jacobian of the steady tier (`chord_group`)."""

    chord_group: ClassVar[str | None] = None
    """The steady tier's chord Jacobian is formed at the centre of each group: the points of every kind of
    one named group share it, a kind without a group (None, every built-in kind) has its own. The grouping only
    moves where the root find starts its Broyden updates, not the roots (within its tolerance: a shared one
    moves simulated outputs in their last bits)."""

    @abc.abstractmethod
    def point(self, gyro: Gyroscope, value: Float[Array, " point"], time: Float[Array, " point"]
              ) -> tuple[Gyroscope, Stimulus]:
        """The device (already at the point's die temperature) and the stimulus of one point: `value` from the
        `input` column, `time` since power-on (s). Every field of the returned `Stimulus` must be an array
        shaped like `value` (`0.0 * value` for zero), so that the points of several sweeps stack into one
        settle."""

    @abc.abstractmethod
    def finish(self, gyro: Gyroscope, gyros: Gyroscope, settled: Settled, inputs: Float[Array, " point"],
               temperatures: Float[Array, " point"], times: Float[Array, " point"]) -> Any:
        """What the kind keeps of its settled points (a `Settled` or the kind's own module): `gyro` the device,
        `gyros` the device at each point (`point`'s), `inputs`, `temperatures` (NaN: not recorded) and `times`
        per point."""

    @abc.abstractmethod
    def read(self, points: Any) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        """The noise-free output per point of `finish`'s points, and a flag of points that could not be
        evaluated (not settled, not finite)."""

    def predict(self, gyro: Gyroscope, inputs: Float[ArrayLike, " point"], temperatures: Float[ArrayLike, " point"],
                times: Float[ArrayLike, " point"] | None, tier: AbstractTier = Steady()
                ) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        (points,) = settled_points(gyro, [(self, inputs, temperatures, times)], tier)
        return self.read(points)


class AbstractSteadySweep(AbstractSettledSweep):
    """A sweep read from the settled rate output of the steady tier: a point is a `Stimulus` held until the
    device settles. Every steady sweep of a device settles in one call of the tier (one compiled settle, a chord
    Jacobian per kind), so a kind only says what it applies (`stimulus`). The output carries the run's turn-on
    bias; the noise is rate noise averaged over the dwell."""

    biased = True
    straight_line = True
    rate_noise = True

    @abc.abstractmethod
    def stimulus(self, value: Float[Array, " point"], time: Float[Array, " point"]) -> Stimulus:
        """What one point applies: `value` from the `input` column, `time` since power-on (s). Every field
        of the returned `Stimulus` must be an array shaped like `value` (`0.0 * value` for zero), so that
        the points of several steady sweeps stack into one settle."""

    def point(self, gyro: Gyroscope, value: Float[Array, " point"], time: Float[Array, " point"]
              ) -> tuple[Gyroscope, Stimulus]:
        return gyro, self.stimulus(value, time)

    def finish(self, gyro: Gyroscope, gyros: Gyroscope, settled: Settled, inputs: Float[Array, " point"],
               temperatures: Float[Array, " point"], times: Float[Array, " point"]) -> Settled:
        return read_out(gyro, settled, self, inputs, temperatures, times)

    def read(self, points: Settled) -> tuple[Float[Array, " point"], Bool[Array, " point"]]:
        return points.rate, points.result != RESULTS.successful

    def simulate(self, lot: Gyroscope, campaign: LotCampaign) -> dict[str, np.ndarray]:
        inputs = campaign.applied(self, campaign.protocol.inputs(self, campaign.gyro))
        temps, times, full = campaign.temperatures(self), campaign.times(self), campaign.shape(self)
        settled = campaign.settled.get(self.name)
        if settled is None:
            settled = lot_steady(lot, ((self, jnp.asarray(inputs), jnp.asarray(temps), jnp.asarray(times)),),
                                 campaign.tier)[0]
            raise_unsettled(settled.result, self.title)
        out = np.asarray(settled.rate, dtype=float)
        dwell = self.dwell_s(campaign.protocol)
        lsb_per_dps = campaign.lsb_per_dps
        if campaign.noise_free:
            sigma = np.zeros(full)
        else:
            bias, wobble = campaign.noise.sample_point_means(campaign.rng(self), full[:2], full[2], dwell)
            out = out + (bias[..., None] + wobble) * lsb_per_dps[:, None, None]
            sigma = np.broadcast_to((campaign.noise.point_sigma_dps(dwell) * lsb_per_dps)[:, None, None], full)
        return {"input": np.broadcast_to(inputs, full), "output": out, "output_sigma": sigma,
                "n_samples": np.full(full, float(campaign.protocol.n_samples(self))), "temperature_c": temps,
                "drive_freq_hz": np.asarray(settled.frequency, dtype=float) / (2.0 * np.pi),
                "time_s": np.broadcast_to(times, full)}


def point_times(times, like):
    """Times since power-on (s) per point; not recorded (None or NaN) is 0."""
    t = jnp.zeros_like(like) if times is None else jnp.broadcast_to(jnp.asarray(times, dtype=float), like.shape)
    return jnp.where(jnp.isnan(t), 0.0, t)


def read_out(gyro: Gyroscope, settled: Settled, sweep: AbstractSweep, inputs, temperatures, times) -> Settled:
    """The settled rate output through the device's readout terms (`AbstractOutputTerm`)."""
    terms = gyro.terms_of(AbstractOutputTerm)
    if not terms:
        return settled
    temps = jnp.where(jnp.isnan(temperatures), gyro.temperature(0.0), temperatures)

    def one(output, x, temp, t):
        cond = PointConditions(sweep.name, x, temp, t)
        for term in terms:
            output = term(gyro, output, cond)
        return output

    return eqx.tree_at(lambda s: s.rate, settled, jax.vmap(one)(settled.rate, inputs, temps, times))


def steady_points(gyro: Gyroscope, requests, tier: AbstractTier = Steady()) -> tuple:
    """Settled points of several sweeps of one device in one call of the tier (one compiled settle for all of
    them: a static VCF point is the same equations as a rate point, at another input; an AGC set-point point
    the same at another set-point).

    **Arguments:**

    - `requests`: a sequence of `(sweep, inputs, temperatures, times)`: `sweep` an `AbstractSettledSweep` (an
      `AbstractSteadySweep` or `AbstractSetpointSweep`), the inputs in its data unit, one die temperature
      (deg C) and one time since power-on (s; None or NaN: not recorded) per point.

    **Returns:** per request, in order, what its kind keeps (`AbstractSettledSweep.finish`): a `Settled` with
    the device's readout terms applied for a steady sweep, a `SetpointReading` for a set-point sweep.
    """
    views, named = [], {}
    for k, (sweep, inputs, temperatures, times) in enumerate(requests):
        if not isinstance(sweep, AbstractSettledSweep):
            raise ValueError(f"steady_points: {sweep!r} is not a settled sweep (an AbstractSteadySweep or "
                             "AbstractSetpointSweep).")
        x = jnp.atleast_1d(jnp.asarray(inputs, dtype=float))
        temps = jnp.broadcast_to(jnp.asarray(temperatures, dtype=float), x.shape)
        t = point_times(times, x)

        def one(value, temp, time, sweep=sweep):
            return sweep.point(at_temperature(gyro, temp), value, time)

        group = (sweep.chord_group,) if sweep.chord_group is not None else (None, k)
        named.setdefault(group, []).append(k)
        views.append((sweep, x, temps, t, jax.vmap(one)(x, temps, t)))
    # The points of a chord group are contiguous, its kinds in request order (one group: the requests' order).
    order = [k for members in named.values() for k in members]
    bounds, slices, start = [], {}, 0
    for members in named.values():
        first = start
        for k in members:
            slices[k] = (start, start + views[k][1].shape[0])
            start = slices[k][1]
        bounds.append((first, start))
    parts = [views[k][4] for k in order]
    gyros, stimuli = jax.tree.map(lambda *leaves: jnp.concatenate(leaves), *parts) if len(parts) > 1 else parts[0]
    if len(bounds) > 1:
        settled = tier.settle_points(gyros, stimuli, groups=tuple(bounds))
    else:
        settled = tier.settle_points(gyros, stimuli)
    out = []
    for k, (sweep, x, temps, t, (gyros_k, _)) in enumerate(views):
        a, b = slices[k]
        piece = jax.tree.map(lambda leaf: leaf[a:b], settled) if len(parts) > 1 else settled
        out.append(sweep.finish(gyro, gyros_k, piece, x, temps, t))
    return tuple(out)



settled_points = jit(steady_points)
"""`steady_points` compiled once per structure and shape, for the public point functions called outside a
traced program (eagerly, each call of a settle's while loop would compile it again)."""

def per_run(x, temperatures):
    """Inputs or times, (point,) or (run, point), as (run, point) like the temperatures' last two axes."""
    return jnp.broadcast_to(jnp.asarray(x, dtype=float), temperatures.shape[1:])


def lot_steady(lot, requests, tier):
    """`steady_points` for every device (axis 0) and run (axis 1), several settled sweeps in one call (one
    compiled settle): `requests` is a tuple of `(sweep, inputs, temperatures, times)` with temperatures
    (device, run, point) and inputs and times (point,) or (run, point) (times NaN: not recorded). Returns what
    each request's kind keeps (a `Settled` or a `SetpointReading`), (device, run, point).

    Called outside a trace, the lot is padded to `gyrojax._lots.stack.bucket_size` devices (copies of its last device,
    settled, then dropped), so that a lot of a nearby size reuses the compiled settle."""
    n = np.shape(requests[0][2])[0]
    size = bucket_size(n) if top_level() else n
    if size == n:
        return _lot_steady(lot, requests, tier)
    padded = tuple((sweep, x, pad_devices(temps, size), t) for sweep, x, temps, t in requests)
    out = _lot_steady(pad_devices(lot, size), padded, tier)
    return unpad_devices(out, n)


@jit
def _lot_steady(lot, requests, tier):
    temps = tuple(r[2] for r in requests)
    inputs = tuple(per_run(r[1], t) for r, t in zip(requests, temps))
    times = tuple(per_run(r[3], t) for r, t in zip(requests, temps))
    sweeps = tuple(r[0] for r in requests)

    def device(g, dev_temps):
        def run(xs, ts, tms):
            return steady_points(g, tuple(zip(sweeps, xs, ts, tms)), tier)

        return jax.vmap(run)(inputs, dev_temps, times)

    return eqx.filter_vmap(device)(lot, temps)


def raise_unsettled(result, what: str):
    """Raise a RuntimeError naming how many `what` points did not settle, if any."""
    codes = np.asarray(result_code(result))
    bad = codes != result_code(RESULTS.successful)
    if bad.any():
        codes = codes[bad]
        raise RuntimeError(
            f"{int(bad.sum())} of {bad.size} {what} points did not settle (result code "
            f"{sorted(set(codes.tolist()))}). Steady() at rtol = atol = 1e-11 can stall at round-off (use "
            "gyrojax.CAMPAIGN_TIER, Steady at 1e-10); otherwise try the averaged tier to see the transient, "
            "smaller inputs, or check the device's loop gains.")
