"""Plots a reader of a fit or a diagnosis wants (matplotlib; every function takes an optional `ax`)."""

import matplotlib.pyplot as plt
import numpy as np

_XLABEL = {"rate_table": "table rate (deg/s)", "vcf_static": "virtual-rate voltage V_ac (V)",
           "vcf_dynamic": "modulation frequency (Hz)", "dac": "DAC word (LSB)"}


def _ax(ax):
    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 4.0))
    return ax


def residuals(fit, sweep: str = "rate_table", *, ax=None, device: int | None = None):
    """Model minus measurement (after each run's bias) in units of the output, with the +/- 1 sigma noise band,
    against the sweep's input, one colour per device."""
    ax = _ax(ax)
    block = fit.data.blocks[sweep]
    x, m = np.asarray(block.inputs), np.asarray(block.mask)
    res = np.asarray(fit.residuals[sweep]) * np.asarray(block.sigmas)
    sig = np.asarray(block.sigmas)
    devices = range(x.shape[0]) if device is None else [device]
    for d in devices:
        order = np.argsort(x[d][m[d]])
        ax.plot(x[d][m[d]][order], res[d][m[d]][order], ".", ms=4, label=fit.devices[d])
        ax.fill_between(x[d][m[d]][order], -sig[d][m[d]][order], sig[d][m[d]][order], color="0.85", zorder=0)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel(_XLABEL.get(sweep, "input"))
    ax.set_ylabel("measurement - model (output units)")
    ax.set_title(f"{sweep}: residuals (grey: 1-sigma noise), chi2_red {fit.chi2_red_total:.3g}")
    if x.shape[0] <= 8:
        ax.legend(fontsize=7)
    return ax


def ranking(scores, *, ax=None):
    """Score-test statistics of the candidate effects (log scale), untestable ones marked."""
    ax = _ax(ax)
    names = [c.effect for c in scores]
    stats = [max(c.statistic, 1e-3) if c.testable else 1e-3 for c in scores]
    colours = ["C3" if c.testable and c.p_value < 0.01 / max(len(scores), 1) else ("C0" if c.testable else "0.7")
               for c in scores]
    ax.barh(names[::-1], stats[::-1], color=colours[::-1])
    ax.set_xscale("log")
    ax.set_xlabel("score statistic S (chi2); red: significant, grey: not testable on this data")
    ax.set_title("which effect is missing? (no refit)")
    return ax


def error_fall(diagnosis, *, ax=None):
    """Reduced chi2 and the model-vs-measurement nonlinearity residual, step by step."""
    from ._diagnose import nonlinearity_residual_ppm

    ax = _ax(ax)
    labels = ["baseline"] + [f"+ {s.effect}" for s in diagnosis.steps]
    chi2 = [f.chi2_red_total for f in diagnosis.fits]
    nl = [nonlinearity_residual_ppm(f) for f in diagnosis.fits]
    ax.semilogy(labels, chi2, "o-", label="reduced chi2")
    ax.semilogy(labels, nl, "s--", label="nonlinearity residual (ppm of FS)")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.set_title("watch the error fall")
    ax.legend()
    return ax


def fingerprints(diagnosis, *, top: int = 3, ax=None):
    """The actual residual of the baseline (device 0, all sweeps in order) against the predicted residual
    change of the top candidates: the one that matches is the missing effect."""
    ax = _ax(ax)
    fit = diagnosis.baseline
    r = np.asarray(fit.residual_vector)[0]
    ax.plot(r, "k.", ms=3, label="baseline residual (device 0)")
    for c in [c for c in diagnosis.ranking if c.testable][:top]:
        ax.plot(c.fingerprint[0], lw=1, label=f"{c.effect} (predicted)")
    ax.set_xlabel("point (sweeps in order, runs within)")
    ax.set_ylabel("standardised residual")
    ax.set_title("candidate fingerprints against the residual")
    ax.legend(fontsize=7)
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
    """VCF (or rate) frequency response amplitude, normalised to its first point."""
    ax = _ax(ax)
    a = np.asarray(amplitude) / np.asarray(amplitude)[0]
    ax.semilogx(freqs_hz, 20 * np.log10(a), label=label)
    if reference is not None:
        ax.semilogx(freqs_hz, 20 * np.log10(np.asarray(reference) / np.asarray(reference)[0]), "--", label="model")
    ax.axhline(-3.0, color="k", lw=0.6)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("gain (dB)")
    ax.legend()
    return ax


def save(fig_or_ax, path):
    """Save atomically (PNG)."""
    import io

    from ._io import atomic_write_bytes

    fig = fig_or_ax.figure if hasattr(fig_or_ax, "figure") and not isinstance(fig_or_ax, plt.Figure) else fig_or_ax
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
