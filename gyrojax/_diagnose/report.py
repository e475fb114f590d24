"""The diagnosis's report folder: Markdown, JSON and PNG plots."""

import numpy as np

from .._identify import Fit
from .location import Location


def write_report(diagnosis, out_dir) -> dict:
    """A report folder of a `gyrojax.Diagnosis`: `diagnosis.md`, `diagnosis.json` and PNG plots (residuals before
    and after, where the misfit lives, the ranking, the fingerprints, the error falling). The folder appears whole
    or not at all (`out_dir` may be new, empty, or a folder gyrojax wrote before, which is replaced). Returns the
    JSON."""
    import os

    from .._data.io import atomic_directory
    from .._report import MarkdownFormat, write_result

    with atomic_directory(out_dir) as folder:
        figures = _figures(diagnosis, folder)
        report = diagnosis.to_json()
        write_result(diagnosis, os.path.join(folder, "diagnosis.json"))
        write_result(diagnosis, os.path.join(folder, "diagnosis.md"), MarkdownFormat(figures=tuple(figures)))
    return report


def markdown_text(diagnosis) -> str:
    """`diagnosis.md` without its plots (the `markdown` output format appends them where there are some)."""
    return "\n".join(_markdown(diagnosis, []))


def _figures(diagnosis, folder) -> list[tuple[str, str]]:
    """The report's PNG plots, written into `folder`: (title, file name) each, in the report's order."""
    import os

    import matplotlib.pyplot as plt

    from .. import plot

    sweeps = diagnosis.baseline.data.sweeps
    figures = []
    fig, axes = plt.subplots(len(sweeps), 2, figsize=(12, 3.2 * len(sweeps)), squeeze=False)
    for i, sweep in enumerate(sweeps):
        plot.residuals(diagnosis.baseline, sweep, ax=axes[i, 0])
        axes[i, 0].set_title(f"baseline {sweep}: chi2_red {diagnosis.baseline.chi2_red_total:.3g}", fontsize=9)
        plot.residuals(diagnosis.final, sweep, ax=axes[i, 1])
        axes[i, 1].set_title(f"final {sweep}: chi2_red {diagnosis.final.chi2_red_total:.3g}", fontsize=9)
    plot.save(fig, os.path.join(folder, "residuals.png"))
    figures.append(("Model against measurement, before and after", "residuals.png"))
    if any(d.significant for d in diagnosis.baseline_discrepancy):
        fig, axes = plt.subplots(1, 2, figsize=(12, 3.8))
        plot.discrepancy(diagnosis, final=False, ax=axes[0])
        plot.discrepancy(diagnosis, final=True, ax=axes[1])
        plot.save(fig, os.path.join(folder, "discrepancy.png"))
        figures.append(("Where the misfit lives: the leading generic shape, at the baseline and at the end",
                        "discrepancy.png"))
    if diagnosis.ranking:
        plot.save(plot.ranking(diagnosis.ranking, alpha=diagnosis.alpha,
                               max_typical_multiple=diagnosis.max_typical_multiple),
                  os.path.join(folder, "ranking.png"))
        figures.append(("Candidate effects ranked by the score test", "ranking.png"))
        plot.save(plot.fingerprints(diagnosis), os.path.join(folder, "fingerprints.png"))
        figures.append(("Predicted residual shape of the top candidates against the residual, per device",
                        "fingerprints.png"))
    plot.save(plot.error_fall(diagnosis), os.path.join(folder, "error_fall.png"))
    figures.append(("The error falling step by step", "error_fall.png"))
    return figures


def _markdown(diagnosis, figures) -> list[str]:
    """The lines of `diagnosis.md`: the verdict, where the misfit lives, the summary, each fit's comparison, the
    steps, what was not confirmed or is not testable, and the `figures`."""
    sweeps = diagnosis.baseline.data.sweeps
    data = diagnosis.baseline.data
    lines = ["# gyrojax diagnosis", "", f"Data: `{data.source}`, {len(diagnosis.baseline.devices)} device(s), "
             f"sweeps {', '.join(sweeps)}.", "", f"**{diagnosis.verdict_text()}**", ""]
    notes = diagnosis.baseline_notes
    if notes:
        lines += ["## About the data", ""] + [f"- {note} ({', '.join(devices)})" for note, devices in notes.items()]
        lines.append("")
    left = diagnosis.remaining
    found = [d for d in diagnosis.baseline_discrepancy if d.significant and not d.within]
    lines += ["## Where the misfit lives", "",
              "Generic shapes (a bias or gain in die temperature, time since power-on, drive frequency or run; "
              "odd cubics after and of the DAC; an even bow; K+ vs K-), scored from the same fit as the "
              "candidate effects, with the share of the misfit each explains and the size of the term it "
              "implies.", ""]
    for title, items in (("At the baseline", found), ("What is left at the end", left)):
        lines += [f"{title}:", ""]
        lines += [f"- `{d.coordinate}`: {discrepancy_text(d)} (S = {d.chi2_explained:.4g}, p = {d.p_value:.2g})"
                  for d in items] or ["- nothing significant"]
        lines.append("")
    lines += ["## Summary", "", "```", diagnosis.summary(comparisons=False), "```", "",
              "## Where the model fails, fit by fit", "",
              "Misfit by sweep, device, run and input band (share of the chi2 in excess of the point count), "
              "and structure tests on the residuals along every recorded coordinate (`gyrojax.compare`):", ""]
    for k, c in enumerate(diagnosis.comparisons):
        name = "baseline" if k == 0 else f"+ {diagnosis.steps[k - 1].effect}"
        lines += [f"### {name}", "", "```", c.summary(), "```", ""]
    lines += ["## Step by step", "", "| step | effect | chi2_red | nonlinearity residual (ppm) |",
              "|---|---|---|---|",
              f"| 0 | baseline | {diagnosis.baseline.chi2_red_total:.3f} | "
              f"{_ppm_cell(diagnosis.baseline_nonlinearity_ppm, diagnosis.baseline)} |"]
    for k, s in enumerate(diagnosis.steps, 1):
        lines.append(f"| {k} | + {s.effect} | {s.chi2_red_after:.3f} | "
                     f"{_ppm_cell(s.nonlinearity_ppm_after, diagnosis.fits[k])} |")
    if diagnosis.rejected:
        lines += ["", "Candidates not confirmed, and why:", ""]
        lines += [f"- `{r.effect}`: {r.reason}." for r in diagnosis.rejected]
    lines += ["", "Effects marked *not testable* leave no fingerprint that the baseline's free parameters "
              "(gains, per-run biases) cannot absorb on this data. What absorbs each, and the measurement that "
              "would reveal it:", ""]
    lines += [f"- `{name}`: {why}." for name, why in diagnosis.absorptions.items()] or ["- none"]
    lines += [""]
    for title, name in figures:
        lines += [f"## {title}", "", f"![{title}]({name})", ""]
    return lines


def _ppm_cell(value: float, fit) -> str:
    """A nonlinearity for the step table: the number, or n/a with the reason."""
    import math

    return f"{value:.2f}" if math.isfinite(value) else f"n/a ({nonlinearity_not_determined(fit)})"


def discrepancy_text(d) -> str:
    """A significant discrepancy in words: its share of the misfit where it has one (1 % or more); else what it
    is, where and how large, with "below 1 % of the misfit" (significant in a large lot, or at a chi2 at the
    noise level, where there is no excess misfit to share) rather than "0 % of the misfit is"."""
    if round(100 * d.share) >= 1 or isinstance(d, Location):  # a location says it in its own words
        return d.description
    where = ", ".join(f"{s} {100 * f:.0f} %" for s, f in d.sweeps)
    size = f"{d.coefficient:.3g} {d.unit}" + (f" (device spread {d.coefficient_spread:.2g})"
                                               if d.coefficient_spread > 0 else "")
    text = f"{d.shape} ({where}): about {size}, significant but below 1 % of the misfit"
    if d.same_shape_as:
        text += f"; this data cannot tell it from {', '.join(d.same_shape_as)}"
    return text + (f"; {d.library}" if d.library else "")


def nonlinearity_not_determined(fit: Fit) -> str:
    """Why the model-vs-measurement nonlinearity of `fit` (`nonlinearity_residual_ppm`) is not a number."""
    if "rate_table" not in fit.residuals:
        return ("no rate_table sweep: the nonlinearity is that of the rate-table points, as ppm of the scale "
                "factor's full scale")
    if not np.all(np.isfinite(np.asarray(fit.scale_factor))):
        return "the data do not determine the scale factor (as identify says): there is no full scale to divide by"
    return "not determined by this fit"
