"""Plots a reader of a fit or a diagnosis wants (matplotlib; every function takes an optional `ax`).

One style throughout: units on every axis, a legend where more than one thing is drawn, sweep and run
boundaries where points of several are in one panel, and a colour-blind-safe palette (Okabe-Ito).
"""

import math

import matplotlib.pyplot as plt
import numpy as np

from ._diagnose.compare import nonlinearity_residual_ppm


PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000")
"""Okabe-Ito: distinguishable with every common colour-vision deficiency."""

_COORDINATE_LABEL = {"temperature_c": "die temperature (deg C)", "time_s": "time since power-on (s)",
                     "drive_freq_hz": "drive frequency (Hz)", "order": "point in its run (time order)",
                     "run": "run", "input": "input (the sweep's unit)"}


def _ax(ax):
    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 4.0))
    return ax


def _colour(i):
    return PALETTE[i % len(PALETTE)]


def _symlog_if_spread(ax, x):
    """A symmetric log axis for log-spaced inputs (seed 000's rates span 0.1 to 200 deg/s)."""
    x = np.abs(np.asarray(x, float))
    x = x[x > 0]
    if x.size and x.max() / x.min() > 100:
        ax.set_xscale("symlog", linthresh=float(x.min()))


def residuals(fit, sweep: str = "rate_table", *, ax=None, device: int | None = None):
    """Measurement minus model (after each run's bias) in the sweep's output unit, with the +/- 1 sigma noise
    band, against the sweep's input, one colour per device."""
    ax = _ax(ax)
    block = fit.data.blocks[sweep]
    x, m = np.asarray(block.inputs), np.asarray(block.mask)
    res = np.asarray(fit.residuals[sweep]) * np.asarray(block.sigmas)
    sig = np.asarray(block.sigmas)
    devices = range(x.shape[0]) if device is None else [device]
    for d in devices:
        order = np.argsort(x[d][m[d]])
        ax.plot(x[d][m[d]][order], res[d][m[d]][order], ".", ms=4, color=_colour(d), label=fit.devices[d])
    # the noise band of the first device shown (the lot's sigmas are alike)
    d0 = list(devices)[0]
    order = np.argsort(x[d0][m[d0]])
    ax.fill_between(x[d0][m[d0]][order], -sig[d0][m[d0]][order], sig[d0][m[d0]][order], color="0.75", alpha=0.6,
                    zorder=0, label="+/- 1 sigma (noise)")
    ax.axhline(0.0, color="k", lw=0.6)
    _symlog_if_spread(ax, x[m])
    kind = block.kind
    ax.set_xlabel(kind.input_label)
    ax.set_ylabel(f"measurement - model ({kind.output_unit})")
    ax.set_title(f"{sweep}: residuals, chi2_red {fit.chi2_red_total:.3g}", fontsize=9)
    if x.shape[0] <= 8:
        ax.legend(fontsize=7)
    return ax


def ranking(scores, *, alpha: float = 0.01, max_typical_multiple: float = 100.0, ax=None):
    """Candidate effects ranked by their score statistic S on a log axis (longer is more significant; p
    underflows to 0 for strong candidates, S does not), each bar with its own significance threshold (the chi2
    quantile of its df at the Bonferroni level, a black tick); a significant candidate that would need more
    than `max_typical_multiple` times its typical size is coloured apart (the diagnosis does not confirm it);
    candidates the data cannot test are listed apart."""
    from matplotlib.artist import Artist
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from ._numerics.stats import chi2_isf

    ax = _ax(ax)
    testable = [c for c in scores if c.testable]
    untestable = [c for c in scores if not c.testable]
    cut = alpha / max(len(scores), 1)
    floor = 1e-2  # S of 0 (nothing to explain) drawn at the axis' floor
    strength = [max(float(c.statistic), floor) for c in testable]
    limits = [chi2_isf(cut, max(int(c.df), 1)) for c in testable]

    def plausible(c):
        return getattr(c, "implied_multiple", 0.0) <= max_typical_multiple

    colours = [(PALETTE[1] if plausible(c) else PALETTE[4]) if c.p_value < cut else PALETTE[0] for c in testable]
    labels = [c.effect for c in testable][::-1]
    bars = ax.barh(labels, strength[::-1], color=colours[::-1])
    ax.set_xscale("log")
    lo = min(strength + limits + [1.0]) / 3.0
    hi = max(strength + limits) * 3.0
    ax.set_xlim(lo, hi)
    for bar, lim in zip(bars, limits[::-1]):
        y = bar.get_y()
        ax.plot([lim, lim], [y - 0.08, y + bar.get_height() + 0.08], color="k", lw=1.2)
    threshold = f"significance threshold (p = {alpha:g} / {len(scores)})"
    handles: list[Artist] = [Line2D([], [], color="k", lw=1.2, label=threshold)]
    for colour, label in ((PALETTE[1], "significant, at a plausible size"),
                          (PALETTE[4], f"significant only beyond {max_typical_multiple:g}x its typical size"),
                          (PALETTE[0], "not significant")):
        if colour in colours:
            handles.append(Patch(color=colour, label=label))
    span = math.log(hi / lo)
    for bar, c in zip(bars, testable[::-1]):
        size = getattr(c, "implied_multiple", math.inf)
        text = f"p = {c.p_value:.2g}" + (f", ~{size:.3g}x typical" if math.isfinite(size) else "")
        width = bar.get_width()
        inside = math.log(width / lo) > 0.6 * span
        ax.annotate(text, (width, bar.get_y() + bar.get_height() / 2), xytext=(-4 if inside else 4, 0),
                    textcoords="offset points", ha="right" if inside else "left", va="center", fontsize=7,
                    color="white" if inside else "black")
    ax.set_xlabel(f"score statistic S (chi2 units, log scale; S < {floor:g} drawn at {floor:g})"
                  if min(strength, default=1.0) <= floor else "score statistic S (chi2 units, log scale)")
    ax.set_title("which effect is missing? (score test at the baseline, no refit)", fontsize=9)
    if untestable:
        ax.text(1.02, 1.0, "not testable on this data:\n" + "\n".join(c.effect for c in untestable),
                transform=ax.transAxes, fontsize=7, va="top")
    # below the axes, where it covers no bar
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    return ax


def _log_or_plain(ax, values):
    """A log axis for values spanning a decade or more; else a linear one with plain tick labels and limits
    that show the values (a log axis over a tiny range labels every tick in scientific notation)."""
    from matplotlib.ticker import ScalarFormatter

    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size and np.all(v > 0) and v.max() / v.min() >= 10.0:
        ax.set_yscale("log")
        return
    fmt = ScalarFormatter(useOffset=False)
    fmt.set_scientific(False)
    ax.yaxis.set_major_formatter(fmt)
    if v.size:
        top = float(v.max())
        ax.set_ylim(min(0.0, float(v.min()) * 1.1), top * 1.15 if top > 0 else 1.0)


def _wrap(text: str, width: int = 70) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width)) or text


def error_fall(diagnosis, *, axes=None):
    """Step by step: the reduced chi2 (left, with the noise level 1 marked) and the model-vs-measurement
    nonlinearity residual in ppm of full scale (right); the last point says what is left unexplained."""
    own = axes is None
    if own:
        _, axes = plt.subplots(1, 2, figsize=(9.6, 3.6))
    left, right = axes
    labels = ["baseline"] + [f"+ {s.effect}" for s in diagnosis.steps]
    chi2 = [f.chi2_red_total for f in diagnosis.fits]
    nl = [nonlinearity_residual_ppm(f) for f in diagnosis.fits]
    left.plot(labels, chi2, "o-", color=PALETTE[0])
    left.axhline(1.0, color="k", ls="--", lw=0.8, label="noise level (chi2_red = 1)")
    _log_or_plain(left, chi2 + [1.0])
    left.set_ylabel("reduced chi2")
    left.legend(fontsize=7)
    right.plot(labels, nl, "s-", color=PALETTE[1])
    _log_or_plain(right, nl)
    right.set_ylabel("nonlinearity residual (ppm of full scale)")
    left_text = diagnosis.verdict
    if diagnosis.remaining:
        left_text += f": {diagnosis.remaining[0].shape} is left ({100 * diagnosis.remaining[0].share:.0f} %)"
    # wrapped: a long verdict must not run off the figure
    left.set_title(_wrap(f"watch the error fall ({left_text})", 60), fontsize=8)
    for a in axes:
        a.tick_params(axis="x", labelsize=7, rotation=15)
        a.set_xlabel("diagnosis step (effect added)")
    if own:
        left.figure.tight_layout()
    return axes


def _boundaries(ax, data, fingerprint_len):
    """Vertical lines and labels at the sweep and run boundaries of a device's residual vector."""
    k = 0
    for sweep in data.sweeps:
        shape = data.blocks[sweep].inputs.shape
        runs, points = int(shape[1]), int(shape[2])
        ax.axvline(k - 0.5, color="k", lw=0.8)
        ax.text(k, 1.0, sweep, transform=ax.get_xaxis_transform(), fontsize=7, va="bottom")
        for r in range(1, runs):
            ax.axvline(k + r * points - 0.5, color="0.6", lw=0.5, ls=":")
        k += runs * points
    ax.set_xlim(-1, min(k, fingerprint_len))


def fingerprints(diagnosis, *, top: int = 3, device: int | None = None, axes=None):
    """The baseline's residual against the predicted residual change of the top candidates, one panel per
    device (sweeps and runs marked): the candidate that traces the residual is the missing effect."""
    fit = diagnosis.baseline
    res = np.asarray(fit.residual_vector)
    devices = list(range(res.shape[0])) if device is None else [device]
    if axes is None:
        _, axes = plt.subplots(len(devices), 1, figsize=(9.6, 2.4 * len(devices)), squeeze=False)
        axes = axes[:, 0]
    rows = sum(int(np.prod(fit.data.blocks[s].inputs.shape[1:])) for s in fit.data.sweeps)
    # a device's real points: a run shorter than the longest is padded, and padding is not data
    real = np.concatenate([np.asarray(fit.data.blocks[s].mask).reshape(res.shape[0], -1) for s in fit.data.sweeps],
                          axis=1)
    # one look per candidate: a wide pale line under a dashed one under a dotted one with markers, so that a
    # fingerprint lying on another stays visible
    looks = ({"lw": 3.0, "ls": "-", "alpha": 0.55}, {"lw": 1.4, "ls": "--"}, {"lw": 1.0, "ls": ":", "marker": "x",
                                                                                "ms": 3})
    for ax, d in zip(axes, devices):
        keep = real[d][:rows]
        x = np.arange(rows)
        ax.plot(x[keep], res[d][:rows][keep], ".", color="0.3", ms=3, label=f"baseline residual ({fit.devices[d]})")
        for i, c in enumerate([c for c in diagnosis.ranking if c.testable][:top]):
            y = np.where(keep, np.asarray(c.fingerprint[d][:rows], dtype=float), np.nan)
            ax.plot(x, y, color=_colour(i), label=f"{c.effect} (predicted)", **looks[i % len(looks)])
        _boundaries(ax, fit.data, rows)
        ax.set_ylabel("standardised\nresidual")
        ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the panel, over no point
    axes[-1].set_xlabel("point (sweeps in order; dotted: run boundaries; points a run lacks are left out)")
    return axes


def discrepancy(diagnosis, *, which: int = 0, final: bool = True, ax=None):
    """Where the misfit lives: the standardised residual of the final fit (or the baseline) against the
    coordinate of its leading discrepancy, one colour per sweep, with the generic shape fitted to it (crosses).
    Along the input each sweep's input is divided by its largest |input|, so sweeps in different units share
    the axis."""
    ax = _ax(ax)
    found = diagnosis.remaining if final else tuple(d for d in diagnosis.baseline_discrepancy
                                                    if d.significant and not d.within)
    fit = diagnosis.final if final else diagnosis.baseline
    stage = "left after the diagnosis" if final else "at the baseline"
    if not found:
        ax.text(0.5, 0.5, f"{stage}: no generic shape explains a significant part of the misfit", ha="center",
                va="center", transform=ax.transAxes, fontsize=9)
        ax.set_axis_off()
        return ax
    d = found[which]
    field = {"temperature_c": "temperatures", "time_s": "times", "drive_freq_hz": "drive_freqs",
             "order": "order", "input": "inputs"}.get(d.coordinate)
    row = 0
    for i, sweep in enumerate(fit.data.sweeps):
        block = fit.data.blocks[sweep]
        n = int(np.prod(block.inputs.shape[1:]))
        mask = np.asarray(block.mask).reshape(len(fit.devices), -1)
        if d.coordinate == "run":
            coord = np.broadcast_to(np.arange(block.inputs.shape[1])[None, :, None], block.inputs.shape)
        elif field is None:
            raise ValueError(f"discrepancy on an unknown coordinate {d.coordinate!r}.")
        else:
            coord = getattr(block, field, None)
        if coord is None:
            row += n
            continue
        coord = np.asarray(coord, float).reshape(len(fit.devices), -1)
        if d.coordinate == "input":
            span = np.max(np.abs(coord[mask])) if mask.any() else 1.0
            coord = coord / (span if span > 0 else 1.0)
        r = np.asarray(fit.residual_vector)[:, row:row + n]
        fp = d.fingerprint[:, row:row + n]
        if sweep in {name for name, _ in d.sweeps} and np.all(np.isfinite(coord[mask])):
            ax.plot(coord[mask], r[mask], ".", ms=4, color=_colour(i), alpha=0.7, label=f"{sweep}: residual")
            ax.plot(coord[mask], fp[mask], "x", ms=4, color=_colour(i), label=f"{sweep}: the shape, fitted")
        row += n
    ax.axhline(0.0, color="k", lw=0.6)
    xlabel = ("input / largest |input| of its sweep" if d.coordinate == "input"
              else _COORDINATE_LABEL.get(d.coordinate, d.coordinate))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("standardised residual (sigma)")
    ax.set_title(f"{stage}: {100 * d.share:.0f} % of the misfit is {d.shape}", fontsize=8)
    ax.legend(fontsize=6)
    return ax


def nonlinearity_curve(rates_dps, errors_ppm, *, ax=None, label=None):
    """A seed 000 Fig. 10-style curve: scale-factor nonlinear error (ppm) against rate."""
    ax = _ax(ax)
    ax.plot(rates_dps, errors_ppm, "o-", ms=3, label=label)
    ax.set_xscale("symlog", linthresh=0.1)
    ax.set_xlabel("rate (deg/s)")
    ax.set_ylabel("nonlinear error (ppm)")
    if label:
        ax.legend()
    return ax


def frequency_response(freqs_hz, amplitude, *, reference=None, ax=None, label=None):
    """VCF (or rate) frequency response amplitude, normalised to its first point, with the -3 dB line."""
    ax = _ax(ax)
    a = np.asarray(amplitude) / np.asarray(amplitude)[0]
    ax.semilogx(freqs_hz, 20 * np.log10(a), label=label)
    if reference is not None:
        ax.semilogx(freqs_hz, 20 * np.log10(np.asarray(reference) / np.asarray(reference)[0]), "--", label="model")
    ax.axhline(-3.0, color="k", lw=0.6, label="-3 dB")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("gain (dB)")
    ax.legend()
    return ax


def save(fig_or_ax, path):
    """Save atomically (PNG)."""
    import io

    from matplotlib.figure import Figure

    from ._data.io import atomic_write_bytes

    if isinstance(fig_or_ax, np.ndarray):
        fig_or_ax = fig_or_ax.flat[0]
    fig = fig_or_ax.figure if hasattr(fig_or_ax, "figure") and not isinstance(fig_or_ax, Figure) else fig_or_ax
    buf = io.BytesIO()
    fig.tight_layout()
    # "tight": titles, legends and notes placed outside the axes are kept, not clipped
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
