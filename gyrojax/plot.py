"""Plots a reader of a fit or a diagnosis wants (matplotlib; every function takes an optional `ax`).

One style throughout: units on every axis, a legend where more than one thing is drawn, sweep and run
boundaries where points of several are in one panel, and a colour-blind-safe palette (Okabe-Ito).
"""

import math

import matplotlib.pyplot as plt
import numpy as np

from ._compare import nonlinearity_residual_ppm
from ._sweeps.registry import sweep_kind


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
    kind = sweep_kind(sweep)
    ax.set_xlabel(kind.input_label)
    ax.set_ylabel(f"measurement - model ({kind.output_unit})")
    ax.set_title(f"{sweep}: residuals, chi2_red {fit.chi2_red_total:.3g}", fontsize=9)
    if x.shape[0] <= 8:
        ax.legend(fontsize=7)
    return ax


def ranking(scores, *, alpha: float = 0.01, max_typical_multiple: float = 100.0, ax=None):
    """Candidate effects ranked by the p-value of their score test (-log10 p: longer is more significant),
    the Bonferroni threshold drawn; a significant candidate that would need more than `max_typical_multiple`
    times its typical size is coloured apart (the diagnosis does not confirm it); candidates the data cannot
    test are listed apart."""
    ax = _ax(ax)
    testable = [c for c in scores if c.testable]
    untestable = [c for c in scores if not c.testable]
    cut = alpha / max(len(scores), 1)
    strength = [min(-math.log10(max(c.p_value, 1e-300)), 300.0) for c in testable]

    def plausible(c):
        return getattr(c, "implied_multiple", 0.0) <= max_typical_multiple

    colours = [(PALETTE[1] if plausible(c) else PALETTE[4]) if c.p_value < cut else PALETTE[0] for c in testable]
    bars = ax.barh([c.effect for c in testable][::-1], strength[::-1], color=colours[::-1])
    ax.axvline(-math.log10(cut), color="k", ls="--", lw=0.8, label=f"significant: p < {alpha:g} / {len(scores)}")
    # which colour means what, for the classes present
    from matplotlib.patches import Patch

    handles = [ax.get_legend_handles_labels()[0][0]]
    for colour, label in ((PALETTE[1], "significant, at a plausible size"),
                          (PALETTE[4], f"significant only beyond {max_typical_multiple:g}x its typical size"),
                          (PALETTE[0], "not significant")):
        if colour in colours:
            handles.append(Patch(color=colour, label=label))
    # p underflows for strong candidates: the score S and the size it implies tell them apart
    for bar, c in zip(bars, testable[::-1]):
        size = getattr(c, "implied_multiple", math.inf)
        text = f"S = {c.statistic:.3g}" + (f", ~{size:.3g}x typical" if math.isfinite(size) else "")
        inside = bar.get_width() > 0.5 * ax.get_xlim()[1]
        ax.annotate(text, (bar.get_width(), bar.get_y() + bar.get_height() / 2), xytext=(-4 if inside else 4, 0),
                    textcoords="offset points", ha="right" if inside else "left", va="center", fontsize=7,
                    color="white" if inside else "black")
    capped = any(s >= 300.0 for s in strength)
    ax.set_xlabel("-log10 p of the score test (no refit)" + ("; p < 1e-300 drawn at 300" if capped else ""))
    ax.set_title("which effect is missing?", fontsize=9)
    if untestable:
        ax.text(1.02, 0.0, "not testable on this data:\n" + "\n".join(c.effect for c in untestable),
                transform=ax.transAxes, fontsize=7, va="bottom")
    ax.legend(handles=handles, fontsize=7, loc="lower right")
    return ax


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
    left.semilogy(labels, chi2, "o-", color=PALETTE[0])
    left.axhline(1.0, color="k", ls="--", lw=0.8, label="noise level (chi2_red = 1)")
    left.set_ylabel("reduced chi2")
    left.legend(fontsize=7)
    right.semilogy(labels, nl, "s-", color=PALETTE[1])
    right.set_ylabel("nonlinearity residual (ppm of full scale)")
    left_text = diagnosis.verdict
    if diagnosis.remaining:
        left_text += f": {diagnosis.remaining[0].shape} is left ({100 * diagnosis.remaining[0].share:.0f} %)"
    left.set_title(f"watch the error fall ({left_text})", fontsize=8)
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
    for ax, d in zip(axes, devices):
        ax.plot(res[d][:rows], ".", color="0.3", ms=3, label=f"baseline residual ({fit.devices[d]})")
        for i, c in enumerate([c for c in diagnosis.ranking if c.testable][:top]):
            ax.plot(c.fingerprint[d][:rows], lw=1, color=_colour(i), label=f"{c.effect} (predicted)")
        _boundaries(ax, fit.data, rows)
        ax.set_ylabel("standardised\nresidual")
        ax.legend(fontsize=6, loc="upper right")
    axes[-1].set_xlabel("point (sweeps in order; dotted: run boundaries; padding points are zero)")
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

    from ._io import atomic_write_bytes

    if isinstance(fig_or_ax, np.ndarray):
        fig_or_ax = fig_or_ax.flat[0]
    fig = fig_or_ax.figure if hasattr(fig_or_ax, "figure") and not isinstance(fig_or_ax, plt.Figure) else fig_or_ax
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
