"""`gyrojax compensate`: a scale-factor compensator fitted on training runs and judged on the rest."""

import argparse
import sys

from .._text import safe_name, safe_text
from .common import (
    EXIT_FAILED,
    EXIT_OK,
    check_outputs,
    effects_module_option,
    load_effects,
    na,
    write_json,
)


def _run_list(text):
    try:
        runs = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--train-runs expects run ids like 0,1, got {text!r}") from None
    if not runs:
        raise argparse.ArgumentTypeError(f"--train-runs expects at least one run id, got {text!r}")
    return runs


def _compensation_na(run: dict, when: str) -> str:
    """Why a run's nonlinearity before/after compensation is None."""
    if when == "after" and run.get("converged") is False:
        return "the compensation did not converge for this device (see its message)"
    if run.get(f"scale_factor_{when}") == 0:
        return ("the outputs do not change with the input" if when == "before"
                else "the compensated rates do not change with the input")
    return "not determined"


def handle(args):
    from .._compensate.compensate import compensate
    from .._data.files import read_table

    check_outputs(("--json", args.json, False))
    load_effects(args)
    result = compensate(read_table(args.data), method=args.method, train_runs=args.train_runs,
                        progress=not args.quiet)
    undetermined = 0
    print(f"{'device':>16} {'run':>4} {'use':>8}  worst nonlinearity before -> after (ppm)")
    for r in result.runs:
        before, after = r["nonlinearity_max_ppm_before"], r["nonlinearity_max_ppm_after"]
        undetermined += before is None or after is None
        print(f"{safe_name(r['device']):>16} {r['run']:>4} {'train' if r['used_for_training'] else 'held-out':>8}  "
              f"{na(before, '10.2f', _compensation_na(r, 'before'))} -> "
              f"{na(after, '.2f', _compensation_na(r, 'after'))}")
    for d in result.devices:
        if d["n_runs"] < 2:
            continue
        before, after = d["repeatability_ppm_before"], d["repeatability_ppm_after"]
        print(f"{safe_name(d['device']):>16} repeatability over {d['n_runs']} runs: "
              f"{na(before, '.2f', 'not determined', ' ppm')} -> {na(after, '.2f', 'not determined', ' ppm')} "
              f"({args.method}, trained on runs "
              f"{', '.join(map(str, d['train_runs']))})")
    if args.json:
        write_json(result.to_json(), args.json)
        print(f"wrote {args.json}")
    for d in result.devices:
        if d.get("converged") is False:
            print(f"gyrojax compensate: device {safe_name(d['device'])}: {safe_text(d['message'])}", file=sys.stderr)
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
    comp.add_argument("--quiet", action="store_true", help="no progress messages (on standard error)")
    effects_module_option(comp)
    comp.set_defaults(func=handle)
