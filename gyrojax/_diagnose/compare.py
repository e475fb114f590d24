r"""`compare`: the model against the measurements, and where it fails.

The standardised residuals of a fit (measurement minus model, after each run's bias, over the point's
standard uncertainty) are, if the model is right, independent and of unit variance. `compare` tests that,
point by point in each sweep ordered by its input, and says where the misfit sits:

- **misfit**: chi2 per sweep, device, run and input band (|input| in thirds of the sweep's range, each sign
  apart), each with its share of the lot's chi2 in excess of the point count;
- **runs**: the Wald-Wolfowitz runs test on the signs of the residuals ordered by input, per (device, run),
  pooled per sweep by Stouffer's sum (one-sided: too few runs, i.e. residuals that cluster by sign, are what a
  missing smooth effect leaves);
- **shape**: the residuals projected on orthonormal polynomials of degree 1, 2 and 3 in the input over each
  run's points (a trend, an even bow, an odd cubic); each projection is N(0, 1) for pure noise, so their sums
  of squares over the sweep's runs are chi2-distributed (conservative: the fit's gains already took up part of
  the linear one);
- **symmetry**: where a run's inputs come in +/- pairs, the odd and even parts (r(x) -+ r(-x)) / sqrt(2) of
  the residual, each chi2 over the pairs: an odd misfit (an S-curve, a cubic) or an even one (a bow, drift
  during an ordered sweep) — seed 000's symmetry argument: a memoryless carrier nonlinearity is odd; and the
  residual projected on a gain that differs between positive and negative inputs (K+ vs K-);
- **every other recorded coordinate**: the residuals projected, run by run, on orthonormal polynomials of
  degree 1 and 2 in the die temperature (`temperature_c`), the time since power-on (`time_s`), the drive
  frequency (`drive_freq_hz`) and the point's order in its run (`order`), and a runs test in time order;
- **confounding**: coordinates that rise or fall together in every run of a sweep (the input swept in one
  direction while the die warms up) cannot be told apart there; the comparison says so and what would separate
  them.

A finding is flagged when its p-value is below `alpha` over the number of tests made (Bonferroni), so pure
noise flags nothing at the family-wise rate `alpha`.
"""

import dataclasses
import math
from typing import ClassVar

import equinox as eqx
import numpy as np

from .._identify import Fit
from .._numerics.stats import chi2_sf
from .confounding import COORDINATE_WORDS, Confounding, confounded_coordinates, confounded_groups


def _normal_cdf(z):
    # Python's erfc, not jax.scipy's ndtr: a scalar on the host, no compiled programs.
    return 0.5 * math.erfc(-float(z) / math.sqrt(2.0))


def runs_test(signs) -> tuple[int, float, float]:
    """Wald-Wolfowitz runs test of a sequence of signs (+1 / -1, zeros dropped): (runs, expected runs, z).
    z < 0: fewer runs than independent signs would give (the residuals cluster)."""
    s = np.asarray(signs)
    s = s[s != 0]
    n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
    n = n1 + n2
    runs = int(1 + np.sum(s[1:] != s[:-1])) if n else 0
    if n1 == 0 or n2 == 0:
        return runs, float(runs), 0.0
    mean = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n**2 * (n - 1.0))
    return runs, mean, (runs - mean) / math.sqrt(var) if var > 0 else 0.0


def shape_components(x, r, degree: int = 3):
    """Projections of residuals `r` on polynomials of degree 1..`degree` in `x` made orthonormal over these
    points (and orthogonal to a constant, which the run bias took): N(0, 1) each for unit-variance noise."""
    x = np.asarray(x, float)
    if len(x) <= degree + 1:
        return np.full(degree, np.nan)
    span = np.max(np.abs(x))
    q, rr = np.linalg.qr(np.vander(x / span if span > 0 else x, degree + 1, increasing=True))
    ok = np.abs(np.diag(rr)) > 1e-12 * np.max(np.abs(np.diag(rr)))
    out = q.T @ np.asarray(r, float)
    return np.where(ok, out, np.nan)[1:]


def symmetric_parts(x, r, rtol: float = 1e-9):
    """The odd and even parts (r(x) - r(-x)) / sqrt(2), (r(x) + r(-x)) / sqrt(2) over the +/- pairs of `x`."""
    x, r = np.asarray(x, float), np.asarray(r, float)
    tol = rtol * (np.max(np.abs(x)) if len(x) else 0.0)
    pos = np.flatnonzero(x > tol)
    odd, even = [], []
    for i in pos:
        j = np.flatnonzero(np.abs(x + x[i]) <= tol)
        if j.size:
            odd.append((r[i] - r[j[0]]) / math.sqrt(2.0))
            even.append((r[i] + r[j[0]]) / math.sqrt(2.0))
    return np.asarray(odd), np.asarray(even)


class Misfit(eqx.Module):
    """chi2 of a group of points (a sweep, a device, a run, an input band) and its share of the lot's excess."""

    label: str
    points: int
    chi2: float
    share: float  # of sum(max(chi2 - points, 0)) over the groups of its kind

    @property
    def chi2_per_point(self) -> float:
        return self.chi2 / self.points if self.points else float("nan")


class Finding(eqx.Module):
    """One structure test of one sweep along one coordinate: its statistic, degrees of freedom (runs: the
    number of runs tested), p-value, and whether it is flagged (p below alpha / number of tests)."""

    sweep: str
    test: str  # "runs", "trend", "even bow", "odd cubic", "odd part", "even part", "sign gain", "linear", ...
    statistic: float
    df: int
    p_value: float
    flagged: bool
    meaning: str
    coordinate: str = "input"  # a data column (input, temperature_c, time_s, drive_freq_hz) or "order"

    @property
    def label(self) -> str:
        return f"{self.sweep} {self.test}" if self.coordinate == "input" else \
            f"{self.sweep} {self.test} in {self.coordinate}"


_MEANING = {
    "runs": "residuals cluster by sign along the input: a smooth effect is missing",
    "trend": "a residual slope: a gain the model gets wrong (partly taken up by the fit's gains)",
    "even bow": "an even (quadratic) shape: a bow, or drift during an ordered sweep",
    "odd cubic": "an odd cubic: a nonlinearity growing with input (INL S-curve, comb gap, AGC sag)",
    "odd part": "the residual is odd in the input: a memoryless carrier nonlinearity (seed 000)",
    "even part": "the residual is even in the input: a DC-path effect, memory, or drift in sweep order",
    "sign gain": "the gain differs for positive and negative inputs (K+ vs K-): memory or a DC-path effect",
}

def _coordinate_meaning(test, coordinate):
    what = COORDINATE_WORDS[coordinate]
    if test == "runs":
        return "residuals cluster by sign in time order: a slow drift during the run"
    if test == "linear":
        return f"the residual changes linearly with {what}: a bias or gain that depends on it"
    return f"the residual bends with {what}: a curved dependence on it"


def _projections(x, r, degree):
    """Projections of `r` on polynomials of degree 1..`degree` in `x`, orthonormal over the points and
    orthogonal to a constant (NaN where `x` does not vary enough)."""
    x = np.asarray(x, float)
    if len(x) <= degree + 1 or not np.all(np.isfinite(x)) or np.ptp(x) == 0:
        return np.full(degree, np.nan)
    return shape_components(x - np.mean(x), r, degree)


def sign_gain_component(x, r):
    """Projection of `r` on a gain for positive inputs only, made orthogonal to a constant and to the input:
    N(0, 1) for unit-variance noise; NaN without inputs of both signs."""
    x = np.asarray(x, float)
    if np.sum(x > 0) < 2 or np.sum(x < 0) < 2:
        return np.nan
    basis = np.stack([np.ones_like(x), x, np.where(x > 0, x, 0.0)], axis=1)
    q, rr = np.linalg.qr(basis / np.max(np.abs(basis), axis=0))
    if abs(rr[2, 2]) < 1e-9:
        return np.nan
    return float(q[:, 2] @ np.asarray(r, float))


class Comparison(eqx.Module):
    """The solution of `compare`: misfit by sweep, device, run and input band, and the structure tests."""

    kind: ClassVar[str] = "comparison"  # the result's name for output formats (gyrojax.io.AbstractResult)

    by_sweep: tuple[Misfit, ...]
    by_device: tuple[Misfit, ...]
    by_run: tuple[Misfit, ...]  # label "sweep device run"
    by_band: tuple[Misfit, ...]  # label "sweep band"
    findings: tuple[Finding, ...]
    chi2: float
    points: int
    alpha: float
    confounded: tuple[Confounding, ...] = ()  # per sweep and pair of coordinates

    @property
    def p_value(self) -> float:
        """Of the chi2 against the point count (conservative: the fit's parameters took some of it)."""
        return chi2_sf(self.chi2, self.points)

    @property
    def fails(self) -> bool:
        """The chi2 is above what noise gives at `alpha`: the misfit shares say where."""
        return self.p_value < self.alpha

    @property
    def flagged(self) -> tuple:
        return tuple(f for f in self.findings if f.flagged)

    def summary(self, top: int = 3, top_findings: int = 6) -> str:
        lines = [f"model against measurement: chi2 {self.chi2:.4g} over {self.points} points "
                 f"({self.chi2 / max(self.points, 1):.3g} per point, p = {self.p_value:.2g})"]
        if not self.fails:
            lines[0] += ": at the noise level"
        for title, groups in (("sweep", self.by_sweep), ("device", self.by_device), ("run", self.by_run),
                              ("input band", self.by_band)) if self.fails else ():
            worst = sorted((g for g in groups if g.share > 0), key=lambda g: -g.share)[:top]
            if worst:
                lines.append(f"  misfit by {title}: " + "; ".join(
                    f"{g.label} {100 * g.share:.0f} % ({g.chi2_per_point:.3g}/point)" for g in worst))
        if self.flagged:
            lines.append(f"  structure in the residuals (p < {self.alpha:g} / {len(self.findings)} tests):")
            ranked = sorted(self.flagged, key=lambda f: f.p_value)
            for f in ranked[:top_findings]:
                lines.append(f"    {f.label}: p = {f.p_value:.2g} ({f.meaning})")
            if len(ranked) > top_findings:
                lines.append(f"    ... and {len(ranked) - top_findings} more: "
                             + ", ".join(f.label for f in ranked[top_findings:]))
        else:
            coords = sorted({f.coordinate for f in self.findings})
            lines.append(f"  no structure in the residuals along {', '.join(coords) or 'the input'} (runs, "
                         f"trend, bow, cubic, odd/even parts, K+/K-; family-wise alpha {self.alpha:g})")
        if self.confounded and (self.flagged or self.fails):
            lines.append("  confounded on this data:")
            lines += [f"    {text}" for text in confounded_groups(self.confounded)]
        return "\n".join(lines)

    def to_json(self) -> dict:
        def groups(gs):
            return [{"label": g.label, "points": g.points, "chi2": g.chi2, "share": g.share} for g in gs]

        return {"chi2": self.chi2, "points": self.points, "p_value": self.p_value, "fails": self.fails,
                "alpha": self.alpha,
                "by_sweep": groups(self.by_sweep), "by_device": groups(self.by_device),
                "by_run": groups(self.by_run), "by_band": groups(self.by_band),
                "findings": [dataclasses.asdict(f) for f in self.findings],
                "confounded": [dataclasses.asdict(c) for c in self.confounded]}


def _shares(items):
    excess = [max(c - n, 0.0) for _, n, c in items]
    total = sum(excess)
    return tuple(Misfit(label=label, points=n, chi2=c, share=e / total if total > 0 else 0.0)
                 for (label, n, c), e in zip(items, excess))


_BANDS = ((0.0, 1.0 / 3.0, "low"), (1.0 / 3.0, 2.0 / 3.0, "mid"), (2.0 / 3.0, np.inf, "high"))


def _sweep_tests(sweep, zs, comps, odd, even, signs, along, time_zs, x_all, coords, m_all) -> list:
    """The tests of one sweep's residuals from its runs' statistics: runs along the input (`zs`), trend, bow and
    cubic (`comps`), odd and even parts, the sign gain, the linear and quadratic parts along each other
    coordinate (`along`), and runs in time order where it is not the input's: (sweep, test, statistic, df, p,
    coordinate) each."""
    tests = []
    if zs:
        z = float(np.sum(zs) / math.sqrt(len(zs)))
        tests.append((sweep, "runs", z, len(zs), _normal_cdf(z), "input"))
    if comps:
        c = np.asarray(comps)
        for i, name in enumerate(("trend", "even bow", "odd cubic")):
            col = c[:, i][np.isfinite(c[:, i])]
            if col.size:
                s = float(np.sum(col**2))
                tests.append((sweep, name, s, int(col.size), chi2_sf(s, col.size), "input"))
    odd_all, even_all = np.concatenate(odd) if odd else np.zeros(0), np.concatenate(even) if even else np.zeros(0)
    if odd_all.size >= 2:
        # The even part of a biased sweep lost one direction per run to the bias: conservative.
        for name, part in (("odd part", odd_all), ("even part", even_all)):
            s = float(np.sum(part**2))
            tests.append((sweep, name, s, int(part.size), chi2_sf(s, part.size), "input"))
    sg = np.asarray(signs, float)
    sg = sg[np.isfinite(sg)]
    if sg.size:
        s = float(np.sum(sg**2))
        tests.append((sweep, "sign gain", s, int(sg.size), chi2_sf(s, sg.size), "input"))
    for name, (proj, _) in along.items():
        c = np.asarray(proj, float).reshape(-1, 2)
        for i, test in enumerate(("linear", "quadratic")):
            col = c[:, i][np.isfinite(c[:, i])]
            if col.size:
                s = float(np.sum(col**2))
                tests.append((sweep, test, s, int(col.size), chi2_sf(s, col.size), name))
    if time_zs and not _same_order(x_all, coords.get("order"), m_all):
        z = float(np.sum(time_zs) / math.sqrt(len(time_zs)))
        tests.append((sweep, "runs", z, len(time_zs), _normal_cdf(z), "order"))
    return tests


def compare_residuals(residuals, inputs, masks, *, devices, run_ids=None, coordinates=None,
                      alpha: float = 0.01) -> Comparison:
    """`compare` on arrays: `residuals`, `inputs`, `masks` are dicts sweep -> (device, run, point)
    standardised residuals, inputs and real-point masks; `devices` the device names; `run_ids` optional
    dict sweep -> per-device run ids (default: run indices); `coordinates` optional dict sweep -> {name:
    (device, run, point)} of the other recorded coordinates (names of `COORDINATES`; NaN: not recorded)."""
    by_sweep, by_device, by_run, by_band = [], {}, [], []
    tests = []  # (sweep, test, statistic, df, p, coordinate)
    confounded = []
    for sweep in residuals:
        r_all, x_all, m_all = (np.asarray(a[sweep]) for a in (residuals, inputs, masks))
        r_all = np.where(m_all, r_all, 0.0)
        by_sweep.append((sweep, int(m_all.sum()), float(np.sum(r_all**2))))
        span = np.max(np.where(m_all, np.abs(x_all), 0.0)) if m_all.any() else 0.0
        band_chi2 = {}
        zs, comps, odd, even, signs = [], [], [], [], []
        coords = {name: np.asarray(v) for name, v in ((coordinates or {}).get(sweep) or {}).items()}
        along = {name: ([], []) for name in coords if name != "order"}  # name -> (projections, runs z)
        time_zs = []
        for d in range(r_all.shape[0]):
            n_d, c_d = by_device.get(devices[d], (0, 0.0))
            by_device[devices[d]] = (n_d + int(m_all[d].sum()), c_d + float(np.sum(r_all[d] ** 2)))
            for k in range(r_all.shape[1]):
                m = m_all[d, k]
                if not m.any():
                    continue
                x, r = x_all[d, k][m], r_all[d, k][m]
                run = run_ids[sweep][d][k] if run_ids is not None else k
                by_run.append((f"{sweep} {devices[d]} run {run}", int(m.sum()), float(np.sum(r**2))))
                rel = np.abs(x) / span if span > 0 else np.zeros_like(x)
                for lo, hi, name in _BANDS:
                    for sign, sname in ((x < 0, "-"), (x >= 0, "+")):
                        sel = (rel >= lo) & (rel < hi) & sign
                        key = f"{sweep} {name} |input| ({sname})"
                        n0, c0 = band_chi2.get(key, (0, 0.0))
                        band_chi2[key] = (n0 + int(sel.sum()), c0 + float(np.sum(r[sel] ** 2)))
                order = np.argsort(x, kind="stable")
                if len(x) >= 4:
                    zs.append(runs_test(np.sign(r[order]))[2])
                comps.append(shape_components(x, r))
                o, e = symmetric_parts(x, r)
                odd.append(o)
                even.append(e)
                signs.append(sign_gain_component(x, r))
                for name, (proj, _) in along.items():
                    proj.append(_projections(coords[name][d, k][m], r, 2))
                if "order" in coords and len(x) >= 4:
                    time_zs.append(runs_test(np.sign(r[np.argsort(coords["order"][d, k][m], kind="stable")]))[2])
        by_band += [(k, n, c) for k, (n, c) in band_chi2.items() if n]
        tests += _sweep_tests(sweep, zs, comps, odd, even, signs, along, time_zs, x_all, coords, m_all)
        confounded += confounded_coordinates({"input": x_all, **coords}, m_all, sweep)
    cut = alpha / max(len(tests), 1)
    findings = tuple(Finding(sweep=s, test=t, statistic=stat, df=df, p_value=p, flagged=p < cut,
                             meaning=_MEANING[t] if coord == "input" else _coordinate_meaning(t, coord),
                             coordinate=coord)
                     for s, t, stat, df, p, coord in tests)
    total_n = sum(n for _, n, _ in by_sweep)
    total_c = sum(c for _, _, c in by_sweep)
    return Comparison(by_sweep=_shares(by_sweep),
                      by_device=_shares([(k, n, c) for k, (n, c) in by_device.items()]),
                      by_run=_shares(by_run), by_band=_shares(by_band), findings=findings, chi2=total_c,
                      points=total_n, alpha=alpha, confounded=tuple(confounded))


def _same_order(inputs, order, mask):
    """Whether time order is input order in every run (then the runs test in time order repeats the one
    along the input)."""
    if order is None:
        return True
    for d, k in np.ndindex(mask.shape[:2]):
        m = mask[d, k]
        if m.sum() and not np.array_equal(np.argsort(inputs[d, k][m], kind="stable"),
                                          np.argsort(order[d, k][m], kind="stable")):
            return False
    return True


def compare(fit: Fit, *, alpha: float = 0.01, residuals: dict | None = None) -> Comparison:
    """Compare a fitted model with its data: where the misfit sits (sweep, device, run, input band) and
    whether the residuals have structure along the input (runs, trend, bow, cubic, odd and even parts).

    **Arguments:**

    - `fit`: a `gyrojax.Fit` (from `identify`, or a `Diagnosis`'s `baseline` / `final`).
    - `alpha`: family-wise false-alarm rate of the structure tests (Bonferroni over all of them).
    - `residuals`: sweep -> (device, run, point) standardised residuals read in place of the fit's (the fit's with
      a description of a misfit taken out).

    **Returns:** a `Comparison` (`summary()`, `to_json()`, `flagged`).
    """
    data = fit.data
    residuals = {s: np.asarray((fit.residuals if residuals is None else residuals)[s]) for s in data.sweeps}
    inputs = {s: np.asarray(data.blocks[s].inputs) for s in data.sweeps}
    masks = {s: np.asarray(data.blocks[s].mask) for s in data.sweeps}
    return compare_residuals(residuals, inputs, masks, devices=data.devices,
                             run_ids={s: data.run_ids(s) for s in data.sweeps},
                             coordinates={s: recorded_coordinates(data.blocks[s]) for s in data.sweeps}, alpha=alpha)


def nonlinearity_residual_ppm(fit) -> float:
    """The worst model-vs-measurement residual of the rate-table points, as ppm of full scale
    (max |y - f - bias| / (|SF| max |rate|)) of a `gyrojax.Fit`: the scale-factor nonlinearity the model leaves
    unexplained."""
    if "rate_table" not in fit.residuals:
        return float("nan")
    block = fit.data.blocks["rate_table"]
    raw = np.abs(np.asarray(fit.residuals["rate_table"]) * np.asarray(block.sigmas))
    full = np.abs(np.asarray(fit.scale_factor))[:, None, None] * np.max(
        np.where(np.asarray(block.mask), np.abs(np.asarray(block.inputs)), 0.0), axis=(1, 2), keepdims=True)
    return float(np.max(np.where(np.asarray(block.mask), raw / full, 0.0)) * 1e6)


def recorded_coordinates(block) -> dict:
    """The coordinates of a sweep block other than the input that the data record (all real points given),
    as dict name -> (device, run, point): `temperature_c`, `time_s`, `drive_freq_hz`, and `order`."""
    mask = np.asarray(block.mask)
    out = {}
    for name, field in (("temperature_c", "temperatures"), ("time_s", "times"), ("drive_freq_hz", "drive_freqs"),
                        ("order", "order")):
        values = getattr(block, field, None)
        if values is None:
            continue
        values = np.asarray(values, float)
        if mask.any() and np.all(np.isfinite(values[mask])):
            out[name] = values
    if "order" in out and not {"temperature_c", "time_s"} & set(out):
        # Neither time nor temperature recorded (a bench sweep such as the DAC's): the file order is not known
        # to be the time order, and nothing drifts along it in the model.
        del out["order"]
    return out
