"""One located misfit (`Location`, what `gyrojax._diagnose.locate` returns) and how it reads: the shape of its
flexible description in words, and where it sits."""

import math

import equinox as eqx
import numpy as np

from .._text import safe_name as clean
from . import changepoints, thresholds
from .descriptions import EACH_RUN, Description


class Location(eqx.Module):
    """Where one unexplained misfit lives, measured on the residuals (`gyrojax._diagnose.locate`).

    The attributes `probe`, `coefficient`, `coefficient_spread`, `unit`, `same_shape_as` and `library` carry
    the generic shape (a probe) that has this misfit, when one does."""

    coordinate: str
    family: str
    shape: str
    sweeps: tuple[tuple[str, float], ...]  # (sweep, measured share), largest first
    chi2_explained: float
    df: int
    share: float  # of the fit's chi2 in excess of its degrees of freedom
    p_value: float
    fingerprint: np.ndarray
    columns: np.ndarray
    located_on: tuple[str, ...]  # the sweeps the description is significant on
    location: dict[str, object]  # the JSON's `location`: interval, runs, at, period, point
    size: dict[str, object] | None  # the JSON's `size`: value, unit, stderr, measure, ppm_of_full_scale
    size_reason: str = ""
    confounded_with: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    probe: str = ""
    coefficient: float = float("nan")
    coefficient_spread: float = 0.0
    unit: str = ""
    same_shape_as: tuple[str, ...] = ()
    library: str = ""
    within: str = ""
    significant: bool = True
    pooled: bool = False  # its columns are one curve for every device (`ResidualSpace.score(..., pooled=True)`)

    @property
    def key(self) -> str:
        return f"{'+'.join(self.located_on)}:{self.coordinate}:{self.family}"

    @property
    def description(self) -> str:
        where = ", ".join(f"{clean(s)} {100 * f:.0f} %" for s, f in self.sweeps) or "no single sweep"
        if round(100 * self.share) >= 1:
            text = f"{100 * self.share:.0f} % of the misfit is {self.shape} ({where})"
        else:  # significant in a large lot, or at a chi2 at the noise level: no excess misfit to share
            text = f"{self.shape} ({where}), significant but below 1 % of the misfit"
        loc = location_text(self.location)
        if loc:
            text += f", {loc}"
        if self.size is not None:
            text += (f": about {self.size['value']:.3g} +/- {self.size['stderr']:.2g} {self.size['unit']}"
                     + (f" ({self.size['ppm_of_full_scale']:.3g} ppm of full scale)"
                        if self.size.get("ppm_of_full_scale") is not None else ""))
        elif self.size_reason:
            text += f"; size not determined: {self.size_reason}"
        if self.confounded_with:
            text += f"; the data confound {self.coordinate} with {', '.join(self.confounded_with)}"
        if self.same_shape_as:
            text += f"; this data cannot tell it from {', '.join(self.same_shape_as)}"
        return text + (f"; {self.library}" if self.library else "")

    def to_json(self) -> dict:
        return {"coordinate": self.coordinate, "shape": self.shape, "family": self.family,
                "sweeps": list(self.located_on), "sweep_shares": {s: f for s, f in self.sweeps},
                "chi2_explained": self.chi2_explained, "df": self.df, "share": self.share, "p": self.p_value,
                "location": self.location, "size": self.size,
                "size_reason": None if self.size is not None else self.size_reason,
                "confounded_with": list(self.confounded_with), "notes": list(self.notes),
                "description": self.description, "probe": self.probe or None,
                "coefficient": _finite(self.coefficient), "coefficient_spread": _finite(self.coefficient_spread),
                "unit": self.unit, "same_shape_as": list(self.same_shape_as), "within": self.within,
                "library": self.library}


def _finite(x):
    return float(x) if math.isfinite(x) else None


def location_text(loc: dict) -> str:
    parts = []
    if "interval" in loc:
        lo, hi = loc["interval"]
        parts.append(f"over {loc['coordinate']} {lo:.4g} to {hi:.4g}")
    if "at_each" in loc:  # steps (or pulses) at their own times, one per run
        parts.append(f"at {loc['coordinate']} " + ", ".join(
            (f"{a:.4g}" if e is None else f"{a:.4g} to {e:.4g}") + f" in {clean(d)} run {r}"
            for (d, r), a, e in list(zip(loc["runs"], loc["at_each"], changepoints.ends(loc)))[:4])
                     + (" ..." if len(loc["runs"]) > 4 else ""))
        return " ".join(parts)
    if "at" in loc:
        parts.append(f"at {loc['coordinate']} {loc['at']:.4g}"
                     + (" (the data place it between {:.4g} and {:.4g})".format(*loc["at_range"])
                        if "at_range" in loc and loc["at_range"][0] < loc["at_range"][1] else ""))
    if "point" in loc:
        parts.append("at " + ", ".join(f"{k} {v:.4g}" for k, v in loc["point"].items()))
    if loc.get("runs"):
        parts.append("in " + ", ".join(f"{clean(d)} run {r}" for d, r in loc["runs"][:3])
                     + (" ..." if len(loc["runs"]) > 3 else ""))
    return " ".join(parts)


def shape_words(d: Description) -> str:
    """How the shape of a location's description reads in the report."""
    if d.family == "step":
        if d.where.get("until_each"):
            return "a pulse of the output partway through a run (it switches on, then back off)"
        return "a step of the output partway through a run"
    if d.family in thresholds.FAMILIES:
        what = "the output" if d.family == "offset step" else "the gain"
        devices = d.where["devices"]
        whom = (f"in {clean(devices[0])} only" if len(devices) == 1 else
                "the same in every device" if d.pooled else "in every device, each its own height")
        return f"a step of {what} where {d.coordinate} passes one value ({whom})"
    if d.family == "single point":
        return "a single point off the model (an outlier: a glitch in the recording or a transient)"
    if d.family == "at one input":
        return "an error at one input value in every device (a narrow feature: a missing code, a resonance)"
    if d.family == "input x":
        return f"an offset along the input whose size changes with {d.coordinate}"
    if d.family in EACH_RUN:
        what = "an offset" if d.family.startswith("offset") else "a gain"
        return f"{what} along {d.coordinate} that differs from run to run" + (
            ", the same in every device" if d.pooled else "")
    if d.family == "periodic":
        unit = " s" if d.coordinate == "time_s" else ""
        what = "a periodic gain error" if d.where.get("gain") else "a periodic error"
        return f"{what} along {'the input' if d.coordinate == 'input' else d.coordinate} " \
               f"(period {d.where['period']:.3g}{unit})"
    if d.coordinate == "device":
        return "an offset of a device's readings, the same in all its runs (a property of the device)"
    if d.coordinate == "run":
        return "a gain that changes from run to run" if d.family == "gain per run" else \
            "an offset that changes from run to run"
    what = "an offset" if d.family == "offset" else "a gain"
    return f"{what} that varies smoothly along {d.coordinate}" + (", the same in every device" if d.pooled else "")
