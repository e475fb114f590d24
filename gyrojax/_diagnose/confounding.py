"""Coordinates that move together: pairs of recorded coordinates that rise or fall together in every run of a
sweep (the input swept in one direction while the die warms up) cannot be told apart there; `compare` says so
and what would separate them."""

import math

import equinox as eqx
import numpy as np


COORDINATES = ("temperature_c", "time_s", "drive_freq_hz", "order")
"""The recorded coordinates besides the input that the residuals are tested against (data columns, and the
point's position in its run in time order)."""

COORDINATE_WORDS = {"input": "the input", "temperature_c": "the die temperature",
                     "time_s": "the time since power-on", "drive_freq_hz": "the drive frequency",
                     "order": "the point's order in its run"}


class Confounding(eqx.Module):
    """Two coordinates that rise or fall together in every run of a sweep: a shape along one cannot be told
    from a shape along the other on this data."""

    sweep: str
    first: str
    second: str
    correlation: float  # the smallest |rank correlation| over the sweep's runs
    advice: str

    def describe(self) -> str:
        return (f"{self.sweep}: {COORDINATE_WORDS[self.first]} and {COORDINATE_WORDS[self.second]} move "
                f"together in every run (|rank correlation| >= {self.correlation:.2f}): a shape along one cannot "
                f"be told from one along the other; {self.advice}")


_ADVICE = {
    frozenset(("input", "time_s")): "sweep some runs in the other direction, or in shuffled order "
                                    "(gyrojax.Protocol(order='alternating' or 'shuffled'))",
    frozenset(("input", "order")): "sweep some runs in the other direction, or in shuffled order "
                                   "(gyrojax.Protocol(order='alternating' or 'shuffled'))",
    frozenset(("input", "temperature_c")): "sweep some runs in the other direction or in shuffled order, or "
                                           "hold the die temperature (a settled chamber plateau)",
    frozenset(("temperature_c", "time_s")): "measure runs at other chamber temperatures (temperature "
                                            "plateaus), or after a full warm-up",
    frozenset(("temperature_c", "order")): "measure runs at other chamber temperatures (temperature "
                                           "plateaus), or after a full warm-up",
    frozenset(("drive_freq_hz", "temperature_c")): "nothing on these sweeps: the drive frequency follows the die "
                                                   "temperature through the TCF by physics",
}


def confounded_groups(confounded) -> list[str]:
    """The confounded pairs as one sentence per sweep and group of coordinates that move together, with what
    would separate them."""
    out = []
    for sweep in dict.fromkeys(c.sweep for c in confounded):
        pairs = [c for c in confounded if c.sweep == sweep]
        groups: list[set] = []
        for c in pairs:
            joined = [g for g in groups if c.first in g or c.second in g]
            merged = set().union({c.first, c.second}, *joined)
            groups = [g for g in groups if g not in joined] + [merged]
        for g in groups:
            names = [n for n in ("input",) + COORDINATES if n in g]
            words = [COORDINATE_WORDS[n] for n in names]
            advice = []
            if "input" in g:
                advice.append("sweep some runs in the other direction or in shuffled order "
                              "(gyrojax.Protocol(order='alternating' or 'shuffled'))")
            if "temperature_c" in g and ({"time_s", "order"} & g):
                advice.append("measure runs at other chamber temperatures (plateaus)")
            if g == {"temperature_c", "drive_freq_hz"}:
                advice.append("nothing here: the drive frequency follows the die temperature by the TCF")
            what = ", ".join(words[:-1]) + f" and {words[-1]}" if len(words) > 1 else words[0]
            out.append(f"{sweep}: {what} move together in every run, so shapes along them cannot be told apart "
                       f"here" + (f"; to separate them: {'; '.join(advice)}" if advice else ""))
    return out


def _rank(x):
    return np.argsort(np.argsort(x, kind="stable"), kind="stable").astype(float)


def _rank_correlation(a, b):
    ra, rb = _rank(a), _rank(b)
    ra, rb = ra - ra.mean(), rb - rb.mean()
    den = math.sqrt(float(np.sum(ra**2) * np.sum(rb**2)))
    return float(np.sum(ra * rb) / den) if den > 0 else 0.0


def confounded_coordinates(coords, mask, sweep, *, threshold: float = 0.95):
    """Pairs of coordinates of one sweep (dict name -> (device, run, point)) whose |rank correlation| is at
    least `threshold` in every run with at least 4 points (time_s and order, the same axis, are not paired)."""
    names = [c for c in ("input",) + COORDINATES if c in coords]
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if {a, b} == {"time_s", "order"} or (b == "order" and "time_s" in names):
                continue
            worst, runs = 1.0, 0
            for d, k in np.ndindex(mask.shape[:2]):
                m = mask[d, k]
                xa, xb = coords[a][d, k][m], coords[b][d, k][m]
                if m.sum() < 4 or not (np.all(np.isfinite(xa)) and np.all(np.isfinite(xb))):
                    continue
                if np.ptp(xa) == 0 or np.ptp(xb) == 0:
                    worst = 0.0
                    break
                worst = min(worst, abs(_rank_correlation(xa, xb)))
                runs += 1
            if runs and worst >= threshold:
                advice = _ADVICE.get(frozenset((a, b)), "change the protocol so that they vary apart")
                out.append(Confounding(sweep=sweep, first=a, second=b, correlation=worst, advice=advice))
    return out
