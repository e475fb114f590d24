r"""The missing term's formula: a sparse closed form over a dictionary of terms in the recorded coordinates.

The dictionary holds, for the sweeps a misfit was located on (each alone and together), terms of one coordinate
(`lin`, `sq`, `cube` of its distance from a reference; `abs` and `sign` of the input and of dT/dt; a `step`
between two set points of the input and an odd `hinge`, a gain change beyond an input magnitude (a saturation);
a `step` and an exponential `relax`ation along the time since power-on; a `periodic` error along the input or the
time, at the period the location's spectral scan found),
each as an offset of the output and as a gain (times the model's prediction, written `*model`), the products of
the temperature and the time with the input, the square and cube of the model's output itself (a compression of
the readout or the amplifier), a gain per run, and, on sweeps of different input units together, the same terms
of the model's output in the input's place (`abs(model)`, `lin(temperature_c)*abs(model)`, ...). Each term has
a coefficient per device.

Forward selection with the score test: at each step the term that removes the most chi2 beyond the fit's own
columns and the terms already chosen is kept if its p-value is below `alpha` over the number of terms in the
dictionary (Bonferroni: the family-wise rate of a spurious term is at most `alpha`), up to `MAX_TERMS`. Where
the selection needed several terms to describe the location completely but one term alone does, that one is
kept (greedy selection can take a term that a second one then mends). The
chosen terms are then fitted together; their coefficients come with standard errors from the projected
information, and `share` is the part of the fit's excess chi2 the formula removes.

Canonical names: `basis(coordinate)` with basis in lin, sq, cube, abs, sign, step, hinge, relax, periodic; a gain is
`basis(coordinate)*model`; products are joined by `*` (`lin(temperature_c)*lin(input)`); `per_run*model` is a
gain per run. References: input 0, temperature 25 C, time 0 s, drive frequency the device's mean.
"""


import equinox as eqx
import numpy as np

from .._sweeps.base import AbstractSweep
from . import thresholds
from .descriptions import SIGNED, coordinates, spread
from .locate import PREFERENCE
from .space import ResidualSpace


MAX_TERMS = 3
Z_DECISIVE = 1.96  # a formula of another coordinate replaces the located one's when this many sigma better
MAX_STEP_LEVELS = 64  # a sweep of at most this many set points is scanned for a step along its input
TIE_CHI2, TIE_SHARE = 1.0, 1e-3  # two terms closer than this in the chi2 they remove are a tie
REFERENCE_C = 25.0  # deg C: where a temperature term is zero (the presets' reference temperature)
RELAX_TAUS_S = tuple(60.0 * 2.0**k for k in range(7))  # 60 s to 64 min, a factor 2 apart: an exponential relaxation
_POWERS = {"lin": 1, "sq": 2, "cube": 3}
_UNITS = {"input": None, "temperature_c": "K", "time_s": "s", "drive_freq_hz": "Hz", "order": "point",
          "dtemperature_dt": "(K/s)"}


class Term(eqx.Module):
    """One dictionary term: its canonical `name`, the sweep `kinds` it acts on (the data's; `sweeps` their
    names), how it reads in code (`expression`, in `x` the input, `T` the temperature, `t` the time), whether it
    is a gain, and its changes of the predictions per unit coefficient (sweep -> (device, run, point))."""

    name: str
    kinds: tuple[AbstractSweep, ...]
    expression: str
    gain: bool
    changes: dict[str, np.ndarray]  # per sweep: (device, run, point)
    unit: str
    coordinate: str = ""  # the recorded coordinate it runs along ("" for a gain per run)

    @property
    def sweeps(self) -> tuple[str, ...]:
        return tuple(k.name for k in self.kinds)

    @property
    def label(self) -> str:
        return f"{self.name} [{'+'.join(self.sweeps)}]"


class Formula(eqx.Module):
    """The selected terms with their lot-wide coefficients, standard errors and the share of the excess chi2
    they remove together."""

    terms: tuple[Term, ...]
    coefficients: np.ndarray
    stderr: np.ndarray
    statistic: float
    df: int
    share: float
    dictionary_size: int
    left_statistic: float  # the location's flexible description beyond the formula
    left_df: int
    left_p_value: float
    complete: bool  # nothing significant left of the location beyond the formula (at alpha)
    spread: np.ndarray | None = None  # the devices' standard deviation of each coefficient

    @property
    def description(self) -> str:
        parts = [f"{_fmt(c, s)} {t.unit} x {t.name} on {'+'.join(t.sweeps)}"
                 for t, c, s in zip(self.terms, self.coefficients, self.stderr)]
        text = (f"{' + '.join(parts)} (takes {100 * self.share:.0f} % of the misfit; chosen from "
                f"{self.dictionary_size} terms)")
        if not self.complete:
            text += (f"; it leaves chi2 {self.left_statistic:.4g} (df {self.left_df}, p = {self.left_p_value:.2g}) "
                     "of the located misfit unexplained: no term of the dictionary has its shape")
        return text

    def to_json(self) -> dict:
        return {"terms": [{"name": t.name, "sweeps": list(t.sweeps), "gain": t.gain, "expression": t.expression,
                           "unit": t.unit} for t in self.terms],
                "coefficients": [float(c) for c in self.coefficients], "stderr": [float(s) for s in self.stderr],
                "device_spread": None if self.spread is None else [float(s) for s in self.spread],
                "share": self.share, "statistic": self.statistic, "df": self.df,
                "dictionary_size": self.dictionary_size, "complete": self.complete,
                "left": {"statistic": self.left_statistic, "df": self.left_df, "p": self.left_p_value},
                "description": self.description}


def _fmt(c, s):
    return f"({c:.4g} +/- {s:.2g})"


def _reference(name, x, mask):
    if name == "temperature_c":
        return REFERENCE_C
    if name == "drive_freq_hz":
        return (np.sum(np.where(mask, x, 0.0), axis=(1, 2), keepdims=True)
                / np.maximum(mask.sum(axis=(1, 2), keepdims=True), 1))
    return 0.0


_CODE = {"input": "x", "temperature_c": f"(T - {REFERENCE_C})", "time_s": "t", "drive_freq_hz": "f",
         "order": "n", "dtemperature_dt": "dTdt"}


def dictionary(fit, sweeps, *, step_at: float | None = None, periods: dict | None = None,
               threshold: tuple[str, float] | None = None) -> list:
    """The dictionary of terms on the sweep sets `sweeps` (tuples of sweep names); `periods` {coordinate:
    period}: a periodic error along the input or the time with that period; `threshold` (coordinate, value): a
    step there, as an offset and as a gain (where a threshold scan found one)."""
    terms = []
    for group in sweeps:
        g = _Group(fit, tuple(group), terms)
        for c in sorted(g.names - {"order"}):
            _coordinate_terms(g, c, step_at, periods or {})
            if threshold is not None and threshold[0] == c:
                _threshold_terms(g, c, threshold[1])
        _output_terms(g)
        _product_terms(g)
        _run_terms(g)
    return terms


class _Group:
    """One sweep set of the dictionary: its masks, predictions and coordinates, and `add` (a term, as an offset
    and, with `gain_too`, as a gain) appending to `terms`."""

    def __init__(self, fit, group, terms):
        self.group, self.terms = group, terms
        blocks = {s: fit.data.blocks[s] for s in group}
        self.masks = {s: np.asarray(b.mask) for s, b in blocks.items()}
        self.preds = {s: np.asarray(fit.predictions[s], float) for s in group}
        self.coords = {s: coordinates(b) for s, b in blocks.items()}
        self.names = set.intersection(*(set(c) for c in self.coords.values()))
        self.kinds = {s: fit.data.kind(s) for s in group}
        self.out_unit = self.kinds[group[0]].output_unit

    def values(self, c, *, centred=False):
        x = {s: np.asarray(self.coords[s][c], float) for s in self.group}
        return {s: x[s] - _reference(c, x[s], self.masks[s]) for s in self.group} if centred else x

    def add(self, name, expr, fn, coordinate, *, gain_too=True, offset=True, unit_power=1, unit=None):
        cu = self.out_unit if coordinate == "model" else (_UNITS.get(coordinate)
                                                          or self.kinds[self.group[0]].input_unit)
        per = f"/{cu}" if unit_power == 1 else (f"/{cu}^{unit_power}" if unit_power else "")
        for gain in ((False, True) if gain_too else (False,)):
            if not gain and not offset:
                continue
            changes = {s: np.where(self.masks[s], fn(s) * (self.preds[s] if gain else 1.0), 0.0) for s in self.group}
            self.terms.append(Term(name=name + ("*model" if gain else ""), kinds=tuple(self.kinds.values()),
                                   expression=f"output * ({expr})" if gain else f"({expr})", gain=gain,
                                   changes=changes, unit=unit or ("1" + per if gain else self.out_unit + per),
                                   coordinate="" if coordinate == "order" else coordinate))


def _coordinate_terms(g: _Group, c, step_at, periods):
    """The terms of one coordinate `c`: powers of its distance from the reference, even and sign terms where its
    sign is physics, and the input's and the time's own families."""
    x = g.values(c)
    ref = {s: _reference(c, x[s], g.masks[s]) for s in g.group}
    code = _CODE[c]
    for basis, k in _POWERS.items():
        g.add(f"{basis}({c})", code if k == 1 else f"{code}**{k}", lambda s, k=k: (x[s] - ref[s]) ** k, c,
              gain_too=c != "input", unit_power=k)
    if c in SIGNED:  # where the sign is physics: even and sign-dependent terms
        g.add(f"abs({c})", f"abs({code})", lambda s: np.abs(x[s]), c)
        g.add(f"sign({c})", f"sign({code})", lambda s: np.sign(x[s]), c, unit_power=0)
    if c == "input":
        _input_terms(g, x)
    if c == "time_s":
        _time_terms(g, x, step_at)
    if periods.get(c):
        _periodic_terms(g, c, x, periods[c])


def _threshold_terms(g: _Group, c, at):
    """A step of the output and of the gain where `c` passes `at` (a mode hop at a temperature, a relay at a
    time); along the input of a short sweep every step between set points is in the dictionary already."""
    x = g.values(c)
    ref = _reference(c, x[g.group[0]], g.masks[g.group[0]])
    if not np.isscalar(ref) or (c == "input" and any(
            np.unique(x[s][g.masks[s]]).size <= MAX_STEP_LEVELS for s in g.group)):
        return
    g.add(f"step({c})", f"where({_CODE[c]} >= {at - ref:.8g}, 1, 0)", lambda s: (x[s] >= at).astype(float), c,
          unit_power=0)


def _input_terms(g: _Group, x):
    """Steps and odd hinges between set points of a short sweep."""
    # a step between two set points (a missing code, a range switch): every position of a short sweep, each a
    # term of the dictionary (its Bonferroni count is the scan's look-elsewhere correction)
    levels = np.unique(np.concatenate([x[s][g.masks[s]] for s in g.group]))
    if 3 <= levels.size <= MAX_STEP_LEVELS:
        for at in (levels[1:] + levels[:-1]) / 2.0:
            g.add("step(input)", f"where(x >= {at:.8g}, 1, 0)", lambda s, at=at: (x[s] >= at).astype(float),
                  "input", gain_too=False, unit_power=0)
        # an odd hinge between two set points' magnitudes (a saturation, a clipping, a range switch of the
        # gain): the output gains c per unit of input beyond |x| = k, with the sign of x
        size = np.unique(np.abs(levels[levels != 0]))
        for at in (size[1:] + size[:-1]) / 2.0:
            g.add("hinge(input)", f"sign(x) * maximum(abs(x) - {at:.8g}, 0)",
                  lambda s, at=at: np.sign(x[s]) * np.maximum(np.abs(x[s]) - at, 0.0), "input", gain_too=False)


def _periodic_terms(g: _Group, c, x, period):
    """A periodic error along `c` (the input, the time) at the period its scan found: sin and cos; along the time
    as a gain too (a reference cycling with the lab's air conditioning)."""
    for fn, nm in ((np.sin, "sin"), (np.cos, "cos")):
        g.add(f"periodic({c})", f"{nm}(2 * pi * {_CODE[c]} / {period:.6g})",
              lambda s, fn=fn: fn(2 * np.pi * x[s] / period), c, gain_too=c == "time_s", unit_power=0)


def _time_terms(g: _Group, x, step_at):
    """Exponential relaxations since power-on, and a step at `step_at` (in every run, and in each run alone)."""
    for tau in RELAX_TAUS_S:
        g.add("relax(time_s)", f"exp(-t / {tau:g})", lambda s, tau=tau: np.exp(-x[s] / tau), "time_s", unit_power=0)
    if step_at is None:
        return
    g.add("step(time_s)", f"where(t >= {step_at:.6g}, 1, 0)", lambda s: (x[s] >= step_at).astype(float), "time_s",
          unit_power=0)
    for r in range(min(m.shape[1] for m in g.masks.values())):
        # the same step in one run only (a jump after one power-on)
        g.add("step(time_s)", f"where((run == {r}) & (t >= {step_at:.6g}), 1, 0)",
              lambda s, r=r: ((x[s] >= step_at) & (np.arange(g.masks[s].shape[1]) == r)[None, :, None]
                              ).astype(float), "time_s", unit_power=0)


def _output_terms(g: _Group):
    """Terms of the model's output: its square and cube (a readout's or an amplifier's compression, the same in
    every device in output units, whatever its scale factor); on sweeps of different input units (deg/s, V),
    which share no input axis, the output's even and temperature- or time-weighted terms, one coefficient for
    all."""
    p = g.preds
    for basis, k in (("sq", 2), ("cube", 3)):
        g.add(f"{basis}(model)", f"output**{k}", lambda s, k=k: p[s] ** k, "model", gain_too=False, unit_power=k - 1)
    if len({g.kinds[s].input_unit for s in g.group}) < 2:
        return
    g.add("abs(model)", "abs(output)", lambda s: np.abs(p[s]), "model", gain_too=False, unit_power=0, unit="1")
    for c in ("temperature_c", "time_s"):
        if c in g.names:
            xc = g.values(c, centred=True)
            for basis, fn, code in (("abs", np.abs, "abs(output)"), ("sq", np.square, "output**2")):
                g.add(f"lin({c})*{basis}(model)", f"{_CODE[c]} * {code}", lambda s, xc=xc, fn=fn: xc[s] * fn(p[s]),
                      c, gain_too=False)


def _product_terms(g: _Group):
    """The temperature's and the time's products with the input (a gain, an even term or a bias of the rate's
    sign that drifts)."""
    if "input" not in g.names:
        return
    xin = g.values("input")
    for c in ("temperature_c", "time_s"):
        if c not in g.names:
            continue
        xc = g.values(c, centred=True)
        g.add(f"lin({c})*lin(input)", f"{_CODE[c]} * x", lambda s, xc=xc: xc[s] * xin[s], c, gain_too=False)
        for basis, fn, code in (("abs", np.abs, "abs(x)"), ("sign", np.sign, "sign(x)"), ("sq", np.square, "x**2"),
                                ("cube", lambda v: v**3, "x**3")):
            g.add(f"lin({c})*{basis}(input)", f"{_CODE[c]} * {code}", lambda s, xc=xc, fn=fn: xc[s] * fn(xin[s]), c,
                  gain_too=False)


def _run_terms(g: _Group):
    """A gain per run beyond the first; on sweeps read without a turn-on bias also an offset per run, and an offset
    (each device its own, the same in all its runs: a bench connection's thermal EMF, a device's own offset)."""
    unbiased = all(not g.kinds[s].biased for s in g.group)
    for r in range(1, min(m.shape[1] for m in g.masks.values())):
        g.add(f"per_run({r})", f"run == {r}",
              lambda s, r=r: np.broadcast_to((np.arange(g.masks[s].shape[1]) == r)[None, :, None],
                                             g.masks[s].shape).astype(float), "order", offset=unbiased,
              unit_power=0)
    if unbiased:
        g.add("offset", "1", lambda s: np.ones(g.masks[s].shape), "device", gain_too=False, unit_power=0)


def _location_dictionary(fit, location, space, step_at, periods):
    """The dictionary on `location`'s sweeps (each alone and together) and each term's standardised columns."""
    groups = [(s,) for s in location.located_on]
    if len(location.located_on) > 1:
        groups.append(tuple(location.located_on))
    loc = location.location
    # a location at one value: a step in time (the time step scan's), or a threshold of its coordinate
    threshold = (location.coordinate, loc["at"]) if location.family in thresholds.FAMILIES else None
    periods = dict(periods or {})
    if "period" in loc:  # a periodic location: its own period along its coordinate
        periods[location.coordinate] = loc["period"]
    terms = dictionary(fit, groups, step_at=loc["at"] if location.family == "step" else step_at, periods=periods,
                       threshold=threshold)
    return terms, {id(t): _columns(space, t) for t in terms}


def propose(fit, location, *, step_at=None, periods=None, alpha: float = 0.01, max_terms: int = MAX_TERMS,
            space: ResidualSpace | None = None, allowed=None, prepared=None, simplest: bool = False):
    """A sparse formula for the misfit at `location` (a `Location` of `locate`; `step_at`, `periods`: where its
    scans found a step, and the period along each coordinate scanned), or None when no term of the dictionary is
    significant. The formula is `complete` when the location's flexible description is not significant beyond it.
    `allowed(term, columns)`, where given, says which terms (a `Term` and its standardised columns) the dictionary
    keeps; `prepared`, the dictionary and columns of `space` already built for this location
    (`_location_dictionary`); `simplest`: of the terms of the best one's coordinate and kind that the data cannot
    tell from it, the lowest power (the formula reported; a rival of a candidate is the best description)."""
    space = space or ResidualSpace(fit)
    terms, cols = prepared or _location_dictionary(fit, location, space, step_at, periods)
    if not terms:
        return None
    size = len(terms)  # the family the Bonferroni cut counts, whatever `allowed` keeps
    cut = alpha / size
    if allowed is not None:
        terms = [t for t in terms if allowed(t, cols[id(t)])]
        if not terms:
            return None
    chosen, current = [], space
    between = _mostly_between_devices(fit)
    while len(chosen) < max_terms:
        scored = [(t, current.score(cols[id(t)])) for t in terms if t not in chosen]
        scored = [(t, sc) for t, sc in scored if sc.df and sc.p_value < cut]
        if not scored:
            break
        # terms the data cannot tell apart (within TIE_CHI2 or TIE_SHARE of the best: a gain along the temperature
        # and along the drive frequency it moves, or T x input where the output follows the input) go to the
        # coordinate named first, then to the term listed first (a gain before a product)
        near = _ties(scored, current, cols, alpha if simplest else None)
        best = min(near, key=lambda x: (x[0].coordinate in between, _rank(x[0].coordinate)))
        chosen.append(best[0])
        current = current.with_columns(cols[id(best[0])])
    if not chosen:
        return None
    if len(chosen) > 1 and current.score(location.columns, location.pooled).p_value >= alpha:
        # greedy selection can need a second term to mend its first choice: one term that says it all is simpler
        whole = [(t, sc) for t in terms
                 if (sc := space.score(cols[id(t)])).df and sc.p_value < cut
                 and space.with_columns(cols[id(t)]).score(location.columns, location.pooled).p_value >= alpha]
        if whole:
            top = max(sc.statistic for _, sc in whole)
            near = [(t, sc) for t, sc in whole if sc.statistic >= top - max(TIE_CHI2, TIE_SHARE * top)]
            best = min(near, key=lambda x: (x[0].coordinate in between, _rank(x[0].coordinate)))
            chosen, current = [best[0]], space.with_columns(cols[id(best[0])])
    joint = space.score(np.concatenate([cols[id(t)] for t in chosen], axis=-1))
    coef, err, spread = lot_mean(joint)
    share = min(max(joint.statistic - joint.df, 0.0) / space.excess, 1.0) if space.excess > 0 else 0.0
    left = current.score(location.columns, location.pooled)
    return Formula(terms=tuple(chosen), coefficients=coef, stderr=err, statistic=joint.statistic, df=joint.df,
                   share=share, dictionary_size=size, left_statistic=left.statistic, left_df=left.df,
                   left_p_value=left.p_value, complete=left.p_value >= alpha, spread=spread)


def _ties(scored, current, cols, alpha):
    """The scored terms the data cannot tell from the best, in the dictionary's order: those
    within TIE_CHI2 or TIE_SHARE of it, and (`alpha` not None) those of its coordinate and kind (offset or
    gain) neither of which adds chi2 significant at `alpha` beyond the other, so that the lowest power goes
    first (over a die that moves 1.6 K, a gain linear and one quadratic in the temperature differ by chi2 5
    and neither stands beyond the other: the linear one is the simpler statement of the same data)."""
    best, best_scored = max(scored, key=lambda x: x[1].statistic)
    top = best_scored.statistic

    def interchangeable(t):
        return (alpha is not None and t.coordinate == best.coordinate and t.gain == best.gain
                and current.with_columns(cols[id(t)]).score(cols[id(best)]).p_value >= alpha
                and current.with_columns(cols[id(best)]).score(cols[id(t)]).p_value >= alpha)

    return [(t, sc) for t, sc in scored
            if sc.statistic >= top - max(TIE_CHI2, TIE_SHARE * top) or t is best or interchangeable(t)]


def lot_mean(scored):
    """Each term's lot value from its per-device coefficients: the inverse-variance weighted mean, its standard
    error, and the devices' spread (standard deviation; 0 for one device)."""
    coef, cov = scored.coefficients, scored.covariance
    var = np.stack([np.diag(c) for c in cov])  # (device, k)
    ok = var > 0
    w = np.where(ok, 1.0 / np.where(ok, var, 1.0), 0.0)
    total = np.sum(w, axis=0)
    mean = np.where(total > 0, np.sum(w * coef, axis=0) / np.where(total > 0, total, 1.0), 0.0)
    err = np.where(total > 0, 1.0 / np.sqrt(np.where(total > 0, total, 1.0)), np.inf)
    spread = np.std(coef, axis=0) if coef.shape[0] > 1 else np.zeros(coef.shape[1])
    return mean, err, spread


def _rank(coordinate: str) -> int:
    return PREFERENCE.index(coordinate) if coordinate in PREFERENCE else len(PREFERENCE)


def _mostly_between_devices(fit) -> set:
    """The recorded coordinates that mostly tell devices apart (within a device less than half their lot span)."""
    out = set()
    for sweep in fit.data.sweeps:
        block = fit.data.blocks[sweep]
        mask = np.asarray(block.mask)
        for name, x in coordinates(block).items():
            _, dev, lot = spread(np.where(mask, np.asarray(x, float), 0.0), mask)
            if lot > 0 and dev < 0.5 * lot:
                out.add(name)
    return out


def _columns(space, term: Term) -> np.ndarray:
    return space.columns({s: g[..., None] for s, g in term.changes.items()})


def formula_coordinate(formula: Formula | None) -> str | None:
    """The one recorded coordinate a complete formula runs along (the first factor's for a product), or None."""
    if formula is None or not formula.complete:
        return None
    coords = {t.coordinate for t in formula.terms}
    return coords.pop() if len(coords) == 1 and "" not in coords else None


def term_size(formula: Formula | None, location) -> dict | None:
    """The size of `location`'s misfit as the formula's coefficient, when the formula is one complete term
    along the location's coordinate: {value, unit, stderr} (a gain in ppm per unit of the coordinate)."""
    if formula is None or not formula.complete or len(formula.terms) != 1:
        return None
    t = formula.terms[0]
    if t.coordinate != location.coordinate:
        return None
    if len(location.location.get("devices", ())) == 1:
        return None  # a misfit of one device: the lot's mean coefficient is not its size
    value, err = float(formula.coefficients[0]), float(formula.stderr[0])
    unit = t.unit
    if t.gain:
        value, err = 1e6 * value, 1e6 * err
        unit = "ppm" + unit[1:] if unit.startswith("1") else "ppm"
    return {"value": value, "unit": unit, "stderr": err, "measure": f"coefficient of {t.name}"}


def formula_columns(space: ResidualSpace, formula: Formula) -> np.ndarray:
    """The formula's terms as standardised-residual columns of `space` (device, rows, terms)."""
    return np.concatenate([_columns(space, t) for t in formula.terms], axis=-1)


def propose_along(fit, location, **kw):
    """The formula of `location` (see `propose`) sought in three dictionaries: the terms of the location's own
    coordinate (a curve along the input may be a power of the output itself, a change from run to run a gain per
    run), those of the coordinates the data confound with it, and every term. Of the complete formulas the one
    with the fewest terms is kept, the narrower dictionary unless a wider one's fits decisively better (by
    `Z_DECISIVE` sigma: a bias that follows dT/dt is not a drift in time that fits it less well): the closed form
    agrees with where the flexible descriptions placed the misfit unless a simpler or a better one elsewhere says
    all of it. Without a complete one, the first formula found."""
    own = {location.coordinate} | ({"model"} if location.coordinate == "input" else set()) | (
        {""} if location.coordinate in ("run", "device") else set())
    space = ResidualSpace(fit)  # one dictionary and its columns for the three searches
    prepared = _location_dictionary(fit, location, space, kw.get("step_at"), kw.get("periods"))
    found = []
    for along in (own, own | set(location.confounded_with), None):
        allowed = None if along is None else (lambda t, _, along=along: t.coordinate in along)
        f = propose(fit, location, allowed=allowed, space=space, prepared=prepared, simplest=True, **kw)
        if f is not None:
            found.append(f)
    complete = [f for f in found if f.complete]
    if not complete:
        return found[0] if found else None
    fewest = [f for f in complete if len(f.terms) == min(len(g.terms) for g in complete)]
    best = fewest[0]  # the narrower dictionary, unless a wider one's formula fits decisively better
    for f in fewest[1:]:
        if f.df == best.df and _decisively_better(space, f, best):
            best = f
    return best


def _decisively_better(space: ResidualSpace, a: Formula, b: Formula) -> bool:
    """Whether formula `a` removes decisively more chi2 than `b` (as many coefficients, not nested): the
    difference over its noise, 2 |f_a - f_b| (the two fits' standardised changes), beyond `Z_DECISIVE`; as in
    the rival comparison (`gyrojax._diagnose.rival`)."""
    fa = space.score(formula_columns(space, a)).fingerprint
    fb = space.score(formula_columns(space, b)).fingerprint
    distance = float(np.sqrt(np.sum((fa - fb) ** 2)))
    return distance > 0 and (a.statistic - b.statistic) / (2.0 * distance) > Z_DECISIVE
