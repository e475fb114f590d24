"""`gyrojax diagnose`: the missing effect found and added."""

import argparse
import os
import sys

from .._data.io import atomic_directory
from .._text import safe_name, safe_text
from .common import (
    EXIT_FAILED,
    EXIT_OK,
    check_result_outputs,
    device_names,
    effects_module_option,
    model_arg,
    positive_int,
    result_options,
    table_and_fit,
    write_result_files,
)


def _alpha(text):
    try:
        alpha = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--alpha expects a number in (0, 0.5], got {text!r}") from None
    if not 0 < alpha <= 0.5:  # also refuses nan
        raise argparse.ArgumentTypeError(f"--alpha is a significance level and must lie in (0, 0.5], got {text!r} "
                                         "(e.g. 0.01; alpha 5 would call every candidate significant)")
    return alpha


def _escape_markdown(folder: str, names) -> None:
    """The report's Markdown pages with the data's unsafe device names escaped (see `safe_text`)."""
    for entry in sorted(os.listdir(folder)):
        if entry.endswith(".md"):
            path = os.path.join(folder, entry)
            with open(path, encoding="utf-8") as f:
                text = f.read()
            if safe_text(text, names) != text:
                with open(path, "w", encoding="utf-8") as f:
                    f.write(safe_text(text, names))


def handle(args):
    from .._diagnose import diagnose, write_report

    if args.workers is not None or args.scheduler is not None:
        raise ValueError(f"{'--workers' if args.workers is not None else '--scheduler'}: a diagnosis is not run in "
                         "chunks of devices: which effect the lot's residuals show, its significance over every "
                         "description and candidate, and each step's fit are decided for the lot as a whole. Fit a "
                         "large lot with gyrojax identify --workers, and diagnose a sample of its devices (a few "
                         "hundred) in one process.")
    check_result_outputs(args, ("--report", args.report, True), ("--draft-effect", args.draft_effect, False))
    table, fit = table_and_fit(args)
    diag = diagnose(args.model, table, alpha=args.alpha, fit=fit, progress=not args.quiet)
    names = device_names(table)
    print(safe_text(diag.summary(), names))
    if args.report:
        with atomic_directory(args.report) as folder:  # the report folder appears whole or not at all
            write_report(diag, folder)
            _escape_markdown(folder, names)
        print(f"wrote report to {args.report}")
    write_result_files(args, diag)
    if args.draft_effect:
        from .._diagnose.draft import DraftError, write_draft
        from .._diagnose.formula import Formula

        formula = diag.formula  # a Formula or None (Diagnosis types it as object)
        if not isinstance(formula, Formula):
            print("gyrojax diagnose: no draft written: no term of the dictionary is significant in what is left "
                  f"(verdict: {diag.verdict})", file=sys.stderr)
            return EXIT_FAILED
        try:
            write_draft(formula, args.draft_effect, source=str(args.data))
        except DraftError as e:
            print(f"gyrojax diagnose: no draft written: {e}", file=sys.stderr)
            return EXIT_FAILED
        print(f"wrote {args.draft_effect}: {formula.description}; load it with --effects-module")
    if "not converged" in diag.final.status:
        bad = [f"{safe_name(d)}: {m}" for d, m, st in zip(diag.final.devices, diag.final.result_message,
                                                            diag.final.status) if st == "not converged"]
        print(f"gyrojax diagnose: the final fit did not converge: {'; '.join(bad)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def add_parser(sub) -> None:
    """`gyrojax diagnose`: the missing effect found and added."""
    diag = sub.add_parser("diagnose", help="compare model and data, find the missing physical effect, add it",
                          description="Fit the preset's baseline (per device: its gains free, a bias per run), "
                                      "rank every candidate effect by a score test, add the significant ones one "
                                      "at a time (likelihood-ratio confirmed) and report the error falling.")
    diag.add_argument("data", help="a tidy data file (.csv or .parquet): rate_table, vcf_static, vcf_dynamic, dac")
    diag.add_argument("--model", type=model_arg, default="paper-qmg",
                      help="baseline device: a preset or a device file FILE.toml (default paper-qmg)")
    diag.add_argument("--alpha", type=_alpha, default=0.01,
                      help="family-wise significance per step, in (0, 0.5] (default 0.01)")
    diag.add_argument("--json", help="write the diagnosis as JSON here (keys in docs/diagnosis.md)")
    result_options(diag, "diagnosis")
    diag.add_argument("--report", metavar="DIR",
                      help="write a Markdown report with PNG plots into the folder DIR (new, empty, or written by "
                           "gyrojax before: it is replaced as a whole)")
    diag.add_argument("--fit", metavar="FIT", help="a fit of this data saved by `gyrojax identify --save`: the "
                                                  "baseline, instead of fitting it again (its preset replaces --model)")
    diag.add_argument("--draft-effect", metavar="FILE.py",
                      help="write the proposed missing term (the diagnosis's formula) as an effect module here, "
                           "ready for --effects-module")
    diag.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    diag.add_argument("--workers", type=positive_int("--workers"), default=None, metavar="N",
                      help="refused, with the reason: a diagnosis decides for the lot as a whole (see identify "
                           "--workers)")
    diag.add_argument("--scheduler", default=None, metavar="ADDRESS", help="refused, as --workers")
    effects_module_option(diag)
    diag.set_defaults(func=handle)
