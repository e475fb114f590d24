"""The rate-table points a compensator is fitted on and applied to: one device, any number of runs."""

import equinox as eqx
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int


class RatePoints(eqx.Module):
    """Rate-table points of one device, flat over its runs (host NumPy arrays, float64).

    **Fields:**

    - `rate_dps`: table rate, deg/s (the truth a compensator is fitted to; unused when applying one).
    - `output`: gyro output, LSB.
    - `drive_freq_hz`: the PLL's drive-frequency reading at the point, Hz; NaN where not given.
    - `temperature_c`: die temperature at the point, deg C; NaN where not given.
    - `output_sigma`: standard uncertainty of `output`, LSB; NaN where not given.
    - `run`: run id of each point (int64).

    Build one from a table with `gyrojax.compensation.rate_points(table, device)`, or directly from arrays.
    """

    rate_dps: Float[np.ndarray, " n"]
    output: Float[np.ndarray, " n"]
    drive_freq_hz: Float[np.ndarray, " n"]
    temperature_c: Float[np.ndarray, " n"]
    output_sigma: Float[np.ndarray, " n"]
    run: Int[np.ndarray, " n"]

    def __init__(self, rate_dps: Float[ArrayLike, " n"], output: Float[ArrayLike, " n"], *,
                 drive_freq_hz: Float[ArrayLike, " n"] | None = None,
                 temperature_c: Float[ArrayLike, " n"] | None = None,
                 output_sigma: Float[ArrayLike, " n"] | None = None,
                 run: Int[ArrayLike, " n"] | None = None):
        self.rate_dps = np.asarray(rate_dps, dtype=np.float64)
        self.output = np.asarray(output, dtype=np.float64)
        n = self.output.shape

        def side(name, value):
            if value is None:
                return np.full(n, np.nan)
            arr = np.asarray(value, dtype=np.float64)
            if arr.shape != n:
                raise ValueError(f"RatePoints.{name} has shape {arr.shape}, expected {n} like output.")
            return arr

        self.drive_freq_hz = side("drive_freq_hz", drive_freq_hz)
        self.temperature_c = side("temperature_c", temperature_c)
        self.output_sigma = side("output_sigma", output_sigma)
        self.run = np.zeros(n, dtype=np.int64) if run is None else np.asarray(run, dtype=np.int64)

    def __check_init__(self):
        if self.output.ndim != 1:
            raise ValueError(f"RatePoints.output must be 1-d (points of one device), got shape {self.output.shape}.")
        for name in ("rate_dps", "run"):
            if getattr(self, name).shape != self.output.shape:
                raise ValueError(f"RatePoints.{name} has shape {getattr(self, name).shape}, expected "
                                 f"{self.output.shape} like output.")
        for name in ("rate_dps", "output"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"RatePoints.{name} must be finite on every point.")

    def __len__(self):
        return self.output.shape[0]

    @property
    def runs(self) -> tuple[int, ...]:
        """Run ids in order of first appearance."""
        _, first = np.unique(self.run, return_index=True)
        return tuple(int(r) for r in self.run[np.sort(first)])

    def select(self, keep: Bool[np.ndarray, " n"] | Int[np.ndarray, " k"]) -> "RatePoints":
        """The points where boolean `keep` is True (or at integer indices `keep`)."""
        return RatePoints(self.rate_dps[keep], self.output[keep], drive_freq_hz=self.drive_freq_hz[keep],
                          temperature_c=self.temperature_c[keep], output_sigma=self.output_sigma[keep],
                          run=self.run[keep])
