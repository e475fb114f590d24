"""`gyrojax compensate`: a scale-factor compensator fitted on training runs and judged on the rest."""

import argparse
import sys

from .._text import safe_name, safe_text
from .common import (
    EXIT_FAILED,
    EXIT_OK,
    check_result_outputs,
    effects_module_option,
    load_effects,
    result_options,
    write_result_files,
)


def _run_list(text):
    try:
        runs = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--train-runs expects run ids like 0,1, got {text!r}") from None
    if not runs:
        raise argparse.ArgumentTypeError(f"--train-runs expects at least one run id, got {text!r}")
    return runs


def handle(args):
    from .._compensate.compensate import compensate
    from .._data.files import read_table

    check_result_outputs(args)
    load_effects(args)
    result = compensate(read_table(args.data), method=args.method, train_runs=args.train_runs,
                        progress=not args.quiet)
    print(result.summary())  # device names escaped by the result
    undetermined = sum(r.nonlinearity_max_ppm_before is None or r.nonlinearity_max_ppm_after is None
                       for r in result.runs)
    write_result_files(args, result)
    for d in result.devices:
        if not d.converged:
            print(f"gyrojax compensate: device {safe_name(d.device)}: {safe_text(d.message)}", file=sys.stderr)
    if undetermined:
        print(f"gyrojax compensate: {undetermined} run(s) gave no nonlinearity (n/a above)", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def add_parser(sub) -> None:
    """`gyrojax compensate`: a scale-factor compensator fitted and judged."""
    comp = sub.add_parser("compensate", help="fit a scale-factor compensator on training runs, judge it on the rest",
                          description="Compensate the rate_table sweeps of a data file: fit on the training runs "
                                      "of each device, report the worst nonlinearity of every run and the "
                                      "repeatability before and after (seed 000's metrics).")
    comp.add_argument("data", help="a tidy data file (.csv or .parquet) with rate_table rows")
    comp.add_argument("--method", choices=("polynomial", "composite", "model"), default="composite",
                      help="polynomial: seed 000's traditional baseline; composite: seed 000's method (needs "
                           "drive_freq_hz); model: invert the identified physical model (needs drive_freq_hz). "
                           "Default composite")
    comp.add_argument("--train-runs", type=_run_list, default=None, metavar="LIST",
                      help="comma-separated run ids to fit on, e.g. 0,1 (default: each device's first run)")
    comp.add_argument("--json", help="write the report as JSON here")
    result_options(comp, "report")
    comp.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    effects_module_option(comp)
    comp.set_defaults(func=handle)
