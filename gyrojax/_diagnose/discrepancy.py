"""Where the misfit lives: the generic shapes (probes) scored at a fit, which of them are one shape on this
data, and which library effect has each significant shape."""

import dataclasses
import math

import equinox as eqx
import numpy as np

from .._identify import Fit
from .._model.fitdata import FitData
from .columns import base_columns, effect_columns, excess_chi2, row_blocks
from .formula import lot_mean
from .locate import SIZE_REL_STDERR
from .probes import PROBES, design, project_out, score_columns
from .space import ResidualSpace


# A candidate "has" a residual shape when the shape, beyond the baseline and the candidate, keeps less than this
# share of the chi2 it explains alone. Not a significance test: at a misfit of 1e7 chi2 every difference between
# two shapes is significant, and the candidate's Jacobian is taken at the baseline, not at the truth, so even
# the right effect leaves a few percent (3.7 % for the demo lot's hidden DAC INL, which its refit then explains
# to the noise).
SHAPE_SHARE_LEFT = 0.1



class Discrepancy(eqx.Module):
    """Where an unexplained misfit lives: a generic shape (a probe) along a recorded coordinate, with the share
    of the misfit it explains and the size of the term it implies."""

    probe: str
    coordinate: str  # a data column (input, temperature_c, time_s, drive_freq_hz), "order" or "run"
    shape: str
    # (sweep, share of the probe's fingerprint) where it acts on this data, largest first
    sweeps: tuple[tuple[str, float], ...]
    chi2_explained: float  # the score S: the chi2 it would remove
    df: int
    share: float  # of the chi2 in excess of the degrees of freedom
    p_value: float
    significant: bool
    coefficient: float  # the lot's mean fitted coefficient (largest |.| for a multi-column probe), in `unit`
    coefficient_spread: float  # standard deviation over the devices
    unit: str
    fingerprint: np.ndarray
    same_shape_as: tuple[str, ...] = ()  # other significant probes this data cannot tell from it
    library: str = ""  # which library effect has this fingerprint, and at what size
    within: str = ""  # a more explanatory probe this one adds nothing beyond (it is part of that misfit)

    @property
    def description(self) -> str:
        where = ", ".join(f"{s} {100 * f:.0f} %" for s, f in self.sweeps)
        size = f"{self.coefficient:.3g} {self.unit}"
        if self.coefficient_spread > 0:
            size += f" (device spread {self.coefficient_spread:.2g})"
        text = f"{100 * self.share:.0f} % of the misfit is {self.shape} ({where}): about {size}"
        if self.same_shape_as:
            text += f"; this data cannot tell it from {', '.join(self.same_shape_as)}"
        return text + (f"; {self.library}" if self.library else "")

    def to_json(self) -> dict:
        return {"coordinate": self.coordinate, "shape": self.shape, "sweeps": [s for s, _ in self.sweeps],
                "chi2_explained": self.chi2_explained, "share": self.share, "p": self.p_value,
                "description": self.description, "probe": self.probe, "df": self.df,
                "coefficient": self.coefficient, "coefficient_spread": self.coefficient_spread, "unit": self.unit,
                "same_shape_as": list(self.same_shape_as), "within": self.within, "library": self.library}


def _sweep_shares(fingerprint, data: FitData):
    total = float(np.sum(fingerprint**2))
    if total <= 0:
        return ()
    shares = [(sweep, float(np.sum(fingerprint[:, i:j] ** 2)) / total) for sweep, i, j in row_blocks(data)]
    return tuple(sorted(((s, f) for s, f in shares if f > 0.05), key=lambda x: -x[1]))


def score_probes(fit: Fit, probes=PROBES, *, alpha: float = 0.01):
    """Every probe scored against `fit`: (Discrepancy per probe, most explanatory first; their designs by
    name). A probe is significant at p < alpha / (number of probes the data can test)."""
    base = base_columns(fit)
    res = np.asarray(fit.residual_vector)
    excess = excess_chi2(fit)
    designs, scored = {}, []
    for probe in probes:
        cols = design(fit, probe)
        if cols.shape[-1] == 0 or not np.any(cols):
            continue
        designs[probe.name] = cols
        scored.append((probe, score_columns(base, cols, res)))
    testable = [x for x in scored if x[1].df > 0]
    cut = alpha / max(len(testable), 1)
    out = []
    for probe, sc in testable:
        coef = sc.coefficients
        mag = coef[:, np.argmax(np.max(np.abs(coef), axis=0))] if coef.shape[1] > 1 else coef[:, 0]
        share = min(max(sc.statistic - sc.df, 0.0) / excess, 1.0) if excess > 0 else 0.0
        out.append(Discrepancy(probe=probe.name, coordinate=probe.coordinate, shape=probe.shape,
                               sweeps=_sweep_shares(sc.fingerprint, fit.data), chi2_explained=sc.statistic,
                               df=sc.df, share=share, p_value=sc.p_value, significant=sc.p_value < cut,
                               coefficient=float(np.mean(mag)),
                               coefficient_spread=float(np.std(mag)) if len(mag) > 1 else 0.0, unit=probe.unit,
                               fingerprint=sc.fingerprint))
    out.sort(key=lambda d: (not d.significant, -d.chi2_explained))
    # A significant shape that adds nothing beyond a more explanatory one is part of it (a drift in time seen
    # through an input swept in time order); two that add nothing beyond each other are the same shape here.
    within, same = {}, {d.probe: [] for d in out}
    significant = [d for d in out if d.significant]
    for i, d in enumerate(significant):
        for e in significant[:i]:
            if e.probe in within:
                continue
            d_beyond = score_columns(np.concatenate([base, designs[e.probe]], -1), designs[d.probe], res)
            if d_beyond.p_value < cut:
                continue
            e_beyond = score_columns(np.concatenate([base, designs[d.probe]], -1), designs[e.probe], res)
            if e_beyond.p_value < cut:
                within[d.probe] = e.probe
                break
            same[d.probe].append(e.probe)
            same[e.probe].append(d.probe)
    final = tuple(dataclasses.replace(d, same_shape_as=tuple(same[d.probe]), within=within.get(d.probe, ""))
                  for d in out)
    return final, designs


class LookAlike(eqx.Module):
    """A significant shape that a confirmed effect takes whole on this data, though the two differ: by
    `separation_sigma` of the noise at the size the shape implies, on `sweeps` (sweep, share of the difference),
    so that the data cannot say which it is. `information_factor`: how many times its information the separating
    sweep would need to tell them apart at 3 sigma."""

    probe: str
    shape: str
    sweeps: tuple[tuple[str, float], ...]  # (sweep, share of the difference)
    separation_sigma: float
    information_factor: float

    @property
    def description(self) -> str:
        if not self.sweeps:
            return f"{self.shape} ({self.probe})"
        sweep, share = self.sweeps[0]
        return (f"{self.shape} ({self.probe}): on this data the two differ by {self.separation_sigma:.2g} sigma, "
                f"{100 * share:.0f} % of it on the {sweep} sweep, which would separate them with "
                f"~{self.information_factor:.2g}x its information (lower noise, more points, or a wider span of "
                "its input)")

    def to_json(self) -> dict:
        return {"probe": self.probe, "shape": self.shape, "sweeps": [list(x) for x in self.sweeps],
                "separation_sigma": self.separation_sigma, "information_factor": self.information_factor,
                "description": self.description}


# The separation (in sigma of the noise, at the size the shape implies) from which the data tell a shape from an
# effect: below it, a confirmed effect that takes the shape's whole misfit could as well be that shape.
SEPARATION_SIGMA = 3.0
# A shape that differs from the effect by less than this share of its own information (0.1 % of its norm) is the
# effect's own form on this data, whatever the noise: bias_vs_temperature against zro_tempco keeps 4e-10 of it
# (through the fitted scale factor), the cubic after the DAC against dac_inl 2e-3 on the demo's DAC sweep.
OWN_FORM_SHARE = 1e-6


def look_alikes(fit: Fit, effect: str, discrepancy, designs, alpha: float) -> tuple:
    """The significant shapes at `fit` (`discrepancy`, from `score_probes` at this fit) that `effect` takes whole
    (nothing significant is left of them beyond it) but that differ from it on some rows of this data, by less
    than `SEPARATION_SIGMA` at their size: what the data cannot tell from `effect`. A shape within `effect`'s
    span, or differing from it by less than `OWN_FORM_SHARE` of its information (its own generic form), is not
    one."""
    je = np.asarray(fit.jacobian)[:, :, effect_columns(fit, effect)]
    against = np.concatenate([base_columns(fit), je], axis=-1)
    res = np.asarray(fit.residual_vector)
    cut = alpha / max(len(discrepancy), 1)
    out = []
    for d in discrepancy:
        if not d.significant or d.within:
            continue
        left = score_columns(against, designs[d.probe], res)
        if left.df == 0 or left.p_value < cut:
            continue  # the effect's own shape here, or a shape the effect cannot take
        # The shape at its size beyond the baseline is its fingerprint (score_probes at this fit); what of it the
        # effect cannot take is the difference the data would have to see.
        diff = np.stack([project_out(f[:, None], a)[:, 0] for f, a in zip(d.fingerprint, against)])
        separation = float(np.sum(diff**2))
        if separation >= SEPARATION_SIGMA**2:
            continue  # the data could tell them apart, and chose the effect
        if separation <= OWN_FORM_SHARE * float(np.sum(d.fingerprint**2)):
            continue  # the effect's own form here
        out.append(LookAlike(probe=d.probe, shape=d.shape, sweeps=_sweep_shares(diff, fit.data),
                             separation_sigma=math.sqrt(separation),
                             information_factor=SEPARATION_SIGMA**2 / max(separation, 1e-300)))
    return tuple(out)


def with_library(fit, discrepancy, designs, scores, rejected, max_multiple, alpha):
    """The discrepancies with `library` filled in: which candidate takes the whole of a shape's misfit (the
    shape adds nothing beyond it, at the probes' significance), and why it does not explain it (implausible
    size, refused), or that none does."""
    cut = alpha / max(len(discrepancy), 1)
    return tuple(d if not d.significant or d.within else dataclasses.replace(
        d, library=_library_text(fit, designs[d.probe], d.chi2_explained, scores, rejected, max_multiple, cut))
        for d in discrepancy)


def with_shapes(fit, locations, discrepancy, designs, scores, rejected, max_multiple, alpha) -> tuple:
    """The `Location`s of `locate` with what the lists know of them: the generic shape (probe) that has a
    location's whole misfit (the location is not significant beyond it, or keeps less than `SHAPE_SHARE_LEFT`
    of its chi2), with its coefficient (and its coordinate, naming the flexible description's as confounded with
    it: a shape with fewer degrees of freedom that explains the same misfit is the better description), and which
    library effect has it (`with_library`'s rule)."""
    if not locations:
        return ()
    space = ResidualSpace(fit)
    cut = alpha / max(len(locations), 1)
    out = []
    for loc in locations:
        matched = None
        for d in discrepancy:  # most explanatory first
            if not d.significant or d.within or designs[d.probe].shape[-1] > loc.columns.shape[-1]:
                continue  # a shape with more directions than the flexible description is not the simpler one
            left = space.with_columns(designs[d.probe]).score(loc.columns, loc.pooled)
            if left.p_value >= cut or left.statistic <= SHAPE_SHARE_LEFT * loc.chi2_explained:
                matched = d
                break
        if matched is not None:
            if matched.coordinate != loc.coordinate:  # the shape's coordinate, the flexible one confounded with it
                loc = dataclasses.replace(loc, coordinate=matched.coordinate, confounded_with=tuple(dict.fromkeys(
                    (loc.coordinate, *(c for c in loc.confounded_with if c != matched.coordinate)))))
            loc = dataclasses.replace(loc, shape=matched.shape, probe=matched.probe,
                                      coefficient=matched.coefficient, coefficient_spread=matched.coefficient_spread,
                                      unit=matched.unit, same_shape_as=matched.same_shape_as)
            # a one-column shape along a recorded coordinate (a bias or gain per kelvin, per hour) gives the size in
            # its physical unit; a shape along the input keeps the location's peak in output units and ppm of the
            # sweep's full scale (a cubic's coefficient at the DAC's full scale is not what the sweep shows)
            size = (_probe_size(space, designs[matched.probe], matched, one_device(fit, loc.location))
                    if designs[matched.probe].shape[-1] == 1 and matched.coordinate != "input" else None)
            if size is not None:
                loc = dataclasses.replace(loc, size=size)
        out.append(dataclasses.replace(loc, library=_library_text(fit, loc.columns, loc.chi2_explained, scores,
                                                                  rejected, max_multiple, cut)))
    return tuple(out)


def one_device(fit, location: dict) -> int | None:
    """The index of the one device a location's misfit lives in (`devices` names one), or None."""
    names = location.get("devices", ())
    return fit.devices.index(names[0]) if len(names) == 1 and names[0] in fit.devices else None


def _probe_size(space, columns, probe, device: int | None = None) -> dict | None:
    """The size of a location a one-column generic shape has whole: the shape's coefficient over the lot (the
    inverse-variance mean of the devices'), or in `device` alone where the misfit lives in that one (the lot's
    mean would divide it by the number of devices), with its standard error; None where the data do not
    determine it."""
    sc = space.score(columns)
    if not sc.df:
        return None
    if device is None:
        mean, stderr, _ = lot_mean(sc)  # per device, as the probe is scored; the lot's inverse-variance mean
        value, err, whom = float(mean[0]), float(stderr[0]), ""
    else:
        value = float(sc.coefficients[device][0])
        err = math.sqrt(max(float(sc.covariance[device][0, 0]), 0.0))
        whom = f" in {space.fit.devices[device]}"
    if not (math.isfinite(value) and math.isfinite(err)) or err > SIZE_REL_STDERR * abs(value):
        return None
    return {"value": value, "unit": probe.unit, "stderr": err, "measure": f"coefficient of {probe.probe}{whom}"}


def _library_text(fit, columns, chi2, scores, rejected, max_multiple, cut) -> str:
    reasons = {r.effect: r.kind or r.reason for r in rejected}
    base = base_columns(fit)
    res = np.asarray(fit.residual_vector)
    jac = np.asarray(fit.jacobian)
    parts, plausible = [], False
    for c in scores:
        if not c.testable:
            continue
        je = jac[:, :, effect_columns(fit, c.effect)]
        left = score_columns(np.concatenate([base, je], axis=-1), columns, res)
        if left.p_value < cut and left.statistic > SHAPE_SHARE_LEFT * chi2:
            continue
        if c.effect in reasons:
            parts.append(f"{c.effect} has it but was not confirmed ({reasons[c.effect]})")
        elif c.implied_multiple > max_multiple:
            parts.append(f"{c.effect} has it only at ~{c.implied_multiple:.3g}x its typical size")
        else:
            parts.append(f"{c.effect} has it")
            plausible = True
    if not parts:
        return "no effect in the library has this fingerprint"
    if not plausible:
        return "no effect in the library explains it: " + "; ".join(parts)
    return "; ".join(parts)
