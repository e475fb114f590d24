"""What a simulated campaign fixes for every sweep of a lot: protocol, runs, noise and the shared settle."""

import equinox as eqx
import numpy as np

from .._gyroscope import Gyroscope
from .._lots.noise import RateNoise
from .._simulate.tiers import AbstractTier
from .protocol import Protocol, Scheduled


class LotCampaign(eqx.Module):
    """The campaign around one sweep's simulation (`AbstractSweep.simulate`).

    **Fields:**

    - `gyro`: the nominal single device (the protocol's inputs and warm-up are set from it).
    - `protocol`, `devices`, `runs`, `seed`, `noise`, `noise_free`, `tier`, `voltmeter_sigma_v`: as given to
      `gyrojax.simulate_table`.
    - `lsb_per_dps`: each device's noise-free rate-table scale factor (LSB per deg/s, shape (device,)),
      converting rate noise to LSB; zeros when no rate table was settled.
    - `settled`: the `Settled` (device, run, point) of the settled sweeps settled together, by the kind's name
      (a campaign holds each kind once; a dict of a pytree needs sortable keys).
    """

    gyro: Gyroscope
    protocol: Protocol
    devices: int
    runs: int
    seed: int
    noise: RateNoise
    noise_free: bool
    tier: AbstractTier
    voltmeter_sigma_v: float
    lsb_per_dps: np.ndarray
    settled: dict

    def shape(self, sweep: Scheduled) -> tuple[int, int, int]:
        """(device, run, point) of `sweep`'s columns."""
        return (self.devices, self.runs, self.protocol.n_points(sweep))

    def temperatures(self, sweep: Scheduled) -> np.ndarray:
        """Die temperature at the middle of each point's dwell, deg C, (device, run, point)."""
        return np.broadcast_to(self.protocol.temperatures(self.gyro, self.runs, sweep), self.shape(sweep))

    def times(self, sweep: Scheduled) -> np.ndarray:
        """Time since power-on at the middle of each point's dwell, s, (run, point)."""
        return np.broadcast_to(self.protocol.point_times(sweep), self.shape(sweep)[1:])

    def applied(self, sweep: Scheduled, listed: np.ndarray) -> np.ndarray:
        """The inputs of each run in the order applied, (run, point): rows of the table in time order."""
        return np.asarray(listed)[self.protocol.point_order(sweep, self.runs, self.seed)]

    def rng(self, sweep: Scheduled) -> np.random.Generator:
        """An independent NumPy generator per sweep kind, numbered by the kind's `stream`: adding a sweep leaves
        the others' noise unchanged."""
        return np.random.default_rng([int(self.seed) % 2**63, sweep.stream])
